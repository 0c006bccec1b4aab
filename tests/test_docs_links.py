"""The documentation's links resolve, and only docs/results.md's history section reads the archive.

A reader follows a link from the README or docs/ to the JSON a figure came from; a moved or deleted
file must not leave a dead link behind. Superseded runs live in docs/results/archive/, each named
in its index (archive/README.md), and live docs cite what is reported, not the archive.
"""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ARCHIVE = "docs/results/archive"
HISTORY = "## History"

FENCE = re.compile(r"^```.*?^```", re.S | re.M)
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)\)")  # [text](target) and ![alt](target)
BACKTICK = re.compile(r"`(docs/[^`\s]+)`")  # a bare `docs/...` path
HEADING = re.compile(r"^#{1,6}\s+(.+?)\s*$", re.M)


def live_docs(root: Path) -> list[Path]:
    return [root / "README.md", *sorted((root / "docs").glob("*.md"))]


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"[^\w\- ]", "", heading.strip().lower())
    return text.replace(" ", "-")


def anchors(doc: Path) -> set[str]:
    names: set[str] = set()
    counts: dict[str, int] = {}
    for heading in HEADING.findall(FENCE.sub("", doc.read_text())):
        base = slug(heading)
        n = counts.get(base, 0)
        counts[base] = n + 1
        names.add(base if n == 0 else f"{base}-{n}")  # GitHub numbers a repeated heading
    return names


def targets(doc: Path, root: Path) -> list[tuple[int, str, Path | None, str]]:
    """(line, as written, the file it names or None for the doc itself, anchor) for each relative link."""
    text = FENCE.sub(lambda m: "\n" * m.group(0).count("\n"), doc.read_text())
    found = []
    for pattern, base in ((LINK, doc.parent), (BACKTICK, root)):
        for m in pattern.finditer(text):
            written = m.group(1)
            if re.match(r"[a-z]+:", written) or any(c in written for c in "*{}<>"):
                continue  # a URL, or a glob / placeholder rather than a path
            path, _, anchor = written.partition("#")
            line = text.count("\n", 0, m.start()) + 1
            found.append((line, written, (base / path) if path else None, anchor))
    return found


def broken_links(root: Path) -> list[str]:
    problems = []
    for doc in live_docs(root) + [root / ARCHIVE / "README.md"]:
        for line, written, path, anchor in targets(doc, root):
            where = f"{doc.relative_to(root)}:{line}: {written}"
            target = path or doc
            if not target.exists():
                problems.append(f"{where} (no such file)")
            elif anchor and target.suffix == ".md" and anchor not in anchors(target):
                problems.append(f"{where} (no heading #{anchor} there)")
    return problems


def archive_links(root: Path) -> list[str]:
    """Links into the archive from anywhere but the history section of docs/results.md."""
    archive = (root / ARCHIVE).resolve()
    problems = []
    for doc in live_docs(root):
        lines = doc.read_text().splitlines()
        history = lines.index(HISTORY) + 1 if doc.name == "results.md" and HISTORY in lines else None
        for line, written, path, _ in targets(doc, root):
            resolved = path.resolve() if path else None
            inside = resolved is not None and (resolved == archive or archive in resolved.parents)
            if inside and not (history is not None and line > history):
                problems.append(f"{doc.relative_to(root)}:{line}: {written}")
    return problems


def test_every_relative_link_in_the_docs_resolves():
    assert len([t for d in live_docs(ROOT) for t in targets(d, ROOT)]) > 100, "the link scan found too few links"
    assert broken_links(ROOT) == []


def test_only_the_history_section_of_results_md_links_into_the_archive():
    assert (ROOT / "docs/results.md").read_text().count(HISTORY) == 1
    assert archive_links(ROOT) == []


def test_every_archived_file_has_an_index_line():
    index = (ROOT / ARCHIVE / "README.md").read_text()
    named = set(re.findall(r"`([^`]+)`", index))
    archive = ROOT / ARCHIVE
    missing = []
    for path in sorted(p for p in archive.rglob("*") if p.is_file() and p.name != "README.md"):
        rel = path.relative_to(archive)
        candidates = {rel.as_posix()} | {f"{parent.as_posix()}/" for parent in rel.parents if parent != Path(".")}
        if not candidates & named:
            missing.append(rel.as_posix())
    assert missing == [], f"archived without an index line in {ARCHIVE}/README.md"


def test_the_checks_catch_a_dead_link_and_a_link_into_the_archive(tmp_path):
    (tmp_path / "docs/results/archive").mkdir(parents=True)
    (tmp_path / "docs/results/archive/README.md").write_text("# Archive\n")
    (tmp_path / "docs/results/archive/old.json").write_text("{}")
    (tmp_path / "docs/results/new.json").write_text("{}")
    (tmp_path / "README.md").write_text(
        "[ok](docs/results/new.json) [gone](docs/results/gone.json) `docs/results/also-gone.json`\n"
        "[a section](docs/model.md#no-such-heading) [old](docs/results/archive/old.json)\n"
    )
    (tmp_path / "docs/model.md").write_text("# Model\n\n[up](../README.md) [here](#model)\n")
    (tmp_path / "docs/results.md").write_text(
        "# Results\n[early](results/archive/old.json)\n\n## History\n[fine](results/archive/old.json)\n"
    )
    assert sorted(broken_links(tmp_path)) == [
        "README.md:1: docs/results/also-gone.json (no such file)",
        "README.md:1: docs/results/gone.json (no such file)",
        "README.md:2: docs/model.md#no-such-heading (no heading #no-such-heading there)",
    ]
    assert sorted(archive_links(tmp_path)) == [
        "README.md:2: docs/results/archive/old.json",
        "docs/results.md:2: results/archive/old.json",
    ]
