"""Generate one work unit: fly its episodes, encode frames, return Parquet bytes.

Workers return bytes instead of writing files so that the driver alone touches OUT: local
processes and Ray tasks on other machines (no shared filesystem) behave the same.
"""

from __future__ import annotations

import io
import os
from dataclasses import dataclass

import pyarrow as pa
import pyarrow.parquet as pq

from orbitdata import schema as S
from orbitdata.codecs import encode_depth, encode_rgb
from orbitdata.config import GenerationConfig
from orbitdata.fly.registry import make_pilot
from orbitdata.fly.rollout import fly_episode
from orbitdata.sim.env import CubeSatEnv
from orbitdata.write.plan import Unit
from orbitdata.write.record import episode_row, episodes_table, steps_table


@dataclass
class UnitResult:
    unit: int
    steps: bytes  # Parquet file of the unit's frames (all splits, episode order)
    episodes: bytes  # Parquet file of the unit's episode rows
    frames: int
    outcomes: dict


_ENV_CACHE: dict = {}


def _env(config: GenerationConfig) -> CubeSatEnv:
    # One env (and GL context) per worker process, reused across units.
    key = repr(config.sim) + repr(config.scenario)
    env = _ENV_CACHE.get(key)
    if env is None:
        # One llvmpipe thread per worker: workers already use every core, and Mesa's
        # rasteriser threads would only contend and slow each frame down. Mesa reads this when the first GL context is made.
        os.environ.setdefault("LP_NUM_THREADS", "1")
        _ENV_CACHE.clear()
        env = _ENV_CACHE[key] = CubeSatEnv(config.sim, config.scenario)
    return env


def parquet_bytes(table: pa.Table, kind: str, config: GenerationConfig) -> bytes:
    sink = io.BytesIO()
    schema = S.with_hf_metadata(table.schema, kind, config.tier)
    pq.write_table(
        table.cast(schema),
        sink,
        compression=config.dataset.compression,
        row_group_size=config.dataset.row_group_rows,
    )
    return sink.getvalue()


def run_unit(config: GenerationConfig, unit: Unit) -> UnitResult:
    env = _env(config)
    ds = config.dataset
    tables, rows, outcomes = [], [], {}
    for task in unit.episodes:
        rgb, depth = [], []

        def sink(t, image, depth_m, _low):
            rgb.append(encode_rgb(image, ds.jpeg_quality))
            depth.append(encode_depth(depth_m, ds.png_compression))

        pilot = make_pilot(task.level, config.flight)
        result = fly_episode(env, pilot, task.seed, frame_sink=sink)
        tables.append(steps_table(result, task.index, rgb, depth, config.tier))
        rows.append(episode_row(result, task.index, task.split, config.tier))
        outcomes[result.outcome] = outcomes.get(result.outcome, 0) + 1
    steps = pa.concat_tables(tables)
    return UnitResult(
        unit=unit.index,
        steps=parquet_bytes(steps, "data", config),
        episodes=parquet_bytes(episodes_table(rows, config.tier), "episodes", config),
        frames=steps.num_rows,
        outcomes=outcomes,
    )


def run_unit_from_dict(config: dict, unit: Unit) -> UnitResult:
    """Entry point for executors: configs travel as plain dicts (picklable everywhere)."""
    return run_unit(GenerationConfig.from_dict(config), unit)
