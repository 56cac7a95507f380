"""The user's guide and docs/: every relative link resolves (file and #anchor), README.md stays a guide
(at most 350 lines, the two commands exactly as CI and the tests run them), and the docs describe the code,
never the project's history (sessions, issue numbers, commit hashes, dates of work)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README_MAX_LINES = 350
TWO_COMMANDS = (
    "pip install '.[test]' && rtloop-fit examples/yellow-ball/scene_input.json examples/yellow-ball/objective.png"
    " --out out/yellow-ball --force --report --truth examples/yellow-ball/scene.json",
    "cargo test && python3 -m pytest",
)

#: Words that tell the project's history rather than what the code does.
HISTORY = re.compile(
    r"\bsessions?\b|\bfiling\b|\bissues?[ -]?#?\d|\bthe issue\b|\bissue's\b|tried and rejected"
    r"|\b20\d\d-\d\d-\d\d\b",
    re.IGNORECASE,
)
#: A commit hash: 7-40 hex digits with a letter and a digit, or 7 digits alone, not part of a decimal number.
HASH = re.compile(r"(?<![\w.])(?:(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}|[0-9]{7})(?![\w.])")
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
FENCE = re.compile(r"^(```|~~~).*?^\1", re.MULTILINE | re.DOTALL)
CODE = re.compile(r"`[^`\n]*`")


def doc_files(root: Path) -> list[Path]:
    """README.md and every markdown file under docs/."""
    return [root / "README.md", *sorted((root / "docs").rglob("*.md"))]


def _prose(text: str) -> str:
    """The text outside code fences and inline code, where links live."""
    return CODE.sub("", FENCE.sub("", text))


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = re.sub(r"[`*_]", "", heading.strip().lower())
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    text = FENCE.sub("", path.read_text(encoding="utf-8"))
    return {slug(m.group(1)) for m in re.finditer(r"^#{1,6}\s+(.+?)\s*#*$", text, re.MULTILINE)}


def broken_links(root: Path) -> list[str]:
    """Every relative link in the docs whose file, or whose #anchor in a markdown file, does not exist."""
    bad = []
    for doc in doc_files(root):
        for target in LINK.findall(_prose(doc.read_text(encoding="utf-8"))):
            if re.match(r"^[a-z][a-z0-9+.-]*:", target, re.IGNORECASE):  # http:, mailto:, ...
                continue
            file_part, _, anchor = target.partition("#")
            dest = (doc.parent / file_part).resolve() if file_part else doc
            where = f"{doc.relative_to(root)}: {target}"
            if not dest.exists():
                bad.append(f"{where} (no such file)")
            elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
                bad.append(f"{where} (no such heading)")
    return bad


def history_mentions(root: Path, files: list[Path] | None = None) -> list[str]:
    """Lines that speak of the project's history: sessions, the filing, issue numbers, commit hashes, dates."""
    hits = []
    for path in files if files is not None else doc_files(root):
        for n, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            for pattern in (HISTORY, HASH):
                m = pattern.search(line)
                if m:
                    hits.append(f"{path.relative_to(root)}:{n}: {m.group(0)!r}")
    return hits


def test_every_relative_link_resolves():
    assert broken_links(ROOT) == []


def test_readme_is_a_short_users_guide_with_the_two_commands():
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(text.splitlines()) <= README_MAX_LINES
    for command in TWO_COMMANDS:
        assert command in text.splitlines(), command


def test_docs_do_not_tell_the_projects_history():
    assert history_mentions(ROOT) == []


#: Where figures are kept: speed (benches), accuracy studies and the fuzz campaign.
RESULTS = ("benches/results", "studies/results", "fuzz/results")


def test_results_files_do_not_tell_the_projects_history():
    results = sorted(p for d in RESULTS for p in (ROOT / d).rglob("*.md"))
    assert results and history_mentions(ROOT, results) == []


def test_results_files_start_with_their_command():
    for path in sorted(p for d in RESULTS for p in (ROOT / d).rglob("*.md")):
        first = path.read_text(encoding="utf-8").lstrip().splitlines()[0]
        assert re.search(r"`(python3? |PYTHONPATH=\S+ python3? |cargo )[^`]*`", first), (path, first)


@pytest.fixture
def faulty_tree(tmp_path: Path) -> Path:
    """A copy of the docs with one of each fault planted."""
    (tmp_path / "docs").mkdir()
    (tmp_path / "README.md").write_text(
        "# Guide\n\n[ok](docs/a.md#part-two) [gone](docs/missing.md) [bad anchor](docs/a.md#nowhere)\n"
        "`[in code](docs/missing-too.md)` [web](https://example.org/x)\n", encoding="utf-8")
    (tmp_path / "docs" / "a.md").write_text(
        "# A\n\n## Part two\n\nMeasured in the sixth session at 8549049, after issue 12's target; see "
        "c3b8429 (2026-12-03). Not hits: 0.0031308, 1e-7, 20 480 triangles, added.\n", encoding="utf-8")
    return tmp_path


def test_the_checks_catch_what_they_are_for(faulty_tree: Path):
    assert broken_links(faulty_tree) == ["README.md: docs/missing.md (no such file)",
                                         "README.md: docs/a.md#nowhere (no such heading)"]
    line = "docs/a.md:5: "
    hits = history_mentions(faulty_tree)
    assert hits == [line + "'session'", line + "'8549049'"]  # the first hit of each pattern on the line
    text = (faulty_tree / "docs" / "a.md").read_text(encoding="utf-8")
    found = [m.group(0) for p in (HISTORY, HASH) for m in p.finditer(text)]
    assert found == ["session", "issue 1", "2026-12-03", "8549049", "c3b8429"]
