"""``orbitmodel push RUN REPO_ID``: a run folder as a Hugging Face model repo, with its card.

It follows ``orbitdata push``: the run is checked first and an incomplete one refused with one
line saying what is missing (``files.check_complete``); ``--dry-run`` lists the files and
prints the card without a token or a network; the token comes from the usual places
(``HF_TOKEN``, then ``hf auth login``'s file) and is never printed. One commit carries the run's
files and the card (``README.md``); pushing again uploads only what changed (LFS objects the Hub
already holds are not sent again). Text files go up with local absolute paths cut to their last
part (``files.scrub_paths``): a push publishes no home folder.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from orbitmodel.publish.card import model_card
from orbitmodel.publish.files import RunFile, check_complete, published_bytes, run_files, scrub_paths
from orbitmodel.runs import RunError

CARD = "README.md"


@dataclass(frozen=True)
class RunPushOptions:
    """How to push a run.

    Attributes:
        private: create the repo private (an existing repo keeps its visibility).
        revision: branch to push to (created from main if missing); None = main.
        message: the commit message.
        grids: folders of grid results (``eval closed-loop`` / ``orbitdata fly --json``) to
            publish under eval/grid/FOLDER/ and show on the card.
        dataset_repo: the Hub id of the dataset the run was trained on, for the card (when the
            run's config names a local folder).
    """

    private: bool = False
    revision: str | None = None
    message: str = "Upload orbitmodel run"
    grids: tuple[Path, ...] = ()
    dataset_repo: str | None = None


@dataclass(frozen=True)
class PushPlan:
    run: Path
    repo_id: str
    stage: str
    files: list[RunFile]
    card: str  # README.md's text

    @property
    def bytes(self) -> int:
        return sum(f.bytes for f in self.files) + len(self.card.encode())


@dataclass
class RunPushResult:
    repo_id: str
    url: str
    revision: str
    commit: str
    files: list[str] = field(default_factory=list)
    bytes: int = 0


def check_model_repo_id(repo_id: str) -> str:
    """``repo_id`` if it can name a model repo as ``owner/name`` (the form a run is loaded back
    by, ``runs.resolve_run``), else RunError saying the form to give."""
    from orbitdata.load.source import check_repo_id

    try:
        if repo_id.count("/") != 1:
            raise ValueError(repo_id)
        check_repo_id(repo_id)
    except ValueError:
        branch = "; a branch goes in --branch" if "@" in repo_id else ""
        raise RunError(
            f"REPO_ID {repo_id!r} cannot name a Hub model repo: give it as owner/name, each part of "
            f"letters, digits, '-', '_' and '.' (e.g. user/orbit-wm-cpu-step5){branch}"
        ) from None
    return repo_id


def plan_push(run: str | Path, repo_id: str, options: RunPushOptions = RunPushOptions()) -> PushPlan:
    """Check ``repo_id`` and ``run`` and gather what a push would upload, card included: no token,
    no network."""
    check_model_repo_id(repo_id)
    run = Path(run)
    stage = check_complete(run)
    files = run_files(run, options.grids)
    card = model_card(run, repo_id, stage, files, options.dataset_repo)
    return PushPlan(run, repo_id, stage, files, scrub_paths(str(card.content)))


def push_run(
    run: str | Path,
    repo_id: str,
    options: RunPushOptions = RunPushOptions(),
    log: Callable[[str], None] = lambda line: None,
) -> RunPushResult:
    """Upload ``run`` (see :func:`plan_push`) to the model repo ``repo_id``. Raises RunError for an
    incomplete run, ``orbitdata.publish.hub.HubError`` when the Hub cannot be reached or refuses."""
    from huggingface_hub import CommitOperationAdd, HfApi, constants, get_token

    from orbitdata.publish.hub import LOGIN_HINT, HubError, hub_errors

    plan = plan_push(run, repo_id, options)
    if constants.HF_HUB_OFFLINE:
        raise HubError("offline mode is on (HF_HUB_OFFLINE=1): unset it to push to the Hub")
    token = get_token()
    if not token:
        raise HubError(f"no Hugging Face token found: {LOGIN_HINT}")
    api = HfApi(endpoint=constants.ENDPOINT, token=token)
    revision = options.revision or "main"
    with hub_errors(repo_id, constants.ENDPOINT):
        log(f"authenticated as {api.whoami().get('name', '?')} on {constants.ENDPOINT}")
        url = api.create_repo(repo_id, repo_type="model", private=True if options.private else None, exist_ok=True)
        repo_id = getattr(url, "repo_id", None) or repo_id
        if revision != "main":
            api.create_branch(repo_id, branch=revision, repo_type="model", exist_ok=True)
        ops = [CommitOperationAdd(path_in_repo=f.rel, path_or_fileobj=published_bytes(f)) for f in plan.files]
        ops.append(CommitOperationAdd(path_in_repo=CARD, path_or_fileobj=plan.card.encode()))
        log(f"commit: {len(ops)} file(s), {plan.bytes / 1e6:.1f} MB")
        info = api.create_commit(
            repo_id, operations=ops, commit_message=options.message, revision=revision, repo_type="model"
        )
    return RunPushResult(repo_id, str(url), revision, info.oid, [f.rel for f in plan.files] + [CARD], plan.bytes)
