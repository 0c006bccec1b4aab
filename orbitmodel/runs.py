"""Run folders: what every stage writes, how it resumes, and how a trained run is read back.

::

    RUN/config.json                     the stage, its preset or recipe, and the dataset's facts
    RUN/model.safetensors               the final weights (written when the run ends)
    RUN/checkpoints/step-NNNNNNN/       model.safetensors + state.pt (optimiser, step, RNG)
    RUN/checkpoints/latest              name of the newest complete checkpoint
    RUN/metrics.jsonl                   one JSON line per logged step
    RUN/training.json                   each training segment (a resume starts one): steps, seconds, hardware
    RUN/tensorboard/                    event files, when tensorboard is installed
    RUN/probe/  RUN/probe-state/  RUN/depth/   a Stage I run's sub-runs, each a run folder

A checkpoint folder is written under a temporary name and renamed, and ``latest`` is replaced
atomically after it, so a run killed at any moment resumes from a complete checkpoint.

This is the bottom layer of ``orbitmodel`` (with ``config``, ``data`` and ``kinematics``): every
stage writes through :class:`RunDir`, every loader reads through :func:`load_run`, and every
run-level refusal is a :class:`RunError`.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import shutil
from dataclasses import dataclass, replace
from pathlib import Path
from typing import TYPE_CHECKING, Callable, Mapping

from orbitmodel.config import Preset
from orbitmodel.data import DatasetMeta, ValidationSplit

if TYPE_CHECKING:  # torch and safetensors load with the first weights read or written, not with the CLI
    import torch

CONFIG = "config.json"
WEIGHTS = "model.safetensors"
STATE = "state.pt"
CHECKPOINTS = "checkpoints"
LATEST = "latest"
METRICS = "metrics.jsonl"
TRAINING = "training.json"  # each training segment's steps, wall time and hardware
TENSORBOARD = "tensorboard"
OWNED = (CONFIG, WEIGHTS, CHECKPOINTS, METRICS, TRAINING, TENSORBOARD)  # what --overwrite may remove
KEEP = 2  # checkpoints kept on disk
# The ``stage`` of a config.json, and the command that makes each.
WORLD_MODEL, PROBE, DEPTH_REFIT, POLICY = "world_model", "probe", "depth_refit", "policy"
MAKES = {
    WORLD_MODEL: "orbitmodel train DATASET --out RUN",
    PROBE: "orbitmodel probe RUN DATASET",
    DEPTH_REFIT: "orbitmodel depth RUN DATASET",
    POLICY: "orbitmodel train-policy DATASET --out RUN",
}


REPO_ID = re.compile(r"^(?P<repo>[A-Za-z0-9][\w.-]*/[\w.-]+)(?:@(?P<revision>[\w./-]+))?$")  # owner/name[@rev]


def max_steps_of(config: dict) -> int:
    """A run config's ``preset.train.loop.max_steps`` (0: none)."""
    return int(config.get("preset", {}).get("train", {}).get("loop", {}).get("max_steps") or 0)


def extends(old: dict, new: dict) -> bool:
    """Whether ``new`` is ``old`` with a larger ``preset.train.loop.max_steps`` and nothing else
    changed (a run trained further, ``--resume --extend``); both as this version writes them."""

    def without_steps(config: dict) -> dict:
        preset = config.get("preset", {})
        train = preset.get("train", {})
        loop = {**train.get("loop", {}), "max_steps": None}
        return {**config, "preset": {**preset, "train": {**train, "loop": loop}}}

    return 0 < max_steps_of(old) < max_steps_of(new) and same_config(without_steps(old), without_steps(new))


class RunError(ValueError):
    """A run folder that cannot be used as asked (the CLI turns it into one line, exit 2)."""


def is_hub_run(run: str | Path) -> bool:
    """True when ``run`` names a Hub model repo (``owner/name[@revision]``), not a local path: no
    such file here, and not even its first folder (``runs/x`` with a ``runs/`` here is local)."""
    text = str(run)
    if isinstance(run, Path) and not REPO_ID.match(text):
        return False
    match = REPO_ID.match(text)
    if match is None or text.startswith((".", "/", "~")) or Path(text).exists():
        return False
    from orbitdata.load.source import is_repo_id

    return is_repo_id(match["repo"]) and not Path(match["repo"].split("/")[0]).exists()


def resolve_run(run: str | Path, revision: str | None = None) -> Path:
    """The local folder of a run: ``run`` itself when it is a path here, else the Hugging Face Hub
    model repo it names (``owner/name``, ``owner/name@revision`` or ``revision=``; see
    :func:`is_hub_run`), downloaded into the ``huggingface_hub`` cache, or found there alone in
    offline mode (``HF_HUB_OFFLINE=1``). ``orbitmodel push`` makes such repos. A path comes back as
    it is, for the caller's own "not a run" error."""
    if not is_hub_run(run):
        if revision is not None:
            raise RunError(f"revision={revision!r} is for a Hub repo id; {run} is a local path")
        return Path(run)
    from huggingface_hub import constants, snapshot_download
    from huggingface_hub.errors import (
        HfHubHTTPError,
        LocalEntryNotFoundError,
        RepositoryNotFoundError,
        RevisionNotFoundError,
    )

    match = REPO_ID.match(str(run))
    repo = match["repo"]
    if match["revision"] and revision and match["revision"] != revision:
        raise RunError(f"{run} names revision {match['revision']!r} but revision={revision!r} was given too; give one")
    rev = match["revision"] or revision
    where = f"{repo}" + (f"@{rev}" if rev else "")
    try:
        return Path(snapshot_download(repo, revision=rev, repo_type="model"))
    except RevisionNotFoundError:
        raise RunError(
            f"{where}: the model repo has no revision {rev!r}; give a branch, tag or commit it has"
        ) from None
    except RepositoryNotFoundError:
        raise RunError(
            f"{run} is neither a run folder here (no such path) nor a model repo on "
            f"{constants.ENDPOINT} (not found, or private without a token that may read it)"
        ) from None
    except LocalEntryNotFoundError:
        raise RunError(
            f"{run} is no run folder here (no such path), and as a Hub repo id it is not in the local "
            "Hugging Face cache while the Hub cannot be reached (offline mode, or no network)"
        ) from None
    except HfHubHTTPError as err:
        status = err.response.status_code if err.response is not None else "?"
        raise RunError(f"the Hub refused {where} (HTTP {status}); check the repo id and your token") from None


@dataclass
class Checkpoint:
    step: int
    weights: dict[str, torch.Tensor]
    state: dict


def write_json_atomic(path: Path, data: dict) -> None:
    """Write ``data`` as sorted, indented JSON through a temporary file, so a reader never sees half of it."""
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_text(json.dumps(data, indent=2, sort_keys=True) + "\n")
    os.replace(tmp, path)


def run_config(stage: str, **parts) -> dict:
    """A run's config.json: its stage and parts, as the file reads back (tuples become lists), so
    that a resumed run compares equal to the one on disk."""
    return json.loads(json.dumps({"stage": stage, **parts}))


def _changed_settings(old: dict, new: dict, most: int = 3) -> str:
    """The settings in which two run configs differ, as ``preset.train.loop.max_steps: 2 -> 4``
    (paths to the same folder are the same; the first ``most``, then how many more)."""
    from orbitdata.config import config_changes

    tops = [k for k in sorted(set(old) | set(new)) if not same_config({k: old.get(k)}, {k: new.get(k)})]
    changes = [c for k in tops for c in config_changes({k: old.get(k)}, {k: new.get(k)})] or tops
    more = f" and {len(changes) - most} more" if len(changes) > most else ""
    return ", ".join(changes[:most]) + more


def same_config(a: dict, b: dict) -> bool:
    """Whether two run configs are one run's: equal, once every string that names an existing local
    path is read as the folder it names (``toy``, ``./toy`` and ``/home/me/toy`` alike)."""

    def resolved(value):
        if isinstance(value, dict):
            return {k: resolved(v) for k, v in value.items()}
        if isinstance(value, list):
            return [resolved(v) for v in value]
        if isinstance(value, str) and value and os.path.exists(value):
            return os.path.realpath(value)
        return value

    return a == b or resolved(a) == resolved(b)


class RunDir:
    """One stage's folder (a Stage I run, a policy run, or a sub-run such as ``probe/``)."""

    def __init__(self, path: str | Path):
        self.path = Path(path)

    # ---- config -----------------------------------------------------------------------------
    def read_config(self) -> dict:
        path = self.path / CONFIG
        if self.path.is_file():
            raise RunError(
                f"{self.path} is a file, not a run folder; give the folder that holds it"
                + (f" ({self.path.parent})" if self.path.name == CONFIG else "")
            )
        if not self.path.exists():
            raise RunError(f"{self.path} is not an orbitmodel run: no such folder")
        if not path.is_file():
            raise RunError(f"{self.path} is not an orbitmodel run: it has no {CONFIG}")
        try:
            return json.loads(path.read_text())
        except json.JSONDecodeError as err:
            raise RunError(f"{path} is not valid JSON ({err}); train the run again") from None

    def start(self, config: dict, resume: bool, overwrite: bool, upgrade=None, extend: bool = False) -> None:
        """Claim the folder for a run with ``config``: new, resumed, or overwritten. ``upgrade``:
        old config -> the same config as this version writes it (a resume then compares like with
        like, and the file is rewritten in the current form). ``extend`` (with ``resume``): the
        config may differ from the run's in a larger ``preset.train.loop.max_steps`` only; the run goes
        on to the new total (its schedule from the checkpoint on is the new total's, and
        training.json records each segment's ``schedule_steps``). A run cut before its first
        checkpoint holds nothing trained: it starts again from step 0, resumed or not (the caller's
        loop resumes only when :meth:`resumes`)."""
        if extend and not resume:
            raise RunError("--extend continues a run: pass --resume with it")
        blocking = next((p for p in (self.path, *self.path.parents) if p.exists()), None)
        if blocking is not None and not blocking.is_dir():
            raise RunError(f"{self.path} cannot be a run folder: {blocking} is a file; give another folder")
        existing = self.path / CONFIG
        config = json.loads(json.dumps(config))  # as it reads back (tuples become lists)
        if existing.exists() and overwrite:
            for name in OWNED:
                target = self.path / name
                if target.is_dir():
                    shutil.rmtree(target)
                elif target.exists():
                    target.unlink()
        elif existing.exists():
            old = self.read_config()
            if upgrade is not None:
                old = json.loads(json.dumps(upgrade(old)))
            same = same_config(old, config)
            if not same and not (extend and extends(old, config)):
                changed = _changed_settings(old, config)
                if extend:
                    raise RunError(
                        f"--extend: {self.path} may differ from this run in a larger --max-steps only "
                        f"(differs in: {changed}); give the run's other settings"
                    )
                keep = "give the run's own settings to continue it, " if resume else ""
                raise RunError(
                    f"{self.path} holds a run with another config (differs in: {changed}); "
                    f"{keep}pass --overwrite to replace it (its training is lost), or train into another folder"
                )
            if not resume and self.trained_any():
                raise RunError(
                    f"{self.path} already holds this run; pass --resume to continue it, or --overwrite to start again"
                )
            if resume and not self.has_checkpoint() and self.trained_any():
                raise RunError(
                    f"--resume: {self.path} holds training but no checkpoint to continue from (no "
                    f"{CHECKPOINTS}/{LATEST}); pass --overwrite to train it again"
                )
            if extend and same and (self.path / WEIGHTS).exists():
                raise RunError(
                    f"--extend: {self.path} is already trained to its --max-steps {max_steps_of(config)}; "
                    "give a larger --max-steps to train it on"
                )
        elif resume:
            raise RunError(f"--resume: {self.path} holds no run to resume; drop --resume to start one")
        elif self.path.exists() and any(p.name not in ("probe",) for p in self.path.iterdir()):
            raise RunError(f"{self.path} is not empty and not an orbitmodel run; choose another --out")
        if (
            extend
            and existing.exists()
            and (self.path / WEIGHTS).exists()
            and not same_config(self.read_config(), config)
        ):
            (self.path / WEIGHTS).unlink()  # the old end's weights (its last checkpoint keeps them): the run is
            # unfinished again until it reaches the new end
        self.path.mkdir(parents=True, exist_ok=True)
        write_json_atomic(existing, config)

    # ---- checkpoints ------------------------------------------------------------------------
    def has_checkpoint(self) -> bool:
        """Whether the run has saved a checkpoint that ``--resume`` continues from."""
        return (self.path / CHECKPOINTS / LATEST).is_file()

    def trained_any(self) -> bool:
        """Whether the run holds any training to lose: a checkpoint (pointed at or not) or its final
        weights. One cut before its first checkpoint holds none, and starts again with or without
        ``--resume``."""
        saved = self.path / CHECKPOINTS
        return self.has_checkpoint() or (self.path / WEIGHTS).exists() or any(saved.glob("step-*"))

    def resumes(self, resume: bool, overwrite: bool) -> bool:
        """Whether training continues from a checkpoint: asked for, not overwritten, and one is there.
        Every DDP rank reads the same answer: without --overwrite, :meth:`start` neither makes nor
        removes the pointer."""
        return resume and not overwrite and self.has_checkpoint()

    def save_checkpoint(self, step: int, weights: dict[str, torch.Tensor], state: dict) -> None:
        import torch
        from safetensors.torch import save_file

        root = self.path / CHECKPOINTS
        root.mkdir(exist_ok=True)
        name = f"step-{step:07d}"
        tmp = root / f".{name}.tmp"
        shutil.rmtree(tmp, ignore_errors=True)
        tmp.mkdir()
        save_file(
            {k: v.detach().contiguous().cpu() for k, v in weights.items()}, tmp / WEIGHTS, metadata={"step": str(step)}
        )
        torch.save(state, tmp / STATE)
        shutil.rmtree(root / name, ignore_errors=True)
        os.replace(tmp, root / name)
        latest = root / LATEST
        (root / f".{LATEST}.tmp").write_text(name + "\n")
        os.replace(root / f".{LATEST}.tmp", latest)
        for old in sorted(p for p in root.glob("step-*") if p.name != name)[: -(KEEP - 1) or None]:
            shutil.rmtree(old, ignore_errors=True)

    def latest_checkpoint(self) -> Checkpoint:
        import torch
        from safetensors import SafetensorError
        from safetensors.torch import load_file

        root = self.path / CHECKPOINTS
        pointer = root / LATEST
        if not pointer.is_file():
            raise RunError(f"--resume: {self.path} has no checkpoint; pass --overwrite to train it again")
        folder = root / pointer.read_text().strip()
        try:
            weights = load_file(folder / WEIGHTS)
            state = torch.load(folder / STATE, map_location="cpu", weights_only=True)
        except (OSError, SafetensorError, RuntimeError, EOFError) as err:
            raise RunError(
                f"checkpoint {folder} is corrupt ({type(err).__name__}); delete it and "
                f"point {pointer} at an older one, or start again with --overwrite"
            ) from None
        return Checkpoint(int(state["step"]), weights, state)

    def add_training_segment(self, segment: dict) -> None:
        """Record one training segment (a run and each resume of it) in training.json."""
        path = self.path / TRAINING
        done = json.loads(path.read_text())["segments"] if path.is_file() else []
        kept = [s for s in done if s["to_step"] <= segment["from_step"] and s["from_step"] != segment["from_step"]]
        write_json_atomic(path, {"segments": kept + [segment]})

    def save_final(self, weights: dict[str, torch.Tensor], step: int) -> None:
        from safetensors.torch import save_file

        tmp = self.path / f".{WEIGHTS}.tmp"
        save_file({k: v.detach().contiguous().cpu() for k, v in weights.items()}, tmp, metadata={"step": str(step)})
        os.replace(tmp, self.path / WEIGHTS)


def load_weights(path: str | Path) -> dict[str, torch.Tensor]:
    """The final weights of a run folder, else its newest checkpoint's; one clear error if corrupt."""
    from safetensors import SafetensorError
    from safetensors.torch import load_file

    run = Path(path)
    candidates = [run / WEIGHTS]
    pointer = run / CHECKPOINTS / LATEST
    if pointer.is_file():
        candidates.append(run / CHECKPOINTS / pointer.read_text().strip() / WEIGHTS)
    for file in candidates:
        if file.is_file():
            try:
                return load_file(file)
            except (OSError, SafetensorError) as err:
                raise RunError(f"{file} is corrupt or truncated ({err}); train the run again") from None
    stage = stage_of(run) if (run / CONFIG).is_file() else WORLD_MODEL
    raise RunError(f"{run} has no weights ({WEIGHTS}); train it first with `{MAKES.get(stage, MAKES[WORLD_MODEL])}`")


def fingerprint(weights: dict[str, torch.Tensor]) -> str:
    """sha256 of a state dict's names and bytes: which weights a sub-run was made from."""
    import torch

    h = hashlib.sha256()
    for name in sorted(weights):
        h.update(name.encode())
        h.update(weights[name].detach().cpu().contiguous().reshape(-1).view(torch.uint8).numpy().tobytes())
    return h.hexdigest()[:16]


def stage_of(path: str | Path) -> str:
    """The ``stage`` a run folder's config.json records ("world_model", "policy", ...)."""
    return str(RunDir(path).read_config().get("stage", "unknown"))


def upgrade_preset_config(old: dict, parse: Callable[[dict], object], builtins: Mapping[str, Callable]) -> dict:
    """A run's config.json as this version writes it, so that a run of an earlier version resumes:
    its preset re-read by ``parse`` (which fills settings added since), a built-in preset's
    description in today's wording (text, not a setting), and no validation split for a run from
    before them. A config this version cannot read comes back unchanged: the comparison with the
    new config then says what differs."""
    try:
        preset = parse(old["preset"])
        if preset.name in builtins:
            preset = replace(preset, description=builtins[preset.name]().description)
        return {
            **old,
            "preset": preset.to_dict(),
            "validation": ValidationSplit.from_dict(old.get("validation")).to_dict(),
        }
    except (KeyError, TypeError, ValueError):
        return old


class HeldOut:
    """The ``validation`` of a run config that keeps its raw config.json as ``raw``."""

    raw: dict

    @property
    def validation(self) -> ValidationSplit:
        """The train-split episodes the run held out (none for a run without a validation split)."""
        return ValidationSplit.from_dict(self.raw.get("validation"))


# ---- Stage I runs ---------------------------------------------------------------------------------
@dataclass(frozen=True)
class RunConfig(HeldOut):
    """A Stage I run's preset, dataset facts and held-out validation episodes (and the raw config.json)."""

    preset: Preset
    dataset: DatasetMeta
    raw: dict


@dataclass(frozen=True)
class Run:
    """A trained Stage I run: its config and its weights (:func:`load_run`)."""

    path: Path
    config: RunConfig
    weights: dict[str, torch.Tensor]


def read_run_config(path: str | Path) -> RunConfig:
    """A Stage I run's preset and dataset facts, from its config.json; RunError for any other run."""
    raw = RunDir(path).read_config()
    stage = raw.get("stage", WORLD_MODEL)
    if stage != WORLD_MODEL:
        raise RunError(
            f"{path} holds a {stage!r} run, not a Stage I world model; give the folder of `{MAKES[WORLD_MODEL]}`"
        )
    try:
        return RunConfig(Preset.from_dict(raw["preset"]), DatasetMeta.from_dict(raw["dataset"]), raw)
    except (KeyError, TypeError, ValueError) as err:
        raise RunError(f"{Path(path) / CONFIG} is not a Stage I run config ({err})") from None


def load_run(path: str | Path, revision: str | None = None) -> Run:
    """A trained Stage I run, a folder or a Hub repo id (:func:`resolve_run`): config and final (else
    newest checkpoint's) weights; RunError with the fix."""
    local = resolve_run(path, revision)
    return Run(local, read_run_config(local), load_weights(local))


def local_run_folder(run: str | Path, what: str) -> Path:
    """``run`` as a local folder that ``what`` may write into; RunError for a Hub repo id (its
    downloaded copy in the cache is not ours to write to)."""
    if is_hub_run(run):
        raise RunError(
            f"{run} is a Hub repo id and {what} writes into the run folder: download it first "
            f"(`hf download {str(run).split('@')[0]} --local-dir DIR`) and give DIR"
        )
    return Path(run)


def check_image_size(meta: DatasetMeta, size: int, user: str, resize: bool = False) -> None:
    """RunError unless the dataset ``meta`` holds the ``size`` px images that ``user`` (a run or a
    preset, named in the message) takes; ``resize`` names the --resize way out too."""
    if meta.image_size != size:
        raise RunError(
            f"{user} takes {size} px images but {meta.source} holds {meta.image_size} px; use a dataset "
            f"generated with `orbitdata generate DIR --image-size {size}`" + (", or pass --resize" if resize else "")
        )
