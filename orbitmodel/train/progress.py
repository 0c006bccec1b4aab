"""Progress for a training run: a rich bar with ETA and losses on a terminal, plain lines in a log."""

from __future__ import annotations

import sys
import time

SHOWN = ("loss", "pred", "sigreg", "depth")


def _fmt(record: dict, keys) -> str:
    return "  ".join(f"{k} {record[k]:.4f}" for k in keys if k in record)


class Progress:
    def __init__(self, label: str, total: int, start: int, enabled: bool = True):
        self.total, self.start, self.enabled = total, start, enabled
        self.t0 = time.perf_counter()
        self.bar = None
        if enabled and sys.stderr.isatty():
            from rich.progress import BarColumn, MofNCompleteColumn, TextColumn, TimeRemainingColumn
            from rich.progress import Progress as Bar

            self.bar = Bar(
                TextColumn("{task.description}"),
                BarColumn(),
                MofNCompleteColumn(),
                TextColumn("ETA"),
                TimeRemainingColumn(),
                TextColumn("{task.fields[losses]}"),
            )
            self.task = self.bar.add_task(label, total=total, completed=start, losses="")
            self.bar.start()
        elif enabled:
            print(f"{label}: steps {start}..{total}", file=sys.stderr, flush=True)
        self.label = label

    def update(self, step: int, record: dict) -> None:
        if not self.enabled:
            return
        keys = [k for k in record if k in SHOWN or k.endswith("_loss")] or list(SHOWN)
        if self.bar is not None:
            self.bar.update(self.task, completed=step, losses=_fmt(record, keys))
            return
        done = step - self.start
        rate = done / max(time.perf_counter() - self.t0, 1e-9)
        eta = (self.total - step) / rate if rate > 0 else float("inf")
        print(
            f"{self.label} {step}/{self.total}  {_fmt(record, keys)}  {record.get('windows_per_s', 0):.1f} win/s  "
            f"ETA {int(eta // 60)}:{int(eta % 60):02d}",
            file=sys.stderr,
            flush=True,
        )

    def close(self) -> None:
        if self.bar is not None:
            self.bar.stop()
