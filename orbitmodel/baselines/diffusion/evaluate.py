"""Open-loop check of a trained policy: action MSE on held-out windows, beside the mean action.

For each window of the held-out split (expert episodes by default), the policy samples 16
actions from the window's first 2 observations; the 8 it would execute (frames t .. t+7) are
compared with the recorded ones, over real, non-terminal frames (windows that run past an
episode's end included: near the goal is where a policy that learnt to cut thrust fails). The
baseline predicts, for every frame, the mean action of the training episodes of the same levels.
Both are also given per executed index (t .. t+7) and per band of the distance to the goal at
frame t. A policy that learnt something sits well below the baseline everywhere; flying it
(``orbitmodel eval closed-loop``) is the real test.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import pyarrow.compute as pc
import torch
from torch.utils.data import DataLoader

from orbitdata import schema as S
from orbitdata.load import IS_PAD, collate_windows, load_windows
from orbitdata.load.select import select_episodes
from orbitdata.load.tables import load_episode_table, load_steps
from orbitmodel.baselines.diffusion.config import read_policy_run
from orbitmodel.baselines.diffusion.policy import DiffusionPolicy
from orbitmodel.baselines.diffusion.train import COLUMNS, DEFAULT_LEVELS, episode_goals
from orbitmodel.data import ValidationSplit, episode_filter, read_dataset_meta, split_selection, training_episodes
from orbitmodel.kinematics import P
from orbitmodel.runs import check_image_size, resolve_run

GOAL_BANDS_M = (1.0, 2.0, 4.0, 8.0)  # metres: upper edges of the bands of distance to the goal


class _Errors:
    """Squared errors of the policy and of the mean action, summed per group (an index, a band)."""

    def __init__(self, groups: int):
        self.policy, self.mean, self.frames = np.zeros(groups), np.zeros(groups), np.zeros(groups, np.int64)

    def add(self, group: np.ndarray, policy: np.ndarray, mean: np.ndarray) -> None:
        np.add.at(self.policy, group, policy)
        np.add.at(self.mean, group, mean)
        np.add.at(self.frames, group, 1)

    def rows(self, labels: list[dict]) -> list[dict]:
        out = []
        for i, label in enumerate(labels):
            n = int(self.frames[i])
            policy, mean = (self.policy[i] / n, self.mean[i] / n) if n else (None, None)
            out.append({**label, "frames": n, "policy": policy, "mean_action": mean,
                        "ratio": policy / mean if n and mean > 0 else None})
        return out


@dataclass(frozen=True)
class ActionMSE:
    """Mean squared error of executed actions (thrust units squared) over ``frames`` frames."""

    split: str
    levels: tuple[str, ...]
    windows: int
    frames: int
    policy: float
    mean_action: float  # baseline: always predict the training mean action
    per_index: tuple = ()  # per executed index k (frame t + k): {"index", "frames", "policy", "mean_action", "ratio"}
    per_band: tuple = ()  # per band of goal distance at frame t: {"from_m", "to_m", "frames", ...}

    @property
    def ratio(self) -> float:
        """policy / mean-action MSE: below 1 the policy beats the constant prediction."""
        return self.policy / self.mean_action if self.mean_action > 0 else float("nan")

    def to_dict(self) -> dict:
        return {**asdict(self), "levels": list(self.levels), "per_index": list(self.per_index),
                "per_band": list(self.per_band), "ratio": self.ratio}


def mean_action(source: str | Path, levels=DEFAULT_LEVELS, outcomes=(), held_out: ValidationSplit | None = None
                ) -> np.ndarray:
    """(8,) mean thrust over the non-terminal frames of the chosen training episodes (not the
    held-out validation ones)."""
    chosen = select_episodes(load_episode_table(source, "train", {}),
                             training_episodes(source, levels, outcomes, held_out), "train")
    table = load_steps(source, "train", False, {}).data.table.select([S.EPISODE_INDEX, S.ACTION, S.IS_LAST])
    keep = pc.and_(pc.is_in(table.column(S.EPISODE_INDEX), value_set=pc.cast(chosen, table.column(S.EPISODE_INDEX).type)),
                   pc.invert(table.column(S.IS_LAST)))
    actions = table.filter(keep).column(S.ACTION).combine_chunks().flatten().to_numpy().reshape(-1, S.ACTION_DIM)
    return actions.mean(axis=0)


@torch.no_grad()
def evaluate_policy(run: str | Path, dataset: str | Path, split: str = "test", levels=DEFAULT_LEVELS, outcomes=(),
                    stride: int = 4, max_windows: int = 0, batch_size: int = 64, seed: int = 0,
                    device: str = "cpu", use_ema: bool = True) -> ActionMSE:
    """Action MSE of the policy in ``run`` on ``split`` windows of ``dataset`` (every ``stride``-th
    start; the first ``max_windows`` when > 0), against predicting the mean training action."""
    if stride < 1 or batch_size < 1 or max_windows < 0:
        raise ValueError(f"stride={stride}, batch_size={batch_size}, max_windows={max_windows}: "
                         "give stride and batch size >= 1 and max_windows >= 0")
    policy = DiffusionPolicy.from_pretrained(run, device)
    c = policy.config
    check_image_size(read_dataset_meta(dataset), c.image_size, f"the policy of {run}")
    held_out = read_policy_run(resolve_run(run)).validation
    source_split, episodes = ("train", None) if split == "train" else split_selection(split, held_out)
    chosen = episode_filter(list(levels), list(outcomes))
    if episodes is not None:  # the held-out episodes of the chosen levels and outcomes
        keep = set(select_episodes(load_episode_table(dataset, "train", {}), chosen, "train").tolist())
        chosen = [e for e in episodes if e in keep]
    windows = load_windows(dataset, split=source_split, context=c.n_obs_steps, horizon=c.horizon - c.n_obs_steps,
                           stride=stride, pad=True, columns=list(COLUMNS), episodes=chosen)
    goals = episode_goals(dataset, source_split)
    baseline = torch.as_tensor(mean_action(dataset, levels, outcomes, held_out), dtype=torch.float32)  # (8,)
    n = len(windows) if max_windows == 0 else min(max_windows, len(windows))
    generator = torch.Generator().manual_seed(seed)
    executed = slice(c.action_start, c.action_start + c.n_action_steps)
    by_index, by_band = _Errors(c.n_action_steps), _Errors(len(GOAL_BANDS_M) + 1)
    To = c.n_obs_steps
    batches = [list(range(first, min(first + batch_size, n))) for first in range(0, n, batch_size)]
    for batch in DataLoader(windows, batch_sampler=batches, collate_fn=collate_windows):
        goal = goals[batch[S.EPISODE_INDEX][:, 0]]
        sampled = policy.sample_actions(batch[S.IMAGE][:, :To], batch[S.STATE][:, :To], goal, generator,
                                        use_ema).cpu()  # (B, H, 8)
        truth = batch[S.ACTION][:, executed]  # (B, 8 steps, 8)
        real = (~(batch[IS_PAD][:, executed] | batch[S.IS_LAST][:, executed])).numpy()  # (B, 8 steps)
        policy_sq = ((sampled[:, executed] - truth) ** 2).mean(-1).numpy()  # (B, 8 steps)
        mean_sq = ((baseline - truth) ** 2).mean(-1).numpy()
        distance = (goal - batch[S.STATE][:, c.action_start, P]).norm(dim=-1).numpy()  # (B,) metres at frame t
        band = np.searchsorted(GOAL_BANDS_M, distance, side="right")  # (B,)
        index = np.broadcast_to(np.arange(c.n_action_steps), real.shape)
        by_index.add(index[real], policy_sq[real], mean_sq[real])
        by_band.add(np.broadcast_to(band[:, None], real.shape)[real], policy_sq[real], mean_sq[real])
    frames = int(by_index.frames.sum())
    if frames == 0:
        raise ValueError(f"no real frames to compare in split {split!r} of {dataset}; use a smaller --stride")
    edges = (0.0, *GOAL_BANDS_M, None)
    return ActionMSE(split=split, levels=tuple(levels), windows=n, frames=frames,
                     policy=float(by_index.policy.sum() / frames), mean_action=float(by_index.mean.sum() / frames),
                     per_index=tuple(by_index.rows([{"index": k} for k in range(c.n_action_steps)])),
                     per_band=tuple(by_band.rows([{"from_m": lo, "to_m": hi} for lo, hi in zip(edges[:-1], edges[1:])])))
