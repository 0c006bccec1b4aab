"""``push``: publish a validated dataset to the Hugging Face Hub with the real client.

How it talks to the Hub (``huggingface_hub.HfApi``; ``HF_ENDPOINT`` picks the server):

1. ``whoami`` checks the token, ``create_repo(repo_type="dataset", exist_ok=True)`` makes the
   repo, ``create_branch`` the revision if it is not ``main``.
2. The remote tree is listed once: files whose sha256 (LFS) or git blob id (small files)
   already match are skipped, so running an interrupted push again resumes it.
3. The rest goes up in several ``create_commit`` calls of at most ``commit_bytes`` /
   ``commit_files`` each (shards first, card and meta/info.json last). Each commit uploads its
   blobs first (Xet where the client and Hub support it, LFS otherwise, e.g. with
   ``HF_HUB_DISABLE_XET=1``); blobs that reached the server before a failure are not sent again.
   ``upload_folder`` would do one commit without ``hf_xet`` and cannot drop stale shards, hence
   our own batching.
4. Shards in the repo that this dataset no longer has (an older sharding), and orbitdata's own
   ``meta/`` files it no longer has, are deleted in the last commit, so ``data/train-*.parquet``
   globs never mix two layouts. Any other file in the repo (one of the user's) stays.

The token comes from the usual sources (``HF_TOKEN``, then ``hf auth login``'s token file); it
is handed to the client and never printed, logged or put in an error message.
"""

from __future__ import annotations

import contextlib
import hashlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterator

from orbitdata import schema as S
from orbitdata.info import sha256_file
from orbitdata.publish.plan import UploadFile, UploadPlan, batches, plan_upload

LOGIN_HINT = "run `hf auth login` or set HF_TOKEN to a token with write access"


class HubError(RuntimeError):
    """The Hub could not be reached or refused; the message says what to do."""


class PushRefused(ValueError):
    """The dataset failed validation and --force was not given."""

    def __init__(self, message: str, report=None):
        super().__init__(message)
        self.report = report


@dataclass(frozen=True)
class PushOptions:
    """How to push.

    Attributes:
        private: create the repo private (an existing repo keeps its visibility).
        revision: branch to push to (created from main if missing); None = main.
        message: commit message; multi-commit pushes add " (part i/n)".
        force: push even if ``validate --quick`` finds problems.
        commit_bytes: at most this many bytes per commit (a failed commit redoes at most this).
        commit_files: at most this many files per commit (the Hub limits commit size).
    """

    private: bool = False
    revision: str | None = None
    message: str = "Upload Orbit-Planner dataset (orbitdata)"
    force: bool = False
    commit_bytes: int = 2_000_000_000
    commit_files: int = 100

    def __post_init__(self) -> None:
        if self.commit_bytes < 1 or self.commit_files < 1:
            raise ValueError("commit_bytes and commit_files must be >= 1")
        if self.revision is not None and not self.revision.strip():
            raise ValueError("revision must be a branch name, e.g. 'main' or 'v1'")


@dataclass
class PushResult:
    repo_id: str  # with its namespace, as the Hub resolved it
    repo_url: str
    revision: str
    commits: list[str] = field(default_factory=list)  # commit ids, in order
    uploaded: list[str] = field(default_factory=list)
    unchanged: list[str] = field(default_factory=list)  # already on the Hub (resumed or re-pushed)
    deleted: list[str] = field(default_factory=list)  # stale shards removed from the repo
    bytes: int = 0


def _git_blob_id(path: Path) -> str:
    """The id git (and the Hub's tree listing) gives a small file: sha1 of "blob <size>\\0" + bytes."""
    data = path.read_bytes()
    return hashlib.sha1(b"blob %d\0" % len(data) + data).hexdigest()


def _unchanged(f: UploadFile, root: Path, remote) -> bool:
    """Same content on the Hub: LFS files by sha256, regular files by git blob id."""
    if remote is None or getattr(remote, "size", None) != f.bytes:
        return False
    lfs = getattr(remote, "lfs", None)
    if lfs is not None:
        return lfs.sha256 == (f.sha256 or sha256_file(root / f.rel))
    return getattr(remote, "blob_id", None) == _git_blob_id(root / f.rel)


@contextlib.contextmanager
def hub_errors(repo_id: str, endpoint: str) -> Iterator[None]:
    """Turn client exceptions into one-line HubErrors that say what to do (never the token)."""
    from httpx2 import TransportError  # huggingface_hub's HTTP client (declared in pyproject.toml)
    from huggingface_hub.errors import HfHubHTTPError, LocalTokenNotFoundError, OfflineModeIsEnabled

    try:
        yield
    except OfflineModeIsEnabled:
        raise HubError("offline mode is on (HF_HUB_OFFLINE=1): unset it to push to the Hub") from None
    except LocalTokenNotFoundError:
        raise HubError(f"no Hugging Face token found: {LOGIN_HINT}") from None
    except HfHubHTTPError as exc:
        status = exc.response.status_code if exc.response is not None else None
        server = (exc.server_message or "").strip().splitlines()[0] if exc.server_message else ""
        detail = f" ({server})" if server else ""
        if status == 401:
            raise HubError(f"the Hub rejected the token (401){detail}: {LOGIN_HINT}") from None
        if status == 403:
            raise HubError(
                f"the token may not write to {repo_id} (403){detail}: use a token with write access "
                "to that namespace, or push to your own namespace"
            ) from None
        if status == 404:
            raise HubError(
                f"{repo_id} was not found (404){detail}: check the repo id and that your token can see it"
            ) from None
        raise HubError(
            f"the Hub refused the push (HTTP {status}){detail}; run the same command again to resume"
        ) from None
    except TransportError as exc:
        raise HubError(
            f"cannot reach the Hub at {endpoint} ({type(exc).__name__}): check the network connection "
            "(and HF_ENDPOINT), then run the same command again to resume"
        ) from None


def _ours(path: str) -> bool:
    """Whether a file in the repo is one orbitdata writes: a shard, or one of its meta/ files."""
    return bool(S.SHARD_RE.match(path)) or path in (S.INFO_PATH, S.STATS_PATH, S.OVERVIEW_PATH)


def push(
    root: Path,
    repo_id: str,
    options: PushOptions = PushOptions(),
    report=None,
    log: Callable[[str], None] = lambda line: None,
) -> PushResult:
    """Validate (quick) and upload the dataset in ``root`` to dataset repo ``repo_id``.

    ``report``: a quick validation report already made for ``root`` (validated here if None).
    Raises PushRefused for an invalid dataset (unless ``options.force``), HubError when the Hub
    cannot be reached or refuses.
    """
    from huggingface_hub import CommitOperationAdd, CommitOperationDelete, HfApi, constants, get_token
    from huggingface_hub.hf_api import RepoFile

    root = Path(root)
    if report is None:
        from orbitdata.validate import ValidateOptions, validate

        report = validate(root, ValidateOptions(quick=True))
    if not report.ok and not options.force:
        raise PushRefused(
            f"{root} failed validation ({', '.join(report.failed())}); fix it, or pass --force to push it anyway",
            report,
        )
    plan = plan_upload(root)
    endpoint = constants.ENDPOINT
    if constants.HF_HUB_OFFLINE:
        raise HubError("offline mode is on (HF_HUB_OFFLINE=1): unset it to push to the Hub")
    token = get_token()
    if not token:
        raise HubError(f"no Hugging Face token found: {LOGIN_HINT}")
    api = HfApi(endpoint=endpoint, token=token)
    revision = options.revision or "main"
    with hub_errors(repo_id, endpoint):
        user = api.whoami().get("name", "?")
        log(f"authenticated as {user} on {endpoint}")
        # private=None (not False) leaves a new repo to the namespace's default visibility
        url = api.create_repo(repo_id, repo_type="dataset", private=True if options.private else None, exist_ok=True)
        repo_id = getattr(url, "repo_id", None) or repo_id
        if revision != "main":
            api.create_branch(repo_id, branch=revision, repo_type="dataset", exist_ok=True)
        remote = {
            f.path: f
            for f in api.list_repo_tree(repo_id, recursive=True, revision=revision, repo_type="dataset")
            if isinstance(f, RepoFile)
        }
        result = PushResult(repo_id, str(url), revision)
        todo = []
        for f in plan.files:
            if _unchanged(f, root, remote.get(f.rel)):
                result.unchanged.append(f.rel)
            else:
                todo.append(f)
        planned = {f.rel for f in plan.files}
        result.deleted = sorted(p for p in remote if _ours(p) and p not in planned)
        if result.unchanged:
            log(f"{len(result.unchanged)} file(s) already on the Hub with the same content: skipped")
        commits = batches(todo, options.commit_bytes, options.commit_files)
        if result.deleted and not commits:
            commits = [[]]
        for i, batch in enumerate(commits):
            ops = [CommitOperationAdd(path_in_repo=f.rel, path_or_fileobj=str(root / f.rel)) for f in batch]
            if i == len(commits) - 1:
                ops += [CommitOperationDelete(path_in_repo=p) for p in result.deleted]
            message = options.message if len(commits) == 1 else f"{options.message} (part {i + 1}/{len(commits)})"
            size = sum(f.bytes for f in batch)
            log(
                f"commit {i + 1}/{len(commits)}: {len(batch)} file(s), {size / 1e6:.1f} MB"
                + (
                    f", deleting {len(result.deleted)} stale file(s)"
                    if i == len(commits) - 1 and result.deleted
                    else ""
                )
            )
            info = api.create_commit(
                repo_id, operations=ops, commit_message=message, revision=revision, repo_type="dataset"
            )
            result.commits.append(info.oid)
            result.uploaded += [f.rel for f in batch]
            result.bytes += size
    return result


def preview(root: Path) -> UploadPlan:
    """What a push would upload (for --dry-run): no token, no network."""
    return plan_upload(Path(root))
