"""Success rates with their uncertainty: every rate we report comes with its episode count and
its 95 % Wilson score interval (Wilson 1927), which stays inside [0, 1] and is honest at 0 % and
100 %, where the normal approximation collapses to a point."""

from __future__ import annotations

import math
import statistics
from pathlib import Path

from orbitdata.schema import TUMBLING

Z95 = 1.959963984540054  # the standard normal's 97.5 % quantile


def wilson(successes: int, n: int, z: float = Z95) -> tuple[float, float]:
    """(low, high) in [0, 1]: the Wilson score interval of ``successes`` out of ``n`` trials."""
    if n <= 0:
        raise ValueError(f"a success rate needs at least one episode, got n={n}")
    if not 0 <= successes <= n:
        raise ValueError(f"successes={successes} must be in [0, n={n}]")
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(0.0, centre - half), min(1.0, centre + half)


def rate_text(successes: int, n: int) -> str:
    """'90.0 % [69.9, 97.2] (18/20)': the rate, its 95 % Wilson interval and the count."""
    low, high = wilson(successes, n)
    return f"{100 * successes / n:.1f} % [{100 * low:.1f}, {100 * high:.1f}] ({successes}/{n})"


def report_totals(report: dict) -> tuple[int, int]:
    """(successes, episodes) over every setting of a grid result (``--json`` table)."""
    return (sum(int(s["success"]) for s in report["settings"]), sum(int(s["episodes"]) for s in report["settings"]))


FAILURES = ("collision", "timeout", "out_of_fuel")  # the dynamic tier's grids also count TUMBLING
# Planner settings recorded only when not their default (plan.config.recorded), with that default
# (the fit's knobs: PlannerConfig's): seeds flown with different ones are different ways of flying.
PLANNER_WAYS = {
    "probe": "the run's own",
    "obstacle_motion": "static",
    "tracker": "none",
    "body": "true",
    "fit_frames": 40,
    "fit_ridge": 1e-5,
    "fit_steps": 1,
}


def failure_kinds(reports: list[dict]) -> tuple[str, ...]:
    """The failures the reports count: :data:`FAILURES`, and ``tumbling`` where a setting counts it
    (a dynamic-tier grid), so that a static grid's tables keep their keys."""
    tumbling = any(TUMBLING in s for r in reports for s in r["settings"])
    return FAILURES + ((TUMBLING,) if tumbling else ())


def failures_text(report: dict) -> str:
    """'3 collisions, 1 timeout' over every setting ('none' without failures)."""
    counts = {kind: sum(int(s.get(kind, 0)) for s in report["settings"]) for kind in failure_kinds([report])}
    words = {"collision": "collisions", "timeout": "timeouts", "out_of_fuel": "out of fuel", TUMBLING: "tumbling"}
    parts = [f"{n} {words[k] if n != 1 else words[k].removesuffix('s')}" for k, n in counts.items() if n]
    return ", ".join(parts) or "none"


def markdown_table(reports: list[dict], sources: list[str] | None = None, per_setting_ci: bool = False) -> str:
    """One row per grid result: successes per setting (k/n, or with ``per_setting_ci`` the rate and
    its interval), the rate over all settings with its 95 % Wilson interval and count, the failures,
    (tables of ``pool_seeds``) the lowest setting on any one seed, and (``sources``) the file each
    row came from. Every report must cover the same settings."""
    settings = [(int(s["obstacles"]), float(s["speed"])) for s in reports[0]["settings"]]
    head = [f"{n} obst. {v:g} m/s" for n, v in settings]
    pooled = all("worst_setting" in r for r in reports)  # eval pool's tables: add each pilot's worst setting
    lines = [
        "| pilot | "
        + " | ".join(head)
        + " | all settings, 95 % CI | failures |"
        + (" lowest setting on one seed |" if pooled else "")
        + (" JSON |" if sources else ""),
        "|---" * (len(head) + 3 + pooled + bool(sources)) + "|",
    ]
    for i, r in enumerate(reports):
        mine = {(int(s["obstacles"]), float(s["speed"])): s for s in r["settings"]}
        if sorted(mine) != sorted(settings):
            raise ValueError(
                f"pilot {r['pilot']!r} was flown on another grid ({sorted(mine)}) than "
                f"{reports[0]['pilot']!r} ({sorted(settings)}); tabulate one grid at a time"
            )
        cells = []
        for key in settings:
            k, n = int(mine[key]["success"]), int(mine[key]["episodes"])
            if per_setting_ci:
                low, high = wilson(k, n)
                cells.append(f"{100 * k / n:.0f} [{100 * low:.0f}, {100 * high:.0f}]")
            else:
                cells.append(f"{k}/{n}")
        label = r["pilot"]
        if sources and Path(sources[i]).name.split(".")[0] != label:  # e.g. the same pilot with another head
            label += f" ({Path(sources[i]).name.split('.')[0]})"
        row = f"| {label} | " + " | ".join(cells) + f" | {rate_text(*report_totals(r))} | {failures_text(r)} |"
        if pooled:
            w = r["worst_setting"]
            row += f" {w['success']}/{w['episodes']} (seed {w['seed']}, {w['obstacles']} obst. {w['speed']:g} m/s) |"
        lines.append(row + (f" [{Path(sources[i]).name}]({sources[i]}) |" if sources else ""))
    return "\n".join(lines) + "\n"


FLIGHT_KEYS = ("preset", "pilot_settings", "image_codec")  # how a grid was flown, beside the pilot and its run
SAME_FLIGHT = ("run", "tier", "max_steps")  # what else pooled seeds share (the pooled table records the first's)


def pool_seeds(reports: list[dict]) -> dict:
    """One pilot's grid flown on several root seeds, as one table: per setting, the episodes and
    outcomes summed over the seeds; ``seeds`` lists them, ``per_seed`` keeps each seed's settings,
    ``worst_setting`` names the lowest-rate (seed, setting) and ``episodes`` holds every seed's
    episode records (where each seed has them). Refuses reports of different
    pilots, runs, tiers, frame limits, grids, pilot settings (a policy's sampling, the camera codec,
    any planner setting both record: K, the probe, obstacle motion, ...) or a repeated seed:
    pooling is for fresh episodes of one way of flying only."""
    if not reports:
        raise ValueError("give the grid results of at least one seed")
    first = reports[0]
    keys = sorted((int(s["obstacles"]), float(s["speed"])) for s in first["settings"])
    if any(r.get("seed") is None for r in reports):
        raise ValueError(
            "every grid result needs its root seed: pool the --json tables, not the .episodes.jsonl of a stopped grid"
        )
    seeds = [int(r["seed"]) for r in reports]
    if len(set(seeds)) != len(seeds):
        raise ValueError(f"seeds {seeds} repeat: pool each root seed once")
    failures = failure_kinds(reports)
    pooled = {
        k: {"obstacles": k[0], "speed": k[1], "episodes": 0, "success": 0, **{f: 0 for f in failures}} for k in keys
    }
    per_seed, worst = {}, None
    for r in reports:
        if r["pilot"] != first["pilot"]:
            raise ValueError(f"pilots differ ({first['pilot']!r}, {r['pilot']!r}): pool one pilot's seeds")
        for key in (*FLIGHT_KEYS, *SAME_FLIGHT):
            if r.get(key) != first.get(key):
                raise ValueError(
                    f"seed {r['seed']} was flown with {key} {r.get(key)!r}, seed {first['seed']} with "
                    f"{first.get(key)!r}: pool one way of flying"
                )
        for key, default in PLANNER_WAYS.items():  # another probe, obstacle motion or body is another way of flying
            mine_, theirs = ((x.get("planner") or {}).get(key) or default for x in (r, first))
            if mine_ != theirs:
                raise ValueError(
                    f"seed {r['seed']} was flown with {key} {mine_}, seed {first['seed']} with {theirs}: "
                    "pool one way of flying"
                )
        mine_, theirs = r.get("planner") or {}, first.get("planner") or {}
        for key in sorted(set(mine_) & set(theirs)):  # the planner's settings (K, horizon, ...) that both record
            if mine_[key] != theirs[key]:
                raise ValueError(
                    f"seed {r['seed']} was flown with the planner's {key} {mine_[key]!r}, seed {first['seed']} "
                    f"with {theirs[key]!r}: pool one way of flying"
                )
        mine = {(int(x["obstacles"]), float(x["speed"])): x for x in r["settings"]}
        if sorted(mine) != keys:
            raise ValueError(f"seed {r['seed']} was flown on another grid ({sorted(mine)}) than seed {first['seed']}")
        per_seed[str(r["seed"])] = r["settings"]
        for k, x in mine.items():
            for f in ("episodes", "success", *failures):
                pooled[k][f] += int(x.get(f, 0))
            rate = int(x["success"]) / int(x["episodes"])
            if worst is None or rate < worst["rate"]:
                worst = {
                    "seed": int(r["seed"]),
                    "obstacles": k[0],
                    "speed": k[1],
                    "rate": rate,
                    "success": int(x["success"]),
                    "episodes": int(x["episodes"]),
                }
    out = {key: first[key] for key in ("pilot", "run", "planner_preset", "planner", *FLIGHT_KEYS) if key in first}
    return {
        **out,
        "seed": seeds[0] if len(seeds) == 1 else None,
        "seeds": seeds,
        "settings": list(pooled.values()),
        "per_seed": per_seed,
        "worst_setting": worst,
        # every seed's episodes, where each recorded them (eval factors breaks them down)
        **(
            {"episodes": [e for r in reports for e in r["episodes"]]} if all(r.get("episodes") for r in reports) else {}
        ),
    }


def outcome_flips(a: dict, b: dict, names: tuple[str, str] = ("the first report", "the second report")) -> dict:
    """Episodes of two flights of one grid (the same pilot and seeds, e.g. on 1 and 2 torch threads,
    or on two machines) whose outcome differs: the robustness of a figure to a tiny perturbation.
    Episodes are matched by seed; both reports need their ``episodes``. Beside the flips, how much
    the flights themselves moved: the episodes flown identically (the same frame count and
    closest approach) and the median and largest change of the closest approach (metres) and of the
    frame count, where the reports record them. Only the episodes both flew are compared; those of
    one alone are counted (``only_first``, ``only_second``)."""

    def by_seed(report: dict, name: str) -> dict[int, dict]:
        episodes = report.get("episodes")
        if not episodes:
            raise ValueError(f"{name} holds no episodes: give the --json tables of eval closed-loop, which list them")
        return {int(e["seed"]): e for e in episodes}

    ea, eb = by_seed(a, names[0]), by_seed(b, names[1])
    common = sorted(set(ea) & set(eb))
    if not common:
        raise ValueError("the two reports share no episode seed: fly the same grid (--seed, settings) twice")
    flips = [
        {
            "obstacles": ea[s]["obstacles"],
            "speed": ea[s]["speed"],
            "episode": ea[s]["episode"],
            "seed": s,
            "first": ea[s]["outcome"],
            "second": eb[s]["outcome"],
        }
        for s in common
        if ea[s]["outcome"] != eb[s]["outcome"]
    ]
    success = (sum(ea[s]["outcome"] == "success" for s in common), sum(eb[s]["outcome"] == "success" for s in common))
    moved: dict = {}
    if all("frames" in e[s] and "min_clearance_m" in e[s] for e in (ea, eb) for s in common):
        clearance = [abs(ea[s]["min_clearance_m"] - eb[s]["min_clearance_m"]) for s in common]
        frames = [abs(ea[s]["frames"] - eb[s]["frames"]) for s in common]
        moved = {
            "identical": sum(c == 0 and f == 0 for c, f in zip(clearance, frames)),
            "clearance_change_m": {"median": float(statistics.median(clearance)), "max": float(max(clearance))},
            "frames_change": {"median": float(statistics.median(frames)), "max": int(max(frames))},
        }
    unshared = {"only_first": len(set(ea) - set(eb)), "only_second": len(set(eb) - set(ea))}
    unshared = {k: v for k, v in unshared.items() if v}  # episodes one flight flew and the other did not
    return {
        "episodes": len(common),
        "flips": len(flips),
        "successes": list(success),
        "flipped": flips,
        **moved,
        **unshared,
    }
