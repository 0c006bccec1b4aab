"""What the planner imagines: candidate thrust sequences -> state trajectories.

Both models answer ``rollout(state0 (16,), actions (K, H, 8)) -> states (K, H, 16)``, the
states after each action (frames t+1..t+H), in the dataset's convention (``orbitdata.state``):

* :class:`LearnedDynamics`: the Stage I world model rolls the latents forward from the last
  ``history`` encoded frames, and the physics probe reads states out of them (the planner);
* :class:`RigidBodyDynamics`: the rigid-body model the simulator integrates, batched in torch
  (the oracles' "true dynamics").

Each episode has its own instance (:meth:`fork`: the learned one keeps the episode's latents);
``rollout_many`` imagines the candidates of several episodes in one call, as the lockstep
flights do (``plan.batch``).
"""

from __future__ import annotations

import copy
from collections import deque
from typing import Protocol

import numpy as np
import torch

from orbitdata.sim.config import SimConfig
from orbitdata.sim.thrusters import wrench_matrix
from orbitmodel.kinematics import FUEL, ROT, P, V, W, matrix_to_rot6d, rot6d_to_matrix, so3_exp
from orbitmodel.plan.frames import FrameEncoder
from orbitmodel.plan.timing import Timings


def joined(parts: list[torch.Tensor]) -> torch.Tensor:
    """The parts concatenated along dim 0; one part is passed on as it is (a batch of one computes
    exactly what the unbatched call did)."""
    return parts[0] if len(parts) == 1 else torch.cat(parts)


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

    def fork(self) -> "RigidBodyDynamics":
        """Stateless: every episode shares it."""
        return self

    def observe(self, obs: dict, previous_action: np.ndarray | None) -> None:
        """Markov: the state alone is enough."""

    @torch.inference_mode()
    def rollout(self, state0: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """state0 (16,) or (K, 16), actions (K, H, 8) thrust in [0,1] -> states (K, H, 16)."""
        with self.timings("rollout"):
            return self._rollout(state0, actions, self.responses([self], [len(actions)]))

    @staticmethod
    @torch.inference_mode()
    def rollout_many(
        members: list["RigidBodyDynamics"], state0s: list[torch.Tensor], actions: list[torch.Tensor]
    ) -> list[torch.Tensor]:
        """Every episode's candidates in one call: state0s N x (16,), actions N x (K, H, 8) -> N x (K, H, 16)."""
        lead = members[0]
        with lead.timings("rollout"):
            sizes = [len(a) for a in actions]
            start = joined([s.float().expand(k, -1) for s, k in zip(state0s, sizes)])  # (N K, 16)
            states = lead._rollout(start, joined(actions), lead.responses(members, sizes))  # (N K, H, 16)
        return list(states.split(sizes))

    def responses(self, members: list["RigidBodyDynamics"], sizes: list[int]) -> list[tuple[torch.Tensor, int]] | None:
        """The thrust response of the ``sizes[i]`` candidates of each of ``members``: None, the
        thruster geometry's wrench for all (a subclass fitting its own gives each member's response
        and its number of candidates: ``plan.fitted_body``)."""
        return None

    def _accelerations(self, actions, scale, mass, inertia, response=None) -> tuple[torch.Tensor, torch.Tensor]:
        """Body-frame acceleration and angular acceleration (K, H, 3) each of the thrusts
        ``actions`` (K, H, 8) scaled by what the tank gives (``scale`` (K, H)), with the mass and
        inertia (K, H) of each step: the thruster geometry's wrench. (``response``: what
        :meth:`responses` gave, which this class ignores.)"""
        wrench = (actions * scale[..., None]) @ self.W.T  # (K, H, 6)
        return wrench[..., :3] / mass[..., None], wrench[..., 3:] / inertia[..., None]

    def _rollout(self, state0: torch.Tensor, actions: torch.Tensor, response=None) -> torch.Tensor:
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
        accel, alpha = self._accelerations(actions, scale, mass, inertia, response)  # (K, H, 3) each, body frame
        accel = accel.repeat_interleave(n, 1)  # (K, H n, 3) m/s^2
        alpha = alpha.repeat_interleave(n, 1)  # (K, H n, 3) rad/s^2
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

    A probe that reads no latent (``ProbeConfig.reads_latent`` false: the ``thrust_only``
    variant) is a model of the dynamics by itself: the rollout then never calls the world model's
    predictor, and the probe reads each candidate's planned thrusts from the observed state. The
    frames are still encoded, for the depth head that shares the encoder pass.
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
        self.reads_latent = getattr(getattr(probe, "config", None), "reads_latent", True)
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

    def fork(self) -> "LearnedDynamics":
        """The same model, probe and settings with an episode's context of its own (empty)."""
        twin = copy.copy(self)
        twin.reset()
        return twin

    @torch.inference_mode()
    def observe(self, obs: dict, previous_action: np.ndarray | None) -> None:
        """Encode the new frame; ``previous_action`` led to it from the last observed frame."""
        with self.timings("encode"):
            cls, _ = self.frames(obs["image"])  # (1, width)
            state = torch.as_tensor(obs["state"], dtype=torch.float32)[None]  # (1, 16)
            z = self.model.latent_from_cls(cls, state)[0]  # (D,)
        self.push(z, previous_action, obs)

    def push(self, z: torch.Tensor, previous_action: np.ndarray | None, obs: dict | None = None) -> None:
        """Take the new frame's latent z (D,), encoded already (``plan.batch`` encodes N frames at
        once); ``obs``, the frame's observation, is for subclasses that also read the state."""
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

    def rollout(self, state0: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """state0 (16,) observed at the newest frame, actions (K, H, 8) -> states (K, H, 16)."""
        return self.rollout_many([self], [state0], [actions])[0]

    @staticmethod
    @torch.inference_mode()
    def rollout_many(
        members: list["LearnedDynamics"], state0s: list[torch.Tensor], actions: list[torch.Tensor]
    ) -> list[torch.Tensor]:
        """Several episodes' candidates, one world-model call and one probe call for all of them:
        ``members`` the episodes' dynamics (forks of one), state0s N x (16,), actions N x (K, H, 8)
        -> N x (K, H, 16). Episodes whose context holds as many latents share a call (an episode's
        first frames have fewer)."""
        lead = members[0]
        s = lead.step
        for d, a in zip(members, actions):
            if not d._z:
                raise RuntimeError("observe() a frame before rollout()")
            if a.shape[1] % s:
                raise ValueError(
                    f"a plan of {a.shape[1]} frames does not split into the world model's steps of {s} frames; "
                    f"give a horizon that is a multiple of {s}"
                )
        if not lead.reads_latent:
            return lead._thrusts_alone(state0s, actions)
        contexts = [d.context() for d in members]
        groups: dict[int, list[int]] = {}
        for i, (z, _) in enumerate(contexts):
            groups.setdefault(len(z), []).append(i)
        out: list[torch.Tensor | None] = [None] * len(members)
        for rows in groups.values():
            sizes = [len(actions[i]) for i in rows]
            steps = actions[rows[0]].shape[1] // s
            with lead.timings("rollout"):
                z_ctx, planned = [], []
                for i, K in zip(rows, sizes):
                    z, past = contexts[i]
                    z_ctx.append(z[None].expand(K, -1, -1))  # (K, m, D)
                    plan = actions[i].float().reshape(K, steps, s * actions[i].shape[-1])  # (K, H / s, 8 s)
                    if past is not None:
                        plan = torch.cat([past[None].expand(K, -1, -1), plan], 1)  # (K, m-1+H/s, 8 s)
                    planned.append(plan)
                z_ctx, planned = joined(z_ctx), joined(planned)  # (G K, m, D), (G K, m-1+H/s, 8 s)
                z_future = lead.model.rollout(z_ctx, planned, lead.history)  # (G K, H / s, D)
            with lead.timings("probe"):
                start = joined([state0s[i].float().expand(K, -1) for i, K in zip(rows, sizes)])  # (G K, 16)
                group = [members[i] for i in rows]
                states = lead.read_states(
                    group, sizes, z_future, start, z_ctx[:, -1], planned[:, -steps:]
                )  # (G K, H, 16)
            for i, part, z_part in zip(rows, states.split(sizes), z_future.split(sizes)):
                out[i] = part
                members[i].imagined_latents = z_part  # (K, H / s, D): what ``plan.imagined`` reads
        return out

    def read_states(
        self,
        members: list["LearnedDynamics"],
        sizes: list[int],
        z_future: torch.Tensor,
        start: torch.Tensor,
        z_last: torch.Tensor,
        planned: torch.Tensor,
    ) -> torch.Tensor:
        """The states (G K, H, 16) of ``members``' candidates (``sizes[i]`` each) from their imagined
        latents z_future (G K, H / s, D), observed states ``start`` (G K, 16), last context latents
        z_last (G K, D) and planned steps (G K, H / s, 8 s): the probe's (a subclass may correct them,
        ``plan.corrected_body``)."""
        return self.probe.per_frame(z_future, start, z_last, self.step, planned)

    def _thrusts_alone(self, state0s: list[torch.Tensor], actions: list[torch.Tensor]) -> list[torch.Tensor]:
        """``rollout_many`` with a probe that reads no latent: one probe call on every episode's
        candidates, each from its observed state, and no world-model rollout. The probe is handed
        zero latents for their shape only (``PhysicsProbe.forward``)."""
        s, sizes = self.step, [len(a) for a in actions]
        steps = actions[0].shape[1] // s
        with self.timings("probe"):
            planned = joined([a.float().reshape(len(a), steps, s * a.shape[-1]) for a in actions])  # (N K, H / s, 8 s)
            start = joined([x.float().expand(K, -1) for x, K in zip(state0s, sizes)])  # (N K, 16)
            z_future = planned.new_zeros(()).expand(len(planned), steps, self.model.config.latent_dim)
            states = self.probe.per_frame(z_future, start, None, s, planned)  # (N K, H, 16)
        return list(states.split(sizes))
