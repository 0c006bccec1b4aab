"""The model card of a pushed run, made with ``huggingface_hub``'s card tooling (``ModelCard``,
``ModelCardData``) from the run's own files: its config (preset, parameters, dataset), its
``training.json`` (time and hardware), and its evaluations (Table I, the latent rollout, grid
results with their 95 % Wilson intervals). A figure the run has no file for is not on the card;
the card says which evaluation is missing and the command that makes it."""

from __future__ import annotations

import json
from collections import defaultdict
from pathlib import Path

from orbitdata.schema import DT
from orbitdata.sim.config import SimConfig
from orbitmodel.publish.files import GRID, RunFile, read_json
from orbitmodel.publish.reproduce import policy_command, stage1_commands
from orbitmodel.runs import POLICY, REPO_ID, TRAINING, RunDir

TEMPLATE = Path(__file__).with_name("model_card.md")
DEFAULT_MAX_STEPS = SimConfig().max_steps  # a grid result that does not record its episode length flew this
TAGS = ["robotics", "world-model", "space", "cubesat", "mujoco", "orbitdata", "orbitmodel"]


def _dataset(raw: dict, dataset_repo: str | None) -> tuple[list[str], str]:
    """(Hub dataset ids for the card's metadata, a sentence on the training data)."""
    meta = raw["dataset"]
    source = dataset_repo or meta["source"]
    episodes = ", ".join(f"{n} {split}" for split, n in meta["episodes"].items())
    made = (
        f"`orbitdata generate DATA --episodes {sum(meta['episodes'].values())} --image-size {meta['image_size']} "
        f"--seed {meta['root_seed']}`"
    )
    if REPO_ID.match(str(source)) and not Path(str(source)).exists():
        return (
            [str(source)],
            f"the dataset [{source}](https://huggingface.co/datasets/{source}) ({episodes} episodes, {meta['image_size']} px)",
        )
    return [], f"a dataset made by {made} (root seed {meta['root_seed']}; {episodes} episodes, {meta['image_size']} px)"


def _training(run: Path, label: str) -> str:
    path = run / TRAINING
    if not path.is_file():
        return f"- {label}: time and hardware not recorded (trained before orbitmodel recorded them)."
    segments = json.loads(path.read_text())["segments"]
    total = sum(s["seconds"] for s in segments)
    parts = "; ".join(
        f"steps {s['from_step']}-{s['to_step']} in {s['seconds'] / 60:.1f} min on {s['hardware']} "
        f"({s['device']}, {s['windows_per_s']} windows/s)"
        for s in segments
    )
    return f"- {label}: {total / 60:.1f} min of training ({parts})."


def _table1(files: list[RunFile]) -> str:
    from orbitmodel.probe.evaluate import markdown

    result = read_json(files, "eval/probe_table.json")
    if result is None:
        return "No Table I: run `orbitmodel eval probe RUN DATASET` before pushing.\n"
    return markdown(result)


def _rollout(files: list[RunFile]) -> str:
    from orbitmodel.evaluate.rollout import summary_lines

    result = read_json(files, "eval/rollout.json")
    if result is None:
        return "No latent-rollout evaluation: run `orbitmodel eval rollout RUN DATASET` before pushing.\n"
    return "```\n" + "\n".join(summary_lines(result)) + "\n```\n"


def _grids(files: list[RunFile]) -> str:
    """One table per grid (seed and settings) of the grid results published under eval/grid/."""
    from orbitmodel.evaluate.figure6 import read_report
    from orbitmodel.evaluate.success import markdown_table

    groups: dict[tuple, list[tuple[str, dict]]] = defaultdict(list)
    for f in files:
        if f.rel.startswith(GRID + "/") and f.rel.endswith(".json"):
            report = read_report(f.path)
            key = (
                report.get("seed"),
                report.get("max_steps", DEFAULT_MAX_STEPS),
                tuple((s["obstacles"], s["speed"], s["episodes"]) for s in report["settings"]),
            )
            groups[key].append((f.rel, report))
    if not groups:
        return (
            "No closed-loop results: fly the grid (`orbitmodel eval closed-loop RUN ... --json DIR/NAME.json`) "
            "and push with `--grid DIR`.\n"
        )
    out = []
    for (seed, frames, settings), rows in sorted(groups.items(), key=lambda kv: str(kv[0])):
        per = {e for *_, e in settings}
        out.append(
            f"Grid seed {seed}, {'/'.join(map(str, sorted(per)))} episodes per setting; success means "
            f"entering the 0.5 m goal sphere within {frames * DT:g} s ({frames} frames):\n"
        )
        out.append(markdown_table([r for _, r in rows], [rel for rel, _ in rows]))
    return "\n".join(out)


def _policy_card(run: Path, repo_id: str, raw: dict, files: list[RunFile], data_sentence: str) -> dict:
    """The template's parts for a Diffusion Policy run."""
    from orbitmodel.baselines.diffusion.config import PolicyPreset
    from orbitmodel.baselines.diffusion.policy import DiffusionPolicy

    preset = raw["preset"]
    params = DiffusionPolicy(PolicyPreset.from_dict(preset).model).num_parameters()
    title = f"Diffusion Policy ({preset['name']} preset) for CubeSat obstacle avoidance"
    return dict(
        title=title,
        summary=(
            f"A Diffusion Policy baseline (Chi et al. 2023), preset `{preset['name']}`, {params / 1e6:.2f} M "
            f"parameters, trained on {data_sentence}."
        ),
        contents="`config.json` and `model.safetensors` (with the EMA weights), and its evaluations",
        cli_usage=(
            f"orbitmodel eval closed-loop {repo_id} --preset cpu --obstacles 1,3,5 --speeds 1,2 --episodes 20"
            f"   # the flight preset the reported grids fly\n"
            f"orbitdata fly --pilot diffusion --pilot-option run={repo_id} --pilot-option preset=cpu "
            f"--image-size {raw['dataset']['image_size']}"
        ),
        python_usage=(
            f"from orbitmodel.baselines.diffusion import DiffusionPolicy, load_policy_pilot, policy_sampling\n"
            f'policy = DiffusionPolicy.from_pretrained("{repo_id}")\n'
            f'pilot = load_policy_pilot("{repo_id}", policy_sampling("cpu"), preset="cpu")  '
            f"# an orbitdata.fly pilot: reset(task), act(obs)"
        ),
        training=_training(run, "policy"),
        results=_grids(files),
        reproduce=policy_command(raw),
    )


def _world_model_card(run: Path, repo_id: str, raw: dict, files: list[RunFile], data_sentence: str) -> dict:
    """The template's parts for a Stage I run with its sub-runs."""
    from orbitmodel.config import Preset
    from orbitmodel.model.world_model import WorldModel

    preset, size = raw["preset"], raw["dataset"]["image_size"]
    model = Preset.from_dict(preset).model
    params = WorldModel(model).num_parameters()
    subs = [f"`{sub}/`" for sub in ("probe", "probe-state", "depth") if any(f.rel.startswith(sub + "/") for f in files)]
    refit = ", the depth head refitted for the planner" if any(f.rel.startswith("depth/") for f in files) else ""
    return dict(
        title=f"Orbit-Planner world model ({preset['name']} preset)",
        summary=(
            f"A latent world model of a free-floating 1U CubeSat (the Stage I model of Orbit-Planner), preset "
            f"`{preset['name']}`: {params / 1e6:.2f} M parameters, {model.image_size} px images, a "
            f"{model.latent_dim}-dimensional latent, {model.frame_step} frame(s) per prediction; trained on "
            f"{data_sentence}. With it: its physics probe (Stage II){refit}, and the evaluations below."
        ),
        contents=f"the Stage I run (`config.json`, `model.safetensors`) and its sub-runs ({', '.join(subs)}), with `eval/`",
        cli_usage=(
            f"orbitmodel eval closed-loop {repo_id} --preset cpu --obstacles 1,3,5 --speeds 1,2 --episodes 20\n"
            f"orbitdata fly --pilot planner --pilot-option run={repo_id} --pilot-option preset=cpu "
            f"--image-size {size}"
        ),
        python_usage=(
            f"from orbitmodel import PhysicsProbe, WorldModel\n"
            f'model = WorldModel.from_pretrained("{repo_id}")\n'
            f'probe = PhysicsProbe.from_pretrained("{repo_id}", world_model=model.fingerprint)\n\n'
            f"from orbitmodel.plan import build_pilot, planner_config\n"
            f'pilot, sim = build_pilot("planner", "{repo_id}", planner_config("cpu"))   # an orbitdata.fly pilot'
        ),
        training="\n".join([_training(run, "Stage I"), _training(run / "probe", "physics probe")]),
        results=(
            "### Table I: the physics probe (`eval/probe_table.json`)\n\n"
            + _table1(files)
            + "\n### Stage I: latent rollout (`eval/rollout.json`)\n\n"
            + _rollout(files)
            + "\n### Closed loop (`eval/grid/`)\n\n"
            + _grids(files)
        ),
        reproduce="\n".join(
            [
                f"orbitdata generate DATA --episodes {sum(raw['dataset']['episodes'].values())} --image-size {size} "
                f"--seed {raw['dataset']['root_seed']}",
                *stage1_commands(run, raw),  # with every setting that differs from the preset
                "orbitmodel eval rollout RUN DATA && orbitmodel eval probe RUN DATA",
                "bash scripts/reproduce_model.sh OUT    # the whole chain, grids included (the project's repository)",
            ]
        ),
    )


def model_card(run: Path, repo_id: str, stage: str, files: list[RunFile], dataset_repo: str | None = None):
    """The ``huggingface_hub.ModelCard`` of a push of ``run`` to ``repo_id``."""
    from huggingface_hub import ModelCard, ModelCardData

    raw = RunDir(run).read_config()
    datasets, data_sentence = _dataset(raw, dataset_repo)
    parts = (_policy_card if stage == POLICY else _world_model_card)(run, repo_id, raw, files, data_sentence)
    data = ModelCardData(
        license="apache-2.0", library_name="orbitmodel", tags=TAGS, datasets=datasets or None, model_name=parts["title"]
    )
    return ModelCard.from_template(data, template_path=str(TEMPLATE), repo_id=repo_id, **parts)
