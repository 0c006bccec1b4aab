"""Everything that defines a dataset, as one typed, frozen, serialisable config.

``GenerationConfig`` nests the scenario, simulator, pilot and dataset settings. It is built
from defaults, a TOML file (``--config``) and CLI flags, and written verbatim into
``meta/info.json`` so a dataset records exactly how it was made.
"""

from __future__ import annotations

import dataclasses
import tomllib
import typing
from dataclasses import dataclass, field
from pathlib import Path

from orbitdata.fly.config import FlightConfig
from orbitdata.fly.pilots.config import PilotsConfig
from orbitdata.scenario.config import STATIC, ScenarioConfig
from orbitdata.schema import LEVELS
from orbitdata.sim.config import SimConfig

PARQUET_CODECS = frozenset({"zstd", "snappy", "gzip", "brotli", "lz4", "lz4_raw", "none"})  # what pyarrow writes


MAX_EPISODES = 10_000_000  # episodes a dataset plans at most (the paper's has 8000)


@dataclass(frozen=True)
class DatasetConfig:
    """Size, split, level mix and storage of a generated dataset.

    Attributes:
        episodes: total number of episodes (the paper: 8000).
        test_fraction: share of each level that goes to the test split (the paper: 0.1).
        seed: root seed; episode i is a pure function of (seed, i, this config).
        level_mix: share of expert / risky / exploratory episodes (normalised).
        episodes_per_unit: episodes per work unit (one part file, the resume granularity).
        jpeg_quality: RGB frames are JPEG at this quality (4:2:0, OpenCV's libjpeg-turbo).
        png_compression: zlib level of the 16-bit depth PNGs (filter: ``codecs.PNG_FILTER``).
        row_group_rows: rows per Parquet row group.
        compression: Parquet codec for every column.
        max_shard_bytes: a data shard closes at the first episode boundary past this size.
    """

    episodes: int = 8000
    test_fraction: float = 0.1
    seed: int = 0
    level_mix: tuple[float, float, float] = (0.5, 0.25, 0.25)
    episodes_per_unit: int = 8
    jpeg_quality: int = 90
    png_compression: int = 3
    row_group_rows: int = 512
    compression: str = "zstd"
    max_shard_bytes: int = 500_000_000

    def __post_init__(self) -> None:
        if not 1 <= self.episodes <= MAX_EPISODES:  # the plan holds a few numbers per episode in memory
            raise ValueError(f"episodes must be from 1 to {MAX_EPISODES:,}, got {self.episodes}")
        if not 0.0 <= self.test_fraction < 1.0:
            raise ValueError(f"test_fraction must be in [0, 1), got {self.test_fraction}")
        if self.seed < 0:
            raise ValueError(f"seed must be >= 0, got {self.seed}")
        if len(self.level_mix) != len(LEVELS) or min(self.level_mix) < 0 or sum(self.level_mix) <= 0:
            raise ValueError(f"level_mix must be 3 non-negative shares for {LEVELS}, got {self.level_mix}")
        if not 1 <= self.jpeg_quality <= 100:
            raise ValueError(f"jpeg_quality must be in [1, 100], got {self.jpeg_quality}")
        if self.episodes_per_unit < 1 or self.row_group_rows < 1 or self.max_shard_bytes < 1:
            raise ValueError("episodes_per_unit, row_group_rows and max_shard_bytes must be positive")
        if not 0 <= self.png_compression <= 9:  # zlib's levels, which the PNG encoder takes
            raise ValueError(f"png_compression must be in [0, 9], got {self.png_compression}")
        if str(self.compression).lower() not in PARQUET_CODECS:
            raise ValueError(
                f"compression must be a Parquet codec ({', '.join(sorted(PARQUET_CODECS))}), got {self.compression!r}"
            )


class TierConflict(ValueError):
    """A config file names one scenario tier and the caller asked for another."""


@dataclass(frozen=True)
class GenerationConfig:
    """Everything that defines a dataset (or a flight grid): one section per stage.

    Attributes:
        dataset: size, split, level mix and storage (:class:`DatasetConfig`).
        scenario: how episodes are randomised (:class:`~orbitdata.scenario.config.ScenarioConfig`).
        sim: physics, camera and hardware (:class:`~orbitdata.sim.config.SimConfig`).
        pilots: the built-in pilots' settings (:class:`~orbitdata.fly.pilots.config.PilotsConfig`).
    """

    dataset: DatasetConfig = field(default_factory=DatasetConfig)
    scenario: ScenarioConfig = field(default_factory=ScenarioConfig)
    sim: SimConfig = field(default_factory=SimConfig)
    pilots: PilotsConfig = field(default_factory=PilotsConfig)

    @property
    def tier(self) -> str:
        """The scenario tier (``static`` or ``dynamic``): it decides the dataset's columns."""
        return self.scenario.tier

    @property
    def flight(self) -> FlightConfig:
        """The sections that flying reads (a pilot factory, the evaluation grid)."""
        return FlightConfig(sim=self.sim, scenario=self.scenario, pilots=self.pilots)

    def to_dict(self) -> dict:
        """Every setting, as meta/info.json records it. The static tier's record leaves the tier
        settings (and the dynamic tier's expert) out, so its datasets keep the bytes (and resume)
        they had before tiers existed."""
        data = dataclasses.asdict(self)
        if self.scenario.tier == STATIC:
            data["scenario"].pop("tier", None)
            data["scenario"].pop("dynamic", None)
            data["pilots"].pop("dynamic_expert", None)
        return data

    @classmethod
    def from_dict(cls, data: dict, where: str = "config") -> "GenerationConfig":
        return build(cls, data, where)

    @classmethod
    def from_toml(cls, path: str | Path, tier: str | None = None) -> "GenerationConfig":
        """The config of a TOML file. ``tier``: build that scenario tier (its defaults, under the
        file's own scenario settings); a file whose ``[scenario]`` names another tier is an error."""
        path = Path(path)
        try:
            data = tomllib.loads(path.read_text(encoding="utf-8"))
        except FileNotFoundError:
            raise ValueError(f"config file {path} does not exist") from None
        except IsADirectoryError:
            raise ValueError(f"config file {path} is a folder; give a TOML file") from None
        except UnicodeDecodeError:
            raise ValueError(f"config file {path} is not UTF-8 text; give a TOML file") from None
        except tomllib.TOMLDecodeError as exc:
            raise ValueError(f"config file {path} is not valid TOML: {exc}") from None
        if tier is not None:
            scenario = data.get("scenario", {})
            named = scenario.get("tier") if isinstance(scenario, dict) else None
            if named is not None and named != tier:
                raise TierConflict(f"{path} sets scenario.tier = {named!r}, not {tier!r}")
            if isinstance(scenario, dict):
                data = {**data, "scenario": {**scenario, "tier": tier}}
        return build(cls, data, str(path))

    @classmethod
    def for_tier(cls, tier: str) -> "GenerationConfig":
        """The defaults with the scenario tier ``tier`` (``ScenarioConfig.for_tier``)."""
        return cls(scenario=ScenarioConfig.for_tier(tier))

    def replace(self, **sections) -> "GenerationConfig":
        """Copy with fields of sections replaced, e.g. ``replace(dataset={'episodes': 10})``."""
        updates = {}
        for name, values in sections.items():
            updates[name] = dataclasses.replace(getattr(self, name), **values)
        return dataclasses.replace(self, **updates)


def config_changes(theirs: dict, mine: dict, prefix: str = "") -> list[str]:
    """The settings that differ between two stored configs (or any nested records), as
    ``key: theirs -> mine`` with dotted keys for nested tables."""
    out = []
    for key in sorted(set(theirs) | set(mine)):
        a, b = theirs.get(key), mine.get(key)
        if isinstance(a, dict) and isinstance(b, dict):
            out += config_changes(a, b, f"{prefix}{key}.")
        elif a != b:
            out.append(f"{prefix}{key}: {a!r} -> {b!r}")
    return out


_KINDS = {bool: "true or false", int: "a whole number", float: "a number", str: "a string"}


def _check_type(hint, value, where: str) -> None:
    """Refuse a TOML value of the wrong kind for a plain setting (``dt = "fast"``), naming the key;
    a whole number stands for a float, and ``str | None`` takes a string."""
    kinds = [k for k in typing.get_args(hint) if k is not type(None)] or [hint]
    if len(kinds) != 1 or kinds[0] not in _KINDS or (value is None and type(None) in typing.get_args(hint)):
        return
    kind = kinds[0]
    ok = isinstance(value, kind) and (kind is bool or not isinstance(value, bool))
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        ok = True
    if not ok:
        raise ValueError(f"{where}: expected {_KINDS[kind]}, got {value!r}")


def build(cls, data, where: str):
    """Build dataclass ``cls`` from a plain dict, strictly: unknown keys are errors.

    A scenario section starts from its tier's defaults (``ScenarioConfig.for_tier``), so
    ``tier = "dynamic"`` alone gives the dynamic tier as a whole.
    """
    if not isinstance(data, dict):
        raise ValueError(f"{where}: expected a table, got {type(data).__name__}")
    hints = typing.get_type_hints(cls)
    names = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(data) - names)
    if unknown:
        raise ValueError(f"{where}: unknown setting(s) {unknown}; known: {sorted(names)}")
    kwargs = {}
    for key, value in data.items():
        hint = hints[key]
        if dataclasses.is_dataclass(hint):
            kwargs[key] = build(hint, value, f"{where}.{key}")
        elif typing.get_origin(hint) is tuple:
            if not isinstance(value, (list, tuple)):
                raise ValueError(f"{where}.{key}: expected a list, got {value!r}")
            kwargs[key] = tuple(value)
        else:
            _check_type(hint, value, f"{where}.{key}")
            kwargs[key] = value
    try:
        if cls is ScenarioConfig and "tier" in kwargs:
            return ScenarioConfig.for_tier(kwargs.pop("tier"), **kwargs)
        return cls(**kwargs)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{where}: {exc}") from None
