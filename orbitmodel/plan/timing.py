"""Wall-clock time per planning phase (encode, rollout, probe, cost, ...), for latency reports."""

from __future__ import annotations

import time
from collections import defaultdict
from contextlib import contextmanager


class Timings:
    """Seconds spent per named phase, summed since the last :meth:`clear`."""

    def __init__(self):
        self.seconds: dict[str, float] = defaultdict(float)

    @contextmanager
    def __call__(self, phase: str):
        start = time.perf_counter()
        try:
            yield
        finally:
            self.seconds[phase] += time.perf_counter() - start

    def clear(self) -> None:
        self.seconds.clear()

    def snapshot(self) -> dict[str, float]:
        return dict(self.seconds)
