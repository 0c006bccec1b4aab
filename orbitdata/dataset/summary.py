"""The data behind ``orbitdata info``: counts, episode lengths, sizes and how a dataset was made.

A dataset is a local folder or a Hugging Face Hub dataset repo id. Everything comes from
``meta/info.json`` and the (small) episodes shards; no frame is read.
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from orbitdata import schema as S

REPO_ID = re.compile(r"^[A-Za-z0-9][\w.-]*/[\w.-]+$")
LENGTH_BINS = 10  # histogram bins over [0, max_steps]


def is_repo_id(source: str) -> bool:
    """True for 'owner/name' that is not an existing local path."""
    return bool(REPO_ID.match(str(source))) and not Path(source).exists()


def _offline() -> bool:
    from huggingface_hub import constants

    env = os.environ.get("HF_HUB_OFFLINE", "").strip().lower() in ("1", "true", "yes", "on")
    return bool(constants.HF_HUB_OFFLINE) or env


def _hub_file(repo_id: str, filename: str) -> Path:
    """Download one file of a dataset repo (or take it from the local cache)."""
    from huggingface_hub import hf_hub_download

    try:
        return Path(hf_hub_download(repo_id, filename, repo_type="dataset"))
    except Exception as exc:  # the hub raises many types; all mean "not available"
        name = type(exc).__name__
        if _offline():
            why = ("offline mode is on (HF_HUB_OFFLINE=1) and the file is not in the local cache; "
                   "unset HF_HUB_OFFLINE to download it, or pass a local dataset folder")
        elif "RepositoryNotFound" in name:
            why = ("there is no such dataset repo, or it is private or gated: check the id, "
                   "or log in with `hf auth login`")
        elif "EntryNotFound" in name:
            why = "the repo has no such file: was it pushed with `orbitdata push`?"
        else:
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else name
            why = f"{first}; check your connection and the repo id, or pass a local dataset folder"
        raise RuntimeError(f"cannot fetch {filename} of dataset repo {repo_id!r} from the Hugging Face Hub: {why}") from None


def read_source(source: str | Path) -> tuple[dict, pa.Table, str]:
    """(info.json, episodes table, where) for a local folder or a Hub repo id."""
    source = str(source)
    columns = [S.SPLIT, S.LEVEL, S.OUTCOME, S.LENGTH]
    if is_repo_id(source):
        info = json.loads(_hub_file(source, S.INFO_PATH).read_text())
        files = [_hub_file(source, rel) for rel in sorted(info.get("files", {})) if rel.startswith(S.EPISODES_DIR + "/")]
        where = f"hf://datasets/{source}"
    else:
        root = Path(source).expanduser()
        if not root.is_dir():
            raise FileNotFoundError(f"{root} is not a folder, nor a Hub repo id like 'user/orbit_planner'; "
                                    "pass a dataset folder made by `orbitdata generate`")
        info_path = root / S.INFO_PATH
        if not info_path.exists():
            raise FileNotFoundError(f"{info_path} is missing: {root} is not a finished orbitdata dataset "
                                    "(if a `generate` run into it was interrupted, run the same command again)")
        info = json.loads(info_path.read_text())
        files = [root / rel for rel in sorted(info.get("files", {})) if rel.startswith(S.EPISODES_DIR + "/")]
        where = str(root)
    missing = [str(f) for f in files if not Path(f).exists()]
    if missing or not files:
        raise FileNotFoundError(f"episodes shards {missing or '(none listed in meta/info.json)'} are missing "
                                f"from {where}; run `orbitdata validate` on it")
    episodes = pa.concat_tables([pq.read_table(f, columns=columns) for f in files])
    return info, episodes, where


def length_stats(lengths: np.ndarray) -> dict:
    """min / p10 / median / mean / p90 / max of episode lengths in frames."""
    if not len(lengths):
        return {"episodes": 0}
    q = np.percentile(lengths, [10, 50, 90])
    return {"episodes": int(len(lengths)), "min": int(lengths.min()), "p10": round(float(q[0]), 1),
            "median": round(float(q[1]), 1), "mean": round(float(lengths.mean()), 1), "p90": round(float(q[2]), 1), "max": int(lengths.max())}


def lengths_summary(episodes: pa.Table, max_steps: int) -> dict:
    """Length statistics overall, per level and per outcome, and a histogram per level."""
    length = np.asarray(episodes.column(S.LENGTH).to_numpy(), dtype=np.int64)
    level = np.asarray(episodes.column(S.LEVEL).to_pylist())
    outcome = np.asarray(episodes.column(S.OUTCOME).to_pylist())
    edges = np.linspace(0, max(max_steps, int(length.max(initial=1))), LENGTH_BINS + 1)
    return {
        "all": length_stats(length),
        "by_level": {lv: length_stats(length[level == lv]) for lv in S.LEVELS if (level == lv).any()},
        "by_outcome": {o: length_stats(length[outcome == o]) for o in S.OUTCOMES if (outcome == o).any()},
        "histogram": {
            "edges": [round(float(e), 3) for e in edges],
            "by_level": {lv: np.histogram(length[level == lv], edges)[0].tolist()
                         for lv in S.LEVELS if (level == lv).any()},
            "by_outcome": {o: np.histogram(length[outcome == o], edges)[0].tolist()
                           for o in S.OUTCOMES if (outcome == o).any()},
        },
    }


def sizes_summary(info: dict) -> dict:
    """Bytes per folder and split, from the file list in info.json."""
    out: dict = {"data": {}, "episodes": {}, "other": {}}
    for rel, entry in sorted(info.get("files", {}).items()):
        folder, _, name = rel.partition("/")
        if folder in (S.DATA_DIR, S.EPISODES_DIR) and name:
            split = name.split("-")[0]
            out[folder][split] = out[folder].get(split, 0) + int(entry["bytes"])
        else:
            out["other"][rel] = int(entry["bytes"])
    out["files"] = len(info.get("files", {}))
    out["total"] = sum(int(e["bytes"]) for e in info.get("files", {}).values())
    frames = info.get("counts", {}).get("frames", 0)
    out["bytes_per_frame"] = round(out["total"] / frames) if frames else None
    return out


def _flatten(d: dict, prefix: str = "") -> dict:
    flat = {}
    for key, value in d.items():
        name = f"{prefix}{key}"
        if isinstance(value, dict):
            flat.update(_flatten(value, name + "."))
        else:
            flat[name] = value
    return flat


def outcome_rates(counts: dict) -> dict:
    """Share of each outcome per level, over all splits."""
    rates = {}
    for level in S.LEVELS:
        per = [s["levels"][level] for s in counts.get("splits", {}).values() if level in s.get("levels", {})]
        n = sum(p["episodes"] for p in per)
        if n:
            rates[level] = {o: round(sum(p["outcomes"].get(o, 0) for p in per) / n, 4) for o in S.OUTCOMES}
    return rates


def summarize(source: str | Path) -> dict:
    """Everything ``orbitdata info`` shows, as plain JSON-able data."""
    info, episodes, where = read_source(source)
    config = info.get("config", {})
    sim = config.get("sim", {})
    counts = info.get("counts", {})
    return {
        "source": where,
        "schema_version": info.get("schema_version"),
        "codebase_version": info.get("codebase_version"),
        "fps": info.get("fps"),
        "dt": info.get("dt"),
        "root_seed": info.get("root_seed"),
        "image_size": sim.get("camera", {}).get("image_size"),
        "episodes": counts.get("episodes"),
        "steps": counts.get("frames"),
        "counts": counts,
        "outcome_rates": outcome_rates(counts),
        "lengths": lengths_summary(episodes, int(sim.get("max_steps", 0))),
        "sizes": sizes_summary(info),
        "parameters": {
            "sim": _flatten(sim),
            "hardware": {"wrench_rank": info.get("hardware", {}).get("wrench_rank")},
            "pilots": _flatten(config.get("pilots", {})),
            "scenario": _flatten(config.get("scenario", {})),
            "dataset": _flatten(config.get("dataset", {})),
        },
    }
