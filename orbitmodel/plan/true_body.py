"""The true dynamics of one dynamic-tier episode, for the oracles handed its record.

On the dynamic tier the CubeSat is built differently each episode (mass, inertia, centre of
mass), one thruster may fail from a given frame on, and the Clohessy-Wiltshire terms may act
(``orbitdata.scenario.dynamics.Dynamics``). :class:`EpisodeBodyDynamics` rolls candidates out
through that record with the simulator's own integrator (``orbitdata.sim.rigid_body``, the
model the validator checks the dataset against), so an oracle's "true dynamics" are the
episode's. ``nominal`` keeps the CW terms and drops the rest: the fault-free body of the
design, what a planner that ignores the fault and the drawn body assumes (``oracle-nominal``).

The static tier has no record: its oracles keep :class:`~orbitmodel.plan.dynamics.RigidBodyDynamics`.
"""

from __future__ import annotations

import copy
from dataclasses import fields

import numpy as np
import torch

from orbitdata.scenario.dynamics import Dynamics
from orbitdata.sim.config import SimConfig
from orbitdata.sim.rigid_body import StepBody, start_of, state_of, step_rows
from orbitdata.state import FUEL
from orbitmodel.plan.timing import Timings


class EpisodeBodyDynamics:
    """Candidates (K, H, 8) -> states (K, H, 16) through one episode's body, fault and CW terms.

    The fault acts on the thrust applied at frame ``onset_step`` and after; the frame of a
    rollout's first action is the newest observed frame (counted by :meth:`observe` since the
    reset). ``substeps``: integrator steps per control step (the simulator's ``sim.substeps`` is
    its own scheme; fewer are faster and drift by the Euler error of the longer step).
    """

    needs_images = False

    def __init__(
        self,
        record: Dynamics,
        sim: SimConfig = SimConfig(),
        substeps: int = 1,
        nominal: bool = False,
        timings: Timings | None = None,
    ):
        if not 1 <= substeps <= sim.substeps or sim.substeps % substeps:
            raise ValueError(f"substeps={substeps}: give a divisor of the simulator's {sim.substeps} substeps")
        self.nominal = bool(nominal)
        self.cubesat, self.dt, self.substeps = sim.cubesat, float(sim.dt), int(substeps)
        self.timings = timings or Timings()
        self._body = StepBody.nominal(1)
        if nominal:
            self._body.n[:] = record.n  # the orbit is no secret: only the body and the fault are
        else:
            self._body.fill(slice(None), record)
        self.reset()

    def reset(self) -> None:
        self._frame = -1  # the newest observed frame

    def fork(self) -> "EpisodeBodyDynamics":
        twin = copy.copy(self)
        twin.reset()
        return twin

    def observe(self, obs: dict, previous_action: np.ndarray | None) -> None:
        """One more frame: the next rollout's first action is applied at it."""
        self._frame += 1

    @torch.inference_mode()
    def rollout(self, state0: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """state0 (16,) at the newest observed frame, actions (K, H, 8) -> states (K, H, 16)."""
        return self.rollout_many([self], [state0], [actions])[0]

    @staticmethod
    @torch.inference_mode()
    def rollout_many(
        members: list["EpisodeBodyDynamics"], state0s: list[torch.Tensor], actions: list[torch.Tensor]
    ) -> list[torch.Tensor]:
        """Several episodes' candidates, each through its own record, in one pass over the horizon."""
        lead = members[0]
        if any(m._frame < 0 for m in members):
            raise RuntimeError("observe() a frame before rollout()")
        sizes = [len(a) for a in actions]
        with lead.timings("rollout"):
            index = np.repeat(np.arange(len(members)), sizes)  # candidate row -> member
            body = StepBody(
                **{f.name: np.concatenate([getattr(m._body, f.name) for m in members]) for f in fields(StepBody)}
            ).take(index)  # one row per candidate
            start = np.concatenate([s.double().expand(k, -1).numpy() for s, k in zip(state0s, sizes)])  # (N K, 16)
            plan = torch.cat([a.double() for a in actions]).numpy()  # (N K, H, 8)
            first = np.array([m._frame for m in members])[index]  # (N K,)
            motion, fuel = start_of(start), start[:, FUEL.start] * lead.cubesat.fuel_mass
            out = np.empty((len(start), plan.shape[1], start.shape[1]))
            for j in range(plan.shape[1]):
                motion, fuel = step_rows(
                    motion, fuel, plan[:, j], first + j, body, lead.cubesat, lead.dt, lead.substeps
                )
                out[:, j] = state_of(motion, fuel / lead.cubesat.fuel_mass)
        return list(torch.from_numpy(out).float().split(sizes))
