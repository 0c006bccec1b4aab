"""Where a dataset is: a local folder or a Hugging Face Hub repo id, and its ``meta/`` files.

The one place that decides what a source names (:func:`is_repo_id`, by ``huggingface_hub``'s
own repo-id rule), says that a folder is not a dataset (:func:`local_folder`,
:func:`dataset_folder`), fetches Hub files with errors that say what to do (:func:`hub_file`)
and reads ``meta/info.json`` (checking its schema version) and ``meta/stats.json``
(:func:`read_meta`). The loader, ``orbitdata info``/``show``/``push`` and ``generate`` all use it.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from orbitdata import schema as S
from orbitdata.info import Info

REPO_ID_HINT = "a Hub repo id like 'user/orbit_planner'"


class HubUnavailable(RuntimeError):
    """A file of a Hub dataset repo could not be fetched; the message says why and what to do."""


def check_repo_id(repo_id: str) -> str:
    """``repo_id`` if the Hub accepts it (``namespace/name`` or ``name``), else ValueError saying why."""
    from huggingface_hub.errors import HFValidationError
    from huggingface_hub.utils import validate_repo_id

    try:
        validate_repo_id(repo_id)
    except HFValidationError as exc:
        raise ValueError(
            f"{repo_id!r} is not a Hub repo id ({str(exc).splitlines()[0]}); expected NAMESPACE/NAME, "
            "e.g. user/orbit_planner"
        ) from None
    return repo_id


def is_repo_id(source: str | Path) -> bool:
    """True for a string ``namespace/name`` that the Hub accepts and that is not a local path."""
    if isinstance(source, Path):
        return False
    text = str(source)
    if text.startswith((".", "/", "~")) or text.count("/") != 1 or Path(text).exists():
        return False
    try:
        check_repo_id(text)
    except ValueError:
        return False
    return True


def local_folder(source: str | Path, repo_ok: bool = True) -> Path | None:
    """The folder ``source`` names, or None for a Hub repo id (when ``repo_ok``); raises if it is neither."""
    path = Path(source).expanduser()
    if path.is_dir():
        return path
    if path.exists():
        raise NotADirectoryError(f"{source} is a file, not a dataset folder: give the folder that holds {S.INFO_PATH}")
    if is_repo_id(source):
        if repo_ok:
            return None
        raise FileNotFoundError(
            f"no dataset folder at {source}: this needs a local folder; download the Hub repo "
            f"first (`hf download {source} --repo-type dataset --local-dir DIR`)"
        )
    repo, _, revision = str(source).partition("@")
    if repo_ok and revision and is_repo_id(repo):
        raise FileNotFoundError(
            f"no dataset folder at {source}: a Hub revision goes apart, as revision={revision!r} "
            f"(load_windows({repo!r}, revision={revision!r}))"
        )
    raise FileNotFoundError(
        f"no dataset folder at {source}: give a folder made by `orbitdata generate`"
        + (f", or {REPO_ID_HINT}" if repo_ok else "")
    )


def dataset_folder(source: str | Path) -> Path:
    """A local, finished dataset folder (it holds meta/info.json); raises saying what is wrong."""
    folder = local_folder(source, repo_ok=False)
    if not (folder / S.INFO_PATH).is_file():
        if (folder / S.PARTS_DIR).is_dir():  # generate's scratch space: a generation under way or stopped
            fix = "a `generate` run into it did not finish: run the same command again"
        else:
            fix = "give a folder made by `orbitdata generate`"
        raise FileNotFoundError(
            f"{folder / S.INFO_PATH} is missing: {folder} is not a finished orbitdata dataset; {fix}"
        )
    return folder


def _offline() -> bool:
    from huggingface_hub import constants

    env = os.environ.get("HF_HUB_OFFLINE", "").strip().lower() in ("1", "true", "yes", "on")
    return bool(constants.HF_HUB_OFFLINE) or env


def _unreachable(repo_id: str, filename: str, why: str) -> HubUnavailable:
    from huggingface_hub import constants

    return HubUnavailable(
        f"cannot fetch {filename} of dataset repo {repo_id!r}: the Hugging Face Hub at "
        f"{constants.ENDPOINT} could not be reached ({why}); check your connection (and "
        "HF_ENDPOINT), or pass a local dataset folder"
    )


def _check_reachable(repo_id: str, filename: str, revision: str | None, token) -> None:
    """One request for the file's metadata, without the client's retries: raises HubUnavailable at
    once when the Hub cannot be reached (the client would retry for half a minute, then report a
    missing file). Any other answer (not found, gated) is left to the download to report."""
    from httpx2 import TransportError  # huggingface_hub's HTTP client (declared in pyproject.toml)
    from huggingface_hub import get_hf_file_metadata, hf_hub_url

    try:
        get_hf_file_metadata(hf_hub_url(repo_id, filename, repo_type="dataset", revision=revision), token=token)
    except TransportError as exc:
        raise _unreachable(
            repo_id, filename, str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        ) from None
    except Exception:  # the download below says what it means
        pass


def hub_file(repo_id: str, filename: str, revision: str | None = None, token=None) -> Path:
    """Download one file of a dataset repo (or take it from the local cache). Only a source that
    names no local folder is looked for on the Hub, so a failure says that too: it may be a
    mistyped path."""
    try:
        return _hub_file(repo_id, filename, revision, token)
    except HubUnavailable as exc:
        raise HubUnavailable(f"no local folder {repo_id}, and {exc}") from None


def _hub_file(repo_id: str, filename: str, revision: str | None = None, token=None) -> Path:
    from huggingface_hub import hf_hub_download, try_to_load_from_cache
    from huggingface_hub.errors import (
        EntryNotFoundError,
        GatedRepoError,
        LocalEntryNotFoundError,
        RepositoryNotFoundError,
        RevisionNotFoundError,
    )

    if not _offline() and not isinstance(
        try_to_load_from_cache(repo_id, filename, revision=revision, repo_type="dataset"), str
    ):
        _check_reachable(repo_id, filename, revision, token)  # not cached: the Hub must answer
    try:
        return Path(hf_hub_download(repo_id, filename, repo_type="dataset", revision=revision, token=token))
    except Exception as exc:  # the client raises many types; every one means "not available"
        if _offline():
            why = (
                "offline mode is on (HF_HUB_OFFLINE=1) and the file is not in the local cache; "
                "unset HF_HUB_OFFLINE to download it, or pass a local dataset folder"
            )
        elif isinstance(exc, (RepositoryNotFoundError, GatedRepoError)):
            why = (
                "there is no such dataset repo, or it is private or gated: check the id, or log in with `hf auth login`"
            )
        elif isinstance(exc, RevisionNotFoundError):
            why = f"the repo has no revision {revision!r}"
        elif isinstance(exc, LocalEntryNotFoundError):  # a connection problem, and the file is not cached
            raise _unreachable(repo_id, filename, "no connection, and the file is not in the local cache") from None
        elif isinstance(exc, EntryNotFoundError):
            why = "the repo has no such file: was it pushed with `orbitdata push`?"
        else:
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            why = f"{first}; check your connection and the repo id, or pass a local dataset folder"
        raise HubUnavailable(
            f"cannot fetch {filename} of dataset repo {repo_id!r} from the Hugging Face Hub: {why}"
        ) from None


def meta_file(source: str | Path, rel: str, revision: str | None = None, token=None) -> Path:
    """Local path of ``rel`` (e.g. meta/stats.json) of a dataset folder or Hub repo; raises if absent."""
    folder = local_folder(source)
    if folder is None:
        return hub_file(str(source), rel, revision, token)
    path = folder / rel
    if not path.is_file():
        if rel == S.INFO_PATH:
            dataset_folder(folder)  # raises the "not a finished dataset" error
        raise FileNotFoundError(
            f"{path} is missing: regenerate meta with `orbitdata shard {folder}`, or check "
            f"the dataset with `orbitdata validate {folder}`"
        )
    return path


def _json(path: Path) -> dict:
    try:
        return json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise ValueError(f"{path} is not valid JSON ({err}); run `orbitdata validate` on the dataset") from None


def read_info(source: str | Path, revision: str | None = None, token=None) -> Info:
    """``meta/info.json`` of a dataset folder or Hub repo, typed; raises for an unreadable schema version."""
    path = meta_file(source, S.INFO_PATH, revision, token)
    where = str(path) if local_folder(source) is not None else f"{source}: {S.INFO_PATH}"
    return Info.from_dict(_json(path), where=where)


def read_meta(source: str | Path, revision: str | None = None, token=None) -> tuple[Info, dict]:
    """(info, stats) of a dataset folder or Hub repo id.

    ``stats`` is ``meta/stats.json``: feature name -> ``{"mean", "std", "min", "max", "q01",
    "q99": lists of floats (one per value of the feature), "count", "q_count": ints}``, over
    the train split (RGB channels in [0, 1]): what training normalises with.
    """
    info = read_info(source, revision, token)
    stats = _json(meta_file(source, S.STATS_PATH, revision, token))
    return info, stats
