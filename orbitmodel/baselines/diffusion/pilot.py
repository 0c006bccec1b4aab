"""The Diffusion Policy as an orbitdata pilot: it sees the camera and the state, and is told
only the task (the goal), never the obstacles.

Action chunking as in the reference: every ``action_steps`` control steps (8 in the flight presets)
the policy samples 16 actions from its last 2 observations and queues those for frames
t .. t + action_steps - 1. At the first step of an episode the one observation stands in for both
(the reference's padding). How it samples, executes and sees is one :class:`PolicySampling`,
usually a named flight preset (``sampling.POLICY_FLIGHTS``: ``cpu`` is the reported flight):
with ``ensemble`` = m (temporal ensembling, as ACT does), every chunk sampled so far that covers
the current frame votes, the oldest with weight 1 and each newer one exp(-m) times the one
before. With ``draws`` = N > 1 a chunk is made of N samples drawn together: their mean
(``pick="mean"``) or the central draw (``pick="central"``: the one nearest their mean over the
executed actions: a real sample); ``eval policy --set draws=N`` measures what each removes from
the error.

    pilot = load_policy_pilot("runs/policy")          # the cpu flight preset
    pilot.reset(task)                   # task.goal: metres, world frame relative to the start
    thrust = pilot.act(obs)             # obs["image"] (H, W, 3) uint8, obs["state"] (16,)

This is the only module that knows the ``orbitdata.fly`` interface.
"""

from __future__ import annotations

import copy
from collections import deque
from pathlib import Path

import numpy as np
import torch

from orbitdata.fly.pilot import Pilot
from orbitdata.seeding import rng
from orbitmodel.baselines.diffusion.policy import DiffusionPolicy
from orbitmodel.baselines.diffusion.sampling import DEFAULT_FLIGHT, PolicySampling, policy_sampling


class DiffusionPilot(Pilot):
    """Flies a trained :class:`DiffusionPolicy` (EMA weights unless ``use_ema=False``) as
    ``sampling`` says (default: the ``cpu`` flight preset); ``preset`` names the preset the
    settings came from, for the record. The policy is never changed.

    Every sampling draw comes from a generator seeded by the task's seed, so an episode is
    reproducible.
    """

    name = "diffusion"
    privileged = False
    needs_images = True

    def __init__(
        self,
        policy: DiffusionPolicy,
        sampling: PolicySampling | None = None,
        use_ema: bool = True,
        preset: str | None = None,
    ):
        if policy.config.obstacles:
            raise ValueError(
                "this policy reads the true obstacles (a privileged diagnostic, preset "
                "cpu-state-obstacles): no pilot is told them, so it cannot fly; score it with eval policy"
            )
        if sampling is None:
            sampling, preset = policy_sampling(DEFAULT_FLIGHT), preset or DEFAULT_FLIGHT
        c = policy.config
        self.sampling = sampling.resolved(c)  # checked once, here, against the run
        self.preset = preset
        self.policy = policy.eval()
        self.needs_images = c.images  # a policy without images flies without rendering
        self.image_codec = self.sampling.image_codec
        self.use_ema = use_ema
        self.action_steps = self.sampling.action_steps
        self.ensemble = self.sampling.ensemble
        self._goal: torch.Tensor | None = None
        self._history: deque = deque(maxlen=c.n_obs_steps)
        self._queue: deque = deque()
        self._chunks: list[tuple[int, np.ndarray]] = []  # (first frame, actions (n, 8) from it on), oldest first
        self._t = 0
        self._generator = torch.Generator()

    def reset(self, task) -> None:
        """Start an episode: keep the goal (metres, world frame relative to the start) and the seed."""
        self._goal = torch.tensor(np.asarray(task.goal, dtype=np.float32).reshape(1, 3))
        self._generator.manual_seed(int(rng(int(task.seed), "pilot").integers(2**62)))
        self._history.clear()
        self._queue.clear()
        self._chunks.clear()
        self._t = 0

    def act(self, obs: dict) -> np.ndarray:
        """(8,) thrusts in [0, 1] from obs["image"] (S, S, 3) uint8 and obs["state"] (16,)."""
        return self.act_batch([self], [obs])[0]

    @staticmethod
    @torch.no_grad()
    def act_batch(pilots: list["DiffusionPilot"], observations: list[dict]) -> list[np.ndarray]:
        """:meth:`act` for several episodes in lockstep, each flown by its own :meth:`fork`: the
        chunks due at this step are sampled in one denoising pass, each episode's noise drawn
        from its own generator."""
        steps = [p._observe(obs) for p, obs in zip(pilots, observations)]
        due = [i for i, (p, t) in enumerate(zip(pilots, steps)) if p._chunk_due(t)]
        chunks = dict(zip(due, sample_chunks([pilots[i] for i in due]))) if due else {}
        return [p._execute(t, chunks.get(i)) for i, (p, t) in enumerate(zip(pilots, steps))]

    @property
    def board_every(self) -> int:
        """Steps between chunks: lockstep flights start episodes on this clock, so that every
        episode in a batch samples its chunks at the same steps, in one denoising pass."""
        return self.action_steps

    def fork(self) -> "DiffusionPilot":
        """A pilot for another episode flown beside this one: the same policy and sampling, its
        own observation history, chunks and generator."""
        twin = copy.copy(self)
        twin._goal = None
        twin._history = deque(maxlen=self.policy.config.n_obs_steps)
        twin._queue = deque()
        twin._chunks = []
        twin._t = 0
        twin._generator = torch.Generator()
        return twin

    def _observe(self, obs: dict) -> int:
        """Take the frame into the observation history; its step in the episode."""
        if self._goal is None:
            raise RuntimeError("call reset(task) before act(obs)")
        c = self.policy.config
        image, state = obs.get("image") if c.images else None, obs["state"]
        if c.images and (image is None or image.shape != (c.image_size, c.image_size, 3)):
            raise ValueError(
                f"pilot {self.name!r} was trained on {c.image_size} px RGB images but the camera gives "
                f"{None if image is None else image.shape}; fly it with a {c.image_size} px camera"
            )
        frame = (
            torch.from_numpy(np.ascontiguousarray(image)).permute(2, 0, 1) if c.images else None,  # (3, S, S)
            torch.as_tensor(state, dtype=torch.float32),
        )  # (16,)
        while len(self._history) < c.n_obs_steps - 1:  # first step: repeat the first observation
            self._history.append(frame)
        self._history.append(frame)
        t, self._t = self._t, self._t + 1
        return t

    def _chunk_due(self, t: int) -> bool:
        """Step t samples a new chunk: the queue ran out, or (ensembling) every ``action_steps``."""
        return not self._queue if self.ensemble is None else t % self.action_steps == 0

    def _execute(self, t: int, chunk: np.ndarray | None) -> np.ndarray:
        """The action of step t, ``chunk`` (n, 8) the one sampled at it, if one was."""
        if self.ensemble is None:
            if chunk is not None:
                self._queue.extend(chunk[: self.action_steps])
            return self._queue.popleft()
        if chunk is not None:
            self._chunks.append((t, chunk))
        self._chunks = [(t0, a) for t0, a in self._chunks if t - t0 < len(a)]  # those that cover frame t
        votes = np.stack([a[t - t0] for t0, a in self._chunks])  # (n, 8), oldest first
        weights = np.exp(-self.ensemble * np.arange(len(votes)))
        return (weights @ votes / weights.sum()).astype(np.float32)

    def _inputs(self) -> tuple[torch.Tensor | None, torch.Tensor, torch.Tensor, torch.Tensor]:
        """This episode's draws for a chunk: images (N, To, 3, S, S) or None, states (N, To, 16),
        goal (N, 3) and their initial noise (N, H, 8), drawn from the episode's generator."""
        n, c = self.sampling.draws, self.policy.config
        images = (
            torch.stack([f[0] for f in self._history])[None].expand(n, -1, -1, -1, -1)  # (N, To, 3, S, S)
            if c.images
            else None
        )
        states = torch.stack([f[1] for f in self._history])[None].expand(n, -1, -1)  # (N, To, 16)
        noise = self.sampling.noise_scale * torch.randn((n, c.horizon, c.action_dim), generator=self._generator)
        return images, states, self._goal.expand(n, -1), noise

    def _chunk(self, draws: torch.Tensor) -> np.ndarray:
        """A chunk from this episode's draws (N, H, 8): (n, 8) thrusts for the current frame on."""
        c = self.policy.config
        if self.sampling.pick == "central":
            executed = draws[:, c.action_start : c.action_start + self.action_steps]
            actions = draws[int(((executed - executed.mean(0)) ** 2).flatten(1).sum(1).argmin())]
        else:
            actions = draws.mean(0)  # (H, 8)
        return actions[c.action_start :].cpu().numpy().astype(np.float32)

    def metadata(self) -> dict:
        """The flight preset's name and every sampling setting it flew with."""
        return {"preset": self.preset, **self.sampling.to_dict()}


def sample_chunks(pilots: list[DiffusionPilot]) -> list[np.ndarray]:
    """A chunk for each of ``pilots`` (forks of one) from its last observations, all of their
    draws denoised together in one pass."""
    inputs = [p._inputs() for p in pilots]
    lead = pilots[0]

    def cat(parts):  # one episode's tensors pass as they are: a batch of one samples as act always did
        return parts[0] if len(parts) == 1 else torch.cat(parts)

    images = None if inputs[0][0] is None else cat([i[0] for i in inputs])  # (sum N, To, 3, S, S)
    draws = lead.policy.sample_actions(
        images,
        cat([i[1] for i in inputs]),  # (sum N, To, 16)
        cat([i[2] for i in inputs]),  # (sum N, 3)
        use_ema=lead.use_ema,
        sampling=lead.sampling,
        noise=cat([i[3] for i in inputs]),  # (sum N, H, 8)
    )  # (sum N, H, 8)
    return [p._chunk(d) for p, d in zip(pilots, draws.split([len(i[1]) for i in inputs]))]


def load_policy_pilot(
    run_dir: str | Path,
    sampling: PolicySampling | None = None,
    device: str = "cpu",
    use_ema: bool = True,
    preset: str | None = None,
) -> DiffusionPilot:
    """A pilot flying the policy of a run folder (``orbitmodel train-policy --out RUN``) or Hub
    repo id, sampled as ``sampling`` says (default: the ``cpu`` flight preset)."""
    return DiffusionPilot(DiffusionPolicy.from_pretrained(run_dir, device), sampling, use_ema=use_ema, preset=preset)


def make_diffusion_pilot(
    config=None, run: str | Path | None = None, device: str = "cpu", preset: str = DEFAULT_FLIGHT, **options
) -> DiffusionPilot:
    """``orbitdata.pilots`` factory: ``orbitdata fly --pilot diffusion --pilot-option run=RUN``
    flies the flight preset ``preset`` (``--pilot-option preset=reference``; default ``cpu``); any
    other option is a field of :class:`PolicySampling` (``--pilot-option draws=4``)."""
    if run is None:
        raise ValueError("pilot 'diffusion' needs its run folder: pass --pilot-option run=RUN")
    pilot = load_policy_pilot(run, policy_sampling(str(preset), **options), device, preset=str(preset))
    size = getattr(getattr(getattr(config, "sim", None), "camera", None), "image_size", None)
    if pilot.needs_images and size is not None and size != pilot.policy.config.image_size:
        raise ValueError(
            f"{run} was trained on {pilot.policy.config.image_size} px images but the camera renders "
            f"{size} px; pass --image-size {pilot.policy.config.image_size}"
        )
    return pilot
