"""The README and docs/ stay a reference a clone can read: short README, every link inside the repository.

A link that leaves the repository (``../shared/...``) or names a file that is not there is a link
a reader of a clone cannot follow; the README is held to a length a newcomer reads in one sitting.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README_MAX_LINES = 150

# [text](target) and ![alt](target); the target ends at whitespace or the closing parenthesis.
LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")
FENCE = re.compile(r"^\s*(```|~~~)")


def documents() -> list[Path]:
    return [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]


def links(path: Path) -> list[tuple[int, str]]:
    """Every markdown link target of ``path`` outside fenced code, with its line number."""
    found = []
    in_fence = False
    for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
        if FENCE.match(line):
            in_fence = not in_fence
            continue
        if in_fence:
            continue
        # Inline code spans are not links.
        text = re.sub(r"`[^`]*`", "", line)
        found.extend((number, target) for target in LINK.findall(text))
    return found


def problem(document: Path, target: str) -> str | None:
    """Why ``target`` linked from ``document`` cannot be followed in a clone, or None."""
    if re.match(r"^[a-z][a-z0-9+.-]*:", target) or target.startswith("#"):
        return None  # a web address or an anchor in the same page
    relative = target.split("#", 1)[0]
    resolved = (document.parent / relative).resolve()
    if not resolved.is_relative_to(ROOT):
        return "points outside the repository"
    if not resolved.exists():
        return "names no file of the repository"
    return None


def test_link_checker_catches_outside_and_missing_targets(tmp_path: Path) -> None:
    page = ROOT / "docs" / "page.md"
    assert problem(page, "../../shared/DESIGN.md") == "points outside the repository"
    assert problem(page, "no-such-page.md") == "names no file of the repository"
    assert problem(page, "../README.md#status") is None
    assert problem(page, "https://example.org/x.md") is None
    sample = tmp_path / "sample.md"
    sample.write_text("see [a](a.md) and `[b](b.md)`\n```\n[c](c.md)\n```\n![d](d.png)\n", encoding="utf-8")
    assert links(sample) == [(1, "a.md"), (5, "d.png")]


def test_readme_is_short() -> None:
    lines = (ROOT / "README.md").read_text(encoding="utf-8").count("\n")
    assert lines <= README_MAX_LINES, f"README.md has {lines} lines; at most {README_MAX_LINES}"


@pytest.mark.parametrize("document", documents(), ids=lambda p: str(p.relative_to(ROOT)))
def test_every_link_resolves_inside_the_repository(document: Path) -> None:
    bad = [
        f"{document.relative_to(ROOT)}:{number}: {target} {why}"
        for number, target in links(document)
        if (why := problem(document, target)) is not None
    ]
    assert not bad, "\n".join(bad)
