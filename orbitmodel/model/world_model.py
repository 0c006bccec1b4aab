"""The Stage I latent world model: encode (image, state) to z_t, predict z_{t+1} from z_{<=t}
and a_{<=t}, and read a coarse depth map from the image's patch tokens.

    z_t   = BN(Linear([ViT_cls(o_t), StateMLP(s_t)]))                    (B, T, D)
    c_t   = ActionMLP(a_t)                                               (B, T, D)
    ẑ_t+1 = z_t + BN(Linear(Predictor(z_<=t, c_<=t)))   causal, AdaLN-Zero (B, T, D)
    d_t   = DepthMLP(ViT_patches(o_t))               16x16, metres

The BatchNorms undo the transformers' final LayerNorms so that SIGReg can shape the latents.

One change from upstream, which predicts z_{t+1} outright: the predictor predicts the change
z_{t+1} - z_t, and its BatchNorm's scale starts at zero, so an untrained model is exactly the
persistence baseline z_{t+1} = z_t. At 25 Hz consecutive latents differ by a few per cent of
their spread, and predicting them outright spends most of a short CPU run re-learning z_t.
States and actions are normalised inside the model (from the dataset's ``meta/stats.json``),
so callers pass raw dataset values.
"""

from __future__ import annotations

import copy
import math
from pathlib import Path

import torch
import torch.nn.functional as F
from torch import nn

from orbitdata.schema import DEPTH_LOW_SIDE
from orbitmodel.config import ModelConfig
from orbitmodel.model.normalise import NormalisedStates
from orbitmodel.model.predictor import Predictor
from orbitmodel.model.sigreg import sigreg
from orbitmodel.model.vit import ViT
from orbitmodel.runs import RunError, fingerprint, load_run


def mlp(dims: tuple[int, ...]) -> nn.Sequential:
    """Linear layers with GELU between them."""
    layers: list[nn.Module] = []
    for i, (a, b) in enumerate(zip(dims[:-1], dims[1:])):
        layers += [nn.Linear(a, b)] + ([nn.GELU()] if i < len(dims) - 2 else [])
    return nn.Sequential(*layers)


class LinearBN(nn.Module):
    """Linear + BatchNorm1d over every (batch, time) sample."""

    def __init__(self, d_in: int, d_out: int):
        super().__init__()
        self.linear = nn.Linear(d_in, d_out)
        self.bn = nn.BatchNorm1d(d_out)

    def forward(self, x: torch.Tensor) -> torch.Tensor:  # (..., d_in) -> (..., d_out)
        y = self.linear(x)
        return self.bn(y.reshape(-1, y.shape[-1])).reshape(y.shape)


class DepthHead(nn.Module):
    """Per-patch-token MLP giving the 16x16 depth grid (normalised units; the model scales it).

    With a g x g patch grid and g < 16, each token gives a (16/g)^2 block of cells (pixel
    shuffle); with g > 16 the g x g map is area-pooled to 16x16.
    """

    def __init__(self, config: ModelConfig):
        super().__init__()
        self.grid = config.grid
        self.up = max(DEPTH_LOW_SIDE // self.grid, 1)
        self.net = mlp((config.width, config.depth_hidden, self.up * self.up))

    def forward(self, patches: torch.Tensor) -> torch.Tensor:  # (B, g*g, width) -> (B, 16, 16)
        B, g, u = len(patches), self.grid, self.up
        cells = self.net(patches).view(B, g, g, u, u).permute(0, 1, 3, 2, 4).reshape(B, g * u, g * u)
        if g * u != DEPTH_LOW_SIDE:
            cells = F.adaptive_avg_pool2d(cells.unsqueeze(1), DEPTH_LOW_SIDE).squeeze(1)
        return cells


def bfloat16_is_native() -> bool:
    """Whether this CPU multiplies bfloat16 natively (AVX-512 BF16 or AMX tiles). Elsewhere PyTorch
    emulates it, and a bfloat16 rollout (:meth:`WorldModel.bfloat16_rollout`) can be slower than float32."""
    checks = ("_is_avx512_bf16_supported", "_is_amx_tile_supported")  # torch.cpu's probes of the CPU's flags
    return any(getattr(torch.cpu, name, lambda: False)() for name in checks)


def images_to_float(images: torch.Tensor) -> torch.Tensor:
    """uint8 (..., 3, H, W) -> float in [0, 1]; float input is taken as already scaled."""
    return images.float() / 255.0 if images.dtype == torch.uint8 else images.float()


class WorldModel(NormalisedStates, nn.Module):
    """Orbit-Planner's Stage I model. Build it from a :class:`ModelConfig`, or load a trained one
    with :meth:`from_pretrained`. Inference methods expect ``model.eval()`` (BatchNorm running
    statistics); wrap them in ``torch.no_grad()`` unless you need gradients.
    """

    def __init__(self, config: ModelConfig):
        super().__init__()
        c = self.config = config
        self.encoder = ViT(c)
        self.state_encoder = mlp((c.state_dim, c.state_hidden, c.state_embed))
        self.projector = LinearBN(c.width + c.state_embed, c.latent_dim)
        self.action_encoder = mlp((c.step_action_dim, c.action_hidden, c.latent_dim))
        self.predictor = Predictor(c)
        self.pred_projector = LinearBN(c.latent_dim, c.latent_dim)
        self.depth_head = DepthHead(c)
        # Normalisation of the raw dataset values (set from meta/stats.json before training).
        self.register_state_stats(c.state_dim)
        self.register_buffer("depth_scale", torch.tensor(50.1))  # metres per unit of the depth head
        self._compiled_step = None  # set by compile_rollout()
        self._low: tuple[nn.Module, ...] = ()  # bfloat16 copies of the rollout's layers, set by bfloat16_rollout()
        self.initialize_weights()

    def initialize_weights(self) -> None:
        """Xavier linears and truncated-normal embeddings (ViT / DiT), then zero every AdaLN
        modulation so each predictor block starts as the identity on its residual path (DiT's
        AdaLN-Zero): early training sees a plain causal transformer that actions then steer."""

        def basic(m: nn.Module):
            if isinstance(m, nn.Linear):
                nn.init.xavier_uniform_(m.weight)
                nn.init.zeros_(m.bias)

        self.apply(basic)
        w = self.encoder.patch.weight
        nn.init.xavier_uniform_(w.view(w.shape[0], -1))
        for p in (self.encoder.cls, self.encoder.pos, self.predictor.pos):
            nn.init.trunc_normal_(p, std=0.02)
        for block in self.predictor.blocks:
            nn.init.zeros_(block.adaln[-1].weight)
            nn.init.zeros_(block.adaln[-1].bias)
        # The predicted change starts at zero: an untrained model is the persistence baseline.
        nn.init.zeros_(self.pred_projector.bn.weight)

    def set_normalisation(self, state_mean, state_std, depth_scale: float) -> None:
        """Take the dataset's state mean/std (16,) and depth range (metres) from meta/stats.json."""
        self.set_state_stats(state_mean, state_std)
        self.depth_scale.fill_(float(depth_scale))

    # ---- the three public operations --------------------------------------------------------
    def encode(self, images: torch.Tensor, states: torch.Tensor) -> torch.Tensor:
        """images (B, T, 3, H, W) uint8, states (B, T, 16) -> z (B, T, D)."""
        return self._encode(images, states)[0]

    def rollout(self, z_context: torch.Tensor, actions: torch.Tensor, history: int | None = None) -> torch.Tensor:
        """Imagine n future latents from m context latents.

        z_context (B, m, D) holds frames t-m+1..t; actions (B, m-1+n, A) holds the m-1 actions
        taken inside the context and then the n planned ones (frames t-m+1..t+n-1). Returns
        z_future (B, n, D), frames t+1..t+n. Frames and actions are model steps: with
        ``config.frame_step`` s > 1 a step is s frames and its action the s thrusts taken
        through it, A = 8 s (``orbitmodel.data.group_actions``). Each prediction is fed back,
        and the predictor sees a sliding window of the last ``history`` latents (default
        ``config.history``; training covers every shorter context, so a planner may pass fewer
        to trade accuracy for time).
        """
        B, m, _ = z_context.shape
        n = actions.shape[1] - m + 1
        history = self.config.history if history is None else history
        if not 1 <= history <= self.config.max_seq_len:
            raise ValueError(f"history={history} must be in [1, max_seq_len={self.config.max_seq_len}]")
        if n < 1:
            raise ValueError(f"actions cover {actions.shape[1]} frames; with {m} context latents give at least {m}")
        action_encoder, predictor, _ = self._rollout_layers()
        dtype = predictor.pos.dtype  # float32, or bfloat16 after bfloat16_rollout()
        cond = action_encoder(self._norm_action(actions).to(dtype))  # (B, m-1+n, D)
        mods = predictor.modulations(cond)  # each block's AdaLN for every frame, computed once
        step = self._compiled_step or self.imagine_step
        z = list(z_context.to(dtype).unbind(1))
        for i in range(n):
            end = m + i  # frames [0, end) are known; predict frame `end`
            start = max(0, end - history)
            z.append(step(torch.stack(z[start:end], 1), [mod[:, start:end] for mod in mods]))
        return torch.stack(z[m:], 1).to(z_context.dtype)

    def imagine_step(self, window: torch.Tensor, mods: list[torch.Tensor]) -> torch.Tensor:
        """One imagined step: latents window (B, T, D) and each block's modulations for those T
        frames -> the latent after the window's last frame (B, D)."""
        _, predictor, projector = self._rollout_layers()
        return window[:, -1] + projector(predictor(window, None, mods, last=True)[:, 0])

    def _rollout_layers(self) -> tuple[nn.Module, nn.Module, nn.Module]:
        """The action encoder, predictor and predictor projector :meth:`rollout` runs: the model's
        own, or their bfloat16 copies (:meth:`bfloat16_rollout`)."""
        return self._low or (self.action_encoder, self.predictor, self.pred_projector)

    def bfloat16_rollout(self) -> "WorldModel":
        """Make :meth:`rollout` run in bfloat16: the action encoder, the predictor and its projector
        are copied to bfloat16 (the model's own layers, and the encoder, stay float32), the context
        latents and normalised actions are rounded to bfloat16 on the way in and the imagined
        latents returned as float32. With PyTorch's CPU kernels each row still gets the same bits
        whatever the batch (``tests/model/test_lockstep.py``). On a CPU with AVX-512 BF16 or AMX
        the products run natively and faster; elsewhere they are emulated and can be much slower
        (``benchmarks/bench_plan.py --profile`` times the rollout both ways). Inference only."""
        layers = (self.action_encoder, self.predictor, self.pred_projector)
        self._low = tuple(copy.deepcopy(layer).to(torch.bfloat16).eval() for layer in layers)
        return self

    def compile_rollout(self) -> "WorldModel":
        """Make :meth:`rollout` run its imagined step through ``torch.compile`` (inductor; on a CPU
        it needs a C++ compiler). Same latents to float rounding; ``benchmarks/bench_plan.py
        --compile`` measures the speed-up. The first rollouts of each batch and window size are
        slow while it compiles. Inference only: the model must be in eval mode."""
        self._compiled_step = torch.compile(self.imagine_step, dynamic=False)
        return self

    def predict_depth(self, images: torch.Tensor, head: nn.Module | None = None) -> torch.Tensor:
        """images (B, T, 3, H, W) uint8 -> depth (B, T, 16, 16) in metres, by ``head`` (a refitted
        copy of the depth head, ``orbitmodel.plan.depth_refit``) or the model's own."""
        self.check_images(images)
        B, T = images.shape[:2]
        _, patches = self.encoder(images_to_float(images.flatten(0, 1)))
        return self.depth_from_patches(patches, head).view(B, T, DEPTH_LOW_SIDE, DEPTH_LOW_SIDE)

    # ---- one encoder pass, two readings (the planner encodes each frame once) ------------------
    def depth_from_patches(self, patches: torch.Tensor, head: nn.Module | None = None) -> torch.Tensor:
        """The ViT's patch tokens (N, P, width) -> depth (N, 16, 16) metres (``predict_depth``'s head)."""
        return (self.depth_head if head is None else head)(patches) * self.depth_scale

    def latent_from_cls(self, cls: torch.Tensor, states: torch.Tensor) -> torch.Tensor:
        """The ViT's CLS features (N, width) and raw states (N, 16) -> z (N, D) (``encode``'s projection)."""
        s = self.state_encoder(self.normalise_states(states))  # (N, embed)
        return self.projector(torch.cat([cls, s], dim=-1))

    # ---- training ---------------------------------------------------------------------------
    def predict_next(self, z: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """Teacher-forced: ẑ (B, T, D), where ẑ[:, t] = z[:, t] + change predicts z[:, t+1] from
        z[:, :t+1] and a[:, :t+1]."""
        cond = self.action_encoder(self._norm_action(actions))
        return z + self.pred_projector(self.predictor(z, cond))

    def loss(
        self,
        images: torch.Tensor,
        states: torch.Tensor,
        actions: torch.Tensor,
        depth_low: torch.Tensor,
        generator: torch.Generator | None = None,
    ) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        """Upstream's Stage I loss over windows of T frames (teacher forcing, no stop-gradient):
        MSE(ẑ[:, :-1], z[:, 1:]) + lambda_sig SIGReg(z, per frame over the batch, or pooled) + lambda_depth
        MSE(depth). images (B, T, 3, H, W) float in [0, 1] or uint8; depth_low (B, T, 16, 16) m."""
        c = self.config
        z, patches = self._encode(images, states)  # (B, T, D), (B*T, P, width)
        z_hat = self.predict_next(z, actions)
        pred = F.mse_loss(z_hat[:, :-1], z[:, 1:])
        samples = z.flatten(0, 1) if c.sigreg_pool else z.transpose(0, 1)  # (B*T, D) or (T, B, D)
        sig = sigreg(samples, c.sigreg_projections, c.sigreg_knots, generator)
        depth = F.mse_loss(self.depth_head(patches), (depth_low / self.depth_scale).flatten(0, 1))
        total = pred + c.lambda_sigreg * sig + c.lambda_depth * depth
        return total, {"pred": pred.detach(), "sigreg": sig.detach(), "depth": depth.detach()}

    def forward(self, images, states, actions, depth_low, generator=None):
        """The training loss (so DDP sees a forward): see :meth:`loss`."""
        return self.loss(images, states, actions, depth_low, generator)

    # ---- internals --------------------------------------------------------------------------
    def _encode(self, images: torch.Tensor, states: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        self.check_images(images)
        B, T = images.shape[:2]
        cls, patches = self.encoder(images_to_float(images.flatten(0, 1)))  # (B*T, width), (B*T, P, width)
        z = self.latent_from_cls(cls, states.flatten(0, 1))  # (B*T, D)
        return z.view(B, T, -1), patches

    def check_images(self, images: torch.Tensor) -> None:
        """Refuse images that are not (B, T, 3, S, S) at this model's size S, saying what to give."""
        size, shape = self.config.image_size, tuple(images.shape)
        want = f"give (batch, frames, 3, {size}, {size}), as load_windows returns them"
        if len(shape) != 5:
            raise ValueError(f"images of shape {shape}: {want}")
        if shape[2] != 3 and shape[-1] == 3:
            raise ValueError(f"images of shape {shape} are channels-last: {want} (images.permute(0, 1, 4, 2, 3))")
        if shape[2:] != (3, size, size):
            raise ValueError(
                f"images of shape {shape}: this world model takes {size} px; "
                f"load_windows(..., image_size={size}) resizes a dataset's"
            )

    @staticmethod
    def _norm_action(actions: torch.Tensor) -> torch.Tensor:
        return actions * 2.0 - 1.0  # thrust in [0, 1] -> [-1, 1]

    # ---- persistence ------------------------------------------------------------------------
    @classmethod
    def from_pretrained(
        cls, path: str | Path, device: str | torch.device = "cpu", revision: str | None = None
    ) -> "WorldModel":
        """Load a trained model, in eval mode, from a run folder (``orbitmodel train --out RUN``) or
        a Hub model repo id (``owner/name``, ``orbitmodel push``; ``revision`` or ``owner/name@rev``).

        ``model.run`` keeps the run's config (preset, dataset facts), ``model.run_dir`` its local
        folder and ``model.fingerprint`` the weights' identity, which every sub-run (probe, depth
        refit) records."""
        run = load_run(path, revision)
        model = cls(run.config.preset.model)
        try:
            model.load_state_dict(run.weights)
        except RuntimeError as err:
            raise RunError(
                f"{path}: the weights do not fit the model its config.json describes "
                f"({str(err).splitlines()[1].strip() if len(str(err).splitlines()) > 1 else err}); "
                "train the run again"
            ) from None
        model.run, model.run_dir = run.config, run.path
        model.run_info = run.config.dataset
        model.fingerprint = fingerprint(run.weights)
        return model.to(device).eval()

    def num_parameters(self) -> int:
        return sum(p.numel() for p in self.parameters())


def effective_rank(z: torch.Tensor) -> float:
    """exp(entropy) of the normalised singular values of centred z (N, D) (Roy & Vetterli 2007)."""
    s = torch.linalg.svdvals(z - z.mean(0))
    p = s / s.sum().clamp(min=1e-12)
    return float(math.exp(-(p * torch.log(p.clamp(min=1e-12))).sum()))
