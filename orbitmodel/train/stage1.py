"""Stage I: train the world model on windows of the dataset (``orbitmodel train``)."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import torch

from orbitdata import schema as S
from orbitdata.load.index import NoWindow
from orbitmodel.config import PRESETS, Preset
from orbitmodel.data import DatasetMeta, load_model_windows, read_dataset_meta, training_episodes, validation_split
from orbitmodel.model.world_model import WorldModel
from orbitmodel.runs import WORLD_MODEL, RunDir, RunError, check_image_size, run_config, upgrade_preset_config
from orbitmodel.train.loop import FitResult, fit, resolve_device, step_generator

COLUMNS = (S.IMAGE, S.STATE, S.ACTION, S.DEPTH_LOW)
STREAM_JITTER, STREAM_SIGREG = 0, 1


def jitter(images: torch.Tensor, p: float, amount: float, generator: torch.Generator) -> torch.Tensor:
    """Upstream's photometric augmentation on (B, T, 3, H, W) floats in [0, 1]: per window, with
    probability p each, brightness x U(1-a, 1+a) and contrast about the window's mean x U(1-a, 1+a)."""
    B = len(images)
    u = torch.rand(B, 4, generator=generator)  # (B, [apply b, factor b, apply c, factor c])
    brightness = torch.where(u[:, 0] < p, 1 - amount + 2 * amount * u[:, 1], torch.ones(B))
    contrast = torch.where(u[:, 2] < p, 1 - amount + 2 * amount * u[:, 3], torch.ones(B))
    shape = (B, 1, 1, 1, 1)
    x = images * brightness.view(shape).to(images)
    mean = x.mean(dim=(1, 2, 3, 4), keepdim=True)
    return ((x - mean) * contrast.view(shape).to(images) + mean).clamp(0, 1)


class Stage1Job:
    def __init__(self, model: WorldModel, preset: Preset, rank: int = 0):
        self.module = self.saved = model
        self.train = preset.train
        self.rank = rank

    def inputs(self, batch: dict, step: int, device: torch.device) -> dict:
        t = self.train
        images = batch[S.IMAGE].float().div_(255.0)  # (B, T, 3, H, W)
        if t.jitter_p > 0:
            images = jitter(images, t.jitter_p, t.jitter, step_generator(t.loop.seed, step, STREAM_JITTER, self.rank))
        return {
            "images": images.to(device),
            "states": batch[S.STATE].to(device),
            "actions": batch[S.ACTION].to(device),
            "depth_low": batch[S.DEPTH_LOW].to(device),
            "generator": step_generator(t.loop.seed, step, STREAM_SIGREG),
        }


@dataclass(frozen=True)
class Stage1Request:
    dataset: str
    preset: Preset
    out: Path
    levels: tuple[str, ...] = ()
    outcomes: tuple[str, ...] = ()
    resize: bool = False
    device: str = "auto"
    resume: bool = False
    overwrite: bool = False


def upgrade_config(old: dict) -> dict:
    """A Stage I config.json as this version writes it (``runs.upgrade_preset_config``): a preset
    from before presets carried their probe recipe gets its named preset's (``Preset.from_dict``)."""
    return upgrade_preset_config(old, Preset.from_dict, PRESETS)


def loader_image_size(meta: DatasetMeta, preset: Preset, resize: bool) -> int | None:
    """The loader's ``image_size``: None when the dataset matches the preset, the preset's size
    when resizing; RunError otherwise."""
    want = preset.model.image_size
    if meta.image_size == want:
        return None
    if not resize:
        check_image_size(meta, want, f"preset {preset.name!r}", resize=True)
    return want


def train_world_model(req: Stage1Request, on_log=None) -> FitResult:
    """Train (or resume) a Stage I run; returns the loop's summary."""
    meta = read_dataset_meta(req.dataset)
    image_size = loader_image_size(meta, req.preset, req.resize)
    device = resolve_device(req.device)
    run = RunDir(req.out)
    t = req.preset.train
    rank = int(os.environ.get("RANK", 0))
    held_out = validation_split(req.dataset, t.val_fraction, t.val_seed)
    step = req.preset.model.frame_step
    try:
        windows = load_model_windows(
            req.dataset,
            step,
            split="train",
            context=t.window,
            horizon=0,
            stride=t.window_stride,
            image_size=image_size,
            columns=list(COLUMNS),
            episodes=training_episodes(req.dataset, req.levels, req.outcomes, held_out),
        )
    except NoWindow as err:  # in the flag's steps, with the longest window that fits
        most = err.longest // step
        raise RunError(
            f"--window {t.window}: a window of {t.window} steps of {step} frame{'s' * (step > 1)} is longer than "
            f"every training episode of {req.dataset} (longest: {err.longest} frames); give --window {most} or less"
        ) from None
    if rank == 0:
        config = run_config(
            WORLD_MODEL,
            preset=req.preset.to_dict(),
            dataset=meta.to_dict(),
            levels=list(req.levels),
            outcomes=list(req.outcomes),
            validation=held_out.to_dict(),
        )
        run.start(config, resume=req.resume, overwrite=req.overwrite, upgrade=upgrade_config)
    torch.manual_seed(t.loop.seed)  # initialisation
    model = WorldModel(req.preset.model)
    model.set_normalisation(meta.state_mean, meta.state_std, meta.depth_max)
    return fit(
        Stage1Job(model, req.preset, rank),
        windows,
        t.loop,
        run,
        device,
        resume=run.resumes(req.resume, req.overwrite),
        label="train",
        on_log=on_log,
    )
