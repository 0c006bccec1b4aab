"""A local stand-in for the Hugging Face Hub: enough of its HTTP API for the real client.

It serves what ``huggingface_hub`` (with ``HF_HUB_DISABLE_XET=1``: plain LFS, no Xet storage)
calls to create a dataset repo and commit to it, and what ``datasets.load_dataset`` and
``snapshot_download`` call to read it back:

    GET  /api/whoami-v2                                    who the token belongs to
    POST /api/repos/create                                 create a repo
    POST /api/validate-yaml                                the card check before a commit
    POST /api/datasets/{repo}/preupload/{rev}              regular or LFS, and the remote oid
    POST /datasets/{repo}.git/info/lfs/objects/batch       LFS batch: where to PUT each object
    PUT  /lfs-objects/{oid}                                the object itself (sha256 checked)
    POST /api/datasets/{repo}/commit/{rev}                 NDJSON commit
    POST /api/datasets/{repo}/branch/{branch}              create a branch
    GET  /api/datasets/{repo}[/revision/{rev}]             repo info (sha, siblings)
    GET  /api/datasets/{repo}/tree/{rev}[/{path}]          file listing
    POST /api/datasets/{repo}/paths-info/{rev}             info on given paths
    GET  /api/datasets/{repo}/refs                         branches
    HEAD/GET /datasets/{repo}/resolve/{rev}/{path}         file download (ETag, Range)

Everything lives in memory. ``requests`` records every call (method, path, status) and
``bodies`` every request body, so tests can look for a leaked token anywhere.
"""

from __future__ import annotations

import base64
import hashlib
import json
import os
import re
import threading
from dataclasses import dataclass, field
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from urllib.parse import parse_qs, unquote, urlparse

# Looks like a real token so that a leak would be easy to spot; it only opens the test Hub.
TOKEN = "hf_OrbitdataTestToken0123456789abcdefXYZ"
LFS_SUFFIXES = (".parquet", ".png", ".jpg", ".arrow", ".bin", ".safetensors")
KINDS = {"dataset": "datasets", "model": "models", "space": "spaces"}  # create_repo's "type" -> URL segment
EMPTY_COMMIT = "0" * 40


def git_oid(data: bytes) -> str:
    return hashlib.sha1(b"blob %d\0" % len(data) + data).hexdigest()


@dataclass
class Blob:
    data: bytes
    lfs: bool

    @property
    def sha256(self) -> str:
        return hashlib.sha256(self.data).hexdigest()

    def pointer(self) -> bytes:
        return f"version https://git-lfs.github.com/spec/v1\noid sha256:{self.sha256}\nsize {len(self.data)}\n".encode()

    def entry(self, path: str) -> dict:
        out = {
            "type": "file",
            "path": path,
            "size": len(self.data),
            "oid": git_oid(self.pointer() if self.lfs else self.data),
        }
        if self.lfs:
            out["lfs"] = {"oid": self.sha256, "size": len(self.data), "pointerSize": len(self.pointer())}
        return out


@dataclass
class Repo:
    repo_id: str
    private: bool
    branches: dict = field(default_factory=lambda: {"main": EMPTY_COMMIT})
    commits: dict = field(default_factory=lambda: {EMPTY_COMMIT: {}})  # sha -> {path: Blob}
    messages: list = field(default_factory=list)  # commit summaries, oldest first

    def resolve(self, rev: str) -> str | None:
        if rev in self.branches:
            return self.branches[rev]
        return rev if rev in self.commits else None


class HubState:
    def __init__(self, token: str, user: str):
        self.token, self.user = token, user
        self.repos: dict[str, Repo] = {}
        self.lfs: dict[str, bytes] = {}
        self.requests: list[tuple[str, str, int]] = []
        self.bodies: list[bytes] = []
        self.refuse: dict[str, int] = {}  # route name -> status to answer with (simulated Hub refusals)
        self.fail_commit: int | None = None  # answer the n-th commit request (1-based) with a 503
        self.commit_requests = 0
        self.lock = threading.RLock()  # handlers answer while holding it; _send records under it too


class Handler(BaseHTTPRequestHandler):
    protocol_version = "HTTP/1.1"
    state: HubState  # set on the subclass made by HubServer
    endpoint: str

    # ---- plumbing ------------------------------------------------------------------------
    def log_message(self, *args) -> None:  # quiet
        pass

    def _body(self) -> bytes:
        n = int(self.headers.get("Content-Length") or 0)
        body = self.rfile.read(n) if n else b""
        with self.state.lock:
            self.state.bodies.append(body)
        return body

    def _send(
        self, status: int, body: bytes = b"", headers: dict | None = None, content_type="application/json"
    ) -> None:
        with self.state.lock:
            self.state.requests.append((self.command, urlparse(self.path).path, status))
        self.send_response(status)
        self.send_header("Content-Type", content_type)
        self.send_header("Content-Length", str(len(body)))
        for k, v in (headers or {}).items():
            self.send_header(k, v)
        self.end_headers()
        if body and self.command != "HEAD":  # a HEAD answer has headers only, or keep-alive desyncs
            self.wfile.write(body)

    def _json(self, status: int, obj, headers: dict | None = None) -> None:
        self._send(status, json.dumps(obj).encode(), headers)

    def _error(self, status: int, message: str, code: str | None = None) -> None:
        headers = {"X-Error-Message": message}
        if code:
            headers["X-Error-Code"] = code
        self._json(status, {"error": message}, headers)

    def _authorized(self) -> bool:
        return self.headers.get("Authorization", "") == f"Bearer {self.state.token}"

    def _repo(self, kind: str, repo_id: str, write: bool = False) -> Repo | None:
        repo = self.state.repos.get((kind, repo_id))
        if repo is None or (repo.private and not self._authorized()):
            self._error(404, "Repository not found", "RepoNotFound")
            return None
        if write and not self._authorized():
            self._error(401, "Invalid credentials in Authorization header")
            return None
        return repo

    def _refused(self, route: str) -> bool:
        status = self.state.refuse.get(route)
        if status:
            self._error(status, f"refused by the test Hub ({route})")
            return True
        return False

    # ---- routes --------------------------------------------------------------------------
    # Dataset repos live under /datasets/ and /api/datasets/; model repos under /api/models/ and at
    # the top level (/{owner}/{name}/resolve/..., /{owner}/{name}.git/...): an empty kind group.
    ROUTES = [
        ("GET", r"^/api/whoami-v2$", "whoami"),
        ("POST", r"^/api/repos/create$", "create_repo"),
        ("POST", r"^/api/validate-yaml$", "validate_yaml"),
        ("POST", r"^/api/(datasets|models)/([^/]+/[^/]+)/preupload/(.+)$", "preupload"),
        ("POST", r"^/(datasets)/([^/]+/[^/]+)\.git/info/lfs/objects/batch$", "lfs_batch"),
        ("POST", r"^/()([^/]+/[^/]+)\.git/info/lfs/objects/batch$", "lfs_batch"),
        ("PUT", r"^/lfs-objects/([0-9a-f]{64})$", "lfs_put"),
        ("POST", r"^/api/(datasets|models)/([^/]+/[^/]+)/commit/(.+)$", "commit"),
        ("POST", r"^/api/(datasets|models)/([^/]+/[^/]+)/branch/(.+)$", "branch"),
        ("GET", r"^/api/(datasets|models)/([^/]+/[^/]+)/refs$", "refs"),
        ("GET", r"^/api/(datasets|models)/([^/]+/[^/]+)/tree/([^/]+)/?(.*)$", "tree"),
        ("POST", r"^/api/(datasets|models)/([^/]+/[^/]+)/paths-info/(.+)$", "paths_info"),
        ("GET", r"^/api/(datasets|models)/([^/]+/[^/]+)/revision/(.+)$", "info"),
        ("GET", r"^/api/(datasets|models)/([^/]+/[^/]+)$", "info"),
        ("GET", r"^/(datasets)/([^/]+/[^/]+)/resolve/([^/]+)/(.+)$", "resolve"),
        ("HEAD", r"^/(datasets)/([^/]+/[^/]+)/resolve/([^/]+)/(.+)$", "resolve"),
        ("GET", r"^/()([^/]+/[^/]+)/resolve/([^/]+)/(.+)$", "resolve"),
        ("HEAD", r"^/()([^/]+/[^/]+)/resolve/([^/]+)/(.+)$", "resolve"),
    ]

    def _route(self) -> None:
        path = urlparse(self.path).path
        for method, pattern, name in self.ROUTES:
            m = re.match(pattern, path)
            if m and method == self.command:
                groups = [unquote(g) if g is not None else g for g in m.groups()]
                if groups and groups[0] == "":  # a top-level path: a model repo
                    groups[0] = "models"
                return getattr(self, name)(*groups)
        self._body()
        self._error(404, f"no such endpoint in the test Hub: {self.command} {path}")

    do_GET = do_POST = do_PUT = do_HEAD = _route

    def whoami(self) -> None:
        if self._refused("whoami"):
            return
        if not self._authorized():
            return self._error(401, "Invalid credentials in Authorization header")
        self._json(
            200,
            {
                "type": "user",
                "name": self.state.user,
                "fullname": self.state.user,
                "orgs": [],
                "auth": {"type": "access_token", "accessToken": {"displayName": "test", "role": "write"}},
            },
        )

    def create_repo(self) -> None:
        body = json.loads(self._body() or b"{}")
        if self._refused("create_repo"):
            return
        if not self._authorized():
            return self._error(401, "Invalid credentials in Authorization header")
        repo_id = f"{body.get('organization') or self.state.user}/{body['name']}"
        kind = KINDS.get(body.get("type"), "models")  # the client sends no type for a model repo
        url = f"{self.endpoint}/{'' if kind == 'models' else kind + '/'}{repo_id}"
        with self.state.lock:
            if (kind, repo_id) in self.state.repos:
                return self._json(409, {"error": f"You already created this {kind[:-1]} repo", "url": url})
            private = body.get("visibility") == "private" or bool(body.get("private"))
            self.state.repos[(kind, repo_id)] = Repo(repo_id, private)
        self._json(200, {"url": url, "name": repo_id, "id": repo_id})

    def validate_yaml(self) -> None:
        self._body()
        self._json(200, {"errors": [], "warnings": []})

    def preupload(self, kind, repo_id, rev) -> None:
        body = json.loads(self._body() or b"{}")
        repo = self._repo(kind, repo_id, write=True)
        if repo is None:
            return
        tree = repo.commits.get(repo.resolve(rev) or EMPTY_COMMIT, {})
        files = []
        for f in body.get("files", []):
            lfs = f["path"].endswith(LFS_SUFFIXES)
            blob = tree.get(f["path"])
            oid = None if blob is None else (blob.sha256 if blob.lfs else git_oid(blob.data))
            files.append(
                {"path": f["path"], "uploadMode": "lfs" if lfs else "regular", "shouldIgnore": False, "oid": oid}
            )
        self._json(200, {"files": files, "commitOid": repo.resolve(rev)})

    def lfs_batch(self, kind, repo_id) -> None:
        body = json.loads(self._body() or b"{}")
        repo = self._repo(kind, repo_id, write=True)
        if repo is None:
            return
        objects = []
        for obj in body.get("objects", []):
            entry = {"oid": obj["oid"], "size": obj["size"]}
            if obj["oid"] not in self.state.lfs:
                entry["actions"] = {"upload": {"href": f"{self.endpoint}/lfs-objects/{obj['oid']}"}}
            objects.append(entry)
        self._send(
            200,
            json.dumps({"transfer": "basic", "objects": objects}).encode(),
            content_type="application/vnd.git-lfs+json",
        )

    def lfs_put(self, oid) -> None:
        data = self._body()
        if hashlib.sha256(data).hexdigest() != oid:
            return self._error(400, "sha256 mismatch")
        with self.state.lock:
            self.state.lfs[oid] = data
        self._send(200)

    def commit(self, kind, repo_id, rev) -> None:
        lines = [json.loads(line) for line in self._body().splitlines() if line.strip()]
        if self._refused("commit"):
            return
        with self.state.lock:
            self.state.commit_requests += 1
            interrupted = self.state.commit_requests == self.state.fail_commit
        if interrupted:
            return self._error(503, "Service temporarily unavailable (a simulated interruption)")
        repo = self._repo(kind, repo_id, write=True)
        if repo is None:
            return
        with self.state.lock:
            parent = repo.resolve(rev)
            if parent is None:
                return self._error(404, f"Invalid rev id: {rev}", "RevisionNotFound")
            tree = dict(repo.commits[parent])
            summary = ""
            for item in lines:
                key, value = item["key"], item["value"]
                if key == "header":
                    summary = value.get("summary", "")
                elif key == "file":
                    tree[value["path"]] = Blob(base64.b64decode(value["content"]), lfs=False)
                elif key == "lfsFile":
                    if value["oid"] not in self.state.lfs:
                        return self._error(422, f"LFS object {value['oid']} was never uploaded")
                    tree[value["path"]] = Blob(self.state.lfs[value["oid"]], lfs=True)
                elif key == "deletedFile":
                    tree.pop(value["path"], None)
                elif key == "deletedFolder":
                    prefix = value["path"].rstrip("/") + "/"
                    tree = {p: b for p, b in tree.items() if not p.startswith(prefix)}
            sha = hashlib.sha1(
                json.dumps([parent, summary, sorted((p, b.sha256) for p, b in tree.items())]).encode()
            ).hexdigest()
            repo.commits[sha] = tree
            repo.branches[rev if rev in repo.branches else "main"] = sha
            repo.messages.append(summary)
        prefix = "" if kind == "models" else f"{kind}/"
        self._json(
            200,
            {"commitUrl": f"{self.endpoint}/{prefix}{repo_id}/commit/{sha}", "commitOid": sha, "pullRequestUrl": None},
        )

    def branch(self, kind, repo_id, name) -> None:
        body = json.loads(self._body() or b"{}")
        repo = self._repo(kind, repo_id, write=True)
        if repo is None:
            return
        with self.state.lock:
            if name in repo.branches:
                return self._error(409, f"Branch {name} already exists")
            start = repo.resolve(body.get("startingPoint") or "main")
            repo.branches[name] = start
        self._json(200, {})

    def refs(self, kind, repo_id) -> None:
        repo = self._repo(kind, repo_id)
        if repo is None:
            return
        self._json(
            200,
            {
                "branches": [
                    {"name": n, "ref": f"refs/heads/{n}", "targetCommit": s} for n, s in repo.branches.items()
                ],
                "converts": [],
                "tags": [],
            },
        )

    def _tree(self, kind, repo_id, rev):
        repo = self._repo(kind, repo_id)
        if repo is None:
            return None, None
        sha = repo.resolve(rev)
        if sha is None:
            self._error(404, f"Invalid rev id: {rev}", "RevisionNotFound")
            return None, None
        return sha, repo.commits[sha]

    def info(self, kind, repo_id, rev="main") -> None:
        sha, tree = self._tree(kind, repo_id, rev)
        if tree is None:
            return
        repo = self.state.repos[(kind, repo_id)]
        self._json(
            200,
            {
                "id": repo_id,
                "_id": repo_id,
                "author": repo_id.split("/")[0],
                "sha": sha,
                "private": repo.private,
                "gated": False,
                "disabled": False,
                "downloads": 0,
                "likes": 0,
                "tags": [],
                "lastModified": "2026-01-01T00:00:00.000Z",
                "createdAt": "2026-01-01T00:00:00.000Z",
                "siblings": [{"rfilename": p} for p in sorted(tree)],
            },
        )

    def tree(self, kind, repo_id, rev, path) -> None:
        sha, tree = self._tree(kind, repo_id, rev)
        if tree is None:
            return
        recursive = parse_qs(urlparse(self.path).query).get("recursive", ["false"])[0].lower() in ("1", "true")
        prefix = path.strip("/")
        if prefix and prefix in tree:
            return self._json(200, [tree[prefix].entry(prefix)])
        base = prefix + "/" if prefix else ""
        if prefix and not any(p.startswith(base) for p in tree):
            return self._error(404, f"{path} does not exist on {rev}", "EntryNotFound")
        entries, dirs = [], set()
        for p in sorted(tree):
            if not p.startswith(base):
                continue
            rest = p[len(base) :].split("/")
            for depth in range(1, len(rest)):
                d = base + "/".join(rest[:depth])
                if (recursive or depth == 1) and d not in dirs:
                    dirs.add(d)
                    entries.append({"type": "directory", "path": d, "oid": git_oid(d.encode()), "size": 0})
            if recursive or len(rest) == 1:
                entries.append(tree[p].entry(p))
        self._json(200, entries)

    def paths_info(self, kind, repo_id, rev) -> None:
        raw = self._body()
        ctype = self.headers.get("Content-Type", "")
        if "json" in ctype:
            paths = json.loads(raw or b"{}").get("paths", [])
        else:
            paths = parse_qs(raw.decode()).get("paths", [])
        sha, tree = self._tree(kind, repo_id, rev)
        if tree is None:
            return
        out = []
        for path in paths:
            path = path.strip("/")
            if path in tree:
                out.append(tree[path].entry(path))
            elif any(p.startswith(path + "/") for p in tree):
                out.append({"type": "directory", "path": path, "oid": git_oid(path.encode()), "size": 0})
        self._json(200, out)

    def resolve(self, kind, repo_id, rev, path) -> None:
        sha, tree = self._tree(kind, repo_id, rev)
        if tree is None:
            return
        blob = tree.get(path)
        if blob is None:
            return self._error(404, f"Entry not found: {path}", "EntryNotFound")
        etag = blob.sha256 if blob.lfs else git_oid(blob.data)
        headers = {"X-Repo-Commit": sha, "ETag": f'"{etag}"', "Accept-Ranges": "bytes"}
        if blob.lfs:
            headers.update({"X-Linked-Etag": f'"{etag}"', "X-Linked-Size": str(len(blob.data))})
        data, status = blob.data, 200
        m = re.match(r"bytes=(\d+)-(\d*)$", self.headers.get("Range", ""))
        if m and self.command == "GET":
            start = int(m.group(1))
            end = int(m.group(2)) if m.group(2) else len(data) - 1
            data, status = data[start : end + 1], 206
            headers["Content-Range"] = f"bytes {start}-{start + len(data) - 1}/{len(blob.data)}"
        self._send(status, data, headers, content_type="application/octet-stream")


class HubServer:
    """A running test Hub on 127.0.0.1 (random port). Use as a context manager."""

    def __init__(self, token: str, user: str = "tester"):
        self.state = HubState(token, user)
        handler = type("BoundHandler", (Handler,), {"state": self.state})
        self.httpd = ThreadingHTTPServer(("127.0.0.1", 0), handler)
        self.url = f"http://127.0.0.1:{self.httpd.server_address[1]}"
        handler.endpoint = self.url
        self.thread = threading.Thread(target=self.httpd.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True)

    def __enter__(self) -> "HubServer":
        self.thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()

    def files(self, repo_id: str, rev: str = "main", kind: str = "datasets") -> dict[str, bytes]:
        repo = self.state.repos[(kind, repo_id)]
        return {p: b.data for p, b in repo.commits[repo.resolve(rev)].items()}


def subprocess_env(hub: HubServer, home, token: str | None = TOKEN) -> dict:
    """Environment for a child process that uses the test Hub, as a user with HF_TOKEN set would."""
    env = {k: v for k, v in os.environ.items() if not k.startswith(("HF_", "HUGGING"))}
    env.update(
        HF_ENDPOINT=hub.url,
        HF_HUB_DISABLE_XET="1",
        HF_HUB_OFFLINE="0",
        HF_DATASETS_OFFLINE="0",
        HF_HOME=str(home),
        HF_HUB_DISABLE_TELEMETRY="1",
        MUJOCO_GL=os.environ.get("MUJOCO_GL", "egl"),
    )
    if token:
        env["HF_TOKEN"] = token
    return env
