"""The expert against itself: the floor under the policy's open-loop action error.

The expert plans its path once, with RRT*, then tracks it; its action at a state depends on
which of the paths around the obstacles it drew, and no observation shows that. For each window
that ``eval policy`` scores, other experts of the same task (``plans`` other RRT* draws, each with
its own thrust noise) that could be in the window's state at frame t (their path passes close by,
at a similar velocity, with the camera turned as they would turn it: ``ExpertPilot.could_be_at``)
take their path up there and act at the recorded states of frames t .. t+7. Their squared error
against the recorded actions is scored as the policy's is, per executed index and per band of
goal distance, beside the mean action on the same frames.

If the other plans that could be at a state are as likely as the recorded one, a policy that
samples exactly the expert's distribution of actions errs as much as another expert (twice the
variance of the expert's action at that state), and the best single prediction (the expert's mean
action there) errs half as much. Another expert is handed the recorded states at t+1 .. t+7
rather than flying from frame t, which tells it where the recorded flight went, so its error
understates that of a chunk sampled at frame t: a lower bound.

The episode's own plan with other thrust noise is scored too (``own``): the part of the error
that is thrust noise alone, and a check that a plan taken up at a recorded state reproduces the
recorded actions.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
from torch.utils.data import DataLoader

from orbitdata import schema as S
from orbitdata.load import IS_PAD, collate_windows
from orbitdata.load.source import read_meta
from orbitdata.load.tables import load_episode_table
from orbitmodel.baselines.diffusion.config import read_policy_run
from orbitmodel.baselines.diffusion.evaluate import GOAL_BANDS_M, Errors, mean_action, scored_windows
from orbitmodel.baselines.diffusion.sampling import PolicySampling
from orbitmodel.baselines.diffusion.train import DEFAULT_LEVELS
from orbitmodel.kinematics import P
from orbitmodel.runs import resolve_run

COLUMNS = (S.STATE, S.ACTION, S.IS_LAST)  # plus episode_index and is_pad
OWN_NOISE_DRAW = 2**31 - 1  # the own plan's other thrust noise: a draw no other plan uses


@dataclass(frozen=True)
class ExpertFloor:
    """Squared errors (thrust units squared) of other experts at the recorded states, beside the
    mean action's, over the ``frames`` real frames of the windows where another plan could be."""

    run: str
    dataset: str
    split: str
    levels: tuple[str, ...]
    windows: int  # windows looked at (those ``eval policy`` scores with the same run and flags)
    plans: int  # other RRT* draws per episode
    position_m: float  # how close another plan's path must pass to the state at frame t
    speed_mps: float  # ... how close its reference velocity must be to the state's
    angle_deg: float  # ... and how close the camera's attitude to the one it would command
    scored_windows: int  # windows with at least one other plan that could be there
    frames: int  # real frames t .. t+7 of those windows
    own_plan_could: float  # fraction of the windows whose own plan passes the same test (its recall)
    own_plan_deviation: dict  # how far the recorded flight is from its own plan at frame t, per quantity
    # ("position_m", "speed_mps", "angle_deg"): its 50th and 90th percentiles over the windows
    plans_per_window: float  # other plans that could be there, mean over the scored windows
    other: float  # MSE of another expert, averaged over the plans that could be there
    own: float  # MSE of the episode's own plan with other thrust noise
    mean_action: float  # MSE of the training mean action on the same frames
    per_index: tuple = ()  # per executed index k: {"index", "frames", "other", "own", "mean_action", *_ratio}
    per_band: tuple = ()  # per band of goal distance at frame t: {"from_m", "to_m", "frames", ...}
    policy: dict | None = None  # ``eval policy``'s result (ActionMSE.to_dict) on the same windows

    @property
    def ratio(self) -> float:
        """other / mean-action MSE: the figure ``eval policy``'s ratio is compared with."""
        return self.other / self.mean_action if self.mean_action > 0 else float("nan")

    def to_dict(self) -> dict:
        return {
            **asdict(self),
            "levels": list(self.levels),
            "per_index": list(self.per_index),
            "per_band": list(self.per_band),
            "ratio": self.ratio,
        }


class _Experts:
    """The experts of one episode: its own plan (other noise) and ``plans`` other draws."""

    def __init__(self, env, generation, row: dict, plans: int):
        from orbitdata.fly.pilot import Task
        from orbitdata.fly.registry import make_pilot

        env.reset(seed=int(row[S.SEED]))
        scn = env.scenario
        if not np.allclose(scn.goal, row[S.GOAL], atol=1e-4):
            raise ValueError(
                f"episode {row[S.EPISODE_INDEX]}: its seed gives the goal {tuple(scn.goal)}, the "
                f"dataset records {tuple(row[S.GOAL])}; the dataset's config no longer rebuilds "
                "its scenarios (made by another version of orbitdata?)"
            )
        task = Task(
            goal=scn.goal, goal_radius=scn.goal_radius, initial_velocity=scn.initial_velocity, seed=int(row[S.SEED])
        )
        self.own = make_pilot("expert", generation, plan_draw=0, noise_draw=OWN_NOISE_DRAW)
        self.others = [make_pilot("expert", generation, plan_draw=k, noise_draw=k) for k in range(1, plans + 1)]
        for pilot in (self.own, *self.others):
            pilot.reset(task, scenario=scn)


def _chunk_errors(pilot, states: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(K,) squared error per executed frame of ``pilot`` taken up at states[0], acting at each state."""
    pilot.rejoin(states[0])
    acts = np.stack([pilot.act({"state": s}) for s in states]).astype(np.float32)
    return ((acts - truth) ** 2).mean(-1)


def expert_floor(
    run: str | Path,
    dataset: str | Path,
    split: str = "test",
    stride: int = 4,
    max_windows: int = 0,
    plans: int = 64,
    position_m: float = 0.1,
    speed_mps: float = 0.1,
    angle_deg: float = 27.0,
    with_policy: bool = True,
    seed: int = 0,
    device: str = "cpu",
    sampling: PolicySampling | None = None,
    preset: str | None = None,
) -> ExpertFloor:
    """Other experts' error on the windows ``eval policy`` scores for the policy in ``run`` (its
    window geometry, validation episodes and mean action; expert episodes only), with ``plans``
    other RRT* draws per episode and the tolerances of ``ExpertPilot.could_be_at`` (the defaults
    are about how far the expert strays from its own plan: docs/results.md); ``with_policy``: the
    policy scored on the same windows beside them (its sampling noise from ``seed``, sampled as
    ``sampling`` says, by default the ``cpu`` flight preset; ``preset`` names it)."""
    if stride < 1 or max_windows < 0 or plans < 1:
        raise ValueError(
            f"stride={stride}, max_windows={max_windows}, plans={plans}: give stride and plans >= 1 and "
            "max_windows >= 0"
        )
    if sampling is not None and not with_policy:
        raise ValueError(
            "sampling settings sample the policy, which with_policy=False (--no-policy) does not score; "
            "drop one of them"
        )
    if not (position_m > 0 and speed_mps > 0 and angle_deg > 0):
        raise ValueError(f"tolerances {position_m} m, {speed_mps} m/s, {angle_deg} deg: give positive ones")
    from orbitdata.sim.env import CubeSatEnv

    policy_run = read_policy_run(resolve_run(run))
    held_out, c = policy_run.validation, policy_run.preset.model
    levels = DEFAULT_LEVELS  # the experts' own episodes: another plan is compared with the recorded one
    source_split, windows = scored_windows(dataset, c, held_out, split, levels, (), stride, list(COLUMNS))
    table = load_episode_table(dataset, source_split, {})
    rows = {int(r[S.EPISODE_INDEX]): r for r in table.select([S.EPISODE_INDEX, S.SEED, S.GOAL]).to_pylist()}
    generation = read_meta(dataset)[0].generation_config()
    env = CubeSatEnv(replace(generation.sim, render=False), generation.scenario)
    baseline = mean_action(dataset, levels, (), held_out)  # (8,)
    n = len(windows) if max_windows == 0 else min(max_windows, len(windows))
    t0, K = c.action_start, c.n_action_steps
    names = ("other", "own", "mean_action")
    by_index, by_band = Errors(K, names), Errors(len(GOAL_BANDS_M) + 1, names)
    experts, episode = None, None
    scored, own_could, could_total, looked, own_deviation = [], 0, 0, 0, []
    batches = [list(range(first, min(first + 64, n))) for first in range(0, n, 64)]
    try:
        for indices, batch in zip(batches, DataLoader(windows, batch_sampler=batches, collate_fn=collate_windows)):
            for b, index in enumerate(indices):
                if bool(batch[IS_PAD][b, t0]):
                    continue
                ep = int(batch[S.EPISODE_INDEX][b, 0])
                if ep != episode:
                    experts, episode = _Experts(env, generation, rows[ep], plans), ep
                states = batch[S.STATE][b, t0 : t0 + K].numpy()
                truth = batch[S.ACTION][b, t0 : t0 + K].numpy()
                real = ~(batch[IS_PAD][b, t0 : t0 + K] | batch[S.IS_LAST][b, t0 : t0 + K]).numpy()
                could = [e for e in experts.others if e.could_be_at(states[0], position_m, speed_mps, angle_deg)]
                looked += 1
                own_could += experts.own.could_be_at(states[0], position_m, speed_mps, angle_deg)
                deviation = experts.own.deviation(states[0])
                if deviation is not None:
                    own_deviation.append(deviation)
                if not could or not real.any():
                    continue
                scored.append(index)
                could_total += len(could)
                errors = {
                    "other": np.mean([_chunk_errors(e, states, truth) for e in could], axis=0),
                    "own": _chunk_errors(experts.own, states, truth),
                    "mean_action": ((baseline - truth) ** 2).mean(-1),
                }
                errors = {k: v[real] for k, v in errors.items()}
                goal = np.asarray(rows[ep][S.GOAL], np.float32)
                band = int(np.searchsorted(GOAL_BANDS_M, np.linalg.norm(goal - states[0, P]), side="right"))
                by_index.add(np.arange(K)[real], **errors)
                by_band.add(np.full(int(real.sum()), band), **errors)
    finally:
        env.close()
    frames = int(by_index.frames.sum())
    if frames == 0:
        raise ValueError(
            f"no window of split {split!r} of {dataset} has another plan within the tolerances; use more "
            "--plans, wider tolerances or a smaller --stride"
        )
    policy = None
    if with_policy:
        from orbitmodel.baselines.diffusion.evaluate import evaluate_policy

        policy = evaluate_policy(
            run,
            dataset,
            split=split,
            levels=levels,
            stride=stride,
            seed=seed,
            device=device,
            indices=scored,
            sampling=sampling,
            preset=preset,
        ).to_dict()
    edges = (0.0, *GOAL_BANDS_M, None)
    quantiles = np.percentile(np.asarray(own_deviation).reshape(-1, 3), [50, 90], axis=0) if own_deviation else None
    spread = {
        name: ([float(q) for q in quantiles[:, k]] if quantiles is not None else None)
        for k, name in enumerate(("position_m", "speed_mps", "angle_deg"))
    }
    return ExpertFloor(
        run=str(run),
        dataset=str(dataset),
        split=split,
        levels=tuple(levels),
        windows=n,
        plans=plans,
        position_m=position_m,
        speed_mps=speed_mps,
        angle_deg=angle_deg,
        scored_windows=len(scored),
        frames=frames,
        own_plan_could=own_could / looked,
        own_plan_deviation=spread,
        plans_per_window=could_total / len(scored),
        other=by_index.total("other"),
        own=by_index.total("own"),
        mean_action=by_index.total("mean_action"),
        per_index=tuple(by_index.rows([{"index": k} for k in range(K)])),
        per_band=tuple(by_band.rows([{"from_m": lo, "to_m": hi} for lo, hi in zip(edges[:-1], edges[1:])])),
        policy=policy,
    )
