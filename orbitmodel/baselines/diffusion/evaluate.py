"""Open-loop check of a trained policy: action MSE on held-out windows, beside the mean action.

For each window of the held-out split (expert episodes by default), the policy samples 16
actions from the window's first 2 observations; the 8 it would execute (frames t .. t+7) are
compared with the recorded ones, over real, non-terminal frames (windows that run past an
episode's end included: near the goal is where a policy that learnt to cut thrust fails). The
baseline predicts, for every frame, the mean action of the training episodes of the same levels.
Both are also given per executed index (t .. t+7) and per band of the distance to the goal at
frame t. A policy that learnt something sits well below the baseline everywhere; flying it
(``orbitmodel eval closed-loop``) is the real test.

With ``draws`` N > 1 (``--set draws=N``) the policy samples each window N times (the first draw is the one scored
above, what a flight executes) and the error splits in two: a sample's MSE is the squared error
of the policy's mean action plus the variance of its samples (``variance``, unbiased over the N
draws), and the mean of the N samples (``sample_mean``) carries the first part and 1/N of the
second; over the N draws, a draw's MSE (``draws``) is the mean's MSE plus (N-1)/N of the
variance. Where the variance is most of the error, the policy spreads its samples over actions
the expert did not take at that moment (several ways round an obstacle, or noise), rather than
missing the expert's action on average. ``central`` scores the draw nearest the N draws' mean over
the executed actions, a real sample: what the pilot flies with ``draws=N, pick="central"`` and its
config's executed actions (the pilot picks over the ones it executes).
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
from orbitmodel.baselines.diffusion.sampling import DEFAULT_FLIGHT, PolicySampling, policy_sampling
from orbitmodel.baselines.diffusion.train import DEFAULT_LEVELS, episode_goals, episode_obstacles, policy_columns
from orbitmodel.data import ValidationSplit, episode_filter, read_dataset_meta, split_selection, training_episodes
from orbitmodel.kinematics import P
from orbitmodel.runs import check_image_size, resolve_run

GOAL_BANDS_M = (1.0, 2.0, 4.0, 8.0)  # metres: upper edges of the bands of distance to the goal


class Errors:
    """Squared errors summed per group (an index, a band), one sum per name: of the policy's
    first sample (``policy``), of the mean action (``mean_action``), with several samples of the
    samples' variance and of their mean, or of other experts (``expert_floor``). A row gives each
    as a ratio to the mean action's: ``ratio`` for ``policy``, ``NAME_ratio`` for the others."""

    def __init__(self, groups: int, names: tuple[str, ...]):
        self.sums = {name: np.zeros(groups) for name in names}
        self.frames = np.zeros(groups, np.int64)

    def add(self, group: np.ndarray, **values: np.ndarray) -> None:
        for name, value in values.items():
            np.add.at(self.sums[name], group, value)
        np.add.at(self.frames, group, 1)

    def total(self, name: str) -> float:
        return float(self.sums[name].sum() / self.frames.sum())

    def rows(self, labels: list[dict]) -> list[dict]:
        out = []
        for i, label in enumerate(labels):
            n = int(self.frames[i])
            row = {**label, "frames": n, **{k: (float(v[i] / n) if n else None) for k, v in self.sums.items()}}
            mean = row["mean_action"]
            for name in self.sums:
                if name != "mean_action":
                    key = "ratio" if name == "policy" else f"{name}_ratio"
                    row[key] = row[name] / mean if n and mean > 0 else None
            out.append(row)
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
    samples: int = 1  # draws per window; with more than one, the rows add "draws", "variance", "sample_mean", "central"
    noise_scale: float = 1.0  # of the noise each draw starts from (1: as trained)
    inference_steps: int | None = None  # the DDIM steps it sampled with
    timestep_spacing: str | None = None  # ... and their spacing
    preset: str | None = None  # the flight preset the sampling settings came from (None: given some other way)
    without_obstacles: bool = False  # a privileged policy told no obstacle (the knock-out)
    draws: float | None = None  # the MSE of a draw, averaged over the N draws (``policy`` is the first's)
    variance: float | None = None  # the policy's own variance: mean over frames of the N draws' unbiased variance
    sample_mean: float | None = None  # MSE of the mean of the N draws
    central: float | None = None  # MSE of the central draw, the one nearest the N draws' mean (the pilot's pick)

    @property
    def ratio(self) -> float:
        """policy / mean-action MSE: below 1 the policy beats the constant prediction."""
        return self.policy / self.mean_action if self.mean_action > 0 else float("nan")

    def to_dict(self) -> dict:
        return {
            **asdict(self),
            "levels": list(self.levels),
            "per_index": list(self.per_index),
            "per_band": list(self.per_band),
            "ratio": self.ratio,
        }


def mean_action(
    source: str | Path, levels=DEFAULT_LEVELS, outcomes=(), held_out: ValidationSplit | None = None
) -> np.ndarray:
    """(8,) mean thrust over the non-terminal frames of the chosen training episodes (not the
    held-out validation ones)."""
    chosen = select_episodes(
        load_episode_table(source, "train", {}), training_episodes(source, levels, outcomes, held_out), "train"
    )
    table = load_steps(source, "train", False, {}).data.table.select([S.EPISODE_INDEX, S.ACTION, S.IS_LAST])
    keep = pc.and_(
        pc.is_in(table.column(S.EPISODE_INDEX), value_set=pc.cast(chosen, table.column(S.EPISODE_INDEX).type)),
        pc.invert(table.column(S.IS_LAST)),
    )
    actions = table.filter(keep).column(S.ACTION).combine_chunks().flatten().to_numpy().reshape(-1, S.ACTION_DIM)
    return actions.mean(axis=0)


def scored_windows(dataset, config, held_out: ValidationSplit, split: str, levels, outcomes, stride: int, columns):
    """(dataset split, windows) that the open-loop evaluations score for a policy with ``config``
    (a PolicyConfig): every ``stride``-th window of ``split`` ("test", "val": the run's
    ``held_out`` episodes, or "train") among the chosen levels and outcomes, padded past the end."""
    source_split, episodes = ("train", None) if split == "train" else split_selection(split, held_out)
    chosen = episode_filter(list(levels), list(outcomes))
    if episodes is not None:  # the held-out episodes of the chosen levels and outcomes
        keep = set(select_episodes(load_episode_table(dataset, "train", {}), chosen, "train").tolist())
        chosen = [e for e in episodes if e in keep]
    return source_split, load_windows(
        dataset,
        split=source_split,
        context=config.n_obs_steps,
        horizon=config.horizon - config.n_obs_steps,
        stride=stride,
        pad=True,
        columns=columns,
        episodes=chosen,
    )


@torch.no_grad()
def evaluate_policy(
    run: str | Path,
    dataset: str | Path,
    split: str = "test",
    levels=DEFAULT_LEVELS,
    outcomes=(),
    stride: int = 4,
    max_windows: int = 0,
    batch_size: int = 64,
    seed: int = 0,
    device: str = "cpu",
    use_ema: bool = True,
    sampling: PolicySampling | None = None,
    without_obstacles: bool = False,
    indices=None,
    preset: str | None = None,
) -> ActionMSE:
    """Action MSE of the policy in ``run`` on ``split`` windows of ``dataset`` (every ``stride``-th
    start; the first ``max_windows`` when > 0), against predicting the mean training action.
    ``sampling`` (default: the ``cpu`` flight preset; ``preset`` names it for the record) sets
    the DDIM steps and spacing, the noise scale and the executed actions scored, as the pilot
    flies them; with ``draws`` > 1 each window is drawn that many times and the error split
    (module docstring). ``without_obstacles``: a privileged policy is told no obstacle (every
    slot empty), a knock-out of how much it relies on them. ``indices``: score only these of the
    split's windows (positions in its window list, as ``expert_floor`` reports them) instead of
    the first ``max_windows``."""
    if sampling is None:
        sampling, preset = policy_sampling(DEFAULT_FLIGHT), preset or DEFAULT_FLIGHT
    samples = sampling.draws
    if stride < 1 or batch_size < 1 or max_windows < 0:
        raise ValueError(
            f"stride={stride}, batch_size={batch_size}, max_windows={max_windows}: "
            "give stride and batch size >= 1 and max_windows >= 0"
        )
    policy = DiffusionPolicy.from_pretrained(run, device)
    c = policy.config
    sampling = sampling.resolved(c)
    if without_obstacles and not c.obstacles:
        raise ValueError(
            f"--without-obstacles: the policy of {run} is told no obstacles; it knocks out a "
            "privileged policy's (preset cpu-state-obstacles)"
        )
    if c.images:
        check_image_size(read_dataset_meta(dataset), c.image_size, f"the policy of {run}")
    held_out = read_policy_run(resolve_run(run)).validation
    source_split, windows = scored_windows(dataset, c, held_out, split, levels, outcomes, stride, policy_columns(c))
    goals = episode_goals(dataset, source_split)
    obstacles = episode_obstacles(dataset, source_split, c.obstacles) if c.obstacles else None  # privileged
    if without_obstacles:
        obstacles = torch.zeros_like(obstacles)
    baseline = torch.as_tensor(mean_action(dataset, levels, outcomes, held_out), dtype=torch.float32)  # (8,)
    if indices is None:
        order = list(range(len(windows) if max_windows == 0 else min(max_windows, len(windows))))
    else:
        order = [int(i) for i in indices]
        if any(not 0 <= i < len(windows) for i in order):
            raise ValueError(
                f"indices: split {split!r} of {dataset} has {len(windows)} windows; give positions below that"
            )
    n = len(order)
    # one noise stream per draw: the first is the stream a single-draw evaluation uses, whatever N
    seeds = [seed] + [int(np.random.SeedSequence([seed, k]).generate_state(1)[0]) for k in range(1, samples)]
    generators = [torch.Generator().manual_seed(k) for k in seeds]
    steps = sampling.action_steps
    executed = slice(c.action_start, c.action_start + steps)
    names = ("policy", "mean_action") + (("draws", "variance", "sample_mean", "central") if samples > 1 else ())
    by_index, by_band = Errors(steps, names), Errors(len(GOAL_BANDS_M) + 1, names)
    To = c.n_obs_steps
    batches = [order[first : first + batch_size] for first in range(0, n, batch_size)]
    for batch in DataLoader(windows, batch_sampler=batches, collate_fn=collate_windows):
        goal = goals[batch[S.EPISODE_INDEX][:, 0]]
        images = batch[S.IMAGE][:, :To] if c.images else None
        told = obstacles[batch[S.EPISODE_INDEX][:, 0]] if obstacles is not None else None
        draws = torch.stack(
            [
                policy.sample_actions(images, batch[S.STATE][:, :To], goal, g, use_ema, told, sampling).cpu()[
                    :, executed
                ]
                for g in generators
            ]
        )  # (N, B, 8, 8)
        truth = batch[S.ACTION][:, executed]  # (B, 8 steps, 8)
        real = (~(batch[IS_PAD][:, executed] | batch[S.IS_LAST][:, executed])).numpy()  # (B, 8 steps)
        errors = {"policy": ((draws[0] - truth) ** 2).mean(-1), "mean_action": ((baseline - truth) ** 2).mean(-1)}
        if samples > 1:
            errors["draws"] = ((draws - truth) ** 2).mean(-1).mean(0)
            errors["variance"] = draws.var(0, unbiased=True).mean(-1)
            errors["sample_mean"] = ((draws.mean(0) - truth) ** 2).mean(-1)
            # the draw nearest the draws' mean over the executed actions (the one the others are closest to)
            spread = ((draws - draws.mean(0)) ** 2).flatten(2).sum(-1)  # (N, B)
            central = draws[spread.argmin(0), torch.arange(draws.shape[1])]  # (B, 8, 8)
            errors["central"] = ((central - truth) ** 2).mean(-1)
        errors = {k: v.numpy()[real] for k, v in errors.items()}  # (B, 8 steps) -> the real frames
        distance = (goal - batch[S.STATE][:, c.action_start, P]).norm(dim=-1).numpy()  # (B,) metres at frame t
        band = np.searchsorted(GOAL_BANDS_M, distance, side="right")  # (B,)
        index = np.broadcast_to(np.arange(steps), real.shape)
        by_index.add(index[real], **errors)
        by_band.add(np.broadcast_to(band[:, None], real.shape)[real], **errors)
    frames = int(by_index.frames.sum())
    if frames == 0:
        raise ValueError(f"no real frames to compare in split {split!r} of {dataset}; use a smaller --stride")
    edges = (0.0, *GOAL_BANDS_M, None)
    several = samples > 1
    return ActionMSE(
        split=split,
        levels=tuple(levels),
        windows=n,
        frames=frames,
        policy=by_index.total("policy"),
        mean_action=by_index.total("mean_action"),
        per_index=tuple(by_index.rows([{"index": k} for k in range(steps)])),
        per_band=tuple(by_band.rows([{"from_m": lo, "to_m": hi} for lo, hi in zip(edges[:-1], edges[1:])])),
        samples=samples,
        noise_scale=sampling.noise_scale,
        without_obstacles=without_obstacles,
        inference_steps=sampling.inference_steps,
        timestep_spacing=sampling.timestep_spacing,
        preset=preset,
        draws=by_index.total("draws") if several else None,
        variance=by_index.total("variance") if several else None,
        sample_mean=by_index.total("sample_mean") if several else None,
        central=by_index.total("central") if several else None,
    )
