"""The paper's Figure 6: success per grid setting and on average, one bar per pilot.

Reads the JSON tables of ``orbitmodel eval closed-loop --json`` and ``orbitdata fly --json``
(both: ``pilot``, ``seed``, ``settings`` with per-outcome counts), so the learned planner, its
oracles, the expert and the risky pilot share one figure.
"""

from __future__ import annotations

import json
from pathlib import Path

from orbitdata.schema import DYNAMIC_OUTCOMES, OUTCOMES
from orbitmodel.extras import pyplot


def read_report(path: str | Path) -> dict:
    """A grid result: the ``--json`` table, or the ``.episodes.jsonl`` stream of a grid that
    was stopped early (its settings count the episodes flown, and ``partial`` is true)."""
    path = Path(path)
    if path.suffix == ".jsonl":
        return report_from_episodes(path)
    report = read_json(path)

    def refuse(why: str) -> ValueError:
        return ValueError(f"{path} is not a grid result ({why}): {GIVE}")

    missing = [key for key in ("settings", "pilot") if key not in report]
    if missing:
        raise refuse(f"it has no {missing[0]!r} key")
    settings, episodes = report["settings"], report.get("episodes", [])
    if not all(isinstance(t, list) and all(isinstance(x, dict) for x in t) for t in (settings, episodes)):
        raise refuse("its settings or episodes are not lists of tables")
    for what, tables, keys in (
        ("a setting", settings, ("obstacles", "speed", "episodes", "success")),
        ("an episode", episodes, ("obstacles", "speed", "episode", "seed", "outcome")),
    ):
        for table in tables:
            lacks = [key for key in keys if key not in table]
            if lacks:
                raise refuse(f"{what} in it has no {lacks[0]!r} key")
    for s in settings:
        n, k = s["episodes"], s["success"]
        if not (_whole(n) and _whole(k) and 0 <= k <= n and n >= 1):
            raise refuse(f"a setting counts {k!r} successes in {n!r} episodes")
    return report


def _whole(x) -> bool:
    return isinstance(x, int) and not isinstance(x, bool)


GIVE = "give the --json table of orbitdata fly or orbitmodel eval closed-loop"


def read_json(path: str | Path) -> dict:
    """A JSON file that should hold a grid result, or a ValueError / FileNotFoundError naming it."""
    path = Path(path)
    if path.is_dir():
        raise ValueError(f"{path} is a folder: {GIVE}, a file")
    if not path.exists():
        raise FileNotFoundError(f"{path} does not exist: {GIVE}")
    try:
        report = json.loads(path.read_text())
    except json.JSONDecodeError as err:
        raise ValueError(f"{path} is not JSON ({err}): {GIVE}") from None
    if not isinstance(report, dict):
        raise ValueError(f"{path} is not a grid result (not a JSON object): {GIVE}")
    return report


def report_from_episodes(path: str | Path) -> dict:
    """The table of the episodes streamed to ``path`` so far (one JSON record per line)."""
    path = Path(path)
    settings: dict[tuple[int, float], dict] = {}
    pilot = None
    try:
        for line in path.read_text().splitlines():
            if not line.strip():
                continue
            e = json.loads(line)
            key = (int(e["obstacles"]), float(e["speed"]))
            cell = settings.setdefault(
                key, {"obstacles": key[0], "speed": key[1], "episodes": 0, **{o: 0 for o in OUTCOMES}}
            )
            cell["episodes"] += 1
            outcome = e["outcome"]
            if outcome not in DYNAMIC_OUTCOMES:
                raise ValueError(f"unknown outcome {outcome!r}")
            cell[outcome] = cell.get(outcome, 0) + 1  # tumbling: the dynamic tier's only
            pilot = e.get("variant", pilot)
    except (json.JSONDecodeError, KeyError, TypeError, ValueError) as err:
        raise ValueError(
            f"{path} is not an episode stream of orbitmodel eval closed-loop --json: {type(err).__name__} {err}"
        ) from None
    if not settings:
        raise ValueError(f"{path} holds no episodes yet")
    name = pilot or path.name.split(".")[0]
    return {"pilot": name, "seed": None, "partial": True, "settings": [settings[k] for k in sorted(settings)]}


def success_table(reports: list[dict]) -> tuple[list[tuple[int, float]], dict[str, list[float]]]:
    """The grid settings and, per pilot, the success rate per setting then the average (in [0, 1]).

    Every report must cover the same settings (raises ValueError naming the odd one).
    """
    if not reports:
        raise ValueError("no results to plot: give at least one JSON file")
    settings = [(int(s["obstacles"]), float(s["speed"])) for s in reports[0]["settings"]]
    rates: dict[str, list[float]] = {}
    for r in reports:
        mine = {(int(s["obstacles"]), float(s["speed"])): s for s in r["settings"]}
        if sorted(mine) != sorted(settings):
            raise ValueError(
                f"pilot {r['pilot']!r} was flown on another grid ({sorted(mine)}) than "
                f"{reports[0]['pilot']!r} ({sorted(settings)}); fly them on the same one"
            )
        name = r["pilot"] if r["pilot"] not in rates else f"{r['pilot']} ({len(rates)})"
        per = [mine[k]["success"] / max(mine[k]["episodes"], 1) for k in settings]
        rates[name] = per + [sum(per) / len(per)]
    return settings, rates


def plot_figure6(reports: list[dict], out: str | Path, title: str | None = None) -> Path:
    """Grouped bars (settings + average) per pilot, written to ``out`` (PNG)."""
    plt = pyplot()
    settings, rates = success_table(reports)
    labels = [f"{n} obst.\n{v:g} m/s" for n, v in settings] + ["average"]
    width = 0.8 / len(rates)
    fig, ax = plt.subplots(figsize=(max(6.0, 1.3 * len(labels)), 3.6), dpi=150)
    for i, (pilot, values) in enumerate(rates.items()):
        xs = [j + (i - (len(rates) - 1) / 2) * width for j in range(len(labels))]
        bars = ax.bar(xs, [100 * v for v in values], width, label=pilot)
        ax.bar_label(bars, labels=[f"{100 * v:.0f}" for v in values], fontsize=6, padding=1)
    ax.set_xticks(range(len(labels)), labels, fontsize=8)
    ax.axvline(len(labels) - 1.5, color="0.7", lw=0.8)
    ax.set_ylabel("success %")
    ax.set_ylim(0, 110)
    episodes = {s["episodes"] for r in reports for s in r["settings"]}
    seeds = sorted({str(s) for r in reports for s in (r.get("seeds") or [r.get("seed")]) if s is not None})
    where = f", seed{'s' if len(seeds) > 1 else ''} {', '.join(seeds)}" if seeds else ""  # eval pool's: every seed
    ax.set_title(
        title or f"closed-loop success, {'/'.join(map(str, sorted(episodes)))} episodes per setting{where}", fontsize=9
    )
    ax.legend(fontsize=7, ncols=min(len(rates), 3), loc="upper center", bbox_to_anchor=(0.5, -0.2), frameon=False)
    fig.tight_layout()
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out)
    plt.close(fig)
    return out
