"""RESULTS.md stays a page of current answers; its dated history lives in docs/journal/.

RESULTS.md's answers are at most 320 lines, every relative link in RESULTS.md and the journal
reaches an existing file (and, with a ``#fragment``, a heading of that file), every journal file is
linked from RESULTS.md, and the docs' links into RESULTS.md's sections land on a heading."""

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "RESULTS.md"
JOURNAL = ROOT / "docs" / "journal"
MAX_ANSWER_LINES = 320

LINK = re.compile(r"\]\(([^)\s]+)\)")


def _slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation dropped, each space a hyphen."""
    text = heading.strip().lower()
    return "".join(c for c in text if c.isalnum() or c in " -_").replace(" ", "-")


def _anchors(path: Path) -> set[str]:
    """The anchors of a markdown file's headings (outside code fences), with GitHub's -1, -2 for repeats."""
    seen: dict[str, int] = {}
    anchors = set()
    fenced = False
    for line in path.read_text().splitlines():
        if line.startswith("```"):
            fenced = not fenced
            continue
        match = re.match(r"#{1,6}\s+(.*)", line)
        if fenced or not match:
            continue
        slug = _slug(match.group(1))
        count = seen.get(slug, 0)
        seen[slug] = count + 1
        anchors.add(slug if count == 0 else f"{slug}-{count}")
    return anchors


def _relative_links(path: Path) -> list[str]:
    links = []
    fenced = False
    for line in path.read_text().splitlines():
        if line.startswith("```"):
            fenced = not fenced
        elif not fenced:
            links += [t for t in LINK.findall(line) if not re.match(r"[a-z]+:", t)]
    return links


def _broken(path: Path) -> list[str]:
    """The relative links of ``path`` whose file or heading is missing."""
    broken = []
    for target in _relative_links(path):
        file, _, fragment = target.partition("#")
        dest = (path.parent / file).resolve() if file else path
        if not dest.exists():
            broken.append(f"{target} (no such file)")
        elif fragment and dest.suffix == ".md" and fragment not in _anchors(dest):
            broken.append(f"{target} (no such heading)")
    return broken


def _journal_files() -> list[Path]:
    return sorted(JOURNAL.glob("*.md"))


def test_results_is_short():
    lines = RESULTS.read_text().splitlines()
    assert len(lines) <= MAX_ANSWER_LINES, (
        f"RESULTS.md has {len(lines)} lines; history goes to docs/journal/"
    )


def test_the_journal_exists_and_is_the_dated_history():
    files = _journal_files()
    assert files, "docs/journal/ holds no markdown file"
    for path in files:
        head = "\n".join(path.read_text().splitlines()[:4]).lower()
        # dated history moved out of a page of current answers (RESULTS.md, docs/paper/README.md)
        assert re.search(r"moved from \S*(results\.md|readme\.md)", head), path.name


@pytest.mark.parametrize("path", [RESULTS, *_journal_files()], ids=lambda p: p.name)
def test_relative_links_resolve(path):
    assert _relative_links(path) or path != RESULTS, "RESULTS.md links nothing"
    assert _broken(path) == [], path.name


def test_every_journal_file_is_linked_from_results():
    linked = {
        (RESULTS.parent / t.partition("#")[0]).resolve()
        for t in _relative_links(RESULTS)
        if t.partition("#")[0]
    }
    missing = [p.name for p in _journal_files() if p.resolve() not in linked]
    assert missing == [], f"journal files not linked from RESULTS.md: {missing}"


def test_links_into_results_sections_land_on_a_heading():
    anchors = _anchors(RESULTS)
    wrong = []
    for path in [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]:
        for target in _relative_links(path):
            file, _, fragment = target.partition("#")
            if fragment and file and (path.parent / file).resolve() == RESULTS.resolve():
                if fragment not in anchors:
                    wrong.append(f"{path.relative_to(ROOT)}: {target}")
    assert wrong == []


def test_the_checks_can_fail(tmp_path):
    """The link check reports a missing file and a missing heading; the slug follows GitHub's."""
    (tmp_path / "a.md").write_text("# A title, with `code`\n\n## Same\n## Same\n")
    page = tmp_path / "b.md"
    page.write_text(
        "[ok](a.md#a-title-with-code) [ok](a.md#same-1) [bad](a.md#nothing) [gone](c.md)\n"
        "```\n[in a fence](nowhere.md)\n```\n[web](https://example.org/x)\n"
    )
    assert _broken(page) == ["a.md#nothing (no such heading)", "c.md (no such file)"]
