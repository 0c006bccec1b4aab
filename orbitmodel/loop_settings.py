"""The training loop's settings, one field of every stage's training config.

Stage I's ``config.TrainConfig``, the probe's ``config.ProbeTrainConfig`` and the Diffusion
Policy's ``PolicyTrainConfig`` each hold one :class:`LoopSettings` as ``loop`` (``train.loop.lr``),
whose default is that stage's recipe, written once in the stage's class; ``train.loop.fit`` reads
it. The checks every stage shares are :class:`LoopSettings`' own.

A run's config.json holds a stage's training config nested (``"train": {"loop": {...}, ...}``);
runs written before the field hold it flat (the loop's settings beside the stage's own), and
both read back the same (:meth:`StageTrainConfig.from_dict`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields, replace


@dataclass(frozen=True)
class LoopSettings:
    """How the one training loop runs (every field is a stage's choice: no defaults here).

    Args:
        batch_size: windows per step (per process under DDP).
        lr, min_lr, weight_decay, betas: AdamW; cosine decay from lr to min_lr.
        epochs, max_steps: the run ends at whichever comes first (max_steps 0 = no bound).
        warmup: linear warm-up, as a fraction of the run's steps.
        grad_clip: global gradient-norm clip.
        num_workers: DataLoader worker processes.
        log_every, save_every: steps between metric lines and between checkpoints.
        seed: data order and initialisation, and the seed of the stage's draws per step.
    """

    batch_size: int
    lr: float
    min_lr: float
    weight_decay: float
    betas: tuple[float, float]
    epochs: int
    max_steps: int
    warmup: float
    grad_clip: float
    num_workers: int
    log_every: int
    save_every: int
    seed: int

    def __post_init__(self):
        if self.batch_size < 1:
            raise ValueError(f"batch_size={self.batch_size}: use at least 1 window per step")
        if self.epochs < 1 or self.max_steps < 0:
            raise ValueError(f"epochs={self.epochs}, max_steps={self.max_steps}: give epochs >= 1 and max_steps >= 0")
        if not 0 <= self.warmup < 1:
            raise ValueError(f"warmup={self.warmup} is a fraction of the run in [0, 1)")
        object.__setattr__(self, "betas", tuple(self.betas))  # a list when read back from JSON


LOOP_FIELDS = frozenset(f.name for f in fields(LoopSettings))


class StageTrainConfig:
    """The base of a stage's training config: a frozen dataclass of the stage's own settings and
    ``loop: LoopSettings`` (whose default is the stage's loop recipe). The loop's settings go by
    their own names where a flat name is handy: :meth:`with_changes` routes them into ``loop``,
    and :meth:`from_dict` reads config.json's flat shape (runs made before ``loop``) too."""

    def with_changes(self, **changes):
        """The config with some settings replaced, the loop's by their own names (``lr=``, not
        ``loop=``); None values are ignored (unset CLI options)."""
        given = {k: v for k, v in changes.items() if v is not None}
        loop = {k: given.pop(k) for k in list(given) if k in LOOP_FIELDS}
        base = given.pop("loop", self.loop)
        return replace(self, **given, loop=replace(base, **loop))

    def to_dict(self) -> dict:
        """As config.json holds it: the loop's settings nested under ``loop``."""
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict):
        """The config as config.json holds it, nested (``loop``) or flat (runs written before the
        ``loop`` field); a setting it lacks takes the stage's default."""
        d = dict(d)
        flat = {k: d.pop(k) for k in list(d) if k in LOOP_FIELDS}
        nested = d.pop("loop", {})
        if flat and nested:
            raise ValueError(
                f"the loop's settings are both under 'loop' and beside it ({', '.join(sorted(flat))}); "
                "give them in one place"
            )
        return cls(**d, loop=LoopSettings(**{**asdict(cls().loop), **flat, **nested}))
