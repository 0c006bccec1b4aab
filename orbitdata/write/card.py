"""The dataset card (README.md): a Hub-compliant YAML header and a datasheet with measured numbers."""

from __future__ import annotations

import importlib.resources
from string import Template

import mujoco
import pyarrow as pa
import yaml
from rich.filesize import decimal

from orbitdata import schema as S
from orbitdata.config import GenerationConfig
from orbitdata.info import Info
from orbitdata.scenario.config import STATIC
from orbitdata.scenario.dynamics import NO_FAULT

LICENSE = "cc-by-4.0"
TAGS = ["space-robotics", "world-models", "cubesat", "obstacle-avoidance", "mujoco", "orbit-planner"]


def _size_category(n: int) -> str:
    bounds = [
        (1_000, "n<1K"),
        (10_000, "1K<n<10K"),
        (100_000, "10K<n<100K"),
        (1_000_000, "100K<n<1M"),
        (10_000_000, "1M<n<10M"),
        (100_000_000, "10M<n<100M"),
    ]
    return next((label for limit, label in bounds if n < limit), "n>100M")


def _features_yaml(kind: str, tier: str = STATIC) -> list:
    from datasets import Features
    from datasets.info import DatasetInfo

    info = DatasetInfo(features=Features.from_dict(S.hf_features(kind, tier)))
    return info._to_yaml_dict()["features"]


def yaml_header(info: Info, sizes: dict) -> dict:
    """The Hub card metadata: license, tags, configs (steps default, episodes), dataset_info."""
    splits = list(info.counts["splits"])
    configs = [
        {
            "config_name": name,
            "data_files": [{"split": s, "path": f"{folder}/{s}-*.parquet"} for s in splits],
            **({"default": True} if name == "default" else {}),
        }
        for name, folder in (("default", S.DATA_DIR), ("episodes", S.EPISODES_DIR))
    ]
    dataset_info = []
    for name, folder, key in (("default", S.DATA_DIR, "frames"), ("episodes", S.EPISODES_DIR, "episodes")):
        split_info = [
            {"name": s, "num_bytes": sizes[folder][s], "num_examples": info.counts["splits"][s][key]} for s in splits
        ]
        total = sum(sizes[folder].values())
        dataset_info.append(
            {
                "config_name": name,
                "features": _features_yaml("data" if folder == S.DATA_DIR else "episodes", info.tier),
                "splits": split_info,
                "download_size": total,
                "dataset_size": total,
            }
        )
    return {
        "license": LICENSE,
        "task_categories": ["robotics"],
        "tags": TAGS,
        "pretty_name": "Orbit-Planner CubeSat obstacle avoidance (MuJoCo)",
        "size_categories": [_size_category(info.counts["frames"])],
        "configs": configs,
        "dataset_info": dataset_info,
    }


def _type_name(t: pa.DataType) -> str:
    if t.equals(S.IMAGE_STRUCT):
        return "Image (bytes)"
    if pa.types.is_fixed_size_list(t):
        return f"{t.list_size} x {_type_name(t.value_type)}"
    if pa.types.is_list(t):
        return f"list of {_type_name(t.value_type)}"
    if pa.types.is_struct(t):
        return "struct"
    return {"float": "float32", "double": "float64"}.get(str(t), str(t))


def column_table(kind: str, tier: str = STATIC) -> str:
    """The card's table of one table's columns in a ``tier`` dataset, from the schema: name, type, unit, meaning."""
    rows = ["| column | type | unit | meaning |", "|---|---|---|---|"]
    for f in S.fields_of(kind, tier):
        rows.append(f"| `{f.name}` | {_type_name(f.type)} | {f.unit or '-'} | {f.description} |")
    return "\n".join(rows)


def _header(columns: list[str], outcomes: tuple[str, ...]) -> str:
    """A composition table's header: the columns, then one per outcome."""
    names = columns + [o.replace("_", " ") for o in outcomes]
    return "| " + " | ".join(names) + " |\n" + "|---" * len(names) + "|"


def rejections(episodes: pa.Table) -> tuple[int, int]:
    """(debris draws rejected as unsurvivable, debris pieces kept) over a dynamic dataset's episodes:
    the tier's rejection rate is the first over their sum."""
    rejected = sum(episodes.column(S.UNSURVIVABLE_DRAWS).to_pylist())
    return rejected, sum(episodes.column(S.N_OBSTACLES).to_pylist())


def _share(count: int, total: int) -> str:
    return f"{count} of {total} ({100 * count / max(total, 1):.0f} %)"


def tier_note(config: GenerationConfig, episodes: pa.Table | None) -> str:
    """The card's paragraph on the dynamic tier, measured from the episodes table ('' for static)."""
    if config.tier == STATIC:
        return ""
    d, n = config.scenario.dynamic, episodes.num_rows
    cw = sum(episodes.column(S.CW).to_pylist())
    faults = sum(f["kind"] != NO_FAULT for f in episodes.column(S.FAULT).to_pylist())
    eclipse = sum(e["eclipse"] for e in episodes.column(S.SENSING).to_pylist())
    rejected, kept = rejections(episodes)
    return (
        "\n\n**The dynamic tier.** Unlike the paper's static scenes (the numbers above on rocks, the RRT*"
        " expert, and the limitations below on sensing and orbital mechanics are the static tier's), the"
        " expert is MPPI told the debris' motion, the body and the fault (the `planner` column then holds its"
        " iterations and no path length), and the debris drifts at"
        f" {d.debris_speed[0]:g}-{d.debris_speed[1]:g} m/s and tumbles at {d.tumble_deg_s[0]:g}-{d.tumble_deg_s[1]:g}"
        f" deg/s, a share of {d.intercept_prob:g} of it aimed to cross the nominal flight; the Clohessy-Wiltshire"
        f" terms (n = {d.mean_motion:g} rad/s) act in {_share(cw, n)} episodes, one thruster is faulty in"
        f" {_share(faults, n)} and {_share(eclipse, n)} are in eclipse; the camera has RGB noise of {d.rgb_noise:g}"
        f" and depth dropout of {d.depth_dropout[0]:g}-{d.depth_dropout[1]:g}; mass and inertia vary by"
        f" x{d.mass_scale[0]:g}-{d.mass_scale[1]:g}. {rejected} debris draws were rejected as unsurvivable against"
        f" {kept} kept (`{S.UNSURVIVABLE_DRAWS}`). Each frame's obstacle poses (`{S.OBSTACLE_POSES}`) and the"
        " episode's motion, body, fault and sensing records are privileged: for oracles and validation, never an"
        " input of a learned pilot."
    )


def render_card(
    info: Info,
    config: GenerationConfig,
    sizes: dict,
    repo: str = "path/to/orbit_planner",
    overview: str | None = None,
    episodes: pa.Table | None = None,
) -> str:
    """The card. ``episodes``: the episodes table, which a dynamic-tier card summarises."""
    c = info.counts
    outcomes = S.outcomes(config.tier)
    split_rows, level_rows = [], []
    for s, sc in c["splits"].items():
        o = sc["outcomes"]
        split_rows.append(
            f"| {s} | {sc['episodes']} | {sc['frames']} | " + " | ".join(str(o[k]) for k in outcomes) + " |"
        )
        for level, lc in sc["levels"].items():
            lo = lc["outcomes"]
            level_rows.append(
                f"| {s} | {level} | {lc['episodes']} | {lc['frames']} | "
                + " | ".join(str(lo[k]) for k in outcomes)
                + " |"
            )
    total_bytes = sum(v for folder in sizes.values() for v in folder.values())
    sim, scn, pil, ds = config.sim, config.scenario, config.pilots, config.dataset
    template = Template(importlib.resources.files("orbitdata.cards").joinpath("dataset_card.md").read_text())
    header = yaml.safe_dump(yaml_header(info, sizes), sort_keys=False, width=1000).strip()
    return template.substitute(
        yaml_header=header,
        total_episodes=c["episodes"],
        total_frames=c["frames"],
        fps=S.FPS,
        dt=S.DT,
        image_size=sim.camera.image_size,
        codebase_version=info.codebase_version,
        schema_version=info.schema_version,
        seed=ds.seed,
        tier_note=tier_note(config, episodes),
        repo=repo,
        split_header=_header(["split", "episodes", "frames"], outcomes),
        level_header=_header(["split", "level", "episodes", "frames"], outcomes),
        split_table="\n".join(split_rows),
        level_table="\n".join(level_rows),
        total_bytes=decimal(total_bytes),
        bytes_per_frame=round(total_bytes / max(c["frames"], 1)),
        jpeg_quality=ds.jpeg_quality,
        near=sim.camera.near,
        far=sim.camera.far,
        mujoco_version=mujoco.__version__,
        substeps=sim.substeps,
        max_steps=sim.max_steps,
        body_size=2 * sim.cubesat.half_size,
        dry_mass=sim.cubesat.dry_mass,
        fuel_mass=sim.cubesat.fuel_mass,
        isp=sim.cubesat.isp,
        max_thrust=sim.cubesat.max_thrust,
        cant_deg=sim.cubesat.cant_deg,
        wrench_rank=info.hardware["wrench_rank"],
        step_columns=column_table("data", config.tier),
        episode_columns=column_table("episodes", config.tier),
        fov=sim.camera.fovy_deg,
        n_obstacles_range=f"{scn.n_obstacles[0]} to {scn.n_obstacles[1]}",
        shapes=", ".join(scn.shapes),
        goal_distance=f"{scn.goal_distance[0]} to {scn.goal_distance[1]}",
        speed_range=f"{scn.speed[0]} to {scn.speed[1]}",
        on_line_prob=scn.on_line_prob,
        margin=pil.expert.planner.margin,
        accel_sigma=pil.exploratory.accel_sigma,
        alpha_sigma=pil.exploratory.alpha_sigma,
        thrust_sigma=pil.exploratory.thrust_sigma,
        ou_tau=pil.exploratory.tau,
        level_mix=", ".join(f"{lv} {share:g}" for lv, share in zip(S.LEVELS, ds.level_mix)),
        test_fraction=ds.test_fraction,
        overview=(f"![Overview: sample frames and outcome rates per level]({overview})" if overview else ""),
    )
