"""A grid's success broken down by what its episodes were dealt, and how they flew.

The dynamic tier draws, per episode, whether the debris move, a faulty thruster (and its kind),
eclipse lighting and the Clohessy-Wiltshire terms (``orbitdata.fly.record.dynamic_factors``).
:func:`breakdown` counts a grid's successes within each of those groups, with Wilson intervals,
and summarises the flights: collisions, timeouts and tumbling, the closest approach, and the
delta-v and time to the goal of the episodes that reached it. It reads the ``episodes`` a grid
result records (``eval closed-loop --json``, ``orbitdata fly --json``, ``eval pool``).
"""

from __future__ import annotations

import statistics
from pathlib import Path
from typing import Callable

from orbitdata.schema import DT, TUMBLING
from orbitmodel.evaluate.success import rate_text, wilson

# (label, the episode record key it needs, whether an episode belongs to the group)
Group = tuple[str, str, Callable[[dict], bool]]
GROUPS: tuple[Group, ...] = (
    ("debris still", "debris_moving", lambda e: e["debris_moving"] == 0),
    ("debris moving", "debris_moving", lambda e: e["debris_moving"] > 0),
    ("no fault", "fault", lambda e: e["fault"] == "none"),
    ("a fault", "fault", lambda e: e["fault"] != "none"),
    ("off", "fault", lambda e: e["fault"] == "off"),
    ("scaled", "fault", lambda e: e["fault"] == "scaled"),
    ("stuck", "fault", lambda e: e["fault"] == "stuck"),
    ("sunlit", "eclipse", lambda e: not e["eclipse"]),
    ("eclipse", "eclipse", lambda e: bool(e["eclipse"])),
    ("no CW", "cw", lambda e: not e["cw"]),
    ("CW", "cw", lambda e: bool(e["cw"])),
)
COUNTED = ("collision", "timeout", TUMBLING, "out_of_fuel")


def _median(values: list[float]) -> float | None:
    return float(statistics.median(values)) if values else None


def breakdown(report: dict) -> dict:
    """Success within each group of :data:`GROUPS` whose key the episodes record (successes,
    episodes and the 95 % Wilson interval), and the flight figures: failures by kind, the median
    closest approach over every episode (m), and over the successes the median delta-v (m/s,
    where recorded) and time to the goal (s)."""
    episodes = report.get("episodes")
    if not episodes:
        raise ValueError(
            f"pilot {report.get('pilot')!r}: the result holds no episodes; break down an eval closed-loop, "
            "orbitdata fly or eval pool --json table (pool older results again)"
        )
    groups = {}
    for label, key, member in GROUPS:
        if not all(key in e for e in episodes):
            continue
        mine = [e for e in episodes if member(e)]
        k = sum(e["outcome"] == "success" for e in mine)
        low, high = wilson(k, len(mine)) if mine else (None, None)
        groups[label] = {"success": k, "episodes": len(mine), "low": low, "high": high}
    won = [e for e in episodes if e["outcome"] == "success"]
    flight = {
        "episodes": len(episodes),
        "success": len(won),
        **{kind: sum(e["outcome"] == kind for e in episodes) for kind in COUNTED},
        "min_clearance_m_median": _median([e["min_clearance_m"] for e in episodes]),
        "delta_v_mps_median_success": (
            _median([e["delta_v_mps"] for e in won]) if all("delta_v_mps" in e for e in episodes) else None
        ),
        "time_to_goal_s_median": _median([e["frames"] * DT for e in won]),
    }
    return {
        "pilot": report.get("pilot"),
        "seeds": report.get("seeds", [report.get("seed")]),
        "groups": groups,
        "flight": flight,
    }


def distinct_names(paths: list[Path]) -> list[str]:
    """Each file's name without its suffix, led by as many of its folders as it takes to tell it
    from the others' (``seed3/planner`` and ``seed4/planner``); a file given twice keeps one name."""
    parts = [Path(p).with_suffix("").parts for p in paths]
    depth = [1] * len(parts)
    while True:
        names = ["/".join(pp[-d:]) for pp, d in zip(parts, depth)]
        shared = {n for n in names if names.count(n) > 1}
        grown = False
        for i, (pp, name) in enumerate(zip(parts, names)):
            if name in shared and depth[i] < len(pp):
                depth[i] += 1
                grown = True
        if not grown:
            return names


def _group_cell(group: dict | None) -> str:
    if group is None:
        return "n/a"
    if group["episodes"] == 0:
        return "none flown"
    return rate_text(group["success"], group["episodes"])


def factor_tables(rows: list[tuple[str, dict]]) -> str:
    """Two markdown tables for (label, :func:`breakdown`) rows: success by group (the groups any
    row has), then the flight figures."""
    labels = [g for g, _, _ in GROUPS if any(g in b["groups"] for _, b in rows)]
    lines = ["| pilot | " + " | ".join(labels) + " |", "|---" * (len(labels) + 1) + "|"]
    for name, b in rows:
        lines.append(f"| {name} | " + " | ".join(_group_cell(b["groups"].get(g)) for g in labels) + " |")
    lines += [
        "",
        "| pilot | episodes | success | collision | timeout | tumbling | out of fuel | closest approach, median (m) "
        "| delta-v of a success, median (m/s) | time to goal, median (s) |",
        "|---" * 10 + "|",
    ]

    def num(x: float | None, digits: int) -> str:
        return "n/a" if x is None else f"{x:.{digits}f}"

    for name, b in rows:
        f = b["flight"]
        lines.append(
            f"| {name} | {f['episodes']} | {f['success']} | {f['collision']} | {f['timeout']} | {f[TUMBLING]} | "
            f"{f['out_of_fuel']} | {num(f['min_clearance_m_median'], 2)} | {num(f['delta_v_mps_median_success'], 1)} "
            f"| {num(f['time_to_goal_s_median'], 1)} |"
        )
    return "\n".join(lines) + "\n"
