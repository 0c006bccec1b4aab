"""A body inferred from the pilot's own history: the thrust response fitted to the frames it flew.

On the dynamic tier each episode's body is drawn (mass, inertia, centre of mass) and one thruster
may fail (``docs/design.md``). A pilot may not read that record; it reads its state and knows the
thrusts it commanded. Over one frame the body's response is linear in the thrusts:

    u_k  = R_k^T (R_{k+1} v_{k+1} - R_k v_k)   the change of velocity, in the body frame at k
    dw_k = w_{k+1} - w_k                        the change of body rate
    [u_k, dw_k] = [a_k, 1] @ B                 B (9, 6): per thruster, and a constant

(a stuck thruster is the constant, an off or weak one a smaller row, the centre of mass and
inertia the torque rows; the gyroscopic torque of the drawn inertia is left out). ``B`` is fitted
by ridge regression to the last ``frames`` observed frames, pulled towards the design's nominal
body with weight ``ridge``, so before any history, and along thrust patterns the history never
excited, the pilot plans with the nominal body. :class:`FittedBodyDynamics` rolls candidates out
with the simulator's integrator (``RigidBodyDynamics``) and the fitted response.
"""

from __future__ import annotations

import copy
from collections import deque

import numpy as np
import torch

from orbitdata.sim.config import SimConfig
from orbitmodel.kinematics import FUEL, ROT, V, W, rot6d_to_matrix
from orbitmodel.plan.dynamics import LearnedDynamics, RigidBodyDynamics, joined
from orbitmodel.plan.timing import Timings


def nominal_response(sim: SimConfig, fuel_ratio: float, wrench: torch.Tensor | None = None) -> torch.Tensor:
    """B (9, 6) of the design's body with ``fuel_ratio`` of its propellant: per unit thrust of each
    thruster the change of body-frame velocity (m/s) and body rate (rad/s) over one frame, and no
    constant. ``wrench``: the thrusters' (6, 8) wrench matrix, when the caller holds it already."""
    cubesat = sim.cubesat
    mass, inertia = cubesat.mass_properties(fuel_ratio * cubesat.fuel_mass)
    wrench = RigidBodyDynamics(sim).W if wrench is None else wrench  # (6, 8)
    per_frame = torch.cat([wrench[:3] / mass, wrench[3:] / inertia]) * float(sim.dt)  # (6, 8)
    return torch.cat([per_frame.T, torch.zeros(1, 6)])  # (9, 6)


def frame_changes(states: torch.Tensor) -> torch.Tensor:
    """states (n+1, 16) of consecutive frames -> (n, 6): each frame's [u_k, dw_k] (module docstring)."""
    R = rot6d_to_matrix(states[:, ROT])  # (n+1, 3, 3) body -> world
    v_world = (R @ states[:, V, None]).squeeze(-1)  # (n+1, 3)
    u = (R[:-1].transpose(-1, -2) @ (v_world[1:] - v_world[:-1])[..., None]).squeeze(-1)  # (n, 3)
    return torch.cat([u, states[1:, W] - states[:-1, W]], -1)


def moments(states: torch.Tensor, actions: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """The regression's sums over states (n+1, 16) and the n actions (n, 8) between them, in
    float64: X^T X (9, 9) and X^T Y (9, 6), X = [a_k, 1] and Y the frame changes (zeros for n = 0)."""
    if len(actions) == 0:
        return torch.zeros(9, 9, dtype=torch.float64), torch.zeros(9, 6, dtype=torch.float64)
    X = torch.cat([actions, actions.new_ones(len(actions), 1)], -1).double()  # (n, 9)
    Y = frame_changes(states.double())  # (n, 6)
    return X.T @ X, X.T @ Y


def ridge_solve(gram: torch.Tensor, cross: torch.Tensor, prior: torch.Tensor, ridge: float) -> torch.Tensor:
    """B (..., 9, 6) from the sums X^T X (..., 9, 9) and X^T Y (..., 9, 6), pulled towards ``prior``
    (..., 9, 6) with weight ``ridge`` on every entry; solved in float64."""
    eye = torch.eye(9, dtype=torch.float64)
    return torch.linalg.solve(gram.double() + ridge * eye, cross.double() + ridge * prior.double()).float()


def fit_response(states: torch.Tensor, actions: torch.Tensor, prior: torch.Tensor, ridge: float) -> torch.Tensor:
    """B (9, 6) fitted to states (n+1, 16) and the n actions (n, 8) between them, pulled towards
    ``prior`` (9, 6) with weight ``ridge`` on every entry (n = 0: the prior)."""
    if len(actions) == 0:
        return prior.clone()
    return ridge_solve(*moments(states, actions), prior, ridge)


def each_times(X: torch.Tensor, parts: list[tuple[torch.Tensor, int]]) -> torch.Tensor:
    """X (sum k, ..., 9) times each member's (9, 6) on its k rows -> (sum k, ..., 6). A member's
    rows take one flat (k ..., 9) @ (9, 6) product, the same call whether the episode flies alone
    or in a lockstep batch (a batched product over per-candidate copies sums in another order)."""
    rows = X.split([k for _, k in parts])
    return joined([(x.reshape(-1, x.shape[-1]) @ B).view(*x.shape[:-1], B.shape[-1]) for x, (B, _) in zip(rows, parts)])


class FittedBodyDynamics(RigidBodyDynamics):
    """The rigid-body rollout with each episode's thrust response fitted to its last ``frames``
    observed frames (:func:`fit_response`). Each episode has its own :meth:`fork`."""

    def __init__(
        self,
        sim: SimConfig = SimConfig(),
        substeps: int = 1,
        timings: Timings | None = None,
        frames: int = 40,
        ridge: float = 1e-5,
    ):
        super().__init__(sim, substeps, timings)
        if frames < 1 or ridge <= 0:
            raise ValueError(f"fit_frames={frames} and fit_ridge={ridge}: give at least 1 frame and a positive ridge")
        self.sim, self.frames, self.ridge = sim, int(frames), float(ridge)
        self.reset()

    def reset(self) -> None:
        self._states: deque[torch.Tensor] = deque(maxlen=self.frames + 1)
        self._actions: deque[torch.Tensor] = deque(maxlen=self.frames)

    def fork(self) -> "FittedBodyDynamics":
        twin = copy.copy(self)
        twin.reset()
        return twin

    def observe(self, obs: dict, previous_action: np.ndarray | None) -> None:
        """One more frame; ``previous_action`` led to it from the last observed one (None: a gap,
        after which the history starts again)."""
        if previous_action is not None and self._states:
            self._actions.append(torch.as_tensor(previous_action, dtype=torch.float32))
        elif self._states:
            self.reset()
        self._states.append(torch.as_tensor(obs["state"], dtype=torch.float32))

    def history(self) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """The frames the response is fitted to: states (n+1, 16), the n actions (n, 8) between
        them, and the design's response (9, 6) at the last frame's fuel."""
        if not self._states:
            raise RuntimeError("observe() a frame before rollout()")
        states = torch.stack(list(self._states))
        prior = nominal_response(self.sim, float(states[-1, FUEL]), self.W)
        taken = len(self._actions)
        actions = torch.stack(list(self._actions)) if taken else states.new_zeros(0, 8)
        return states[len(states) - 1 - taken :], actions, prior

    def response(self) -> torch.Tensor:
        """B (9, 6) fitted to the history (the nominal body's before any frame)."""
        return fit_response(*self.history(), self.ridge)

    def responses(self, members: list["FittedBodyDynamics"], sizes: list[int]) -> list[tuple[torch.Tensor, int]]:
        """Each member's fitted response (9, 6) and its number of candidates."""
        return [(m.response(), k) for m, k in zip(members, sizes)]

    def _accelerations(self, actions, scale, mass, inertia, response):
        """Body-frame acceleration and angular acceleration (K, H, 3) each, from each member's
        fitted response (:meth:`responses`) on its candidates' rows."""
        given = actions * scale[..., None]
        X = torch.cat([given, given.new_ones(*given.shape[:-1], 1)], -1)  # (K, H, 9)
        change = each_times(X, response)  # (K, H, 6) per frame
        return change[..., :3] / self.dt, change[..., 3:] / self.dt


class FittedBodyLearnedDynamics(LearnedDynamics):
    """The world-model planner with the fitted body's states: the world model encodes each frame
    (its depth head reads them) and, when ``imagine`` (``obstacle_motion="imagined"``), rolls each
    candidate's latents out for the imagined depth; the states the cost reads come from
    :class:`FittedBodyDynamics`, not from the probe. Without ``imagine`` no latent is rolled out."""

    def __init__(self, model, probe, body: FittedBodyDynamics, imagine: bool, **kwargs):
        self.body, self.imagine = body, bool(imagine)
        super().__init__(model, probe, **kwargs)

    def reset(self) -> None:
        super().reset()
        self.body.reset()

    def fork(self) -> "FittedBodyLearnedDynamics":
        twin = copy.copy(self)
        twin.body = self.body.fork()  # before the reset, which would otherwise clear this one's history
        twin.reset()
        return twin

    def push(self, z: torch.Tensor, previous_action: np.ndarray | None, obs: dict | None = None) -> None:
        if obs is None:
            raise ValueError("the fitted body reads each frame's state: push(z, previous_action, obs)")
        super().push(z, previous_action, obs)
        self.body.observe(obs, previous_action)

    @staticmethod
    @torch.inference_mode()
    def rollout_many(
        members: list["FittedBodyLearnedDynamics"], state0s: list[torch.Tensor], actions: list[torch.Tensor]
    ) -> list[torch.Tensor]:
        """The fitted body's states; the world model's imagined latents beside them when ``imagine``."""
        if members[0].imagine:
            LearnedDynamics.rollout_many(members, state0s, actions)  # sets each member's imagined_latents
        return FittedBodyDynamics.rollout_many([m.body for m in members], state0s, actions)
