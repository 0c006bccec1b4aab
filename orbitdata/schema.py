"""The dataset contract in one place: schema version, column names, Arrow schemas, paths.

Nothing else in the package spells a column name as a bare string: import the constants
from here. The layout is a Hugging Face dataset repository (see ``shared/DESIGN.md``)::

    README.md                          dataset card (YAML header + datasheet)
    data/{split}-{i:05d}-of-{n:05d}.parquet       one row per frame
    episodes/{split}-{i:05d}-of-{n:05d}.parquet   one row per episode
    meta/info.json  meta/stats.json

Frame semantics (row ``t`` of an episode of length ``L``):

* ``observation.*`` and ``observation.state`` are observed at time ``t * dt``.
* ``action`` is the thrust applied from ``t`` to ``t + 1``. The last frame is the terminal
  observation: nothing is applied after it, so its action is all zeros.
* ``collision`` / ``success`` describe the step that *ended* at frame ``t``: a contact happened
  while flying from ``t - 1`` to ``t`` / frame ``t`` is inside the goal region. The episode ends
  at the first event, so they can only be true on the last frame (``is_last``).
"""

from __future__ import annotations

import json
import re

import pyarrow as pa

SCHEMA_VERSION = "1.0"
FPS = 25
DT = 1.0 / FPS  # seconds per control step
STATE_DIM = 16
ACTION_DIM = 8
DEPTH_LOW_SIDE = 16
DEPTH_LOW_DIM = DEPTH_LOW_SIDE * DEPTH_LOW_SIDE
SPLITS = ("train", "test")
LEVELS = ("expert", "risky", "exploratory")
OUTCOMES = ("success", "collision", "timeout", "out_of_fuel")
SHAPES = ("sphere", "ellipsoid", "box", "capsule", "cylinder")

# Names of the 16 state entries, in order (the upstream convention).
STATE_NAMES = (
    "p_x", "p_y", "p_z",
    "v_x", "v_y", "v_z",
    "r_00", "r_01", "r_10", "r_11", "r_20", "r_21",
    "w_x", "w_y", "w_z",
    "fuel",
)
STATE_SLICES = {
    "p": slice(0, 3),  # metres, world frame, relative to the start
    "v": slice(3, 6),  # m/s, body frame
    "r": slice(6, 12),  # rot6d: first two columns of R (body->world), row-major
    "w": slice(12, 15),  # rad/s, body frame
    "fuel": slice(15, 16),  # ratio in [0, 1]
}

# ---- steps table -------------------------------------------------------------------------
EPISODE_INDEX = "episode_index"
FRAME_INDEX = "frame_index"
TIMESTAMP = "timestamp"
IMAGE = "observation.image"
DEPTH = "observation.depth"
DEPTH_LOW = "observation.depth_low"
STATE = "observation.state"
ACTION = "action"
COLLISION = "collision"
SUCCESS = "success"
IS_LAST = "is_last"
MIN_CLEARANCE = "min_clearance"

# Hugging Face's Image feature is stored as this plain struct.
IMAGE_STRUCT = pa.struct([("bytes", pa.binary()), ("path", pa.string())])

STEP_SCHEMA = pa.schema(
    [
        (EPISODE_INDEX, pa.int32()),
        (FRAME_INDEX, pa.int32()),
        (TIMESTAMP, pa.float32()),
        (IMAGE, IMAGE_STRUCT),
        (DEPTH, IMAGE_STRUCT),
        (DEPTH_LOW, pa.list_(pa.float32(), DEPTH_LOW_DIM)),
        (STATE, pa.list_(pa.float32(), STATE_DIM)),
        (ACTION, pa.list_(pa.float32(), ACTION_DIM)),
        (COLLISION, pa.bool_()),
        (SUCCESS, pa.bool_()),
        (IS_LAST, pa.bool_()),
        (MIN_CLEARANCE, pa.float32()),
    ]
)
IMAGE_COLUMNS = (IMAGE, DEPTH)

# ---- episodes table ----------------------------------------------------------------------
SPLIT = "split"
LEVEL = "level"
SEED = "seed"
LENGTH = "length"
OUTCOME = "outcome"
N_OBSTACLES = "n_obstacles"
OBSTACLES = "obstacles"
GOAL = "goal"
GOAL_RADIUS = "goal_radius"
INITIAL_VELOCITY = "initial_velocity"
INITIAL_QUAT = "initial_quat"
LIGHTING = "lighting"
PLANNER = "planner"
DATA_FILE = "data_file"
ROW_START = "row_start"
ROW_END = "row_end"

VEC3 = pa.list_(pa.float32(), 3)
OBSTACLE_STRUCT = pa.struct(
    [
        ("shape", pa.string()),
        ("center", VEC3),  # metres, world frame relative to the start
        ("size", VEC3),  # MuJoCo geom size: radius / half-extents / (radius, half-length, 0)
        ("quat", pa.list_(pa.float32(), 4)),  # (w, x, y, z), body->world
        ("rgba", pa.list_(pa.float32(), 4)),
    ]
)
LIGHTING_STRUCT = pa.struct(
    [
        ("sun_direction", VEC3),  # unit vector the light travels along, world frame
        ("sun_intensity", pa.float32()),
        ("ambient", pa.float32()),
    ]
)
PLANNER_STRUCT = pa.struct(
    [
        ("solved", pa.bool_()),  # False: the expert fell back to direct flight
        ("iterations", pa.int32()),
        ("path_length", pa.float32()),  # metres, after shortening
    ]
)

EPISODE_SCHEMA = pa.schema(
    [
        (EPISODE_INDEX, pa.int32()),
        (SPLIT, pa.string()),
        (LEVEL, pa.string()),
        (SEED, pa.int64()),
        (LENGTH, pa.int32()),
        (OUTCOME, pa.string()),
        (N_OBSTACLES, pa.int32()),
        (OBSTACLES, pa.list_(OBSTACLE_STRUCT)),
        (GOAL, VEC3),
        (GOAL_RADIUS, pa.float32()),
        (INITIAL_VELOCITY, VEC3),
        (INITIAL_QUAT, pa.list_(pa.float32(), 4)),
        (LIGHTING, LIGHTING_STRUCT),
        (PLANNER, PLANNER_STRUCT),
        (DATA_FILE, pa.string()),
        (ROW_START, pa.int64()),
        (ROW_END, pa.int64()),
    ]
)

# ---- paths --------------------------------------------------------------------------------
DATA_DIR = "data"
EPISODES_DIR = "episodes"
META_DIR = "meta"
PARTS_DIR = "parts"  # generation scratch space, removed by `shard`
INFO_PATH = "meta/info.json"
STATS_PATH = "meta/stats.json"
CARD_PATH = "README.md"
OVERVIEW_PATH = "meta/overview.png"
SHARD_PATTERN = "{kind}/{split}-{index:05d}-of-{count:05d}.parquet"
SHARD_RE = re.compile(r"^(data|episodes)/(train|test)-(\d{5})-of-(\d{5})\.parquet$")


def shard_path(kind: str, split: str, index: int, count: int) -> str:
    """Relative path of shard ``index`` of ``count`` for ``kind`` ('data' or 'episodes')."""
    return SHARD_PATTERN.format(kind=kind, split=split, index=index, count=count)


def hf_features(kind: str) -> dict:
    """The `datasets` feature spec for a table, as stored in Parquet metadata and the card."""
    def seq(dtype: str, n: int) -> dict:
        return {"feature": {"dtype": dtype, "_type": "Value"}, "length": n, "_type": "List"}

    vec3 = seq("float32", 3)
    if kind == "data":
        return {
            EPISODE_INDEX: {"dtype": "int32", "_type": "Value"},
            FRAME_INDEX: {"dtype": "int32", "_type": "Value"},
            TIMESTAMP: {"dtype": "float32", "_type": "Value"},
            IMAGE: {"_type": "Image"},
            DEPTH: {"_type": "Image"},
            DEPTH_LOW: seq("float32", DEPTH_LOW_DIM),
            STATE: seq("float32", STATE_DIM),
            ACTION: seq("float32", ACTION_DIM),
            COLLISION: {"dtype": "bool", "_type": "Value"},
            SUCCESS: {"dtype": "bool", "_type": "Value"},
            IS_LAST: {"dtype": "bool", "_type": "Value"},
            MIN_CLEARANCE: {"dtype": "float32", "_type": "Value"},
        }
    if kind == "episodes":
        value = lambda d: {"dtype": d, "_type": "Value"}  # noqa: E731
        return {
            EPISODE_INDEX: value("int32"),
            SPLIT: value("string"),
            LEVEL: value("string"),
            SEED: value("int64"),
            LENGTH: value("int32"),
            OUTCOME: value("string"),
            N_OBSTACLES: value("int32"),
            OBSTACLES: {
                "feature": {
                    "shape": value("string"),
                    "center": vec3,
                    "size": vec3,
                    "quat": seq("float32", 4),
                    "rgba": seq("float32", 4),
                },
                "_type": "List",
            },
            GOAL: vec3,
            GOAL_RADIUS: value("float32"),
            INITIAL_VELOCITY: vec3,
            INITIAL_QUAT: seq("float32", 4),
            LIGHTING: {
                "sun_direction": vec3,
                "sun_intensity": value("float32"),
                "ambient": value("float32"),
            },
            PLANNER: {
                "solved": value("bool"),
                "iterations": value("int32"),
                "path_length": value("float32"),
            },
            DATA_FILE: value("string"),
            ROW_START: value("int64"),
            ROW_END: value("int64"),
        }
    raise ValueError(f"unknown table kind {kind!r}: expected 'data' or 'episodes'")


def with_hf_metadata(schema: pa.Schema, kind: str) -> pa.Schema:
    """Attach the `datasets` feature metadata so Image columns decode with no custom code."""
    meta = {b"huggingface": json.dumps({"info": {"features": hf_features(kind)}}).encode()}
    return schema.with_metadata(meta)
