"""Every relative link and image in the documentation resolves: the file exists and an #anchor names a heading.

The README is an entry that links into docs/; pages move and headings change, and a broken link is found by a reader
long after the change that broke it. Checked: every Markdown file at the repository's root, under docs/ (recursively)
and each package's src/<pkg>/README.md. A link is checked when its target has no scheme (http:, mailto: ...): the path,
relative to the file that holds the link, must exist (a file or a folder), and an anchor into a Markdown file (or into
the same file, `#anchor`) must match one of its headings by GitHub's slug rules. Links inside code (fenced blocks and
inline spans) are text, not links. No ROS, no network: a core test.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.core

REPO = Path(__file__).resolve().parents[3]
#: Pages that are linked before they are committed -> why. Their links are let through while the file is missing;
#: once it exists the entry must go (test_pending_pages_are_still_missing), and its links are checked like any other.
PENDING: dict = {}  # files linked before they exist (path: why); the test below fails once they do

FENCE = re.compile(r"^ {0,3}(`{3,}|~{3,})")
INLINE_CODE = re.compile(r"(`+)(?:(?!\1).)+?\1")
#: The target of an inline link or image: `](target)` or `](target "title")` (the link text may hold brackets or an
#: image, so the text is not matched).
LINK = re.compile(r"\]\(\s*<?([^)\s>]*)>?(?:\s+\"[^\"]*\")?\s*\)")
#: A reference definition: `[label]: target`.
REFERENCE = re.compile(r"^ {0,3}\[[^\]]+\]:\s*<?(\S+?)>?(?:\s+.*)?$")
HEADING = re.compile(r"^ {0,3}(#{1,6})\s+(.*?)\s*#*\s*$")
SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.-]*:")


def markdown_files() -> list[Path]:
    """The files whose links are checked: *.md at the root, under docs/ and src/<pkg>/README.md."""
    files = sorted(REPO.glob("*.md")) + sorted((REPO / "docs").rglob("*.md")) + sorted(REPO.glob("src/*/README.md"))
    return [f for f in files if ".venv" not in f.parts]


def prose_lines(text: str, keep_code_spans: bool = False) -> list[tuple[int, str]]:
    """(line number, line) outside fenced code blocks, with inline code spans removed unless keep_code_spans (a
    heading's code spans are part of its anchor)."""
    lines, fence = [], None
    for number, line in enumerate(text.splitlines(), 1):
        m = FENCE.match(line)
        if fence is not None:
            if m and m.group(1)[0] == fence[0] and len(m.group(1)) >= len(fence):
                fence = None
            continue
        if m:
            fence = m.group(1)
            continue
        lines.append((number, line if keep_code_spans else INLINE_CODE.sub("", line)))
    return lines


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: its text (code spans' backticks dropped, a link's text kept) lowercased, every
    character but letters, digits, '_', '-' and spaces dropped, spaces made '-'."""
    text = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", heading).replace("`", "")
    return re.sub(r"[^\w\- ]", "", text.strip().lower()).replace(" ", "-")


def anchors(path: Path) -> set[str]:
    """Every heading anchor of a Markdown file; a repeated heading gets -1, -2, ... as on GitHub."""
    seen: dict[str, int] = {}
    result = set()
    for _, line in prose_lines(path.read_text(encoding="utf-8"), keep_code_spans=True):
        m = HEADING.match(line)
        if not m:
            continue
        base = slug(m.group(2))
        n = seen.get(base, 0)
        seen[base] = n + 1
        result.add(base if n == 0 else f"{base}-{n}")
    return result


def links(path: Path) -> list[tuple[int, str]]:
    """(line number, target) of every inline link, image and reference definition outside code."""
    found = []
    for number, line in prose_lines(path.read_text(encoding="utf-8")):
        found += [(number, t) for t in LINK.findall(line)]
        m = REFERENCE.match(line)
        if m:
            found.append((number, m.group(1)))
    return found


def broken_links(path: Path) -> list[str]:
    """What is wrong with each relative link of one Markdown file, as `file:line: target: reason`."""
    problems = []
    for number, target in links(path):
        if not target or SCHEME.match(target):
            continue
        file_part, _, anchor = target.partition("#")
        dest = (path.parent / file_part).resolve() if file_part else path
        where = f"{path.relative_to(REPO)}:{number}: {target}"
        if file_part.startswith("/"):
            problems.append(f"{where}: an absolute path (GitHub resolves it against the site, not the repository)")
            continue
        try:
            rel = dest.relative_to(REPO).as_posix()
        except ValueError:
            problems.append(f"{where}: points outside the repository")
            continue
        if not dest.exists():
            if rel in PENDING and not anchor:
                continue
            problems.append(f"{where}: no such file or folder ({rel})")
            continue
        if anchor and dest.suffix == ".md" and anchor not in anchors(dest):
            known = ", ".join(sorted(anchors(dest)))
            problems.append(f"{where}: no heading '#{anchor}' in {rel} (its anchors: {known})")
    return problems


def test_the_documentation_is_found():
    names = {f.relative_to(REPO).as_posix() for f in markdown_files()}
    assert {"README.md", "DEVELOPERS.md"} <= names, names
    assert any(n.startswith("docs/") for n in names), names


@pytest.mark.parametrize("path", markdown_files(), ids=lambda p: p.relative_to(REPO).as_posix())
def test_every_relative_link_resolves(path):
    problems = broken_links(path)
    assert not problems, "broken link(s):\n" + "\n".join(problems)


def test_pending_pages_are_still_missing():
    present = [p for p in PENDING if (REPO / p).exists()]
    assert not present, f"{present} exist now: remove them from PENDING in {Path(__file__).name}"


def test_the_readme_links_into_docs():
    """The README is the entry: it links the docs pages and every one of them resolves (checked above)."""
    targets = {t.partition("#")[0] for _, t in links(REPO / "README.md")}
    pages = {t for t in targets if t.startswith("docs/") and t.endswith(".md") and t.count("/") == 1}
    assert len(pages) >= 5, sorted(pages)


def test_slug_rules():
    """GitHub's slugs for headings of this repository's kinds: '-' and '_' stay, other punctuation goes, every
    space becomes '-' (so " + " gives "--"); these anchors are the ones the README linked before it was split."""
    assert slug("Parallel envs with SB3 (`--n-envs`)") == "parallel-envs-with-sb3---n-envs"
    assert slug("The launched graph: nothing outlives it, nobody else reaches it") == (
        "the-launched-graph-nothing-outlives-it-nobody-else-reaches-it"
    )
    assert slug("Experiments: the paper's Figures 6 and 7") == "experiments-the-papers-figures-6-and-7"
    assert slug("Hard starts: the whole joint range, SAC + HER vs PPO") == (
        "hard-starts-the-whole-joint-range-sac--her-vs-ppo"
    )
    assert slug("Out of a person's way (strategy `retreat`)") == "out-of-a-persons-way-strategy-retreat"


def test_a_broken_link_is_found(tmp_path, monkeypatch):
    """The check itself: a missing file, a wrong anchor and a link in code (ignored) in a page of a repository."""
    monkeypatch.setattr(sys.modules[__name__], "REPO", tmp_path)
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "a.md").write_text("# A page\n\n## Its part (`code`)\n")
    page = tmp_path / "README.md"
    page.write_text(
        "[ok](docs/a.md#its-part-code) [self](#top) [gone](docs/b.md) [bad anchor](docs/a.md#its-part-)\n"
        "`[code](docs/c.md)`\n```\n[block](docs/d.md)\n```\n# Top\n![img](docs/e.png) [web](https://example.org)\n"
    )
    problems = broken_links(page)
    assert [p.split(": ")[1] for p in problems] == ["docs/b.md", "docs/a.md#its-part-", "docs/e.png"], problems
