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

With ``fit_steps`` L > 1 the step that ended at each frame is also imagined as the j-th step
(j = 2..L) from the context that ends j steps back and the thrusts flown since, and each j gets a
correction of its own, C_1 .. C_L, fitted like C: for misses that depend on how far a step lies
from the last real latent. A rollout's j-th step is corrected by C_j (C_L beyond the L-th).
"""

from __future__ import annotations

from collections import deque

import numpy as np
import torch

from orbitmodel.plan.dynamics import LearnedDynamics, joined
from orbitmodel.plan.fitted_body import each_times, ridge_solve
from orbitmodel.probe.integrator import D_V, D_W, increments_of, integrate

CORRECTED = slice(D_V.start, D_W.stop)  # the increments the correction changes: dv (3), dw (3)


class CorrectedLearnedDynamics(LearnedDynamics):
    """:class:`LearnedDynamics` whose probe increments are corrected per episode by the thrust
    response of their misses over the last ``fit_frames`` frames (module docstring). Needs a probe
    that predicts every frame (``substeps`` = the world model's ``frame_step``) and reads latents."""

    def __init__(self, model, probe, fit_frames: int = 40, ridge: float = 1e-5, fit_steps: int = 1, **kwargs):
        if fit_frames < 1 or ridge <= 0 or fit_steps < 1:
            raise ValueError(
                f"fit_frames={fit_frames}, fit_ridge={ridge} and fit_steps={fit_steps}: give at least 1 frame, "
                "a positive ridge and at least 1 step"
            )
        self.fit_frames, self.ridge, self.fit_steps = int(fit_frames), float(ridge), int(fit_steps)
        super().__init__(model, probe, **kwargs)
        config = getattr(probe, "config", None)
        if config is None or config.substeps != self.step or not self.reads_latent:
            raise ValueError(
                "body=corrected corrects a probe that reads latents and predicts every frame "
                f"(substeps = the world model's {self.step}); this probe does not: fly its run's own probe"
            )

    def reset(self) -> None:
        super().reset()
        reach = (self.history + self.fit_steps - 1) * self.step + 1  # oldest context latent .. the L-th step's end
        self._seen: deque[tuple[torch.Tensor, torch.Tensor]] = deque(maxlen=reach)  # (z (D,), state (16,))
        self._taken: deque[torch.Tensor] = deque(maxlen=reach - 1)  # (8,) the thrusts into each frame
        # per imagined step j: the regression sums X^T X, X^T Y of its last fit_frames fits
        self._sums: list[deque[tuple[torch.Tensor, torch.Tensor]]] = [
            deque(maxlen=self.fit_frames) for _ in range(self.fit_steps)
        ]

    def push(self, z: torch.Tensor, previous_action: np.ndarray | None, obs: dict | None = None) -> None:
        if obs is None:
            raise ValueError("the corrected dynamics read each frame's state: push(z, previous_action, obs)")
        super().push(z, previous_action, obs)  # resets this history too after a gap
        if previous_action is not None and self._seen:
            self._taken.append(torch.as_tensor(previous_action, dtype=torch.float32))
        self._seen.append((z, torch.as_tensor(obs["state"], dtype=torch.float32)))
        n = (len(self._seen) - 1) // self.step - self.history + 1  # imagined steps the history holds
        if n >= 1:
            for sums, step in zip(self._sums, self.step_misses(n)):
                sums.append(step)

    @torch.inference_mode()
    def step_misses(self, n: int = 1) -> list[tuple[torch.Tensor, torch.Tensor]]:
        """Per imagined step j = 1..n, the regression sums (float64) X^T X (9, 9) and X^T Y (9, 6) of
        the step that ended at the newest frame t, imagined as the j-th step from the context that
        ends j steps back and the thrusts flown since: X = [a, 1] per frame of that step, Y the
        recorded minus the probe's dv and dw. Every step's fit ends at the newest frame."""
        s, m = self.step, self.history
        seen = list(self._seen)[-((m + n - 1) * s + 1) :]  # frames t - (m+n-1) s .. t
        z = torch.stack([pair[0] for pair in seen])
        states = torch.stack([pair[1] for pair in seen[-s - 1 :]])  # (s + 1, 16): frames t - s .. t
        taken = torch.stack(list(self._taken)[-(m + n - 1) * s :])  # ((m+n-1) s, 8) the thrusts into them
        # row j-1: the context that ends j steps back, its thrusts to t, zeros after (never read)
        last = (m + n - 1) * s  # index of frame t
        z_ctx = torch.stack([z[last - (m + j - 1) * s : last - j * s + 1 : s] for j in range(1, n + 1)])
        planned = taken.new_zeros(n, m - 1 + n, 8 * s)
        for j in range(1, n + 1):
            flown = taken[last - (m + j - 1) * s :]  # (m-1+j) s thrusts
            planned[j - 1, : m - 1 + j] = flown.reshape(m - 1 + j, 8 * s)
        with self.timings("correct"):
            z_next = self.model.rollout(z_ctx, planned, m)  # (n, n, D): imagining is causal in the thrusts
            probe = self.probe.step_increments(z_next, z_ctx[:, -1], planned[:, -n:])[..., CORRECTED]  # (n, n s, 6)
            probe = torch.stack([probe[j, j * s : (j + 1) * s] for j in range(n)])  # (n, s, 6): each row's step to t
            config = self.probe.config
            recorded = increments_of(states[None], config.dt, config.coasting)[0, :, CORRECTED]  # (s, 6)
        thrust = taken[-s:]
        X = torch.cat([thrust, thrust.new_ones(s, 1)], -1).double()  # (s, 9)
        gram = X.T @ X
        return [(gram, X.T @ (recorded - probe[j]).double()) for j in range(n)]

    def corrections(self) -> list[torch.Tensor]:
        """Per imagined step, C (9, 6): the thrust response of the probe's misses (a step not
        fitted yet takes the one before it's; zeros before the first full step). Each is the
        solve's own tensor: its memory layout sets the reduction order of the rollout's matmul."""
        out, last = [], torch.zeros(9, 6)
        for sums in self._sums:
            if sums:
                gram = torch.stack([g for g, _ in sums]).sum(0)
                cross = torch.stack([c for _, c in sums]).sum(0)
                last = ridge_solve(gram, cross, torch.zeros(9, 6), self.ridge)
            out.append(last)
        return out

    def correction(self) -> torch.Tensor:
        """C (fit_steps, 9, 6): :meth:`corrections` stacked."""
        return torch.stack(self.corrections())

    def read_states(self, members, sizes, z_future, start, z_last, planned) -> torch.Tensor:
        """The probe's increments with each member's correction added, integrated from ``start``."""
        config = self.probe.config
        inc = self.probe.step_increments(z_future, z_last, planned)  # (G K, H, 10)
        thrust = planned.reshape(len(planned), inc.shape[1], -1)  # (G K, H, 8) each frame's thrusts
        X = torch.cat([thrust, thrust.new_ones(*thrust.shape[:-1], 1)], -1)  # (G K, H, 9)
        inc = inc.clone()
        if self.fit_steps == 1:  # one correction for every frame
            inc[..., CORRECTED] += each_times(X, [(m.corrections()[0], k) for m, k in zip(members, sizes)])
        else:  # each imagined step's frames their step's correction, member by member
            which = (torch.arange(inc.shape[1]) // self.step).clamp(max=self.fit_steps - 1)  # each frame's step
            C = [m.correction()[which] for m in members]  # G x (H, 9, 6)
            inc[..., CORRECTED] += joined(
                [
                    torch.einsum("khi,khio->kho", x, c[None].expand(len(x), -1, -1, -1))
                    for x, c in zip(X.split(sizes), C)
                ]
            )  # (G K, H, 6)
        return integrate(start, inc, config.dt, config.coasting)
