"""What the planner imagines: candidate thrust sequences -> state trajectories.

Both models answer ``rollout(state0 (16,), actions (K, H, 8)) -> states (K, H, 16)``, the
states after each action (frames t+1..t+H), in the dataset's convention (``orbitdata.state``):

* :class:`LearnedDynamics`: the Stage I world model rolls the latents forward from the last
  ``history`` encoded frames, and the physics probe reads states out of them (the planner);
* :class:`RigidBodyDynamics`: the rigid-body model the simulator integrates, batched in torch
  (the oracles' "true dynamics").
"""

from __future__ import annotations

from collections import deque
from typing import Protocol

import numpy as np
import torch

from orbitdata.sim.config import SimConfig
from orbitdata.sim.thrusters import wrench_matrix
from orbitmodel.kinematics import FUEL, ROT, P, V, W, matrix_to_rot6d, rot6d_to_matrix, so3_exp
from orbitmodel.plan.frames import FrameEncoder
from orbitmodel.plan.timing import Timings


class Probe(Protocol):
    """The PhysicsProbe's API: latents (B, n, D) of a world model stepping s frames, the state
    (B, 16) and latent (B, D) of frame t, the planned actions (B, n, 8 s) of the n steps -> states
    (B, n s, 16) of frames t+1..t+n s. z_last is what a probe reading latent changes starts from,
    the actions what one reading thrusts reads (others ignore them)."""

    def per_frame(
        self,
        z_future: torch.Tensor,
        state0: torch.Tensor,
        z_last: torch.Tensor | None,
        frame_step: int,
        actions: torch.Tensor | None = None,
    ) -> torch.Tensor: ...


class RigidBodyDynamics:
    """The simulator's physics in torch: thrust -> body wrench (the thruster geometry), mass and
    inertia from the fuel, fuel burn with the empty-tank cut-off, semi-implicit Euler.

    MuJoCo (``orbitdata.sim.env``) steps a free body with Euler at ``dt / sim.substeps``:
    velocity first, then position and attitude (``R <- R exp(w h)``) with the new velocity; the
    inertia is isotropic, so there is no gyroscopic torque. With ``substeps`` equal to the
    simulator's this is MuJoCo's own scheme (to float32 rounding); fewer substeps are faster and
    fold the skipped fine steps into the position and angle increments exactly for a constant
    attitude (errors measured in ``tests/model/test_plan_dynamics.py``).
    """

    needs_images = False

    def __init__(self, sim: SimConfig = SimConfig(), substeps: int = 1, timings: Timings | None = None):
        if not 1 <= substeps <= sim.substeps or sim.substeps % substeps:
            raise ValueError(f"substeps={substeps}: give a divisor of the simulator's {sim.substeps} substeps")
        cubesat = self.cubesat = sim.cubesat
        self.dt, self.substeps = float(sim.dt), int(substeps)
        fine = sim.substeps // substeps  # simulator steps folded into each of ours
        self._fold = (fine - 1) / (2 * fine)
        self.W = torch.tensor(wrench_matrix(cubesat), dtype=torch.float32)  # (6, 8) [N; N m] per unit thrust
        self.mdot = cubesat.mass_flow_per_thrust  # kg/s per unit thrust
        self.timings = timings or Timings()

    def reset(self) -> None:
        pass

    def observe(self, obs: dict, previous_action: np.ndarray | None) -> None:
        """Markov: the state alone is enough."""

    @torch.inference_mode()
    def rollout(self, state0: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """state0 (16,) or (K, 16), actions (K, H, 8) thrust in [0,1] -> states (K, H, 16)."""
        with self.timings("rollout"):
            return self._rollout(state0, actions)

    def _rollout(self, state0: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        # Everything but the attitude chain is a cumulative sum, so it runs as a few batched
        # ops over the whole horizon; only R <- R exp(w h) is a loop (one bmm per substep).
        K, H, _ = actions.shape
        n, h = self.substeps, self.dt / self.substeps
        s0 = state0.float().expand(K, -1)
        R0 = rot6d_to_matrix(s0[:, ROT])  # (K, 3, 3) body -> world
        # Fuel: once the tank is empty it stays empty, so the fuel at each step's start is the
        # clamped running sum; the step that empties it is scaled to what was left (as the env).
        burn = actions.sum(-1) * (self.mdot * self.dt)  # (K, H) kg per step at full command
        fuel = (s0[:, FUEL] * self.cubesat.fuel_mass - (torch.cumsum(burn, 1) - burn)).clamp(min=0.0)  # (K, H) kg
        scale = (fuel / burn.clamp(min=1e-12)).clamp(max=1.0)  # (K, H)
        mass, inertia = self.cubesat.mass_properties(fuel)  # (K, H) each, held over the step
        wrench = (actions * scale[..., None]) @ self.W.T  # (K, H, 6) body frame
        accel = (wrench[..., :3] / mass[..., None]).repeat_interleave(n, 1)  # (K, H n, 3) m/s^2, body
        alpha = (wrench[..., 3:] / inertia[..., None]).repeat_interleave(n, 1)  # (K, H n, 3) rad/s^2, body
        w = s0[:, None, W] + torch.cumsum(alpha * h, 1)  # (K, H n, 3) after each substep
        # The simulator's fine steps inside one of ours turn by sum_i w_i h/f = (w - c alpha h) h
        # and move by (v - c a h) h, with c = (f - 1) / 2f: the same scheme, summed exactly.
        turn = so3_exp((w - self._fold * h * alpha) * h)  # (K, H n, 3, 3)
        Rs = [R0]
        for j in range(H * n):
            Rs.append(Rs[-1] @ turn[:, j])
        R = torch.stack(Rs, 1)  # (K, H n + 1, 3, 3): R[:, j] at the start of substep j
        v0 = (R0 @ s0[:, V, None]).squeeze(-1)  # (K, 3) m/s, world
        # ... and push along the attitude they pass through: R (I + c h [w]x) to first order.
        accel = accel + self._fold * h * torch.linalg.cross(w, accel, dim=-1)
        accel_world = (R[:, :-1] @ accel[..., None]).squeeze(-1)  # (K, H n, 3)
        v = v0[:, None] + torch.cumsum(accel_world * h, 1)  # (K, H n, 3) m/s, world
        p = s0[:, None, P] + torch.cumsum((v - self._fold * h * accel_world) * h, 1)  # (K, H n, 3) metres, world
        end = slice(n - 1, None, n)  # the last substep of each control step
        R_end = R[:, n::n]  # (K, H, 3, 3)
        v_body = (R_end.transpose(-1, -2) @ v[:, end, :, None]).squeeze(-1)  # (K, H, 3)
        fuel_after = (fuel - burn * scale).clamp(min=0.0) / self.cubesat.fuel_mass  # (K, H) ratio
        return torch.cat([p[:, end], v_body, matrix_to_rot6d(R_end), w[:, end], fuel_after[..., None]], -1)


class LearnedDynamics:
    """The world model and its probe: encode each observed frame, keep the latents and actions
    its next rollout starts from, roll K candidate sequences out in latent space and read the
    states with the probe.

    ``rollout`` imagines from the newest observed frame t: context latents t-m+1..t (m <=
    history; fewer at the start of an episode), the m-1 actions taken between them, then the
    H planned actions; the probe integrates from the observed state at t.

    A world model with ``frame_step`` s > 1 steps s frames at a time: its context latents are
    frames t, t-s, t-2s, ..., each step's action the s thrusts taken through it, and a plan of
    H frames (a multiple of s) is H / s predictor calls. A per-frame probe gives every frame's
    state; one giving the state every s frames has the frames between interpolated linearly
    (position, velocity, attitude columns, rates, fuel), so the cost sees one state per frame
    whatever the model's step (``PhysicsProbe.per_frame``).
    """

    needs_images = True

    def __init__(
        self,
        model,
        probe: Probe,
        timings: Timings | None = None,
        history: int | None = None,
        frames: FrameEncoder | None = None,
    ):
        self.model = model.eval()
        self.probe = probe
        self.frames = frames or FrameEncoder(self.model)  # share it with the depth head: one ViT pass a frame
        self.step = int(model.config.frame_step)
        self.history = model.config.history if history is None else int(history)
        if not 1 <= self.history <= model.config.history:
            raise ValueError(
                f"history={self.history}: the world model rolls out from at most "
                f"{model.config.history} latents; give 1..{model.config.history}"
            )
        self.timings = timings or Timings()
        self.reset()

    def reset(self) -> None:
        span = (self.history - 1) * self.step  # frames between the oldest and the newest context latent
        self._z: deque[torch.Tensor] = deque(maxlen=span + 1)  # (D,) per observed frame
        self._actions: deque[torch.Tensor] = deque(maxlen=max(span, 1))  # (8,) each, between frames

    @torch.inference_mode()
    def observe(self, obs: dict, previous_action: np.ndarray | None) -> None:
        """Encode the new frame; ``previous_action`` led to it from the last observed frame."""
        with self.timings("encode"):
            cls, _ = self.frames(obs["image"])  # (1, width)
            state = torch.as_tensor(obs["state"], dtype=torch.float32)[None]  # (1, 16)
            z = self.model.latent_from_cls(cls, state)[0]  # (D,)
        if previous_action is not None and len(self._z):
            self._actions.append(torch.as_tensor(previous_action, dtype=torch.float32))
        elif len(self._z):  # a gap in the action record: the old context no longer leads here
            self.reset()
        self._z.append(z)

    def context(self) -> tuple[torch.Tensor, torch.Tensor | None]:
        """The newest frame's context: latents (m, D), oldest first, every ``step``-th frame back
        from the newest, and the actions between them (m-1, 8 step), or None when m = 1."""
        s, seen = self.step, len(self._z)
        m = min(self.history, 1 + (seen - 1) // s)
        frames = range(seen - 1 - (m - 1) * s, seen, s)
        z = torch.stack([self._z[i] for i in frames])  # (m, D)
        if m == 1:
            return z, None
        taken = list(self._actions)[-(m - 1) * s :]  # the (m-1) s thrusts since the oldest context frame
        assert len(taken) == (m - 1) * s, "one action between each pair of observed frames"
        return z, torch.stack(taken).reshape(m - 1, s * taken[0].shape[-1])

    @torch.inference_mode()
    def rollout(self, state0: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """state0 (16,) observed at the newest frame, actions (K, H, 8) -> states (K, H, 16)."""
        if not self._z:
            raise RuntimeError("observe() a frame before rollout()")
        K, H, _ = actions.shape
        s = self.step
        if H % s:
            raise ValueError(
                f"a plan of {H} frames does not split into the world model's steps of {s} frames; "
                f"give a horizon that is a multiple of {s}"
            )
        with self.timings("rollout"):
            z, past = self.context()
            z_ctx = z[None].expand(K, -1, -1)  # (K, m, D)
            planned = actions.float().reshape(K, H // s, s * actions.shape[-1])  # (K, H / s, 8 s)
            if past is not None:
                planned = torch.cat([past[None].expand(K, -1, -1), planned], 1)  # (K, m-1+H/s, 8 s)
            z_future = self.model.rollout(z_ctx, planned, self.history)  # (K, H / s, D)
        with self.timings("probe"):
            start = state0.float().expand(K, -1)
            return self.probe.per_frame(z_future, start, z_ctx[:, -1], s, planned[:, -(H // s) :])  # (K, H, 16)
