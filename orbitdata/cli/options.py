"""Flag helpers: repeatable ``KEY=VALUE`` flags (``orbitdata fly --pilot-option``, ``orbitmodel eval closed-loop
--set``), the grid's comma-separated lists, and output paths checked before any work."""

from __future__ import annotations

import os
from pathlib import Path

from orbitdata.cli.errors import usage


def key_values(pairs: list[str], flag: str, example: str) -> dict[str, str]:
    """``["a=1", "b=x"]`` -> ``{"a": "1", "b": "x"}``; a pair without ``=`` or a key is a usage
    error naming ``flag`` and an ``example`` pair. The values stay strings: the receiver converts
    and checks them."""
    options = {}
    for pair in pairs:
        key, sep, value = pair.partition("=")
        if not sep or not key.strip():
            usage(f"{flag} {pair!r} must be KEY=VALUE, e.g. {flag} {example}")
        options[key.strip()] = value
    return options


def comma_numbers(text: str, kind: type, flag: str) -> list:
    """``"1,3,5"`` -> ``[1, 3, 5]`` of ``kind`` (int or float; spaces allowed, one trailing comma
    too); anything else, an empty item included (``1,,3``), is a ValueError naming ``flag`` with an
    example."""
    items = [x.strip() for x in text.split(",")]
    if items and not items[-1]:
        items.pop()
    try:
        if items and all(items):
            return [kind(x) for x in items]
    except ValueError:
        pass
    raise ValueError(f"{flag} {text!r} must be a comma-separated list of numbers, e.g. {flag} 1,3,5")


def check_report_path(path: Path | None, flag: str = "--json") -> None:
    """Refuse, before any work, an output path that could not be written at the end (a folder, a
    file where a folder must be, a folder not writable)."""
    if path is None:
        return
    path = Path(path).expanduser()
    if path.is_dir():
        raise ValueError(f"{flag} {path} is a folder: give a file's path, such as one in it")
    _check_makeable(path.parent, path, flag)


def _check_makeable(folder: Path, path: Path, flag: str) -> None:
    """Refuse ``path`` (given as ``flag``) when ``folder`` could not be made: a file stands where one
    of its folders must be, or the first folder that exists is not writable."""
    while not folder.exists() and folder != folder.parent:  # the first folder that exists: the rest is made
        folder = folder.parent
    if not folder.is_dir():
        raise ValueError(f"{flag} {path}: {folder} is a file, not a folder; give another path")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise ValueError(f"{flag} {path}: {folder} is not writable; give a path you can write to")


def check_out_folder(path: Path | None, flag: str = "--out") -> None:
    """Refuse, before any work, an output folder that could not be made: an existing file, a file
    where one of its folders must be, or a folder not writable."""
    if path is None:
        return
    path = Path(path).expanduser()
    if path.exists() and not path.is_dir():
        raise ValueError(f"{flag} {path} is a file: give a folder")
    _check_makeable(path, path, flag)


def check_video_folder(video: Path | None) -> None:
    """Refuse, before any flight, a ``--video`` folder that could not be made (:func:`check_out_folder`)."""
    if video is not None and Path(video).exists() and not Path(video).is_dir():
        raise ValueError(f"--video {video} is a file: give a folder for the videos")
    check_out_folder(video, "--video")


def wide_console():
    """A rich console for tables: the terminal's width, or 160 columns into a pipe or a file (rich's
    80 would cut the tables' cells)."""
    import sys

    from rich.console import Console

    return Console() if sys.stdout.isatty() else Console(width=160)
