"""Closed loop: fly a planning pilot, or a trained policy, over the ``orbitdata fly`` grid and
record every episode.

The grid is orbitdata's (obstacle count x initial speed, ``orbitdata.seeding.grid_seed``), so
the planner, its oracles, the Diffusion Policy, the expert and the risky pilot fly exactly the
same episodes. None of those seeds generated a training episode: :func:`check_unseen_seeds`
checks it against the run's dataset before flying. A run folder is flown as what it holds: a
Stage I run by the planning pilot of ``variant``, a policy run (``orbitmodel train-policy``) by
its own pilot. ``batch`` episodes fly in lockstep (``evaluate.lockstep``), chunk by chunk here or
as Ray tasks (``evaluate.executors``).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from orbitdata.config import GenerationConfig, config_changes
from orbitdata.fly.grid import CellResult, check_grid, grid_report
from orbitdata.fly.record import episode_summary
from orbitdata.seeding import episode_seed, grid_seed
from orbitdata.sim.config import CubeSatConfig
from orbitdata.sim.env import CubeSatEnv
from orbitmodel.baselines.diffusion.sampling import PolicySampling
from orbitmodel.evaluate.executors import EXECUTORS, run_local, run_ray
from orbitmodel.evaluate.lockstep import ChunkResult, FlownEpisode, GridEpisode, chunks, fly_lockstep
from orbitmodel.plan.config import PLANNER_PRESETS, PlannerConfig, default_planner_preset, planner_config, recorded
from orbitmodel.plan.factory import build_pilot, camera_for_run
from orbitmodel.plan.pilot import Variant
from orbitmodel.plan.timing import Timings
from orbitmodel.runs import POLICY, RunDir, RunError, resolve_run, stage_of

PilotSettings = PlannerConfig | PolicySampling


@dataclass(frozen=True)
class ClosedLoopRequest:
    """One grid flight.

    Args:
        variant: the planning pilot (see ``orbitmodel.plan.pilot``); a policy run flies its own.
        run: the Stage I run folder (world model, probe, dataset facts), or a policy run, or
            the Hub model repo id of either (``owner/name[@revision]``); optional for the
            rigid-body oracles, which then skip the unseen-seed check.
        obstacles, speeds, episodes, seed: the grid, as ``orbitdata fly``.
        settings: the pilot's settings: a :class:`PlannerConfig` for a planning pilot, a
            :class:`PolicySampling` for a policy run (see :func:`pilot_settings`); checked by the
            pilot that owns them. ``preset`` names the preset they started from, for the report.
        config: scenario and simulator settings (the camera is set to the run's).
        max_steps: frames per episode at most (None: the simulator's 300).
        video_dir, video_format: one video per episode (".mp4" or ".gif").
        batch: episodes flown in lockstep, one batched pilot call per control step
            (``evaluate.lockstep``; 1: one at a time, exactly the unbatched flight).
        executor: "local" (this process) or "ray": the grid's chunks as Ray tasks
            (``evaluate.executors``), the same episodes as a local flight with the same batch.
        ray_address: with executor "ray", the cluster to join (None: ``RAY_ADDRESS``'s, else a
            local Ray instance).
    """

    variant: Variant = Variant.PLANNER
    run: Path | None = None
    obstacles: tuple[int, ...] = (1, 3, 5)
    speeds: tuple[float, ...] = (1.0, 2.0)
    episodes: int = 20
    seed: int = 0
    settings: PilotSettings = field(default_factory=PlannerConfig)
    preset: str | None = None
    config: GenerationConfig = field(default_factory=GenerationConfig)
    max_steps: int | None = None
    video_dir: Path | None = None
    video_format: str = ".mp4"
    batch: int = 1
    executor: str = "local"
    ray_address: str | None = None


def pilot_settings(run: str | Path | None, preset: str | None = None, **options) -> tuple[PilotSettings, str]:
    """(settings, preset name) for flying ``run``: a policy run's flight preset
    (``sampling.POLICY_FLIGHTS``, default ``cpu``), else a planner preset (``PLANNER_PRESETS``,
    default: the one that suits this machine), with single fields changed by ``options``
    (``--set KEY=VALUE``)."""
    if run is not None and stage_of(resolve_run(run)) == POLICY:
        from orbitmodel.baselines.diffusion.sampling import DEFAULT_FLIGHT, POLICY_FLIGHTS, policy_sampling

        if preset is not None and preset not in POLICY_FLIGHTS:
            raise ValueError(
                f"--preset {preset}: {run} holds a diffusion policy, whose flight presets are "
                f"{', '.join(POLICY_FLIGHTS)}"
            )
        preset = preset or DEFAULT_FLIGHT
        return policy_sampling(preset, **options), preset
    if preset is not None and preset not in PLANNER_PRESETS:
        raise ValueError(f"--preset {preset}: the planning pilots' presets are {', '.join(PLANNER_PRESETS)}")
    preset = preset or default_planner_preset()
    return planner_config(preset, **options), preset


@dataclass
class ClosedLoopResult:
    cells: list[CellResult]
    episodes: list[dict]  # one record per episode (see episode_record)
    step_ms: list[float]  # every control step's planning time
    replan_ms: list[float]
    timings: dict[str, float]  # seconds per phase, summed


def grid_seeds(obstacles, speeds, episodes: int, seed: int) -> list[GridEpisode]:
    """(obstacles, speed, episode, episode seed) of every grid episode, setting by setting
    (:meth:`ClosedLoop.fly` flies them round-robin: episode k of every setting, then k + 1)."""
    return [
        GridEpisode(n, float(v), k, grid_seed(seed, n, v, k))
        for n in obstacles
        for v in speeds
        for k in range(episodes)
    ]


def dataset_seeds(root_seed: int, episodes: int) -> set[int]:
    """The episode seeds of a dataset generated with ``root_seed`` (``orbitdata.write.plan``)."""
    return {episode_seed(root_seed, i) for i in range(episodes)}


def check_unseen_seeds(seeds: list[int], root_seed: int, episodes: int) -> None:
    """Raise ValueError if a grid seed generated one of the dataset's episodes."""
    seen = dataset_seeds(root_seed, episodes) & set(seeds)
    if seen:
        raise ValueError(
            f"{len(seen)} grid seed(s) generated training episodes of the run's dataset "
            f"(root seed {root_seed}); choose another --seed"
        )


def episode_record(n: int, v: float, k: int, seed: int, result, cubesat: CubeSatConfig) -> dict:
    """One episode of the grid: its setting, number and seed, ``orbitdata.fly.record``'s summary
    (``cubesat``: the body flown, for the delta-v) and what the pilot reported."""
    return {
        "obstacles": n,
        "speed": v,
        "episode": k,
        "seed": seed,
        **episode_summary(result, cubesat),
        **result.pilot_info,
    }


EpisodeHook = Callable[[CellResult, dict], None]


def load_pilot(req: "ClosedLoopRequest", run: Path | None, sim, timings: Timings):
    """(pilot, simulator settings, pilot name) for ``req``, whose run is in the local folder ``run``:
    the run's policy for a policy run, else the planning pilot of ``req.variant``."""
    policy = run is not None and stage_of(run) == POLICY
    if policy:
        from orbitmodel.baselines.diffusion.pilot import load_policy_pilot

        if req.variant != Variant.PLANNER:
            raise RunError(
                f"{req.run} holds a diffusion policy, which flies as itself; drop --pilot {req.variant.value}"
            )
        if not isinstance(req.settings, PolicySampling):
            raise RunError(
                f"{req.run} holds a diffusion policy: fly it with a flight preset (--preset cpu) and its "
                "sampling settings, not planner settings"
            )
        pilot = load_policy_pilot(run, req.settings, preset=req.preset)
        return pilot, camera_for_run(sim, pilot.policy), pilot.name
    if not isinstance(req.settings, PlannerConfig):
        raise RunError(
            f"{req.run or 'a rigid-body oracle'} is flown by a planning pilot: give planner settings "
            "(--preset cpu), not a policy's sampling settings"
        )
    planner = dataclasses.replace(req.settings, record=req.video_dir is not None)
    pilot, sim = build_pilot(req.variant, run, planner, sim, timings)
    return pilot, sim, req.variant.value


def run_dataset(run: Path):
    """The dataset facts (``DatasetMeta``) a Stage I or policy run recorded."""
    from orbitmodel.data import DatasetMeta

    raw = RunDir(run).read_config()
    try:
        return DatasetMeta.from_dict(raw["dataset"])
    except (KeyError, TypeError) as err:
        raise RunError(f"{run}/config.json records no dataset facts ({err}); train the run again") from None


class ClosedLoop:
    """A grid flight, checked and loaded: construction raises ValueError / RunError on input it
    cannot fly (bad grid, missing weights or probe, another camera, seeds seen in training);
    :meth:`fly` then flies every episode."""

    def __init__(self, req: ClosedLoopRequest):
        check_grid(list(req.obstacles), list(req.speeds), req.episodes)
        if req.video_format not in (".mp4", ".gif"):
            raise ValueError(f"video format {req.video_format!r}: use .mp4 or .gif")
        if req.max_steps is not None and req.max_steps < 2:
            raise ValueError(f"max_steps={req.max_steps}: an episode needs at least 2 frames")
        if req.batch < 1:
            raise ValueError(f"batch={req.batch}: fly 1 or more episodes at a time")
        if req.executor not in EXECUTORS:
            raise ValueError(f"executor {req.executor!r}: use {' or '.join(EXECUTORS)}")
        if req.ray_address and req.executor != "ray":
            raise ValueError(f"ray_address={req.ray_address!r} is for Ray tasks: give executor='ray', or drop it")
        if req.executor == "ray" and req.video_dir is not None:
            raise ValueError("videos are written where the episodes fly: fly --video with the local executor")
        if req.executor == "ray":
            from orbitdata.write.executors import check_ray_address

            check_ray_address(req.ray_address, "ray_address")  # before the flight: Ray retries a dead one for minutes
        settings, tier = req.settings, req.config.tier
        if req.variant.privileged and isinstance(settings, PlannerConfig) and tier != "static":
            if settings.obstacle_motion == "static":
                raise ValueError(
                    f"the debris of the {tier} tier moves: fly the {req.variant.value} oracle with --set "
                    "obstacle_motion=true (their exact motion) or --set obstacle_motion=frozen (held at each replan)"
                )
        self.req = req
        self.seeds = grid_seeds(req.obstacles, req.speeds, req.episodes, req.seed)
        # Round-robin over the settings (episode k of every setting, then k + 1): a grid stopped
        # early has covered every setting alike. Each episode's seed is fixed by (n, v, k).
        self.order = sorted(self.seeds, key=lambda cell: cell.episode)
        self.run = run = None if req.run is None else resolve_run(req.run)  # a folder, or a Hub id downloaded once
        if run is not None:
            meta = run_dataset(run)
            check_unseen_seeds([s for *_, s in self.seeds], meta.root_seed, sum(meta.episodes.values()))
        self.timings = Timings()
        self.pilot, sim, self.name = load_pilot(req, run, req.config.sim, self.timings)
        self.image_codec = bool(getattr(self.pilot, "image_codec", False))
        self.image_quality = req.config.dataset.jpeg_quality if self.image_codec else None
        self.sim = dataclasses.replace(
            sim, render=self.pilot.needs_images or req.video_dir is not None, max_steps=req.max_steps or sim.max_steps
        )

    def report(self, result: ClosedLoopResult) -> dict:
        """:func:`closed_loop_report` of this flight, with the pilot's own settings (a policy's
        flight preset and every sampling setting), and the torch threads and kernels (the CPU
        capability, which ``ATEN_CPU_CAPABILITY`` can lower) of this process (on Ray, the driver's)."""
        planning = self.name == self.req.variant.value
        report = closed_loop_report(self.req, result, None if planning else self.name, self.image_codec)
        return {
            **report,
            "pilot_settings": None if planning else self.pilot.metadata(),
            "threads": torch.get_num_threads(),
            "cpu_capability": torch.backends.cpu.get_cpu_capability(),
            "batch": self.req.batch,
        }

    def parts(self) -> list[range]:
        """The flight's chunks (:func:`lockstep.chunks`), in flight order."""
        return chunks(len(self.order), self.req.batch)

    def key(self) -> str:
        """The flight's identity for its kept chunks (``kept_chunks.flight_key``)."""
        from orbitmodel.evaluate.kept_chunks import flight_key

        return flight_key(self.req, self.run, self.parts())

    def fly(
        self,
        on_episode: EpisodeHook | None = None,
        kept: dict[int, ChunkResult] | None = None,
        on_chunk: Callable[[ChunkResult], None] | None = None,
    ) -> ClosedLoopResult:
        """Fly every grid episode, ``req.batch`` at a time, chunk by chunk (:func:`lockstep.chunks`)
        here or on Ray; ``on_episode(cell, record)`` as each episode lands (on Ray, as its chunk does),
        ``on_chunk(chunk)`` as each chunk ends. ``kept``: chunks a cut flight of this request flew
        (``kept_chunks.ChunkLog``), by their first episode: they land first and are not flown again."""
        req, kept = self.req, kept or {}
        cells = {
            (n, float(v)): CellResult(obstacles=n, speed=float(v), episodes=req.episodes)
            for n in req.obstacles
            for v in req.speeds
        }
        flown: list[FlownEpisode] = []
        timings: dict[str, float] = {}

        def land(entry: FlownEpisode) -> None:
            cell = cells[(entry.record["obstacles"], entry.record["speed"])]
            cell.count(entry.record)
            flown.append(entry)
            if on_episode:
                on_episode(cell, entry.record)

        def count(chunk: ChunkResult) -> None:
            for phase, seconds in chunk.timings.items():
                timings[phase] = timings.get(phase, 0.0) + seconds

        parts = [part for part in self.parts() if part.start not in kept]
        for start in sorted(kept):
            for entry in kept[start].episodes:
                land(entry)
            count(kept[start])
        if req.executor == "ray" and parts:  # none left: no cluster to start
            threads = torch.get_num_threads()
            done = run_ray(
                fly_chunk_task, [(req, part, threads) for part in parts], cpus=threads, address=req.ray_address
            )
        else:
            done = run_local(lambda part: self.fly_chunk(part, land), [(part,) for part in parts])
        for chunk in done:
            if req.executor == "ray":
                for entry in chunk.episodes:
                    land(entry)
            count(chunk)
            if on_chunk:
                on_chunk(chunk)
        flown.sort(key=lambda entry: entry.index)  # grid order, however the chunks and batches landed
        return ClosedLoopResult(
            list(cells.values()),
            [e.record for e in flown],
            [ms for e in flown for ms in e.step_ms],
            [ms for e in flown for ms in e.replan_ms],
            timings,
        )

    def fly_chunk(self, part: range, on_landed: Callable[[FlownEpisode], None] | None = None) -> ChunkResult:
        """Fly the episodes ``part`` of the flight order in lockstep, ``req.batch`` at a time."""
        req = self.req
        self.timings.clear()
        flown: list[FlownEpisode] = []

        def landed(i: int, result, pilot, frames) -> None:
            n, v, k, seed = self.order[part[i]]
            entry = FlownEpisode(
                part[i],
                episode_record(n, v, k, seed, result, self.sim.cubesat),
                [1e3 * s for s in getattr(pilot, "step_seconds", [])],
                [1e3 * s for s in getattr(pilot, "replan_seconds", [])],
            )
            flown.append(entry)
            if frames is not None:
                from orbitmodel.evaluate.video import write_episode_video

                name = f"{self.name}-obst{n}-v{v:g}-ep{k:03d}-{result.outcome}{req.video_format}"
                write_episode_video(Path(req.video_dir) / name, frames, result, getattr(pilot, "replans", []))
            if on_landed:
                on_landed(entry)

        fly_lockstep(
            self.pilot,
            lambda: CubeSatEnv(self.sim, req.config.scenario),
            [self.order[j] for j in part],
            req.batch,
            landed,
            self.image_quality,
            keep_frames=req.video_dir is not None,
        )
        return ChunkResult(part, flown, self.timings.snapshot())


def fly_chunk_task(req: ClosedLoopRequest, part: range, threads: int) -> ChunkResult:
    """A Ray task: load ``req``'s pilot and fly the episodes ``part`` on ``threads`` torch threads."""
    torch.set_num_threads(threads)
    return ClosedLoop(req).fly_chunk(part)


def fly_closed_loop(req: ClosedLoopRequest, on_episode: EpisodeHook | None = None) -> ClosedLoopResult:
    """Check, load and fly ``req`` (see :class:`ClosedLoop`)."""
    return ClosedLoop(req).fly(on_episode)


def _stats(values: list[float]) -> dict:
    if not values:
        return {"median": None, "p95": None}
    return {"median": float(np.median(values)), "p95": float(np.percentile(values, 95))}


def closed_loop_report(
    req: ClosedLoopRequest, result: ClosedLoopResult, pilot: str | None = None, image_codec: bool = False
) -> dict:
    """``orbitdata fly --json``'s table (pilot, seed, settings) plus episodes, settings, latency;
    ``pilot``: the name of a pilot that is not a planning variant (a policy run's), which has no
    planner settings; ``image_codec``: the pilot saw its camera through the dataset's codec."""
    planning = pilot is None
    report = grid_report(req.variant.value if planning else pilot, req.seed, result.cells, tier=req.config.tier)
    total = sum(result.timings.values()) or 1.0
    report.update(
        {
            "run": None if req.run is None else str(req.run),
            "preset": req.preset,
            "planner_preset": req.preset if planning else None,
            "planner": recorded(req.settings) if planning else None,
            "image_codec": image_codec,
            "max_steps": req.max_steps or req.config.sim.max_steps,  # an episode's frames at most (300: 12 s)
            "latency_ms": {"step": _stats(result.step_ms), "replan": _stats(result.replan_ms)},
            "time_share": {k: v / total for k, v in sorted(result.timings.items())},
            "episodes": result.episodes,
        }
    )
    return report


# What makes two parts one grid: the same pilot flown the same way on the same scenario.
SAME_GRID = ("pilot", "seed", "tier", "run", "preset", "planner_preset", "planner", "flight", "pilot_settings")
SAME_GRID += ("image_codec", "max_steps", "cpu_capability")


def merge_reports(reports: list[dict]) -> dict:
    """One grid table from grids flown in parallel on disjoint settings (e.g. ``--speeds 1`` and
    ``--speeds 2`` in two processes; each episode's seed depends only on its setting and index,
    so the episodes are the ones a single run flies).

    Every part must be the same pilot, grid seed, tier, preset and planner settings, frame limit and
    episodes per setting, flown on the same kernels (``cpu_capability``); a refusal names the first
    field that differs. Latency, which the parts summarise separately, becomes the median and p95
    over the episodes' own medians; the dynamic tier's rejected debris draws are summed.
    """
    if len(reports) < 2:
        raise ValueError("give at least two grid results to merge")
    first = reports[0]
    for report in reports[1:]:
        odd = config_changes({k: first.get(k) for k in SAME_GRID}, {k: report.get(k) for k in SAME_GRID})
        if odd:
            more = f" and {len(odd) - 1} more" if len(odd) > 1 else ""
            raise ValueError(
                f"the parts differ in {odd[0]}{more}; merge only parts of one grid flown with the same "
                "flags and kernels (ATEN_CPU_CAPABILITY)"
            )
    counts = sorted({s["episodes"] for r in reports for s in r["settings"]})
    if len(counts) > 1:
        raise ValueError(
            f"the parts fly {' and '.join(map(str, counts))} episodes per setting; fly every part with the same --episodes"
        )
    keys = [(s["obstacles"], s["speed"]) for r in reports for s in r["settings"]]
    if len(set(keys)) != len(keys):
        raise ValueError(
            f"the parts overlap in settings {sorted({k for k in keys if keys.count(k) > 1})}; "
            "fly disjoint --obstacles / --speeds"
        )
    settings = sorted((s for r in reports for s in r["settings"]), key=lambda s: (s["obstacles"], s["speed"]))
    episodes = [e for r in reports for e in r.get("episodes", [])]
    merged = {**first, "settings": settings, "episodes": episodes, "merged_from": len(reports)}
    if "rejections" in first:
        rejected = sum(r["rejections"]["unsurvivable_draws"] for r in reports)
        kept = sum(r["rejections"]["debris"] for r in reports)
        rate = rejected / (rejected + kept) if rejected + kept else 0.0
        merged["rejections"] = {"unsurvivable_draws": rejected, "debris": kept, "rate": rate}
    merged["latency_ms"] = {
        name: _stats([e[f"{name}_ms_median"] for e in episodes if e.get(f"{name}_ms_median") is not None])
        for name in ("step", "replan")
    }
    merged["latency_ms"]["of"] = "per-episode medians (merged parts)"
    total = sum(sum(r.get("time_share", {}).values()) for r in reports) or 1.0
    shares: dict[str, float] = {}
    for r in reports:
        for k, v in r.get("time_share", {}).items():
            shares[k] = shares.get(k, 0.0) + v / total
    merged["time_share"] = dict(sorted(shares.items()))
    return merged
