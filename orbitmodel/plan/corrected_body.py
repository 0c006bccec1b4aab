"""The world model's dynamics corrected by its own history: a thrust response fitted to its misses.

On the dynamic tier each episode's body is drawn and one thruster may fail (``docs/design.md``).
The world model and its probe predict how thrusts change the craft's motion as if for the
average body (``docs/results.md``). This pilot keeps their rollout and corrects it with what its
own history shows they get wrong. At every frame t it imagines the world-model step that ended
there (s frames, s = the model's ``frame_step``), from the context latents before it and the
thrusts it really commanded, reads the probe's per-frame increments and sets them against the
recorded ones. The misses of the velocity and rate increments are regressed on each frame's
thrusts:

    [dv, dw]_recorded - [dv, dw]_probe = [a, 1] @ C        C (9, 6)

by ridge regression over the steps that end at the last ``fit_frames`` frames, pulled towards zero (the
world model's own dynamics). A candidate's rollout adds ``[a, 1] @ C`` to every frame's probe
increments before they are integrated. Thrust patterns the history never excited keep the world
model's response. The latents are the world model's; only the states the cost reads are
corrected (a hand-built fit on the learned model's errors, not a learned inference).
"""

from __future__ import annotations

from collections import deque

import numpy as np
import torch

from orbitmodel.plan.dynamics import LearnedDynamics, joined
from orbitmodel.plan.fitted_body import ridge_solve
from orbitmodel.probe.integrator import D_V, D_W, increments_of, integrate

CORRECTED = slice(D_V.start, D_W.stop)  # the increments the correction changes: dv (3), dw (3)


class CorrectedLearnedDynamics(LearnedDynamics):
    """:class:`LearnedDynamics` whose probe increments are corrected per episode by the thrust
    response of their misses over the last ``fit_frames`` frames (module docstring). Needs a probe
    that predicts every frame (``substeps`` = the world model's ``frame_step``) and reads latents."""

    def __init__(self, model, probe, fit_frames: int = 40, ridge: float = 1e-5, **kwargs):
        if fit_frames < 1 or ridge <= 0:
            raise ValueError(
                f"fit_frames={fit_frames} and fit_ridge={ridge}: give at least 1 frame and a positive ridge"
            )
        self.fit_frames, self.ridge = int(fit_frames), float(ridge)
        super().__init__(model, probe, **kwargs)
        config = getattr(probe, "config", None)
        if config is None or config.substeps != self.step or not self.reads_latent:
            raise ValueError(
                "body=corrected corrects a probe that reads latents and predicts every frame "
                f"(substeps = the world model's {self.step}); this probe does not: fly its run's own probe"
            )

    def reset(self) -> None:
        super().reset()
        reach = self.history * self.step + 1  # frames from the oldest context latent to a step's end
        self._seen: deque[tuple[torch.Tensor, torch.Tensor]] = deque(maxlen=reach)  # (z (D,), state (16,))
        self._taken: deque[torch.Tensor] = deque(maxlen=reach - 1)  # (8,) the thrusts into each frame
        self._sums: deque[tuple[torch.Tensor, torch.Tensor]] = deque(maxlen=self.fit_frames)  # per step: X^T X, X^T Y

    def push(self, z: torch.Tensor, previous_action: np.ndarray | None, obs: dict | None = None) -> None:
        if obs is None:
            raise ValueError("the corrected dynamics read each frame's state: push(z, previous_action, obs)")
        super().push(z, previous_action, obs)  # resets this history too after a gap
        if previous_action is not None and self._seen:
            self._taken.append(torch.as_tensor(previous_action, dtype=torch.float32))
        self._seen.append((z, torch.as_tensor(obs["state"], dtype=torch.float32)))
        if len(self._seen) == self._seen.maxlen:
            self._sums.append(self.step_misses())

    @torch.inference_mode()
    def step_misses(self) -> tuple[torch.Tensor, torch.Tensor]:
        """The regression sums (float64) X^T X (9, 9) and X^T Y (9, 6) of the step that ended at the
        newest frame: X = [a, 1] per frame, Y the recorded minus the probe's dv and dw."""
        s, m = self.step, self.history
        z = torch.stack([pair[0] for pair in self._seen])  # (m s + 1, D)
        states = torch.stack([pair[1] for pair in list(self._seen)[-s - 1 :]])  # (s + 1, 16): frames t - s .. t
        taken = torch.stack(list(self._taken))  # (m s, 8)
        z_ctx = z[: m * s : s][None]  # (1, m, D): frames t - m s .. t - s, every s-th
        planned = taken.reshape(1, m, 8 * s)  # the m-1 actions inside the context, then the step's
        with self.timings("correct"):
            z_next = self.model.rollout(z_ctx, planned, m)  # (1, 1, D)
            probe = self.probe.step_increments(z_next, z_ctx[:, -1], planned[:, -1:])[0, :, CORRECTED]  # (s, 6)
            config = self.probe.config
            recorded = increments_of(states[None], config.dt, config.coasting)[0, :, CORRECTED]  # (s, 6)
        thrust = taken[-s:]
        X = torch.cat([thrust, thrust.new_ones(s, 1)], -1).double()  # (s, 9)
        return X.T @ X, X.T @ (recorded - probe).double()

    def correction(self) -> torch.Tensor:
        """C (9, 6): the thrust response of the probe's misses (zeros before the first full step)."""
        if not self._sums:
            return torch.zeros(9, 6)
        gram = torch.stack([g for g, _ in self._sums]).sum(0)
        cross = torch.stack([c for _, c in self._sums]).sum(0)
        return ridge_solve(gram, cross, torch.zeros(9, 6), self.ridge)

    def read_states(self, members, sizes, z_future, start, z_last, planned) -> torch.Tensor:
        """The probe's increments with each member's correction added, integrated from ``start``."""
        config = self.probe.config
        inc = self.probe.step_increments(z_future, z_last, planned)  # (G K, H, 10)
        thrust = planned.reshape(len(planned), inc.shape[1], -1)  # (G K, H, 8) each frame's thrusts
        X = torch.cat([thrust, thrust.new_ones(*thrust.shape[:-1], 1)], -1)  # (G K, H, 9)
        C = joined([m.correction()[None].expand(k, -1, -1) for m, k in zip(members, sizes)])  # (G K, 9, 6)
        inc = inc.clone()
        inc[..., CORRECTED] += X @ C
        return integrate(start, inc, config.dt, config.coasting)
