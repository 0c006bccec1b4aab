"""The dataset contract in one place: schema version, columns (type, unit, meaning), paths.

Nothing else in the package spells a column name as a bare string: import the constants
from here. Each column is written once, as a :class:`Field`; the Arrow schemas, the Hugging Face
features and the card's column tables are derived from those. The state layout and rotation
maths are in :mod:`orbitdata.state`, the frame codecs in :mod:`orbitdata.codecs` and the typed
``meta/info.json`` in :mod:`orbitdata.info`. The layout is a Hugging Face dataset repository (see ``shared/DESIGN.md``)::

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

import functools
import json
import re
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:  # pyarrow loads where a schema is built, not with the column names
    import pyarrow as pa

SCHEMA_VERSION = "1.0"
FPS = 25
DT = 1.0 / FPS  # seconds per control step
STATE_DIM = 16
ACTION_DIM = 8
ACTION_NAMES = tuple(f"thruster_{i}" for i in range(ACTION_DIM))  # normalised thrust of each
DEPTH_LOW_SIDE = 16
DEPTH_LOW_DIM = DEPTH_LOW_SIDE * DEPTH_LOW_SIDE
SPLITS = ("train", "test")
LEVELS = ("expert", "risky", "exploratory")
OUTCOMES = ("success", "collision", "timeout", "out_of_fuel")
# The dynamic tier's episodes may also end "tumbling": the body spun past the tier's rate limit
# (``DynamicConfig.max_body_rate``). A static dataset, its grid JSON and its card never name it.
TUMBLING = "tumbling"
DYNAMIC_OUTCOMES = OUTCOMES + (TUMBLING,)


def outcomes(tier: str = "static") -> tuple[str, ...]:
    """How an episode of ``tier`` can end: :data:`OUTCOMES`, and on the dynamic tier also ``tumbling``."""
    return DYNAMIC_OUTCOMES if tier == "dynamic" else OUTCOMES


SHAPES = ("sphere", "ellipsoid", "box", "capsule", "cylinder")


# ---- steps table: column names ------------------------------------------------------
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

IMAGE_COLUMNS = (IMAGE, DEPTH)

# ---- episodes table: column names ---------------------------------------------------
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

# ---- the dynamic tier's columns ---------------------------------------------------------
# The scenario tiers whose tables differ: orbitdata.scenario.config.TIERS (the schema sits below
# the scenario package, so it names them itself; a test checks that they agree).
STATIC_TIER, DYNAMIC_TIER = "static", "dynamic"
# A dynamic-tier dataset appends these to the tables above (a static one is unchanged).
PRIVILEGED_PREFIX = "privileged."  # for oracles and validation: a learned pilot never reads them
OBSTACLE_POSES = "privileged.obstacle_poses"  # steps
DEBRIS_MOTION = "debris_motion"
CW = "cw"
MEAN_MOTION = "mean_motion"
BODY = "body"
FAULT = "fault"
SENSING = "sensing"
UNSURVIVABLE_DRAWS = "unsurvivable_draws"
# Field of orbitdata.scenario.dynamics.Dynamics -> its episode column (the values are the
# record's, as dataclasses.asdict gives them).
DYNAMICS_COLUMNS = {
    "debris": DEBRIS_MOTION,
    "cw": CW,
    "mean_motion": MEAN_MOTION,
    "body": BODY,
    "fault": FAULT,
    "sensing": SENSING,
    "unsurvivable_draws": UNSURVIVABLE_DRAWS,
}

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


# ---- fields: name, Arrow type, unit and meaning, once ----------------------------------
@dataclass(frozen=True)
class Field:
    """One column: its Arrow type, unit ("" when it has none) and meaning (the card's column table)."""

    name: str
    type: pa.DataType
    unit: str
    description: str


# ---- the Arrow half: types, fields with unit and meaning, schemas ----------------------
# Built on first use: pyarrow takes ~0.2 s to import, and `orbitdata --help` or a config needs none
# of it. ``schema.STEP_SCHEMA`` etc. read as plain module attributes (see ``__getattr__``).
ARROW_NAMES = (
    "IMAGE_STRUCT",
    "VEC3",
    "QUAT",
    "OBSTACLE_STRUCT",
    "LIGHTING_STRUCT",
    "PLANNER_STRUCT",
    "STEP_FIELDS",
    "EPISODE_FIELDS",
    "STEP_SCHEMA",
    "EPISODE_SCHEMA",
    "FIELDS",
    "DEBRIS_MOTION_STRUCT",
    "BODY_STRUCT",
    "FAULT_STRUCT",
    "SENSING_STRUCT",
    "DYNAMIC_STEP_FIELDS",
    "DYNAMIC_EPISODE_FIELDS",
)


@functools.cache
def _arrow() -> dict:
    import pyarrow as pa

    # Hugging Face's Image feature is stored as this plain struct.
    IMAGE_STRUCT = pa.struct([("bytes", pa.binary()), ("path", pa.string())])
    VEC3 = pa.list_(pa.float32(), 3)
    QUAT = pa.list_(pa.float32(), 4)
    OBSTACLE_STRUCT = pa.struct(
        [
            ("shape", pa.string()),
            ("center", VEC3),  # metres, world frame relative to the start
            ("size", VEC3),  # metres, MuJoCo geom size: radius / half-extents / (radius, half-length, 0)
            ("quat", QUAT),  # (w, x, y, z), body->world
            ("rgba", QUAT),  # colour, each in [0, 1]
        ]
    )
    LIGHTING_STRUCT = pa.struct(
        [
            ("sun_direction", VEC3),  # unit vector the light travels along, world frame
            ("sun_intensity", pa.float32()),  # MuJoCo diffuse, 0..1+
            ("ambient", pa.float32()),  # MuJoCo ambient, 0..1
        ]
    )
    PLANNER_STRUCT = pa.struct(
        [
            ("solved", pa.bool_()),  # False: the expert fell back to direct flight
            ("iterations", pa.int32()),  # RRT* iterations run
            ("path_length", pa.float32()),  # metres, after shortening
        ]
    )

    STEP_FIELDS = (
        Field(EPISODE_INDEX, pa.int32(), "", "unique across splits"),
        Field(FRAME_INDEX, pa.int32(), "", "0..L-1 within the episode"),
        Field(TIMESTAMP, pa.float32(), "s", f"frame_index x {DT:g} s"),
        Field(IMAGE, IMAGE_STRUCT, "", "onboard RGB camera, JPEG, H x W x 3"),
        Field(
            DEPTH,
            IMAGE_STRUCT,
            "mm",
            "z-depth along the optical axis, 16-bit PNG; 0 = no return within the camera's [near, far]",
        ),
        Field(
            DEPTH_LOW,
            pa.list_(pa.float32(), DEPTH_LOW_DIM),
            "m",
            f"{DEPTH_LOW_SIDE}x{DEPTH_LOW_SIDE} area-pooled depth, row-major (no return counts as the far plane)",
        ),
        Field(
            STATE,
            pa.list_(pa.float32(), STATE_DIM),
            "m, m/s, 1, rad/s, 1",
            "[p(3) world position relative to the start, v(3) body-frame velocity, r(6) rot6d = first two columns "
            "of R (body->world) row-major [R00,R01,R10,R11,R20,R21], w(3) body-frame angular velocity, fuel ratio]",
        ),
        Field(
            ACTION,
            pa.list_(pa.float32(), ACTION_DIM),
            "1",
            "normalised thrust of thrusters 0..7 in [0, 1], applied from t to t+1; zeros on the last (terminal) frame",
        ),
        Field(COLLISION, pa.bool_(), "", "a contact happened during the step that ended at this frame"),
        Field(SUCCESS, pa.bool_(), "", "this frame is inside the goal region"),
        Field(IS_LAST, pa.bool_(), "", "last frame of the episode"),
        Field(MIN_CLEARANCE, pa.float32(), "m", "hull to the nearest obstacle surface (0 in contact)"),
    )

    EPISODE_FIELDS = (
        Field(EPISODE_INDEX, pa.int32(), "", "unique across splits"),
        Field(SPLIT, pa.string(), "", f"one of {', '.join(SPLITS)}"),
        Field(LEVEL, pa.string(), "", f"the pilot: {', '.join(LEVELS)}"),
        Field(SEED, pa.int64(), "", "episode seed: the episode is a pure function of it and the config"),
        Field(LENGTH, pa.int32(), "frames", "rows of the episode in the steps table"),
        Field(OUTCOME, pa.string(), "", f"how it ended: {', '.join(OUTCOMES)}"),
        Field(N_OBSTACLES, pa.int32(), "", "number of obstacles"),
        Field(
            OBSTACLES,
            pa.list_(OBSTACLE_STRUCT),
            "m",
            "shape, center (world), size (MuJoCo geom size), quat (w, x, y, z) and rgba of each obstacle",
        ),
        Field(GOAL, VEC3, "m", "centre of the goal region, world frame relative to the start"),
        Field(GOAL_RADIUS, pa.float32(), "m", "radius of the goal region"),
        Field(INITIAL_VELOCITY, VEC3, "m/s", "velocity at frame 0, world frame"),
        Field(INITIAL_QUAT, QUAT, "", "attitude at frame 0, (w, x, y, z) body->world"),
        Field(LIGHTING, LIGHTING_STRUCT, "", "sun_direction (unit, world), sun_intensity and ambient"),
        Field(
            PLANNER,
            PLANNER_STRUCT,
            "",
            "the expert's RRT* result: solved, iterations, path_length (m); zeros for other levels",
        ),
        Field(DATA_FILE, pa.string(), "", "the data shard that holds the episode's rows"),
        Field(ROW_START, pa.int64(), "", "first row of the episode in data_file"),
        Field(ROW_END, pa.int64(), "", "one past its last row"),
    )

    # The dynamic tier's columns, appended to a dynamic dataset's tables (see ``step_fields``).
    # The struct fields are those of orbitdata.scenario.dynamics' records.
    DEBRIS_MOTION_STRUCT = pa.struct(
        [
            ("velocity", VEC3),  # m/s, world frame, at t = 0
            ("angular_velocity", VEC3),  # rad/s, world frame, constant
            ("intercept", pa.bool_()),  # aimed at the nominal flight
            ("t_star", pa.float32()),  # s, the nominal flight passes the aim point (null: drifting)
            ("crossing_time", pa.float32()),  # s, the piece is at the aim point (null: drifting)
            ("aim", VEC3),  # metres, world frame (null: drifting)
        ]
    )
    BODY_STRUCT = pa.struct(
        [
            ("mass_scale", pa.float32()),  # factor on the dry mass
            ("inertia_scale", VEC3),  # factors on the principal dry inertias, body x, y, z
            ("com_offset", VEC3),  # metres, body frame, from the cube's centre
        ]
    )
    FAULT_STRUCT = pa.struct(
        [
            ("kind", pa.string()),  # none, off, scaled, stuck
            ("thruster", pa.int32()),  # 0..7, -1 for none
            ("level", pa.float32()),  # scaled: factor; stuck: thrust; off: 0; none: 1
            ("onset_step", pa.int32()),  # frame from which the thrust is faulty (onset = onset_step x dt)
        ]
    )
    SENSING_STRUCT = pa.struct(
        [
            ("rgb_noise", pa.float32()),  # std of the Gaussian RGB noise, [0, 1] units
            ("depth_dropout", pa.float32()),  # share of depth pixels with no return
            ("eclipse", pa.bool_()),  # no sun: lit by the onboard light alone
            ("onboard_light", pa.float32()),  # MuJoCo diffuse of the spotlight beside the camera
        ]
    )
    DYNAMIC_STEP_FIELDS = (
        Field(
            OBSTACLE_POSES,
            pa.list_(pa.list_(pa.float32(), 7)),
            "m, 1",
            "privileged, for oracles and validation only: each obstacle's centre (world) and quat (w, x, y, z) "
            "at this frame, in the order of the episode's obstacles",
        ),
    )
    DYNAMIC_EPISODE_FIELDS = (
        Field(DEBRIS_MOTION, pa.list_(DEBRIS_MOTION_STRUCT), "m/s, rad/s, s, m", "how each obstacle moves"),
        Field(CW, pa.bool_(), "", "the Clohessy-Wiltshire terms act on the CubeSat and the debris"),
        Field(MEAN_MOTION, pa.float32(), "rad/s", "mean motion n of the reference orbit"),
        Field(BODY, BODY_STRUCT, "1, 1, m", "mass_scale, inertia_scale and com_offset of the body as built"),
        Field(FAULT, FAULT_STRUCT, "", "the faulty thruster: kind, thruster, level and onset_step"),
        Field(SENSING, SENSING_STRUCT, "", "rgb_noise, depth_dropout, eclipse and onboard_light"),
        Field(UNSURVIVABLE_DRAWS, pa.int32(), "", "debris draws rejected as unsurvivable before this episode's"),
    )

    STEP_SCHEMA = pa.schema([(f.name, f.type) for f in STEP_FIELDS])
    EPISODE_SCHEMA = pa.schema([(f.name, f.type) for f in EPISODE_FIELDS])
    FIELDS = {"data": STEP_FIELDS, "episodes": EPISODE_FIELDS}
    arrow = {name: value for name, value in locals().items() if name.isupper()}
    assert set(arrow) == set(ARROW_NAMES), sorted(arrow)
    return arrow


def __getattr__(name: str):
    if name in ARROW_NAMES:
        return _arrow()[name]
    raise AttributeError(f"module 'orbitdata.schema' has no attribute {name!r}")


def is_privileged(name: str) -> bool:
    """Whether a column is for oracles and validation only (``privileged.*``): no learned pilot reads it."""
    return name.startswith(PRIVILEGED_PREFIX)


def fields_of(kind: str, tier: str = STATIC_TIER) -> tuple[Field, ...]:
    """The columns of a table (``'data'`` or ``'episodes'``) of a tier's dataset: the static
    tier's, and for the dynamic tier those plus its own appended at the end."""
    arrow = _arrow()
    if kind not in arrow["FIELDS"]:
        raise ValueError(f"unknown table kind {kind!r}: expected 'data' or 'episodes'")
    if tier not in (STATIC_TIER, DYNAMIC_TIER):
        raise ValueError(f"unknown scenario tier {tier!r}; choose one of {STATIC_TIER}, {DYNAMIC_TIER}")
    fields = arrow["FIELDS"][kind]
    if tier == STATIC_TIER:
        return fields
    return fields + (arrow["DYNAMIC_STEP_FIELDS"] if kind == "data" else arrow["DYNAMIC_EPISODE_FIELDS"])


def step_fields(tier: str = STATIC_TIER) -> tuple[Field, ...]:
    """The steps table's columns in a dataset of ``tier``."""
    return fields_of("data", tier)


def episode_fields(tier: str = STATIC_TIER) -> tuple[Field, ...]:
    """The episodes table's columns in a dataset of ``tier``."""
    return fields_of("episodes", tier)


@functools.cache
def _schema(kind: str, tier: str):
    import pyarrow as pa

    return pa.schema([(f.name, f.type) for f in fields_of(kind, tier)])


def step_schema(tier: str = STATIC_TIER):
    """The steps table's Arrow schema in a dataset of ``tier`` (``STEP_SCHEMA`` for static)."""
    return _schema("data", tier)


def episode_schema(tier: str = STATIC_TIER):
    """The episodes table's Arrow schema in a dataset of ``tier`` (``EPISODE_SCHEMA`` for static)."""
    return _schema("episodes", tier)


def column_width(name: str) -> int:
    """Values per row of a steps column: its fixed list size, or 1."""
    t = _arrow()["STEP_SCHEMA"].field(name).type
    return getattr(t, "list_size", 1)


def readable_schema(version) -> bool:
    """Whether this code reads a dataset of schema ``version``: same major (minors only add)."""
    return isinstance(version, str) and version.split(".")[0] == SCHEMA_VERSION.split(".")[0]


def _hf_feature(t) -> dict:
    """The `datasets` feature of an Arrow type (JSON form; key order as `datasets` writes it)."""
    import pyarrow as pa

    if t.equals(_arrow()["IMAGE_STRUCT"]):
        return {"_type": "Image"}
    if pa.types.is_fixed_size_list(t):
        return {"feature": _hf_feature(t.value_type), "length": t.list_size, "_type": "List"}
    if pa.types.is_list(t):
        return {"feature": _hf_feature(t.value_type), "_type": "List"}
    if pa.types.is_struct(t):
        return {t.field(i).name: _hf_feature(t.field(i).type) for i in range(t.num_fields)}
    return {"dtype": {"float": "float32", "double": "float64"}.get(str(t), str(t)), "_type": "Value"}


def hf_features(kind: str, tier: str = STATIC_TIER) -> dict:
    """The `datasets` feature spec of a table, derived from its Arrow schema (Parquet metadata, card)."""
    return {f.name: _hf_feature(f.type) for f in fields_of(kind, tier)}


def with_hf_metadata(schema, kind: str, tier: str = STATIC_TIER):
    """Attach the `datasets` feature metadata so Image columns decode with no custom code."""
    meta = {b"huggingface": json.dumps({"info": {"features": hf_features(kind, tier)}}).encode()}
    return schema.with_metadata(meta)
