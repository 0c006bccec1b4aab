"""Train the Diffusion Policy on windows of the dataset (``orbitmodel train-policy``).

A training window is ``horizon`` (16) frames starting at t-1: its first ``n_obs_steps`` (2)
frames are the observations, and all 16 actions are the target. The horizon may run past the
episode end (``pad=True``); padded frames repeat the terminal frame, whose action is zero
thrust, so the loss skips both (they are no action the expert took). The goal is joined from
the episodes table by ``episode_index``. Only the image (of the observed frames; none for a
policy without the camera), the state, the action and the goal are read: never the obstacles,
except by the privileged diagnostic (``PolicyConfig.obstacles``, preset ``cpu-state-obstacles``),
which cannot fly.

EMA: the weights' moving average lives in the policy module (``policy.ema``), so checkpoints
and exact resume carry it; the shared loop calls :meth:`PolicyJob.after_step` after each
optimiser step.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from torch.utils.data import Dataset, DistributedSampler

from orbitdata import schema as S
from orbitdata.load import IS_PAD, load_windows
from orbitdata.load.collate import WindowBatch
from orbitdata.load.tables import load_episode_table
from orbitmodel.baselines.diffusion.config import FAMILY, POLICY_PRESETS, PolicyPreset
from orbitmodel.baselines.diffusion.policy import DiffusionPolicy
from orbitmodel.data import DatasetMeta, ValidationSplit, read_dataset_meta, training_episodes, validation_split
from orbitmodel.kinematics import P
from orbitmodel.runs import POLICY, RunDir, RunError, check_image_size, run_config, upgrade_preset_config
from orbitmodel.train.loop import FitResult, fit, resolve_device, step_generator

COLUMNS = (S.IMAGE, S.STATE, S.ACTION, S.IS_LAST)  # plus episode_index and is_pad, always loaded; the goal comes
# from the episodes table
DEFAULT_LEVELS = ("expert",)
STREAM_NOISE, STREAM_SHIFT = 0, 1


# ---- data ------------------------------------------------------------------------------------
def policy_columns(model) -> list[str]:
    """The columns a policy with ``model`` (a PolicyConfig) reads: COLUMNS, less the image for one
    that does not see the camera."""
    return [c for c in COLUMNS if model.images or c != S.IMAGE]


def episode_goals(source: str | Path, split: str) -> torch.Tensor:
    """(max episode_index + 1, 3) goals, metres, world frame relative to the start; NaN rows for
    episodes not in the split. Reads only the goal and index columns of the episodes table."""
    table = load_episode_table(source, split, {}).select([S.EPISODE_INDEX, S.GOAL])
    ids = table.column(S.EPISODE_INDEX).to_numpy().astype(np.int64)
    goals = np.asarray(table.column(S.GOAL).to_pylist(), dtype=np.float32).reshape(-1, 3)
    lookup = torch.full((int(ids.max()) + 1, 3), float("nan"))
    lookup[torch.from_numpy(ids)] = torch.from_numpy(goals)
    return lookup


def episode_obstacles(source: str | Path, split: str, slots: int) -> torch.Tensor:
    """(max episode_index + 1, slots, 4): each episode's first ``slots`` true obstacles as centre
    (metres, world frame relative to the start) and bounding radius; empty slots are zeros. Only a
    privileged diagnostic policy (``PolicyConfig.obstacles``) reads them."""
    from orbitdata.scenario.spec import Obstacle

    table = load_episode_table(source, split, {}).select([S.EPISODE_INDEX, S.OBSTACLES])
    ids = table.column(S.EPISODE_INDEX).to_numpy().astype(np.int64)
    lookup = torch.zeros((int(ids.max()) + 1, slots, 4))
    for idx, row in zip(ids, table.column(S.OBSTACLES).to_pylist()):
        for k, ob in enumerate(row[:slots]):
            o = Obstacle(ob["shape"], tuple(ob["center"]), tuple(ob["size"]), tuple(ob["quat"]))
            lookup[idx, k] = torch.tensor([*o.center, o.bounding_radius])
    return lookup


def action_range(source: str | Path) -> tuple[list[float], list[float]]:
    """Per-thruster (min, max) of the action over the dataset, from meta/stats.json."""
    from orbitdata.load import read_meta

    stats = read_meta(source)[1][S.ACTION]
    return [float(x) for x in stats["min"]], [float(x) for x in stats["max"]]


def goal_scale(meta: DatasetMeta) -> float:
    """Metres per unit of the goal input: the position's mean spread (the goal's order of size)."""
    return float(np.mean(meta.state_std[P]))


def random_shift(images: torch.Tensor, pad: int, generator: torch.Generator) -> torch.Tensor:
    """DrQ-style augmentation on (B, To, 3, S, S) uint8: replicate-pad by ``pad`` pixels and crop
    back at a random offset per window (the same for its observations)."""
    if pad == 0:
        return images
    B, To, C, H, W = images.shape
    padded = F.pad(images.flatten(1, 2).float(), (pad,) * 4, mode="replicate")  # (B, To*3, H+2p, W+2p)
    dx, dy = torch.randint(0, 2 * pad + 1, (2, B), generator=generator).tolist()
    out = torch.stack([padded[b, :, dy[b] : dy[b] + H, dx[b] : dx[b] + W] for b in range(B)])
    return out.view(B, To, C, H, W).to(images.dtype)


class PolicyJob:
    """What the shared loop needs: the module, how a batch becomes its inputs, the EMA update."""

    def __init__(
        self,
        policy: DiffusionPolicy,
        preset: PolicyPreset,
        goals: torch.Tensor,
        rank: int = 0,
        obstacles: torch.Tensor | None = None,
    ):
        self.module = self.saved = policy
        self.preset = preset
        self.goals = goals
        self.obstacles = obstacles  # (episodes, K, 4): a privileged policy's (episode_obstacles)
        self.rank = rank

    def inputs(self, batch: dict, step: int, device: torch.device) -> dict:
        t, To = self.preset.train, self.preset.model.n_obs_steps
        images = None
        if self.preset.model.images:
            images = random_shift(
                batch[S.IMAGE][:, :To], t.shift, step_generator(t.loop.seed, step, STREAM_SHIFT, self.rank)
            ).to(device)
        goal = self.goals[batch[S.EPISODE_INDEX][:, 0]]  # (B, 3)
        inputs = {
            "images": images,
            "states": batch[S.STATE][:, :To].to(device),
            "goal": goal.to(device),
            "actions": batch[S.ACTION].to(device),
            "generator": step_generator(t.loop.seed, step, STREAM_NOISE, self.rank),
        }
        if self.preset.model.obstacles:
            inputs["obstacles"] = self.obstacles[batch[S.EPISODE_INDEX][:, 0]].to(device)
        if t.mask_padding:  # the terminal frame's and the padding's zero thrust are no action anyone took; they
            # add no loss (else the policy learns to cut thrust near the goal)
            inputs["real"] = (~(batch[IS_PAD] | batch[S.IS_LAST])).to(device)
        return inputs

    def after_step(self, step: int) -> None:
        t = self.preset.train
        self.module.ema_update(step, t.ema_power, t.ema_max)


def policy_windows(
    source: str | Path, split: str, preset: PolicyPreset, episodes, stride: int | None = None, pad_before: int = 0
):
    """Windows of ``horizon`` frames (the first ``n_obs_steps`` real; images decoded for those only) of
    the ``episodes=`` selection;
    with ``pad_before`` > 0 also, per episode, windows that start that many frames before its first
    (:class:`PadBefore`)."""
    m = preset.model
    windows = load_windows(
        source,
        split=split,
        context=m.n_obs_steps,
        horizon=m.horizon - m.n_obs_steps,
        stride=stride or preset.train.window_stride,
        pad=True,
        columns=policy_columns(m),
        episodes=episodes,
        context_only=[S.IMAGE] if m.images else [],
    )
    return PadBefore(windows, pad_before) if pad_before else windows


def shift_in(window: dict, s: int, time_dim: int = 0) -> dict:
    """A window of T frames moved s frames later in its episode's past: its first frame repeated s
    times in front, its last s frames dropped, the repeats marked ``is_pad``."""
    out = {}
    for key, x in window.items():
        first = x.narrow(time_dim, 0, 1)
        front = torch.ones_like(first, dtype=torch.bool) if key == IS_PAD else first
        shape = list(first.shape)
        shape[time_dim] = s
        out[key] = torch.cat([front.expand(shape), x.narrow(time_dim, 0, x.shape[time_dim] - s)], time_dim)
    return out


class PadBefore(Dataset):
    """The policy's windows plus, per episode, ``pad`` windows that start before its first frame:
    the first observation (and action) repeated in front, marked ``is_pad`` (so they add no loss),
    as the reference pads (``pad_before = n_obs_steps - 1``). Without them no training window is
    what the pilot sees at an episode's first step, where its one observation stands in for two."""

    def __init__(self, windows, pad: int):
        self.windows, self.pad = windows, int(pad)
        episode = np.asarray(windows.index.episode)
        firsts = np.flatnonzero(np.r_[True, episode[1:] != episode[:-1]]) if len(episode) else []
        self.extra = [(int(f), s) for f in firsts for s in range(1, self.pad + 1)]  # (window, frames in front)

    def __len__(self) -> int:
        return len(self.windows) + len(self.extra)

    def __getitem__(self, i: int) -> dict:
        if i < len(self.windows):
            return self.windows[i]
        base, s = self.extra[i - len(self.windows)]
        return shift_in(self.windows[base], s)

    def __getitems__(self, indices) -> WindowBatch:
        n = len(self.windows)
        bases = [i if i < n else self.extra[i - n][0] for i in indices]
        stacked = self.windows.__getitems__(bases).stacked  # key -> (B, T, ...)
        rows = [
            shift_in({k: v[j] for k, v in stacked.items()}, self.extra[i - n][1])
            if i >= n
            else {k: v[j] for k, v in stacked.items()}
            for j, i in enumerate(indices)
        ]
        return WindowBatch({k: torch.stack([r[k] for r in rows]) for k in stacked})

    def sampler(
        self,
        shuffle: bool = True,
        seed: int = 0,
        drop_last: bool = False,
        rank: int | None = None,
        world_size: int | None = None,
    ) -> DistributedSampler:
        """Order a pure function of (seed, epoch), as ``WindowDataset.sampler``."""
        return DistributedSampler(
            self, num_replicas=world_size or 1, rank=rank or 0, shuffle=shuffle, seed=seed, drop_last=drop_last
        )


# ---- runs ------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PolicyRequest:
    dataset: str
    preset: PolicyPreset
    out: Path
    levels: tuple[str, ...] = DEFAULT_LEVELS
    outcomes: tuple[str, ...] = ()
    device: str = "auto"
    resume: bool = False
    overwrite: bool = False
    extend: bool = False  # with resume: train the run on to a larger max_steps


def upgrade_config(old: dict) -> dict:
    """A policy run's config.json as this version writes it (``runs.upgrade_preset_config``); a run
    from before padding and masking settings keeps the recipe it was started with (none of either)."""

    def parse(preset: dict) -> PolicyPreset:
        return PolicyPreset.from_dict({**preset, "train": {"pad_before": 0, "mask_padding": False, **preset["train"]}})

    return upgrade_preset_config(old, parse, POLICY_PRESETS)


def policy_run_config(
    preset: PolicyPreset, meta: DatasetMeta, levels, outcomes, held_out: ValidationSplit | None = None
) -> dict:
    """The run's config.json (``runs.run_config``)."""
    held_out = held_out or ValidationSplit(0.0, 0, ())
    return run_config(
        POLICY,
        policy=FAMILY,
        preset=preset.to_dict(),
        dataset=meta.to_dict(),
        levels=list(levels),
        outcomes=list(outcomes),
        validation=held_out.to_dict(),
    )


def build_policy(preset: PolicyPreset, meta: DatasetMeta) -> DiffusionPolicy:
    """A fresh policy (initialised from the preset's seed) with the dataset's normalisation."""
    if preset.model.images:
        check_image_size(meta, preset.model.image_size, f"policy preset {preset.name!r}")
    torch.manual_seed(preset.train.loop.seed)  # initialisation
    policy = DiffusionPolicy(preset.model)
    low, high = action_range(meta.source)
    policy.set_normalisation(meta.state_mean, meta.state_std, low, high, goal_scale(meta))
    return policy


def train_policy(req: PolicyRequest, on_log=None) -> FitResult:
    """Train (or resume) a Diffusion Policy run; returns the loop's summary."""
    meta = read_dataset_meta(req.dataset)
    device = resolve_device(req.device)
    policy = build_policy(req.preset, meta)  # checks the image size before the run folder is claimed
    run = RunDir(req.out)
    rank = int(os.environ.get("RANK", 0))
    t = req.preset.train
    held_out = validation_split(req.dataset, t.val_fraction, t.val_seed)
    windows = policy_windows(
        req.dataset,
        "train",
        req.preset,
        training_episodes(req.dataset, req.levels, req.outcomes, held_out),
        pad_before=t.pad_before,
    )
    loop = t.loop
    if req.extend and loop.max_steps:  # the loop stops at the run's epochs too: an extension must fit in them
        world = int(os.environ.get("WORLD_SIZE", 1))
        per_epoch = len(windows.sampler(seed=loop.seed, drop_last=True, rank=0, world_size=world)) // loop.batch_size
        if per_epoch * loop.epochs < loop.max_steps:
            raise RunError(
                f"--extend --max-steps {loop.max_steps}: the run's {loop.epochs} epochs end at step "
                f"{per_epoch * loop.epochs}, and an extension changes only --max-steps; extend it to at "
                f"most {per_epoch * loop.epochs}"
            )
    if rank == 0:
        run.start(
            policy_run_config(req.preset, meta, req.levels, req.outcomes, held_out),
            resume=req.resume,
            overwrite=req.overwrite,
            upgrade=upgrade_config,
            extend=req.extend,
        )
    goals = episode_goals(req.dataset, "train")
    slots = req.preset.model.obstacles
    obstacles = episode_obstacles(req.dataset, "train", slots) if slots else None
    return fit(
        PolicyJob(policy, req.preset, goals, rank, obstacles),
        windows,
        loop,
        run,
        device,
        resume=run.resumes(req.resume, req.overwrite),
        label="train-policy",
        on_log=on_log,
    )
