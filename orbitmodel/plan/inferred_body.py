"""A body inferred from the pilot's history under a prior learned from the tier's episodes.

The fitted body (``plan.fitted_body``) solves for the thrust response ``B`` (9, 6) by ridge
regression on the pilot's last frames, with the design's body as its only prior. It knows
nothing of how the tier draws bodies and faults: that one thruster fails (off, weak or stuck),
the centre of mass moves a little, the mass and inertia scatter around the design. Short or
dull histories (a few frames, thrust patterns the history never excited) leave the fit at the
design's body in those directions.

:class:`BodyInference` learns that prior from the tier's training episodes. It reads the same
history as the fit, as the regression's sufficient statistics (the normalised Gram matrix
``X^T X / n``, the cross moments ``X^T Y / n``, the ridge solution itself, the history's length
and the fuel left), gives a prior response and a weight per thrust row, and solves the ridge
regression under that prior: a long, rich history outweighs it and the inference tends to the
fit. It is trained to predict the summed frame changes of the next ``ahead`` frames from the
thrusts flown in them (:func:`train_inference`), on random cuts of the run's training episodes,
never its held-out validation episodes. ``orbitmodel body RUN DATASET`` trains it into
``RUN/body``; ``--set body=inferred`` flies it. It reads the pilot's states and thrusts, not the
world model's latents.
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch
from safetensors.torch import load_file, save_file
from torch import nn

from orbitdata.sim.config import SimConfig
from orbitmodel.kinematics import FUEL, W
from orbitmodel.plan.body_recipe import InferenceConfig
from orbitmodel.plan.fitted_body import FittedBodyDynamics, frame_changes, moments, nominal_response, ridge_solve
from orbitmodel.plan.timing import Timings

FOLDER = "body"  # RUN/body: the trained inference
WEIGHTS, CARD = "model.safetensors", "config.json"  # as every sub-run (``orbitmodel push`` publishes them)
N_FEATURES = 45 + 54 + 54 + 2  # upper Gram, cross moments, ridge solution's offset, log length, fuel


class BodyInference(nn.Module):
    """A prior over the body, inferred from the history, and the least-squares fit under it.

    From the history's statistics (N_FEATURES) the network gives a prior response ``B0`` (9, 6)
    and a precision per thrust row ``lam`` (9,); the response is the ridge solution under that
    prior, ``(X^T X + diag(lam))^-1 (X^T Y + diag(lam) B0)``. A long, rich history outweighs the
    prior, so the inference tends to the fit; a short one leans on what the tier's bodies are
    like. Corrections are in units of each change's spread ``scale`` (6,) per thrust unit."""

    def __init__(self, width: int = 256):
        super().__init__()
        self.net = nn.Sequential(
            nn.Linear(N_FEATURES, width), nn.GELU(), nn.Linear(width, width), nn.GELU(), nn.Linear(width, 54 + 9)
        )
        nn.init.zeros_(self.net[-1].weight)
        nn.init.zeros_(self.net[-1].bias)
        self.register_buffer("scale", torch.ones(6))
        self.register_buffer("action_scale", torch.ones(9))

    def forward(self, gram, cross, ridge_b, prior, n, fuel):
        """gram (N, 9, 9), cross (N, 9, 6) (means over the history), ridge_b and prior (N, 9, 6),
        n and fuel (N,) -> B (N, 9, 6)."""
        a = self.action_scale
        g = (gram / (a[:, None] * a[None, :]))[:, *torch.triu_indices(9, 9)]
        c = cross / (a[:, None] * self.scale)
        offset = (ridge_b - prior) * a[:, None] / self.scale
        x = torch.cat([g, c.flatten(1), offset.flatten(1), torch.log1p(n)[:, None], fuel[:, None]], -1)
        out = self.net(x)
        B0 = prior + out[:, :54].view(-1, 9, 6) * self.scale / a[:, None]
        lam = nn.functional.softplus(out[:, 54:]) * a**2  # (N, 9): precision in thrust units squared
        count = n.clamp(min=1)[:, None, None].double()
        lhs = (gram.double() * count) + torch.diag_embed(lam.double())
        rhs = (cross.double() * count) + lam.double()[:, :, None] * B0.double()
        return torch.linalg.solve(lhs, rhs).float()


def statistics(X: torch.Tensor, Y: torch.Tensor, n: torch.Tensor, prior: torch.Tensor, ridge: float):
    """Sums X^T X (N, 9, 9) and X^T Y (N, 9, 6) over n (N,) frames -> their means and the ridge
    solution pulled towards ``prior`` (N, 9, 6) (``fitted_body.fit_response``, batched)."""
    d = n.clamp(min=1)[:, None, None]
    return X / d, Y / d, ridge_solve(X, Y, prior, ridge)


class InferredBodyDynamics(FittedBodyDynamics):
    """The fitted body's rollout with the response :class:`BodyInference` infers from the same
    history: the last ``frames`` frames (at most, and by default, the ``frames`` it was trained
    on), and the ridge it was trained with."""

    def __init__(
        self,
        inference: BodyInference,
        config: InferenceConfig,
        sim: SimConfig = SimConfig(),
        substeps: int = 1,
        timings: Timings | None = None,
        frames: int | None = None,
    ):
        frames = config.frames if frames is None else int(frames)
        if not 1 <= frames <= config.frames:
            raise ValueError(
                f"fit_frames={frames}: the prior was trained on histories of 1 to {config.frames} frames; "
                f"pass --set fit_frames={config.frames} or fewer"
            )
        super().__init__(sim, substeps, timings, frames, config.ridge)
        self.inference = inference.eval()

    @torch.inference_mode()
    def response(self) -> torch.Tensor:
        states, actions, prior = self.history()
        gram, cross = moments(states, actions)
        count = torch.tensor([float(len(actions))])
        g, c, B = statistics(gram[None].float(), cross[None].float(), count, prior[None], self.ridge)
        return self.inference(g, c, B, prior[None], count, states[-1:, FUEL][:, 0])[0]


class Cuts:
    """The training episodes' frames for random cuts: X (thrusts and a one), Y (frame changes),
    prefix sums of their products, and each frame's fuel."""

    def __init__(self, episodes: list[tuple[np.ndarray, np.ndarray]], sim: SimConfig, config: InferenceConfig):
        self.config = config
        xs, ys, fuels, spans, valid = [], [], [], [], []
        offset = 0
        for states, actions in episodes:
            s = torch.from_numpy(states).double()
            L = len(states) - 1  # frame changes
            if L < config.ahead + 1:
                continue
            X = torch.cat([torch.from_numpy(actions[:L]).double(), torch.ones(L, 1, dtype=torch.float64)], -1)
            xs.append(X)
            ys.append(frame_changes(s))
            fuels.append(s[:L, FUEL][:, 0].float())
            spans.append((offset, offset + L))
            calm = s[: L - config.ahead + 1, W].abs().amax(-1) <= config.max_rate
            valid.append(offset + torch.nonzero(calm)[:, 0])  # cuts with `ahead` frames after, turning slowly
            offset += L + 1  # one padding row between episodes keeps the prefix sums apart
            xs.append(torch.zeros(1, 9, dtype=torch.float64))
            ys.append(torch.zeros(1, 6, dtype=torch.float64))
            fuels.append(torch.zeros(1))
        if not valid or not sum(map(len, valid)):
            raise ValueError(
                f"no episode has {config.ahead + 1} frames or more with the body turning at most "
                f"{config.max_rate} rad/s at the cut: pass the dynamic-tier dataset the run was trained on"
            )
        self.X, self.Y, self.fuel = torch.cat(xs), torch.cat(ys), torch.cat(fuels)
        self.cuts = torch.cat(valid)
        self.episode_start = torch.zeros(len(self.X), dtype=torch.long)
        for start, end in spans:
            self.episode_start[start:end] = start
        XX = self.X[:, :, None] * self.X[:, None, :]
        XY = self.X[:, :, None] * self.Y[:, None, :]
        self.PXX = torch.cat([torch.zeros(1, 9, 9, dtype=torch.float64), XX.cumsum(0)])
        self.PXY = torch.cat([torch.zeros(1, 9, 6, dtype=torch.float64), XY.cumsum(0)])
        self.scale = self.Y[self.cuts].float().std(0).clamp(min=1e-8)
        self.action_scale = self.X[self.cuts].float().abs().mean(0).clamp(min=1e-3)
        # the design's body at every whole percent of fuel (a flight computes its own exactly; the
        # two differ by about 1e-4 of the response)
        self.priors = torch.stack([nominal_response(sim, float(f)) for f in torch.linspace(0, 1, 101)])

    def prior(self, fuel: torch.Tensor) -> torch.Tensor:
        """(N,) fuel ratios -> the design's response (N, 9, 6) at the nearest whole percent."""
        return self.priors[(fuel.clamp(0, 1) * 100).round().long()]

    def sample(self, gen: torch.Generator, size: int):
        """``size`` random cuts (:meth:`at`), each with a random history of 0 to ``frames`` frames."""
        t = self.cuts[torch.randint(len(self.cuts), (size,), generator=gen)]
        room = t - self.episode_start[t]
        return self.at(t, torch.minimum(torch.randint(self.config.frames + 1, (size,), generator=gen), room))

    def at(self, t: torch.Tensor, n: torch.Tensor):
        """The cuts before rows ``t`` (N,) with ``n`` (N,) frames of history: the inference's inputs
        (the history's statistics, the prior, the length and the fuel), and the thrusts X and
        changes Y of the next ``ahead`` frames."""
        gram, cross = self.PXX[t] - self.PXX[t - n], self.PXY[t] - self.PXY[t - n]
        fuel = self.fuel[t]
        prior = self.prior(fuel)
        g, c, B = statistics(gram.float(), cross.float(), n.float(), prior, self.config.ridge)
        span = t[:, None] + torch.arange(self.config.ahead)
        return (g, c, B, prior, n.float(), fuel), self.X[span].float(), self.Y[span].float()


def prediction_error(B: torch.Tensor, X: torch.Tensor, Y: torch.Tensor, scale: torch.Tensor) -> torch.Tensor:
    """Mean squared error of the summed changes over the first 1, 2, ... ``ahead`` frames (what a
    rollout integrates), X @ B against Y, in units of each change's spread times the frames summed."""
    drift = ((X @ B) - Y).cumsum(1) / scale  # (N, ahead, 6)
    return (drift / torch.arange(1, X.shape[1] + 1)[:, None]).pow(2).mean()


def train_inference(train: Cuts, held: Cuts, config: InferenceConfig, log=print) -> tuple[BodyInference, dict]:
    """AdamW on the training cuts; the held-out cuts (a fixed draw of 4096) scored before and after."""
    with torch.random.fork_rng():  # the initial weights from the seed, the caller's generator untouched
        torch.manual_seed(config.seed)
        model = BodyInference(config.width)
    model.scale.copy_(train.scale)
    model.action_scale.copy_(train.action_scale)
    opt = torch.optim.AdamW(model.parameters(), lr=config.lr, weight_decay=1e-4)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, config.steps)
    gen = torch.Generator().manual_seed(config.seed)
    held_batch = held.sample(torch.Generator().manual_seed(config.seed + 1), 4096)

    def held_error() -> tuple[float, float]:
        with torch.no_grad():
            inputs, X, Y = held_batch
            return (
                float(prediction_error(inputs[2], X, Y, train.scale)),
                float(prediction_error(model(*inputs), X, Y, train.scale)),
            )

    ridge0, _ = held_error()
    for step in range(config.steps):
        inputs, X, Y = train.sample(gen, config.batch)
        loss = prediction_error(model(*inputs), X, Y, train.scale)
        opt.zero_grad()
        loss.backward()
        opt.step()
        sched.step()
        if step % 500 == 0 or step == config.steps - 1:
            log(f"step {step}: train {loss.item():.4f}, held-out {held_error()[1]:.4f} (ridge fit {ridge0:.4f})")
    ridge_err, inferred_err = held_error()
    return model.eval(), {"held_out_cuts": 4096, "ridge_error": ridge_err, "inferred_error": inferred_err}


def save_inference(run: Path, model: BodyInference, config: InferenceConfig, card: dict) -> Path:
    folder = Path(run) / FOLDER
    folder.mkdir(parents=True, exist_ok=True)
    save_file({k: v.contiguous() for k, v in model.state_dict().items()}, folder / WEIGHTS)
    (folder / CARD).write_text(json.dumps({"config": asdict(config), **card}, indent=1) + "\n")
    return folder


def load_inference(run: Path) -> tuple[BodyInference, InferenceConfig]:
    """RUN/body's inference and its config; FileNotFoundError with the command that makes it."""
    folder = Path(run) / FOLDER
    if not (folder / WEIGHTS).is_file():
        raise FileNotFoundError(
            f"{run} has no inferred body ({folder / WEIGHTS} is missing); train one with `orbitmodel body {run} DATASET`"
        )
    card = json.loads((folder / CARD).read_text())
    config = InferenceConfig(**card["config"])
    model = BodyInference(config.width)
    model.load_state_dict(load_file(folder / WEIGHTS))
    return model.eval(), config


def flown_episodes(dataset: str, episodes: list[int] | None = None) -> dict[int, tuple[np.ndarray, np.ndarray, bool]]:
    """{episode: (states (L, 16), actions (L, 8), faulty)} of the train split (``episodes``: only these)."""
    import pyarrow as pa
    import pyarrow.compute as pc

    from orbitdata import schema as S
    from orbitdata.load.tables import load_episode_table, load_steps

    table = load_episode_table(dataset, "train", {})
    faults = table.column("fault").to_pylist() if "fault" in table.column_names else [None] * table.num_rows
    fault = dict(
        zip(table.column(S.EPISODE_INDEX).to_pylist(), (f is not None and f["kind"] != "none" for f in faults))
    )
    steps = load_steps(dataset, "train", False, {}).select_columns([S.EPISODE_INDEX, S.STATE, S.ACTION])
    rows = steps.with_format("arrow")[:]
    if episodes is not None:
        rows = rows.filter(pc.is_in(rows.column(S.EPISODE_INDEX), value_set=pa.array(episodes, pa.int32())))
    index = rows.column(S.EPISODE_INDEX).to_numpy()
    states = np.stack(rows.column(S.STATE).to_numpy(zero_copy_only=False)).astype(np.float32)
    actions = np.stack(rows.column(S.ACTION).to_numpy(zero_copy_only=False)).astype(np.float32)
    bounds = np.flatnonzero(np.diff(index)) + 1  # rows are ordered by (episode, frame)
    out = {}
    for lo, hi in zip(np.r_[0, bounds], np.r_[bounds, len(index)]):
        e = int(index[lo])
        out[e] = (states[lo:hi], actions[lo:hi], fault[e])
    return out


def fit_body(
    run: Path, dataset: str, config: InferenceConfig = InferenceConfig(), overwrite: bool = False, log=print
) -> dict:
    """Train :class:`BodyInference` on ``dataset``'s train-split episodes that ``run`` trained on
    (its held-out validation episodes are scored, never trained on) and save it in RUN/body."""
    from orbitdata import schema as S
    from orbitdata.load import read_meta
    from orbitmodel.runs import read_run_config

    run = Path(run)
    tier = read_meta(dataset)[0].tier
    if tier != S.DYNAMIC_TIER:
        raise ValueError(
            f"{dataset} is a {tier}-tier dataset: its episodes share one body and no thruster fails, so there is no "
            "body to infer; pass a dataset made with `orbitdata generate --tier dynamic` and a run trained on it"
        )
    if (run / FOLDER / WEIGHTS).exists() and not overwrite:
        raise FileExistsError(f"{run / FOLDER} already holds an inferred body; pass --overwrite to train it again")
    held = set(read_run_config(run).validation.episodes)
    if not held:
        raise ValueError(
            f"{run} holds out no validation episodes to score the inference on; train the run with "
            "`orbitmodel train --val-fraction 0.05` (the cpu-step5 presets hold 5 % out)"
        )
    flown = flown_episodes(dataset)
    if not held <= flown.keys():
        raise ValueError(
            f"{dataset} lacks {len(held - flown.keys())} of {run}'s held-out episodes: pass the dataset the run was trained on"
        )
    sim = SimConfig(render=False)
    training = [(s, a) for e, (s, a, _) in sorted(flown.items()) if e not in held]
    train = Cuts(training, sim, config)
    scored = Cuts([(s, a) for e, (s, a, _) in sorted(flown.items()) if e in held], sim, config)
    log(f"{len(training)} training episodes ({len(train.cuts)} cuts), {len(held)} held out")
    began = time.monotonic()
    model, card = train_inference(train, scored, config, log)
    card.update(
        dataset=str(dataset),
        training_episodes=len(training),
        held_out_episodes=len(held),
        train_seconds=round(time.monotonic() - began, 1),
    )
    save_inference(run, model, config, card)
    return card
