"""One training loop for every stage: data order, optimiser, schedule, precision, checkpoints,
resume, DDP, metrics and progress.

A stage hands in a :class:`Job`: the module whose ``forward(**inputs)`` returns
``(loss, parts)``, the module whose weights a checkpoint holds, and how a batch becomes inputs;
and its training config's ``loop`` (``loop_settings.LoopSettings``).

Resuming is exact on CPU: the data order is a pure function of (seed, epoch) and the step
(a resumed run skips the batches it already took, without reading them), every augmentation
and projection draw comes from a generator seeded by (seed, step), and the global torch RNG
(dropout) is saved in each checkpoint.
"""

from __future__ import annotations

import json
import math
import os
import platform
import time
from contextlib import nullcontext
from dataclasses import dataclass
from typing import Callable, Protocol

import torch
from torch import nn
from torch.utils.data import DataLoader

from orbitdata.load import collate_windows
from orbitmodel.loop_settings import LoopSettings
from orbitmodel.runs import METRICS, TENSORBOARD, RunDir, RunError
from orbitmodel.train.progress import Progress


class Job(Protocol):
    module: nn.Module  # forward(**inputs) -> (loss, {name: scalar tensor})
    saved: nn.Module  # whose state_dict a checkpoint holds (the module, or its trainable part)

    def inputs(self, batch: dict[str, torch.Tensor], step: int, device: torch.device) -> dict: ...

    # Optional: ``after_step(step)`` is called after each optimiser step (1-based), e.g. to update
    # EMA weights kept inside ``saved`` (so that checkpoints and resume carry them).


@dataclass
class FitResult:
    steps: int
    seconds: float
    windows_per_s: float
    data_wait: float  # fraction of step time spent waiting for the next batch


def hardware(device: torch.device) -> str:
    """What trained: the GPU's name, or the CPU's model and core count."""
    if device.type == "cuda":
        return torch.cuda.get_device_name(device)
    model = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            model = next((line.split(":", 1)[1].strip() for line in f if line.startswith("model name")), model)
    except OSError:
        pass
    return f"{model}, {os.cpu_count()} cores visible, {torch.get_num_threads()} torch threads"


def resolve_device(name: str) -> torch.device:
    """'auto' -> cuda when available (this rank's GPU under torchrun), else cpu."""
    if name == "auto":
        name = "cuda" if torch.cuda.is_available() else "cpu"
    if name == "cuda":
        if not torch.cuda.is_available():
            raise RunError("--device cuda: no CUDA device is available; use --device cpu or auto")
        return torch.device("cuda", int(os.environ.get("LOCAL_RANK", 0)))
    if name != "cpu":
        raise RunError(f"--device {name}: choose auto, cpu or cuda")
    return torch.device("cpu")


def distributed(device: torch.device) -> tuple[int, int]:
    """(rank, world size); under torchrun, join the process group (NCCL on GPU, gloo on CPU)."""
    world = int(os.environ.get("WORLD_SIZE", 1))
    if world == 1:
        return 0, 1
    import torch.distributed as dist

    if not dist.is_initialized():
        dist.init_process_group("nccl" if device.type == "cuda" else "gloo")
        if device.type == "cuda":
            torch.cuda.set_device(device)
    return dist.get_rank(), dist.get_world_size()


def lr_at(step: int, total: int, s: LoopSettings) -> float:
    """Linear warm-up over ``warmup * total`` steps, then cosine from lr to min_lr."""
    warm = max(1, round(s.warmup * total)) if s.warmup > 0 else 0
    if step < warm:
        return s.lr * (step + 1) / warm
    progress = (step - warm) / max(1, total - warm)
    return s.min_lr + 0.5 * (s.lr - s.min_lr) * (1 + math.cos(math.pi * min(progress, 1.0)))


def step_generator(seed: int, step: int, stream: int, rank: int = 0) -> torch.Generator:
    """A generator for one purpose (stream) at one step: resumable without saved state."""
    return torch.Generator().manual_seed(((seed * 1_000_003 + step) * 31 + stream) * 257 + rank)


def _optimizer(params: list[nn.Parameter], s: LoopSettings) -> torch.optim.AdamW:
    decay = [p for p in params if p.ndim >= 2]  # matrices; no decay on biases, norms, embeddings' 1-D parts
    rest = [p for p in params if p.ndim < 2]
    return torch.optim.AdamW(
        [{"params": decay, "weight_decay": s.weight_decay}, {"params": rest, "weight_decay": 0.0}],
        lr=s.lr,
        betas=s.betas,
    )


def _rng_state() -> dict:
    state = {"torch": torch.get_rng_state()}
    if torch.cuda.is_available():
        state["cuda"] = torch.cuda.get_rng_state_all()
    return state


def _set_rng_state(state: dict) -> None:
    torch.set_rng_state(state["torch"])
    if "cuda" in state and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(state["cuda"])


class _Metrics:
    """metrics.jsonl (appended across resumes) and TensorBoard when it is installed."""

    def __init__(self, run: RunDir, enabled: bool, start_step: int):
        self.enabled = enabled
        self.file = None
        self.tb = None
        if not enabled:
            return
        path = run.path / METRICS
        if path.exists():  # drop lines past the checkpoint we resume from
            lines = [r for r in path.read_text().splitlines() if r and json.loads(r)["step"] <= start_step]
            path.write_text("".join(r + "\n" for r in lines))
        self.file = path.open("a")
        try:
            from torch.utils.tensorboard import SummaryWriter

            self.tb = SummaryWriter(str(run.path / TENSORBOARD), purge_step=start_step + 1)
        except ImportError:
            self.tb = None

    def write(self, record: dict) -> None:
        if not self.enabled:
            return
        self.file.write(json.dumps(record) + "\n")
        self.file.flush()
        if self.tb is not None:
            for k, v in record.items():
                if k != "step" and isinstance(v, (int, float)):
                    self.tb.add_scalar(k, v, record["step"])

    def close(self) -> None:
        if self.file:
            self.file.close()
        if self.tb is not None:
            self.tb.close()


class _Tally:
    """Loss parts averaged between log lines, windows seen, and time waiting for data vs computing."""

    def __init__(self, world: int):
        self.world, self.started = world, time.perf_counter()
        self.sums: dict[str, float] = {}
        self.count, self.wait, self.busy, self.windows = 0, 0.0, 0.0, 0

    def add(self, batch: dict, values: dict) -> None:
        self.windows += len(batch[next(iter(batch))]) * self.world
        for k, v in values.items():
            self.sums[k] = self.sums.get(k, 0.0) + float(v)
        self.count += 1

    def record(self, step: int, epoch: int, lr: float) -> dict:
        """The metrics line for ``step`` (the averages since the last one), then start averaging again."""
        elapsed = time.perf_counter() - self.started
        record = {
            "step": step,
            "epoch": epoch,
            "lr": lr,
            **{k: v / self.count for k, v in self.sums.items()},
            "windows_per_s": self.windows / max(elapsed, 1e-9),
            "data_wait": self.data_wait,
            "elapsed_s": elapsed,
            "world_size": self.world,
        }
        self.sums, self.count = {}, 0
        return record

    @property
    def data_wait(self) -> float:
        return self.wait / max(self.wait + self.busy, 1e-9)

    def result(self, steps: int) -> FitResult:
        elapsed = time.perf_counter() - self.started
        return FitResult(
            steps=steps, seconds=elapsed, windows_per_s=self.windows / max(elapsed, 1e-9), data_wait=self.data_wait
        )


def _batches(
    dataset,
    sampler,
    step: int,
    per_epoch: int,
    total: int,
    s: LoopSettings,
    device: torch.device,
    rank: int,
    tally: _Tally,
):
    """(epoch, batch) from ``step`` to ``total``; a resumed run skips the batches it already took
    without reading them. The time spent waiting for each batch goes to ``tally.wait``."""
    while step < total:
        epoch, offset = divmod(step, per_epoch)
        sampler.set_epoch(epoch)
        order = list(sampler)
        batches = [
            order[i * s.batch_size : (i + 1) * s.batch_size]
            for i in range(offset, min(per_epoch, offset + total - step))
        ]
        # Its own generator: a DataLoader draws its workers' base seed from the global RNG
        # otherwise, and a resumed run (a new loader mid-epoch) would shift the dropout masks.
        loader = DataLoader(
            dataset,
            batch_sampler=batches,
            num_workers=s.num_workers,
            collate_fn=collate_windows,
            pin_memory=device.type == "cuda",
            generator=step_generator(s.seed, step, stream=99, rank=rank),
        )
        tick = time.perf_counter()
        for batch in loader:
            tally.wait += time.perf_counter() - tick
            yield epoch, batch
            step += 1
            tick = time.perf_counter()


def _restore(job: Job, optimizer, run: RunDir, rank: int) -> int:
    """Load the newest checkpoint into the job and the optimiser; returns its step."""
    ckpt = run.latest_checkpoint()
    job.saved.load_state_dict(ckpt.weights)
    optimizer.load_state_dict(ckpt.state["optimizer"])
    _set_rng_state(ckpt.state["rng"][rank] if isinstance(ckpt.state["rng"], list) else ckpt.state["rng"])
    return ckpt.step


def fit(
    job: Job,
    dataset,
    settings: LoopSettings,
    run: RunDir,
    device: torch.device,
    resume: bool = False,
    label: str = "train",
    on_log: Callable[[dict], None] | None = None,
) -> FitResult:
    """Train ``job`` on map-style window ``dataset`` until ``epochs`` or ``max_steps``."""
    s = settings
    rank, world = distributed(device)
    sampler = dataset.sampler(seed=s.seed, drop_last=True, rank=rank, world_size=world)
    per_epoch = len(sampler) // s.batch_size
    if per_epoch == 0:
        raise RunError(
            f"{len(dataset)} windows give no batch of {s.batch_size} per process; "
            "use a larger dataset or a smaller --batch-size"
        )
    total = per_epoch * s.epochs if not s.max_steps else min(per_epoch * s.epochs, s.max_steps)
    params = [p for p in job.module.parameters() if p.requires_grad]
    optimizer = _optimizer(params, s)
    torch.manual_seed(s.seed + rank)
    step = start = _restore(job, optimizer, run, rank) if resume else 0
    job.module.to(device)
    model = (
        job.module
        if world == 1
        else nn.parallel.DistributedDataParallel(
            job.module, device_ids=[device.index] if device.type == "cuda" else None
        )
    )
    autocast = torch.autocast("cuda", dtype=torch.bfloat16) if device.type == "cuda" else nullcontext()
    after_step = getattr(job, "after_step", None)
    main = rank == 0
    metrics, progress, tally = _Metrics(run, main, step), Progress(label, total, step, enabled=main), _Tally(world)
    diverged = torch.zeros((), dtype=torch.bool, device=device)  # a non-finite loss or gradient since the start
    try:
        for epoch, batch in _batches(dataset, sampler, step, per_epoch, total, s, device, rank, tally):
            got = time.perf_counter()
            lr = lr_at(step, total, s)
            for group in optimizer.param_groups:
                group["lr"] = lr
            inputs = job.inputs(batch, step, device)
            with autocast:
                loss, parts = model(**inputs)
            optimizer.zero_grad(set_to_none=True)
            loss.backward()
            grad_norm = torch.nn.utils.clip_grad_norm_(params, s.grad_clip)
            diverged |= ~torch.isfinite(loss.detach()) | ~torch.isfinite(grad_norm)  # read at logs and checkpoints
            optimizer.step()
            step += 1
            if after_step is not None:
                after_step(step)
            tally.add(batch, {"loss": loss.detach(), **parts, "grad_norm": grad_norm})
            if step % s.log_every == 0 or step == total:
                record = tally.record(step, epoch, lr)
                metrics.write(record)
                progress.update(step, record)
                if on_log:
                    on_log(record)
            if (step % s.log_every == 0 or step % s.save_every == 0 or step == total) and diverged.item():
                raise RunError(
                    f"{run.path}: the loss or its gradient became nan or inf by step {step}, so the weights "
                    f"diverged and nothing after the last checkpoint was saved; train again with a lower --lr "
                    f"(this run's: {s.lr:g}) and --overwrite"
                )
            if step % s.save_every == 0 or step == total:
                _save(run, job, optimizer, step, world, main)
                if main:  # the segment so far: a run killed after this checkpoint still records its time
                    run.add_training_segment(_segment(start, step, total, tally, world, device))
            tally.busy += time.perf_counter() - got
        if main:
            run.save_final(job.saved.state_dict(), step)
            run.add_training_segment(_segment(start, step, total, tally, world, device))
    finally:
        progress.close()
        metrics.close()
    return tally.result(step)


def _segment(start: int, step: int, total: int, tally: _Tally, world: int, device: torch.device) -> dict:
    """training.json's record of this process's part of the run: steps, the schedule's length
    (a run extended with ``--resume --extend`` changes it), wall time, hardware."""
    result = tally.result(step)
    return {
        "from_step": start,
        "to_step": step,
        "schedule_steps": total,
        "seconds": round(result.seconds, 1),
        "windows_per_s": round(result.windows_per_s, 2),
        "world_size": world,
        "device": str(device),
        "hardware": hardware(device),
        "torch": torch.__version__,
    }


def _save(run: RunDir, job: Job, optimizer, step: int, world: int, main: bool) -> None:
    rng = _rng_state()
    if world > 1:
        import torch.distributed as dist

        gathered = [None] * world
        dist.all_gather_object(gathered, rng)
        rng = gathered
    if main:
        run.save_checkpoint(
            step, job.saved.state_dict(), {"step": step, "optimizer": optimizer.state_dict(), "rng": rng}
        )
