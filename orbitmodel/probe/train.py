"""Stage II: train the probe on a frozen world model (``orbitmodel probe RUN DATASET``), or the
state-only reference MLP on the same windows (``--state-only``), with the shared training loop.

Per window of ``context + horizon`` frames (8 + 12 upstream)::

    z        = WM.encode(images[:, :m], states[:, :m])          (B, m, D)    frozen
    z_future = WM.rollout(z, actions[:, :m-1+n])                 (B, n, D)    frozen
    x_hat    = probe(z_future, states[:, m-1], z[:, -1])         (B, n, 16)
    loss     = sum_q w_q MSE(x_hat[q], states[:, m:][q])         q = p, v, rot6d, w, fuel

A world model stepping s frames counts m and n in its steps; a per-frame probe (``per_frame``:
s increments per latent) is scored on the state of every one of the n s frames. With
``increment_weight`` w > 0 the loss adds w MSE((inc_hat - inc) / scale), the per-step increments
against the true ones (``increments_of``), which scores how a step's change divides among its
frames directly rather than through every later state.

The world model stays in eval mode (BatchNorm running statistics, no dropout) with
``requires_grad`` off, so its weights and buffers end the run bit-for-bit as they started.
The probe is written to ``RUN/probe/`` (``RUN/probe-state/`` for the reference), a run folder
of its own: config.json, checkpoints/, metrics.jsonl, model.safetensors. A named variant of the
run's probe (``probe.variants``: the paper's, the thrust-only one, the latent-only candidates)
goes to ``RUN/probe-NAME/``, and reuses the latents the run's probe imagined when its windows
are the same.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from dataclasses import asdict, dataclass
from importlib.metadata import version
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn

from orbitdata import schema as S
from orbitdata.load import collate_windows
from orbitmodel.config import KINDS, ProbeRecipe, ProbeTrainConfig, reads_thrust
from orbitmodel.data import (
    FRAME_STATES,
    DatasetMeta,
    calm_windows,
    load_model_windows,
    read_dataset_meta,
    training_episodes,
)
from orbitmodel.kinematics import FUEL, ROT, P, V, W
from orbitmodel.model.world_model import WorldModel
from orbitmodel.probe.baselines import STATE_ACTION_DIM, StateDynamics
from orbitmodel.probe.cache import (
    CACHE_FILE,
    LAST,
    LATENT,
    TensorWindows,
    cache_key,
    gather,
    imagine,
    load_cache,
    save_cache,
    subset,
)
from orbitmodel.probe.config import ProbeConfig
from orbitmodel.probe.integrator import increments_of, integrate
from orbitmodel.probe.model import PhysicsProbe, probe_folder
from orbitmodel.probe.variants import FLOWN, check_variant
from orbitmodel.runs import (
    CONFIG,
    PROBE,
    RunDir,
    RunError,
    check_image_size,
    local_run_folder,
    read_run_config,
    resolve_run,
    run_config,
)
from orbitmodel.train.loop import FitResult, fit, resolve_device

COLUMNS = {"latent": (S.IMAGE, S.STATE, S.ACTION), "state": (S.STATE, S.ACTION)}
PARTS = ("pos", "vel", "rot", "w", "fuel")
SLICES = (P, V, ROT, W, FUEL)


def state_loss(pred: torch.Tensor, target: torch.Tensor, weights) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """Weighted MSE per quantity over states (B, n, 16): upstream's ProberLoss."""
    parts = {name: F.mse_loss(pred[..., s], target[..., s].float()) for name, s in zip(PARTS, SLICES)}
    total = sum(w * parts[name] for w, name in zip(weights, PARTS))
    return total, {k: v.detach() for k, v in parts.items()}


class LatentObjective(nn.Module):
    """Frozen world model + trainable probe -> the Stage II loss."""

    def __init__(self, world_model: WorldModel, probe: PhysicsProbe, train: ProbeTrainConfig):
        super().__init__()
        self.world_model = world_model.requires_grad_(False).eval()
        self.probe = probe
        self.context, self.weights, self.increment_weight = train.context, train.weights, train.increment_weight
        self.frames = probe.config.substeps  # states per latent step: 1, or every frame of it

    def train(self, mode: bool = True) -> "LatentObjective":
        """Only the probe follows train/eval; the world model stays in eval (BatchNorm, dropout)."""
        super().train(mode)
        self.world_model.eval()
        return self

    def forward(self, states, actions, images=None, z_future=None, z_last=None, frame_states=None):
        """states (B, m+n, 16); actions (B, m+n, 8); either images (B, m, 3, H, W) uint8 of the
        context, or the latents the world model imagined for this window (B, n, D) with the
        last context latent (B, D); a per-frame probe of a world model stepping s frames also
        needs frame_states (B, (m+n) s, 16), the window's state at every frame."""
        m, s = self.context, self.frames
        if z_future is None:
            with torch.no_grad():
                z = self.world_model.encode(images, states[:, :m])  # (B, m, D)
                z_future = self.world_model.rollout(z, actions[:, :-1])  # (B, n, D)
                z_last = z[:, -1]  # (B, D)
        taken = actions[:, m - 1 : -1].float()  # (B, n, 8 s): the action that led to each imagined latent
        c = self.probe.config
        inc = self.probe.step_increments(z_future.float(), None if z_last is None else z_last.float(), taken)
        pred = integrate(states[:, m - 1], inc, c.dt, c.coasting)  # (B, n s, 16)
        target = states[:, m:] if s == 1 else frame_states[:, (m - 1) * s + 1 : (m - 1) * s + 1 + pred.shape[1]]
        loss, parts = state_loss(pred, target, self.weights)
        if self.increment_weight:
            true_inc = increments_of(torch.cat([states[:, m - 1 : m], target], 1).float(), c.dt, c.coasting)
            scale = self.probe.increments.scale
            parts["increments"] = F.mse_loss(inc / scale, true_inc / scale)
            loss = loss + self.increment_weight * parts["increments"]
            parts["increments"] = parts["increments"].detach()
        return loss, parts


class StateObjective(nn.Module):
    """The state-only reference on the same windows: rolled out from the same state, same loss."""

    def __init__(self, model: StateDynamics, train: ProbeTrainConfig):
        super().__init__()
        self.model = model
        self.context, self.weights = train.context, train.weights

    def forward(self, states, actions):
        m = self.context
        pred = self.model(states[:, m - 1], actions[:, m - 1 : -1])  # (B, n, 16)
        return state_loss(pred, states[:, m:], self.weights)


class ProbeJob:
    def __init__(self, module: nn.Module, saved: nn.Module, kind: str, context: int):
        self.module, self.saved, self.kind, self.context = module, saved, kind, context

    def inputs(self, batch: dict, step: int, device: torch.device) -> dict:
        out = {"states": batch[S.STATE].to(device), "actions": batch[S.ACTION].to(device)}
        if FRAME_STATES in batch:
            out["frame_states"] = batch[FRAME_STATES].to(device)
        if LATENT in batch:
            out["z_future"] = batch[LATENT].to(device)
            out["z_last"] = batch[LAST].to(device)
        elif self.kind == "latent":
            out["images"] = batch[S.IMAGE][:, : self.context].to(device)  # only the context frames are seen
        return out


@dataclass(frozen=True)
class ProbeRequest:
    run: Path  # the Stage I run folder
    dataset: str
    recipe: ProbeRecipe  # the run's preset's (``run_recipe``), with any changes the command asked for
    kind: str = "latent"
    device: str = "auto"
    resume: bool = False
    overwrite: bool = False
    variant: str = FLOWN  # which of the run's probes (``probe.variants``); the recipe is already the variant's


def load_stage1(run: str | Path, meta: DatasetMeta | None = None) -> WorldModel:
    """A Stage I run's world model, frozen, in eval mode, on CPU (``WorldModel.from_pretrained``:
    ``.run`` its config, ``.fingerprint`` its weights'); RunError with the fix when the run is
    missing or untrained, or when the dataset ``meta`` does not give the images it takes."""
    run = resolve_run(run)  # a folder, or a Hub repo id downloaded once
    if meta is not None:  # before loading weights that may not fit this dataset's images
        config = read_run_config(run)
        check_image_size(
            meta, config.preset.model.image_size, f"the world model of {run} (trained on {config.dataset.source})"
        )
    return WorldModel.from_pretrained(run).requires_grad_(False)


def run_recipe(run: str | Path) -> ProbeRecipe:
    """The probe recipe a Stage I run's preset prescribes (``Preset.probe``)."""
    return read_run_config(run).preset.probe


def trained_recipe(run: str | Path) -> ProbeRecipe:
    """The recipe the run's probe (``RUN/probe``) was trained with, flags included; the preset's
    when it has none yet. A variant of the run's probe (``probe.variants``) changes this one, so
    that it differs from the probe it stands beside only in what the variant names."""
    path = probe_folder(run, "latent") / CONFIG
    if not path.is_file():
        return run_recipe(run)
    raw = upgrade_probe_config(json.loads(path.read_text()))
    p = raw["probe"]
    return ProbeRecipe(
        inputs=p["inputs"],
        integrator=p["integrator"],
        hidden=p["hidden"],
        layers=p["layers"],
        per_frame=p["substeps"] > 1,
        train=ProbeTrainConfig.from_dict(raw["train"]),
    )


def training_pool(windows, train: ProbeTrainConfig) -> Sequence[int]:
    """The training windows a probe draws from (its cache and its output scale): every one, or
    those whose body rate stays at or below ``max_body_rate`` when it is set."""
    if not train.max_body_rate:
        return range(len(windows))
    calm = calm_windows(windows, train.max_body_rate)
    if not calm:
        raise RunError(
            f"--max-body-rate {train.max_body_rate:g}: no training window stays at or below that body rate "
            "(rad/s); give a larger rate, or 0 for every window"
        )
    return calm


def increment_scale(
    dataset: str,
    train: ProbeTrainConfig,
    config: ProbeConfig,
    pool: Sequence[int],
    frame_step: int = 1,
    episodes=None,
) -> torch.Tensor:
    """RMS (10,) of the true per-step increments over up to ``scale_windows`` of the training
    windows ``pool`` (:func:`training_pool`: indices into windows of the same context, horizon,
    stride and episodes; a seeded draw), the probe's output units; a step is
    ``frame_step`` frames, or one frame for a per-frame probe (``config.substeps == frame_step``)."""
    per_frame = config.substeps > 1
    windows = load_model_windows(
        dataset,
        frame_step,
        split="train",
        context=train.context,
        horizon=train.horizon,
        stride=train.window_stride,
        columns=[S.STATE],
        episodes=episodes,
        frame_states=per_frame,
    )
    g = torch.Generator().manual_seed(train.loop.seed)
    chosen = [pool[i] for i in torch.randperm(len(pool), generator=g)[: train.scale_windows].tolist()]
    states = collate_windows(windows.__getitems__(chosen))[FRAME_STATES if per_frame else S.STATE]  # (N, T, 16)
    inc = increments_of(states, config.dt, config.coasting)  # (N, T-1, 10)
    return inc.flatten(0, 1).pow(2).mean(0).sqrt()  # (10,)


def imagined(
    world_model,
    windows,
    chosen,
    req: ProbeRequest,
    wm_print: str,
    meta: DatasetMeta,
    device,
    folder: Path,
    held_out: tuple[int, ...] = (),
) -> dict:
    """The latents of the chosen windows: from the probe folder when it holds exactly these (or from
    the run's own probe folder, for a variant on the same windows), else imagined."""
    # The rollout depends on the weights, the model's config (its history) and the code that
    # rolls out: a new release (orbitmodel ships in the orbitdata distribution) imagines again,
    # and so does --overwrite.
    t = req.recipe.train

    def key(frame_states: bool) -> str:
        return cache_key(
            world_model=wm_print,
            config=asdict(world_model.config),
            package=version("orbitdata"),
            dataset=meta.to_dict(),
            windows=chosen,
            context=t.context,
            horizon=t.horizon,
            stride=t.window_stride,
            **({"held_out": list(held_out)} if held_out else {}),
            **({"frame_states": True} if frame_states else {}),
        )

    per_frame = getattr(windows, "frame_states", False)
    own = key(per_frame)
    # a probe scored on model steps can train on latents cached with every frame's states too
    usable = [own] if per_frame else [own, key(True)]
    # --overwrite imagines again: the flown probe's cache may come from other model code
    folders = (folder,) if req.overwrite else dict.fromkeys((folder, probe_folder(req.run, "latent")))
    cached = next((c for f in folders for k in usable if (c := load_cache(f, k)) is not None), None)
    if cached is not None and not per_frame:
        cached.pop(FRAME_STATES, None)
    if cached is None:
        cached = imagine(world_model.to(device), windows, chosen, t.context, device)
        save_cache(folder, own, cached)
    return cached


def upgrade_probe_config(old: dict) -> dict:
    """A probe run's config.json from before per-frame heads, thrust inputs, the increment loss and
    the nested loop settings, as this version writes it (the defaults it trained with), so such a
    run resumes. A config this version cannot read comes back unchanged: the comparison with the
    new config then says what differs."""
    probe = {"substeps": 1, "action_dim": 0, **old.get("probe", {})}
    train = {"increment_weight": 0.0, **old.get("train", {})}
    try:
        train = ProbeTrainConfig.from_dict(train).to_dict()
    except (TypeError, ValueError):
        pass
    return {**old, "probe": probe, "train": train}


def probe_config(recipe: ProbeRecipe, kind: str, latent_dim: int, frame_step: int) -> ProbeConfig:
    """The probe network of ``kind`` that ``recipe`` prescribes for a world model with latents of
    ``latent_dim`` stepping ``frame_step`` frames (the state-only reference reads state and action);
    a per-frame recipe predicts each of the ``frame_step`` frames of a latent step."""
    latent = kind == "latent"
    substeps = frame_step if latent and recipe.per_frame else 1
    return ProbeConfig(
        kind=kind,
        latent_dim=latent_dim if latent else STATE_ACTION_DIM,
        hidden=recipe.hidden,
        layers=recipe.layers,
        dt=S.DT * frame_step / substeps,
        inputs=recipe.inputs if latent else "latent",
        integrator=recipe.integrator,
        substeps=substeps,
        action_dim=S.ACTION_DIM * frame_step if latent and reads_thrust(recipe.inputs) else 0,
    )


def train_probe(req: ProbeRequest, on_log=None) -> FitResult:
    """Train (or resume) the probe of a Stage I run; returns the loop's summary."""
    if req.kind not in KINDS:
        raise ValueError(f"probe kind {req.kind!r}: choose one of {', '.join(KINDS)}")
    if req.kind != "latent" and check_variant(req.variant) != FLOWN:
        raise ValueError(f"variant {req.variant}: the state-only reference has no variants; drop one of them")
    local_run_folder(req.run, "training a probe")
    meta = read_dataset_meta(req.dataset)
    world_model = load_stage1(req.run, meta)
    stage1, wm_print = world_model.run, world_model.fingerprint
    device = resolve_device(req.device)
    t = req.recipe.train
    latent = req.kind == "latent"
    frame_step = stage1.preset.model.frame_step
    if not latent and frame_step > 1:
        raise RunError(
            f"{req.run} steps {frame_step} frames per prediction; the state-only reference reads "
            "one frame's state and action, so train it on a per-frame run (`orbitmodel train` "
            "without --frame-step)"
        )
    if not latent and t.increment_weight:
        raise RunError(
            f"--increment-weight {t.increment_weight:g}: the state-only reference is scored on its states "
            "only; pass --increment-weight 0 with --state-only"
        )
    config = probe_config(req.recipe, req.kind, stage1.preset.model.latent_dim, frame_step)
    episodes = training_episodes(req.dataset, (), (), stage1.validation)  # the run's validation episodes stay out
    windows = load_model_windows(
        req.dataset,
        frame_step,
        split="train",
        context=t.context,
        horizon=t.horizon,
        stride=t.window_stride,
        columns=list(COLUMNS[req.kind]),
        episodes=episodes,
        frame_states=config.substeps > 1,
    )
    pool = training_pool(windows, t)  # refused before anything is written
    out = probe_folder(req.run, req.kind, req.variant)
    if req.overwrite:
        # The cache is keyed on the Stage I weights, not on the code that rolled them out: starting
        # again must not reuse latents imagined by another version of the model code.
        (out / CACHE_FILE).unlink(missing_ok=True)
    run = RunDir(out)
    parts = {"probe": config.to_dict(), "train": t.to_dict(), "dataset": meta.to_dict(), "stage1_run": str(req.run)}
    if latent:
        parts["world_model"] = wm_print  # a probe reads one world model's latents only
    if req.variant != FLOWN:
        parts["variant"] = req.variant
    run.start(run_config(PROBE, **parts), resume=req.resume, overwrite=req.overwrite, upgrade=upgrade_probe_config)
    resume = run.resumes(req.resume, req.overwrite)  # a probe cut before its first checkpoint starts again
    data = windows
    if t.cache_windows:
        chosen = [pool[i] for i in subset(len(pool), t.cache_windows, t.loop.seed)]
        if latent:
            data = TensorWindows(
                imagined(world_model, windows, chosen, req, wm_print, meta, device, out, stage1.validation.episodes)
            )
        else:
            data = TensorWindows(gather(windows, chosen, (S.STATE, S.ACTION)))
    torch.manual_seed(t.loop.seed)  # initialisation
    if latent:
        model = PhysicsProbe(config)
        module = LatentObjective(world_model, model, t)
    else:
        model = StateDynamics(config)
        model.set_state_stats(stage1.dataset.state_mean, stage1.dataset.state_std)
        module = StateObjective(model, t)
    if not resume:
        model.increments.set_scale(increment_scale(req.dataset, t, config, pool, frame_step, episodes))
        if latent and config.reads_thrust:
            model.set_thrust_stats(meta.action_mean, meta.action_std)
    job = ProbeJob(module, model, req.kind, t.context)
    return fit(job, data, t.loop, run, device, resume=resume, label="probe" if latent else "state-only", on_log=on_log)
