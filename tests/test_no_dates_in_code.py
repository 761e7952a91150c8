"""No date in a comment or docstring of the code: src/, sim/, tools/, bench/ and tests/.

Comments and docstrings say what the code does and why; when a figure was measured, and how it
moved from run to run, belongs to git and the records (models/vision/history.md, docs/). Strings
the code uses at run time (messages, log text) are not looked at.
"""

from __future__ import annotations

import ast
import io
import re
import tokenize
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCANNED = ("src", "sim", "tools", "bench", "tests")
# YYYY-MM or YYYY-MM-DD of this century, a real month; not inside a longer number or name. Older
# dates are references, not history (the CCSDS time code's 1958-01-01 epoch).
DATE = re.compile(r"(?<![\w-])(?<!\w\.)20\d\d-(?:0[1-9]|1[0-2])(?:-(?:0[1-9]|[12]\d|3[01]))?(?!\w|\.\w)")


def _docstrings(tree: ast.AST) -> Iterator[tuple[int, str]]:
    """(line, text) of every docstring: a string alone as a statement in a module, class or
    function body (the first one, and attribute docstrings after an assignment)."""
    for node in ast.walk(tree):
        if not isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        for statement in node.body:
            if (
                isinstance(statement, ast.Expr)
                and isinstance(statement.value, ast.Constant)
                and isinstance(statement.value.value, str)
            ):
                yield statement.lineno, statement.value.value


def dates_in_comments(source: str) -> list[tuple[int, str]]:
    """(line, date) of each date in ``source``'s comments and docstrings."""
    found: list[tuple[int, str]] = []
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.COMMENT:
            found += [(tok.start[0], m.group()) for m in DATE.finditer(tok.string)]
    for line, text in _docstrings(ast.parse(source)):
        for m in DATE.finditer(text):
            found.append((line + text.count("\n", 0, m.start()), m.group()))
    return sorted(found)


def test_the_check_finds_dates_in_comments_and_docstrings_only() -> None:
    source = '''"""Module, tuned on 2026-11-28."""
x = 1  # since 2026-12.
LABEL = "built 2026-12-04"


def f():
    """Nothing dated here: 1.2026-12, v2026-13, ports 2000-1000."""
    return "2026-01-01"


class C:
    y = 2
    """Attribute docstring of 2025-12-31. Not 1958-01-01, an epoch."""
'''
    assert dates_in_comments(source) == [(1, "2026-11-28"), (2, "2026-12"), (13, "2025-12-31")]


def test_no_date_in_a_comment_or_docstring_of_the_code() -> None:
    found = [
        f"{path.relative_to(ROOT)}:{line}: {date}"
        for top in SCANNED
        for path in sorted((ROOT / top).rglob("*.py"))
        for line, date in dates_in_comments(path.read_text(encoding="utf-8"))
    ]
    assert not found, "dates in comments or docstrings (say what and why, not when):\n" + "\n".join(found)
