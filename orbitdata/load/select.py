"""Episode selection through the episodes table: by column values, by a predicate, or by index.

``episodes=`` accepts:

* ``None``: every episode of the split.
* a mapping ``{column: value or list of values}`` over flat episode columns, ANDed across
  columns, ORed within one: ``{"level": ["expert"], "outcome": "success"}``.
* a callable ``row -> bool`` over the episode row as a dict (all columns, nested ones
  included): ``lambda ep: ep["outcome"] != "collision"`` keeps collision-free episodes.
* a sequence of ``episode_index`` values: ``[0, 3, 17]``.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Iterable, Mapping
from typing import Any, Union

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from orbitdata import schema as S

EpisodeFilter = Union[None, Mapping[str, Any], Callable[[dict], bool], Iterable[int]]

# Columns whose values have a closed vocabulary, so a typo is an error rather than an empty set.
VOCABULARY = {S.LEVEL: S.LEVELS, S.OUTCOME: S.DYNAMIC_OUTCOMES, S.SPLIT: S.SPLITS}  # any tier's outcomes


def _values(value) -> list:
    if isinstance(value, (str, bytes, int, float, bool, np.generic)):
        return [value]
    return list(value)


def _available(table: pa.Table, names: Iterable[str]) -> str:
    parts = []
    for name in names:
        counts = Counter(table.column(name).to_pylist())
        parts.append(f"{name}: " + ", ".join(f"{v} ({n})" for v, n in sorted(counts.items(), key=str)))
    return "; ".join(parts)


def _by_values(table: pa.Table, where: Mapping[str, Any], split: str) -> np.ndarray:
    mask = np.ones(table.num_rows, bool)
    for name, value in where.items():
        if name not in table.column_names:
            raise ValueError(f"episodes filter: no episode column {name!r}; columns: {table.column_names}")
        column = table.column(name)
        if pa.types.is_nested(column.type):
            raise ValueError(
                f"episodes filter: {name!r} is a nested column; filter it with a callable, e.g. lambda ep: ..."
            )
        values = _values(value)
        if not values:
            raise ValueError(f"episodes filter: empty list of values for {name!r}")
        unknown = [v for v in values if name in VOCABULARY and v not in VOCABULARY[name]]
        if unknown:
            raise ValueError(f"episodes filter: unknown {name} {unknown}; expected one of {list(VOCABULARY[name])}")
        try:
            value_set = pa.array(values, type=column.type)
        except (pa.ArrowInvalid, pa.ArrowTypeError, TypeError, OverflowError):
            message = f"episodes filter: {name}={value!r} does not match the column type {column.type}"
            raise ValueError(message) from None
        mask &= pc.is_in(column, value_set=value_set).to_numpy(zero_copy_only=False)
    if not mask.any():
        raise ValueError(
            f"episodes filter {dict(where)!r} matches no episode of split {split!r}; it has {_available(table, where)}"
        )
    return mask


def _by_predicate(table: pa.Table, keep: Callable[[dict], bool], split: str) -> np.ndarray:
    mask = np.array([bool(keep(row)) for row in table.to_pylist()], dtype=bool)
    if not mask.any():
        raise ValueError(
            f"episodes filter {getattr(keep, '__name__', keep)!r} keeps no episode of split {split!r}; "
            f"it has {_available(table, [S.LEVEL, S.OUTCOME])}"
        )
    return mask


def _by_index(table: pa.Table, wanted: Iterable[int], split: str) -> np.ndarray:
    wanted = np.asarray(list(wanted))
    if wanted.size == 0:
        raise ValueError(f"episodes=[] selects no episode of split {split!r}; pass None for all of them")
    if not np.issubdtype(wanted.dtype, np.integer):
        raise TypeError(
            f"episodes: expected episode_index integers, got {wanted.dtype} values like {wanted[:3].tolist()}"
        )
    ids = table.column(S.EPISODE_INDEX).to_numpy()
    missing = np.setdiff1d(wanted, ids)
    if missing.size:
        raise ValueError(
            f"episode(s) {missing[:10].tolist()}{' ...' if missing.size > 10 else ''} are not in split {split!r} "
            f"(it has {ids.size} episodes, indices {ids.min()}..{ids.max()}, not contiguous: the splits interleave)"
        )
    return np.isin(ids, wanted)


def select_episodes(table: pa.Table, episodes: EpisodeFilter, split: str) -> np.ndarray:
    """The ``episode_index`` values (sorted, int64) that ``episodes`` selects in the split's table."""
    if episodes is None:
        mask = np.ones(table.num_rows, bool)
    elif isinstance(episodes, Mapping):
        mask = _by_values(table, episodes, split)
    elif callable(episodes):
        mask = _by_predicate(table, episodes, split)
    elif isinstance(episodes, (str, bytes)):
        raise TypeError(f"episodes={episodes!r}: use a dict like {{'level': {episodes!r}}} to filter by a value")
    elif isinstance(episodes, (Iterable, np.ndarray)):
        mask = _by_index(table, episodes, split)
    else:
        raise TypeError(
            f"episodes: expected None, a dict, a callable or a list of indices, got {type(episodes).__name__}"
        )
    return np.sort(table.column(S.EPISODE_INDEX).to_numpy()[mask].astype(np.int64))
