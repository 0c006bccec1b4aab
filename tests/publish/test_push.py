"""`orbitdata push` against a local HTTP server that speaks the Hub's API, through the real client."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from hub_server import TOKEN, subprocess_env
from typer.testing import CliRunner

from orbitdata import schema as S
from orbitdata.cli.app import app
from orbitdata.publish import HubError, PushOptions, PushRefused, push

REPO = "tester/orbit"
runner = CliRunner()


def dataset_files(root: Path) -> dict[str, bytes]:
    info = json.loads((root / S.INFO_PATH).read_text())
    return {rel: (root / rel).read_bytes() for rel in [*info["files"], S.INFO_PATH]}


def assert_no_token(*texts: str) -> None:
    for text in texts:
        assert TOKEN not in text
        assert TOKEN[3:15] not in text  # not even a slice of it


LOAD = r"""
import json, sys
from datasets import load_dataset
from huggingface_hub import snapshot_download
from orbitdata.validate import ValidateOptions, validate
steps = load_dataset(sys.argv[1])
episodes = load_dataset(sys.argv[1], "episodes")
snap = snapshot_download(sys.argv[1], repo_type="dataset", local_dir=sys.argv[2])
report = validate(snap, ValidateOptions(workers=1))
print(json.dumps({"steps": {k: v.num_rows for k, v in steps.items()},
                  "episodes": {k: v.num_rows for k, v in episodes.items()},
                  "image": list(steps["train"][0][sys.argv[3]].size),
                  "snapshot_valid": report.ok, "failed": report.failed()}))
"""


def test_push_end_to_end_then_load_dataset(hub, tiny_dataset_master, tmp_path):
    """The CLI pushes with the real client; plain load_dataset(REPO_ID) reads it back."""
    env = subprocess_env(hub, tmp_path / "hf_home")
    cmd = [sys.executable, "-m", "orbitdata.cli.app", "push", str(tiny_dataset_master), REPO]
    pushed = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=240)
    assert pushed.returncode == 0, pushed.stderr
    assert "validate --quick: valid" in pushed.stdout and f'load_dataset("{REPO}")' in pushed.stdout
    assert hub.files(REPO) == dataset_files(tiny_dataset_master)  # the uploaded set is the dataset, byte for byte

    loaded = subprocess.run(
        [sys.executable, "-c", LOAD, REPO, str(tmp_path / "snapshot"), S.IMAGE],
        env=env,
        capture_output=True,
        text=True,
        timeout=240,
    )
    assert loaded.returncode == 0, loaded.stderr[-3000:]
    result = json.loads(loaded.stdout.strip().splitlines()[-1])
    counts = json.loads((tiny_dataset_master / S.INFO_PATH).read_text())["counts"]["splits"]
    assert result["steps"] == {s: c["frames"] for s, c in counts.items()}
    assert result["episodes"] == {s: c["episodes"] for s, c in counts.items()}
    assert result["image"] == [64, 64]
    assert result["snapshot_valid"], result["failed"]  # a downloaded snapshot validates (Hub extras tolerated)

    assert_no_token(pushed.stdout, pushed.stderr, loaded.stdout, loaded.stderr)
    for path in (tmp_path / "hf_home").rglob("*"):  # caches, logs: anything the client wrote
        if path.is_file() and path.name != "token":
            assert_no_token(path.read_bytes().decode("latin-1"))


def test_push_in_several_commits_resumes_after_an_interruption(hub_client, tiny_dataset_master):
    hub = hub_client
    options = PushOptions(commit_files=2, message="orbit")
    hub.state.fail_commit = 2  # the Hub goes away during the second commit
    with pytest.raises(HubError, match="run the same command again to resume"):
        push(tiny_dataset_master, REPO, options)
    first = set(hub.files(REPO))
    assert first and first < set(dataset_files(tiny_dataset_master))
    assert S.INFO_PATH not in first  # meta/info.json goes last: a partial repo never looks complete

    hub.state.fail_commit = None
    result = push(tiny_dataset_master, REPO, options)
    assert set(result.unchanged) == first  # resumed: what went up before is not sent again
    assert hub.files(REPO) == dataset_files(tiny_dataset_master)
    messages = hub.state.repos["datasets", REPO].messages
    assert messages == ["orbit (part 1/3)", "orbit (part 1/2)", "orbit (part 2/2)"]  # part 2/3 was cut
    puts = [path for method, path, _ in hub.state.requests if method == "PUT"]
    assert len(puts) == len(set(puts))  # no blob crossed the wire twice

    again = push(tiny_dataset_master, REPO, options)  # nothing changed: nothing to commit
    assert again.commits == [] and len(again.unchanged) == len(dataset_files(tiny_dataset_master))


def test_invalid_dataset_is_refused_unless_forced(hub_client, tiny_dataset):
    with open(tiny_dataset / S.CARD_PATH, "a") as f:
        f.write("\nedited after generation\n")
    result = runner.invoke(app, ["push", str(tiny_dataset), REPO])
    assert result.exit_code == 1
    assert "refusing to push" in result.output and "FAIL  files.sha256" in result.output
    assert not any(path == "/api/repos/create" for _, path, _ in hub_client.state.requests)
    with pytest.raises(PushRefused):
        push(tiny_dataset, REPO)

    forced = runner.invoke(app, ["push", str(tiny_dataset), REPO, "--force"])
    assert forced.exit_code == 0, forced.output
    assert hub_client.files(REPO) == dataset_files(tiny_dataset)
    assert_no_token(result.output, forced.output)


def test_dry_run_lists_files_sizes_and_card_without_the_hub(hub_client, tiny_dataset_master, monkeypatch):
    monkeypatch.delenv("HF_TOKEN")
    result = runner.invoke(app, ["push", str(tiny_dataset_master), REPO, "--dry-run"])
    assert result.exit_code == 0, result.output
    for rel in dataset_files(tiny_dataset_master):
        assert rel in result.output
    assert "dry run: would push" in result.output and "license: cc-by-4.0" in result.output
    assert hub_client.state.requests == []


def test_push_to_a_branch(hub_client, tiny_dataset_master):
    result = runner.invoke(
        app, ["push", str(tiny_dataset_master), REPO, "--branch", "v1", "--private", "--message", "first release"]
    )
    assert result.exit_code == 0, result.output
    repo = hub_client.state.repos["datasets", REPO]
    assert repo.private and hub_client.files(REPO, "v1") == dataset_files(tiny_dataset_master)
    assert hub_client.files(REPO, "main") == {} and repo.messages == ["first release"]
    assert "revision='v1'" in result.output


def test_repush_of_a_resharded_dataset_removes_stale_shards_and_keeps_the_users_files(hub_client, tiny_dataset):
    from huggingface_hub import HfApi

    from orbitdata.viz import overview_figure
    from orbitdata.write.finalize import finalize

    push(tiny_dataset, REPO)
    mine = {"meta/notes.md": b"how we use it\n", "data/README.txt": b"the shards\n"}  # added on the Hub by hand
    for rel, data in mine.items():
        HfApi().upload_file(path_or_fileobj=data, path_in_repo=rel, repo_id=REPO, repo_type="dataset")
    finalize(
        tiny_dataset, max_shard_bytes=100_000, figure=overview_figure
    )  # several smaller shards replace each split's one
    result = push(tiny_dataset, REPO)
    assert result.deleted == [S.shard_path(S.DATA_DIR, "test", 0, 1), S.shard_path(S.DATA_DIR, "train", 0, 1)]
    assert hub_client.files(REPO) == {**dataset_files(tiny_dataset), **mine}


@pytest.mark.parametrize(
    "problem, hint",
    [
        ("no token", "hf auth login"),
        ("stored token", None),
        ("bad token", "rejected the token (401)"),
        ("no write access", "write access"),
        ("offline", "HF_HUB_OFFLINE"),
        ("unreachable", "cannot reach the Hub"),
    ],
)
def test_hub_problems_give_one_clear_line(hub_client, tiny_dataset_master, monkeypatch, tmp_path, problem, hint):
    from huggingface_hub import constants

    if problem in ("no token", "stored token"):
        monkeypatch.delenv("HF_TOKEN")
        if problem == "stored token":  # what `hf auth login` leaves behind works as well
            Path(constants.HF_TOKEN_PATH).write_text(TOKEN)
    elif problem == "bad token":
        monkeypatch.setenv("HF_TOKEN", "hf_wrong")
    elif problem == "no write access":
        hub_client.state.refuse["create_repo"] = 403
    elif problem == "offline":
        monkeypatch.setattr(constants, "HF_HUB_OFFLINE", True)
    elif problem == "unreachable":
        hub_client.httpd.shutdown()
        hub_client.httpd.server_close()
    result = runner.invoke(app, ["push", str(tiny_dataset_master), REPO])
    assert_no_token(result.output)
    if hint is None:
        assert result.exit_code == 0, result.output
        return
    assert result.exit_code == 1, result.output
    error = [line for line in result.output.splitlines() if line.startswith("error:")]
    assert len(error) == 1 and hint in error[0], result.output
    assert "Traceback" not in result.output


@pytest.mark.parametrize(
    "args", [["not a repo id"], ["a/b/c"], ["orbit", "--dry-run"], ["tester/orbit", "--revision", " "]]
)
def test_usage_errors_exit_2(tiny_dataset_master, args):
    result = runner.invoke(app, ["push", str(tiny_dataset_master), *args])
    assert result.exit_code == 2, result.output


def test_missing_folder_exits_2(tmp_path):
    assert runner.invoke(app, ["push", str(tmp_path / "nope"), REPO]).exit_code == 2


def test_a_dry_run_says_when_the_cards_snippet_names_another_repo(hub_client, tiny_dataset_master, monkeypatch):
    monkeypatch.delenv("HF_TOKEN")
    result = runner.invoke(app, ["push", str(tiny_dataset_master), "someone/elsewhere", "--dry-run"])
    assert result.exit_code == 0, result.output
    assert "`orbitdata shard" in result.output and "--repo-id someone/elsewhere` rewrites it" in result.output
