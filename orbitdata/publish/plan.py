"""What a push uploads, and in which commits.

Exactly the dataset goes up: the files meta/info.json lists, plus meta/info.json itself; local
extras (scratch files, a Hub snapshot's ``.cache/``) never do. Data and episodes shards go first
and the card and meta/info.json last, in the final commit, so a repo whose push was cut short
never advertises a complete dataset it does not hold (as ``generate`` writes info.json last).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from orbitdata import schema as S
from orbitdata.load.source import dataset_folder, read_info

LAST = (S.CARD_PATH, S.INFO_PATH)  # the final commit, in this order


@dataclass(frozen=True)
class UploadFile:
    rel: str  # path in the dataset and in the repo
    bytes: int
    sha256: str | None  # from meta/info.json (None for info.json itself)


@dataclass(frozen=True)
class UploadPlan:
    root: Path
    files: tuple[UploadFile, ...]

    @property
    def bytes(self) -> int:
        return sum(f.bytes for f in self.files)


def plan_upload(root: Path) -> UploadPlan:
    """Every file of the dataset in ``root``, in upload order."""
    root = dataset_folder(root)
    info_path = root / S.INFO_PATH
    listed = read_info(root).files
    missing = [rel for rel in listed if not (root / rel).is_file()]
    if missing:
        raise FileNotFoundError(
            f"{root}: {len(missing)} file(s) listed in {S.INFO_PATH} are missing, e.g. "
            f"{missing[0]}; run `orbitdata validate {root}`"
        )

    def order(rel: str) -> tuple:
        folder = rel.split("/")[0]
        rank = {S.DATA_DIR: 0, S.EPISODES_DIR: 1}.get(folder, 2)
        return (rank if rel not in LAST else 3 + LAST.index(rel), rel)

    files = [UploadFile(rel, (root / rel).stat().st_size, entry.sha256) for rel, entry in listed.items()]
    files.append(UploadFile(S.INFO_PATH, info_path.stat().st_size, None))
    return UploadPlan(root, tuple(sorted(files, key=lambda f: order(f.rel))))


def batches(files: list[UploadFile], max_bytes: int, max_files: int) -> list[list[UploadFile]]:
    """Greedy commits of at most ``max_bytes`` / ``max_files``; the card and info.json close the last one."""
    body = [f for f in files if f.rel not in LAST]
    tail = [f for f in files if f.rel in LAST]
    out: list[list[UploadFile]] = []
    current: list[UploadFile] = []
    size = 0
    for f in body:
        if current and (size + f.bytes > max_bytes or len(current) >= max_files):
            out.append(current)
            current, size = [], 0
        current.append(f)
        size += f.bytes
    if tail:
        current += tail
    if current:
        out.append(current)
    return out
