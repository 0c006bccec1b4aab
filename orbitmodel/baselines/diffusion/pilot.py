"""The Diffusion Policy as an orbitdata pilot: it sees the camera and the state, and is told
only the task (the goal), never the obstacles.

Action chunking as in the reference: every ``action_steps`` control steps (the config's
``n_action_steps``, 8, by default) the policy samples 16 actions from its last 2 observations and
queues those for frames t .. t + action_steps - 1. At the first step of an episode the one
observation stands in for both (the reference's padding). With ``ensemble`` = m (temporal
ensembling, as ACT does), every chunk sampled so far that covers the current frame votes, the
oldest with weight 1 and each newer one exp(-m) times the one before. With ``draws`` = N > 1 a
chunk is made of N samples drawn together: their mean (``pick="mean"``: the policy's mean action
rather than one draw), or the central draw (``pick="central"``: the one nearest their mean over
the executed actions: a real sample, the most typical of the N); ``eval policy
--samples`` measures what each removes from the error. ``timestep_spacing``
samples with that DDIM spacing instead of the run's (``PolicyConfig.timestep_spacing``).
``noise_scale`` below 1 starts each draw from scaled-down noise (:meth:`DiffusionPolicy.sample_actions`): 0 flies the one
chunk that the zero noise gives.

    pilot = load_policy_pilot("runs/policy")
    pilot.reset(task)                   # task.goal: metres, world frame relative to the start
    thrust = pilot.act(obs)             # obs["image"] (H, W, 3) uint8, obs["state"] (16,)

This is the only module that knows the ``orbitdata.fly`` interface.
"""

from __future__ import annotations

from collections import deque
from pathlib import Path

import numpy as np
import torch

from orbitdata.fly.pilot import Pilot
from orbitdata.seeding import rng
from orbitmodel.baselines.diffusion.policy import DiffusionPolicy, check_noise_scale


PICKS = ("mean", "central")  # how a chunk is made of several draws


class DiffusionPilot(Pilot):
    """Flies a trained :class:`DiffusionPolicy` (EMA weights unless ``use_ema=False``). The pilot
    owns the policy it is given: ``timestep_spacing`` sets that policy's sampler.

    Every sampling draw comes from a generator seeded by the task's seed, so an episode is
    reproducible.
    """

    name = "diffusion"
    privileged = False
    needs_images = True

    def __init__(self, policy: DiffusionPolicy, use_ema: bool = True, action_steps: int | None = None,
                 ensemble: float | None = None, draws: int = 1, noise_scale: float = 1.0, pick: str = "mean",
                 timestep_spacing: str | None = None):
        if policy.config.obstacles:
            raise ValueError("this policy reads the true obstacles (a privileged diagnostic, preset "
                             "cpu-state-obstacles): no pilot is told them, so it cannot fly; score it with eval policy")
        if timestep_spacing is not None:  # sampling only: the run's own unless given; the pilot owns ``policy``
            policy.set_sampler(timestep_spacing=timestep_spacing)
        c = policy.config
        self.policy = policy.eval()
        self.needs_images = c.images  # a policy without images flies without rendering
        self.use_ema = use_ema
        self.action_steps = int(c.n_action_steps if action_steps is None else action_steps)
        most = c.horizon - c.n_obs_steps + 1  # actions a sample holds from the current frame on
        if not 1 <= self.action_steps <= most:
            raise ValueError(f"action_steps={self.action_steps}: execute 1 to {most} actions of each sampled chunk")
        if ensemble is not None and not ensemble >= 0:
            raise ValueError(f"ensemble={ensemble}: give a decay >= 0 (0: every covering chunk votes alike)")
        self.ensemble = None if ensemble is None else float(ensemble)
        if not int(draws) >= 1:
            raise ValueError(f"draws={draws}: average 1 or more sampled chunks")
        self.draws = int(draws)
        if pick not in PICKS:
            raise ValueError(f"pick={pick!r}: choose one of {', '.join(PICKS)} (how a chunk is made of the draws)")
        if pick == "central" and self.draws < 2:
            raise ValueError("pick='central' chooses among several draws: give draws=N with N >= 2")
        self.pick = pick
        self.noise_scale = check_noise_scale(noise_scale)  # refused here, before any flight
        self._goal: torch.Tensor | None = None
        self._history: deque = deque(maxlen=c.n_obs_steps)
        self._queue: deque = deque()
        self._chunks: list[tuple[int, np.ndarray]] = []  # (first frame, actions (n, 8) from it on), oldest first
        self._t = 0
        self._generator = torch.Generator()

    def reset(self, task) -> None:
        """Start an episode: keep the goal (metres, world frame relative to the start) and the seed."""
        self._goal = torch.tensor(np.asarray(task.goal, dtype=np.float32).reshape(1, 3))
        self._generator.manual_seed(int(rng(int(task.seed), "pilot").integers(2 ** 62)))
        self._history.clear()
        self._queue.clear()
        self._chunks.clear()
        self._t = 0

    def act(self, obs: dict) -> np.ndarray:
        """(8,) thrusts in [0, 1] from obs["image"] (S, S, 3) uint8 and obs["state"] (16,)."""
        if self._goal is None:
            raise RuntimeError("call reset(task) before act(obs)")
        c = self.policy.config
        image, state = obs.get("image") if c.images else None, obs["state"]
        if c.images and (image is None or image.shape != (c.image_size, c.image_size, 3)):
            raise ValueError(f"pilot {self.name!r} was trained on {c.image_size} px RGB images but the camera gives "
                             f"{None if image is None else image.shape}; fly it with a {c.image_size} px camera")
        frame = (torch.from_numpy(np.ascontiguousarray(image)).permute(2, 0, 1) if c.images else None,  # (3, S, S)
                 torch.as_tensor(state, dtype=torch.float32))  # (16,)
        while len(self._history) < c.n_obs_steps - 1:  # first step: repeat the first observation
            self._history.append(frame)
        self._history.append(frame)
        t, self._t = self._t, self._t + 1
        if self.ensemble is None:
            if not self._queue:
                self._queue.extend(self._sample()[:self.action_steps])
            return self._queue.popleft()
        if t % self.action_steps == 0:
            self._chunks.append((t, self._sample()))
        self._chunks = [(t0, a) for t0, a in self._chunks if t - t0 < len(a)]  # those that cover frame t
        votes = np.stack([a[t - t0] for t0, a in self._chunks])  # (n, 8), oldest first
        weights = np.exp(-self.ensemble * np.arange(len(votes)))
        return (weights @ votes / weights.sum()).astype(np.float32)

    def _sample(self) -> np.ndarray:
        """A chunk from the last observations: (n, 8) thrusts for the current frame on."""
        n = self.draws
        images = (torch.stack([f[0] for f in self._history])[None].expand(n, -1, -1, -1, -1)  # (N, To, 3, S, S)
                  if self.policy.config.images else None)
        states = torch.stack([f[1] for f in self._history])[None].expand(n, -1, -1)  # (N, To, 16)
        draws = self.policy.sample_actions(images, states, self._goal.expand(n, -1), self._generator,
                                           self.use_ema, noise_scale=self.noise_scale)  # (N, H, 8)
        c = self.policy.config
        if self.pick == "central":
            executed = draws[:, c.action_start:c.action_start + self.action_steps]
            actions = draws[int(((executed - executed.mean(0)) ** 2).flatten(1).sum(1).argmin())]
        else:
            actions = draws.mean(0)  # (H, 8)
        return actions[c.action_start:].cpu().numpy().astype(np.float32)

    def metadata(self) -> dict:
        return {"action_steps": self.action_steps, "ensemble": self.ensemble, "draws": self.draws,
                "noise_scale": self.noise_scale, "pick": self.pick,
                "timestep_spacing": self.policy.config.timestep_spacing}


def load_policy_pilot(run_dir: str | Path, device: str = "cpu", use_ema: bool = True, action_steps: int | None = None,
                      ensemble: float | None = None, draws: int = 1, noise_scale: float = 1.0,
                      pick: str = "mean", timestep_spacing: str | None = None) -> DiffusionPilot:
    """A pilot flying the policy of a run folder (``orbitmodel train-policy --out RUN``) or Hub repo id."""
    return DiffusionPilot(DiffusionPolicy.from_pretrained(run_dir, device), use_ema=use_ema, action_steps=action_steps,
                          ensemble=ensemble, draws=draws, noise_scale=noise_scale, pick=pick,
                          timestep_spacing=timestep_spacing)


def make_diffusion_pilot(config=None, run: str | Path | None = None, device: str = "cpu", action_steps=None,
                         ensemble=None, draws=1, noise_scale=1.0, pick="mean", timestep_spacing=None) -> DiffusionPilot:
    """``orbitdata.pilots`` factory: ``orbitdata fly --pilot diffusion --pilot-option run=RUN``
    (``--pilot-option action_steps=4``, ``ensemble=0.1``, ``draws=4``, ``noise_scale=0.5``,
    ``pick=central``, ``timestep_spacing=trailing``: see :class:`DiffusionPilot`)."""
    if run is None:
        raise ValueError("pilot 'diffusion' needs its run folder: pass --pilot-option run=RUN")
    try:
        draws = int(draws)
    except ValueError:
        raise ValueError(f"--pilot-option draws={draws}: give a whole number of chunks to average") from None
    try:
        noise_scale = float(noise_scale)
    except ValueError:
        raise ValueError(f"--pilot-option noise_scale={noise_scale}: give a number >= 0 (1: as trained)") from None
    pilot = load_policy_pilot(run, device, action_steps=None if action_steps is None else int(action_steps),
                              ensemble=None if ensemble is None else float(ensemble), draws=draws,
                              noise_scale=noise_scale, pick=str(pick),
                              timestep_spacing=None if timestep_spacing is None else str(timestep_spacing))
    size = getattr(getattr(getattr(config, "sim", None), "camera", None), "image_size", None)
    if pilot.needs_images and size is not None and size != pilot.policy.config.image_size:
        raise ValueError(f"{run} was trained on {pilot.policy.config.image_size} px images but the camera renders "
                         f"{size} px; pass --image-size {pilot.policy.config.image_size}")
    return pilot
