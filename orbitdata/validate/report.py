"""Findings, the per-check cap, and the report (readable text and JSON).

Every problem is a :class:`Finding` that names its check and, where it has one, the file,
episode and frame. A :class:`Sink` keeps the first ``cap`` findings of each check and counts
the rest, so a dataset with a million bad rows still gives a short report with true counts.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable, Sequence

from orbitdata.validate.checks import BY_NAME, CHECKS, Check

DEFAULT_CAP = 20  # findings shown per check; the rest are counted


@dataclass(frozen=True)
class Finding:
    check: str
    message: str
    file: str | None = None  # path relative to the dataset root
    episode: int | None = None
    frame: int | None = None

    def where(self) -> str:
        parts = [self.file or ""]
        if self.episode is not None:
            parts.append(f"episode {self.episode}")
        if self.frame is not None:
            parts.append(f"frame {self.frame}")
        return " ".join(p for p in parts if p)


class Sink:
    """Collects findings: the first ``cap`` per check are kept, all are counted."""

    def __init__(self, cap: int = DEFAULT_CAP):
        self.cap = cap
        self.kept: dict[str, list[Finding]] = {}
        self.counts: dict[str, int] = {}

    def add(
        self, check: str, message: str, file: str | None = None, episode: int | None = None, frame: int | None = None
    ) -> None:
        assert check in BY_NAME, f"unknown check {check!r}"
        self.counts[check] = self.counts.get(check, 0) + 1
        kept = self.kept.setdefault(check, [])
        if len(kept) < self.cap:
            kept.append(Finding(check, message, file, episode, frame))

    def add_rows(
        self,
        check: str,
        rows: Sequence[int],
        message: Callable[[int], str],
        file: str | None,
        episodes: Sequence[int] | None = None,
        frames: Sequence[int] | None = None,
    ) -> None:
        """Many hits at once (indices into ``episodes``/``frames``); messages only for kept ones."""
        n = len(rows)
        if not n:
            return
        kept = self.kept.setdefault(check, [])
        room = max(0, self.cap - len(kept))
        for i in list(rows)[:room]:
            ep = None if episodes is None else int(episodes[i])
            fr = None if frames is None else int(frames[i])
            kept.append(Finding(check, message(int(i)), file, ep, fr))
        self.counts[check] = self.counts.get(check, 0) + n

    def merge(self, other: "Sink") -> None:
        for check, n in other.counts.items():
            kept = self.kept.setdefault(check, [])
            kept.extend(other.kept.get(check, [])[: max(0, self.cap - len(kept))])
            self.counts[check] = self.counts.get(check, 0) + n

    def total(self) -> int:
        return sum(self.counts.values())


@dataclass
class Report:
    """The outcome of one validation run."""

    root: str
    mode: str  # "quick" or "full"
    sink: Sink
    skipped: dict[str, str] = field(default_factory=dict)  # check -> why it did not run
    files: int = 0
    bytes: int = 0
    frames: int = 0
    episodes: int = 0
    seconds: float = 0.0
    workers: int = 1
    checks: tuple[Check, ...] = CHECKS  # those this dataset's tier runs (checks.checks_for)

    @property
    def ok(self) -> bool:
        return self.sink.total() == 0

    def status(self, check: str) -> str:
        if self.sink.counts.get(check):
            return "fail"
        return "skip" if check in self.skipped else "pass"

    def failed(self) -> list[str]:
        return [c.name for c in self.checks if self.sink.counts.get(c.name)]

    def findings(self, check: str) -> list[Finding]:
        return list(self.sink.kept.get(check, []))

    def throughput(self) -> dict:
        s = max(self.seconds, 1e-9)
        return {
            "seconds": round(self.seconds, 3),
            "mb_per_s": round(self.bytes / 1e6 / s, 2),
            "frames_per_s": round(self.frames / s, 1),
        }

    def to_dict(self) -> dict:
        checks = []
        for c in self.checks:
            entry = {
                "name": c.name,
                "group": c.group,
                "summary": c.summary,
                "status": self.status(c.name),
                "count": self.sink.counts.get(c.name, 0),
                "findings": [asdict(f) for f in self.findings(c.name)],
            }
            if c.name in self.skipped:
                entry["skipped"] = self.skipped[c.name]
            checks.append(entry)
        return {
            "dataset": self.root,
            "mode": self.mode,
            "ok": self.ok,
            "problems": self.sink.total(),
            "failed_checks": self.failed(),
            "cap_per_check": self.sink.cap,
            "checked": {
                "files": self.files,
                "bytes": self.bytes,
                "episodes": self.episodes,
                "frames": self.frames,
                "workers": self.workers,
                **self.throughput(),
            },
            "checks": checks,
        }

    def write_json(self, path: Path) -> None:
        from orbitdata.write.parts import write_report

        write_report(Path(path), json.dumps(self.to_dict(), indent=2) + "\n")

    def render(self) -> str:
        """The readable report: one line per check, problems listed under failing ones."""
        t = self.throughput()
        lines = [
            f"orbitdata validate {self.root} ({self.mode}, {self.workers} worker{'s' if self.workers != 1 else ''})",
            f"checked {self.files} files, {self.episodes} episodes, {self.frames} frames, "
            f"{self.bytes / 1e6:.1f} MB in {t['seconds']:.1f} s ({t['mb_per_s']:.1f} MB/s, "
            f"{t['frames_per_s']:.0f} frames/s)",
            "",
        ]
        width = max(len(c.name) for c in self.checks)
        for group in dict.fromkeys(c.group for c in self.checks):
            lines.append(f"{group}")
            for c in (c for c in self.checks if c.group == group):
                status = self.status(c.name)
                n = self.sink.counts.get(c.name, 0)
                if status == "fail":
                    lines.append(f"  FAIL  {c.name:<{width}}  {n} problem{'s' if n != 1 else ''}: {c.summary}")
                    for f in self.findings(c.name):
                        where = f.where()
                        lines.append(f"          {where + ': ' if where else ''}{f.message}")
                    if n > len(self.findings(c.name)):
                        lines.append(
                            f"          ... and {n - len(self.findings(c.name))} more "
                            f"(see --json, or raise --max-per-check)"
                        )
                elif status == "skip":
                    lines.append(f"  skip  {c.name:<{width}}  {self.skipped[c.name]}")
                else:
                    lines.append(f"  ok    {c.name:<{width}}  {c.summary}")
        lines.append("")
        if self.ok:
            lines.append("valid: no problems found")
        else:
            lines.append(
                f"INVALID: {self.sink.total()} problem(s) in {len(self.failed())} check(s): " + ", ".join(self.failed())
            )
        return "\n".join(lines)
