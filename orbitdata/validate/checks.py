"""The catalogue of checks ``orbitdata validate`` runs: names, groups, what each guarantees.

A check's name is what a report (text or JSON) and the tests refer to. ``quick`` checks run in
``--quick`` mode (structure, integrity, schema, counts: footers and metadata, no data pages);
the others read every row and image and run only in the full (default) mode.

``CHECKS`` run on every dataset. A dataset of the dynamic tier (``config.scenario.tier`` in
meta/info.json) also runs ``DYNAMIC_CHECKS``, the physics of its episode record; a static
dataset's report lists only ``CHECKS``. :func:`checks_for` gives a tier's list.
"""

from __future__ import annotations

from dataclasses import dataclass

from orbitdata.scenario.config import STATIC


@dataclass(frozen=True)
class Check:
    name: str
    group: str
    summary: str  # what a pass guarantees
    quick: bool  # also runs in --quick mode


# Names, once, so that code and tests never drift from the catalogue.
MISSING = "files.missing"
EXTRA = "files.extra"
UNREADABLE = "files.unreadable"
SHA256 = "files.sha256"
CORRUPT = "parquet.corrupt"
COLUMNS = "schema.columns"
VERSION = "schema.version"
FRAMES = "episodes.frames"
TIMESTAMPS = "episodes.timestamps"
LENGTHS = "episodes.lengths"
EVENTS = "episodes.events"
TABLE = "episodes.table"
DUPLICATES = "splits.duplicates"
LEAK = "splits.leak"
FINITE = "values.finite"
ACTION = "values.action"
ROT6D = "values.rot6d"
FUEL = "values.fuel"
START = "values.start"
CLEARANCE = "values.clearance"
KIN_POSITION = "kinematics.position"
KIN_ROTATION = "kinematics.rotation"
DECODE = "images.decode"
SIZE = "images.size"
DEPTH_RANGE = "images.depth_range"
DEPTH_LOW = "images.depth_low"
COUNTS = "consistency.counts"
STATS = "consistency.stats"
DYN_RECORD = "dynamics.record"
DYN_THRUST = "dynamics.thrust"
DYN_DEBRIS = "dynamics.debris"
DYN_CW = "dynamics.cw"

CHECKS: tuple[Check, ...] = (
    Check(MISSING, "structure", "every file the layout and meta/info.json name is present", True),
    Check(EXTRA, "structure", "no file outside the layout and meta/info.json", True),
    Check(UNREADABLE, "structure", "every file opens and parses (JSON, card YAML)", True),
    Check(SHA256, "integrity", "sha256 and size of every file match meta/info.json", True),
    Check(CORRUPT, "integrity", "Parquet footers (quick) and every data page (full) decode", True),
    Check(COLUMNS, "schema", "column names, types and fixed sizes match the schema", True),
    Check(VERSION, "schema", "meta/info.json names a schema version this orbitdata reads (same major)", True),
    Check(TABLE, "episodes", "episodes table fields are valid (split, level, outcome, length, obstacles)", True),
    Check(DUPLICATES, "episodes", "every episode_index appears once", True),
    Check(LEAK, "episodes", "no episode or seed in both splits; rows live in their split's files", True),
    Check(LENGTHS, "episodes", "lengths, row ranges and is_last agree with the episodes table", True),
    Check(FRAMES, "episodes", "frames of an episode are 0..L-1, contiguous, in order, once each", False),
    Check(TIMESTAMPS, "episodes", "timestamp = frame_index x dt (the 0.04 s grid)", False),
    Check(EVENTS, "episodes", "collision/success only on the last frame and as the outcome says", False),
    Check(FINITE, "values", "no NaN, Inf or null in any numeric column", False),
    Check(ACTION, "values", "actions in [0, 1], all zero on the terminal frame", False),
    Check(ROT6D, "values", "rot6d columns are orthonormal", False),
    Check(FUEL, "values", "fuel stays in [0, 1] and never rises", False),
    Check(START, "values", "position is 0 at frame 0", False),
    Check(CLEARANCE, "values", "min_clearance >= 0, and 0 on a collision frame", False),
    Check(KIN_POSITION, "kinematics", "position steps match the velocity rotated to world over dt", False),
    Check(KIN_ROTATION, "kinematics", "attitude steps match the body angular velocity over dt", False),
    Check(DECODE, "images", "every RGB JPEG and depth PNG decodes", False),
    Check(SIZE, "images", "image size and channels match meta/info.json", False),
    Check(DEPTH_RANGE, "images", "depth is 0 (no return) or inside the camera's [near, far]", False),
    Check(DEPTH_LOW, "images", "depth_low is the 16x16 area-pooled depth image", False),
    Check(COUNTS, "consistency", "counts agree between the card YAML, meta/info.json and the data", True),
    Check(STATS, "consistency", "meta/stats.json matches the train split", False),
)
DYNAMIC_CHECKS: tuple[Check, ...] = (
    Check(
        DYN_RECORD,
        "dynamics",
        "each episode's dynamic record is well formed, and each frame has one pose per obstacle",
        True,
    ),
    Check(
        DYN_THRUST,
        "dynamics",
        "velocity, angular velocity and fuel steps follow the commanded thrust through the recorded fault and body",
        False,
    ),
    Check(DYN_DEBRIS, "dynamics", "privileged.obstacle_poses follow each obstacle's recorded motion", False),
    Check(
        DYN_CW, "dynamics", "the Clohessy-Wiltshire terms act on the CubeSat and the debris as the cw flag says", False
    ),
)
BY_NAME = {c.name: c for c in CHECKS + DYNAMIC_CHECKS}


def checks_for(tier: str) -> tuple[Check, ...]:
    """The checks a dataset of ``tier`` runs (the static list, plus the dynamic tier's own)."""
    return CHECKS if tier == STATIC else CHECKS + DYNAMIC_CHECKS
