"""User documentation describes the code as it is: README.md, the pages under docs/ and every
docstring in jaxrod hold no development history (no numbered work periods, issue references,
commit hashes or dated progress lines). History belongs in CHANGELOG.md and git."""
import ast
import pathlib
import re

import pytest

REPO = pathlib.Path(__file__).resolve().parent.parent

MARKERS = {
    "issue reference": re.compile(r"\bissues?\s+\d|(?<![&\w])#\d+\b", re.I),
    "work period": re.compile(r"\bsessions?\b|\bwork periods?\b", re.I),
    # 7 to 40 hex digits with at least one digit and one letter, as a word of its own (not a
    # colour after '#', not part of an identifier or a number with a unit)
    "commit hash": re.compile(r"(?<![#\w.-])(?=[0-9a-f]*[0-9])(?=[0-9a-f]*[a-f])[0-9a-f]{7,40}(?![\w-])"),
    "dated line": re.compile(r"\b20\d\d-\d\d-\d\d\b"),
}


def history_markers(text):
    """(kind, the matching text) for each development-history marker in text."""
    return [(kind, m.group(0)) for kind, pattern in MARKERS.items() for m in pattern.finditer(text)]


def _docstrings(path):
    tree = ast.parse(path.read_text(encoding="utf-8"))
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            doc = ast.get_docstring(node, clean=False)
            if doc:
                yield getattr(node, "name", "module"), doc


def test_the_markers_are_found():
    # the test can fail: each kind of marker is recognised, and ordinary text is not flagged
    for text in ("as issue 17 asked", "see #12", "the third session", "at commit 8b401c8",
                 "re-run on 2026-12-04"):
        assert history_markers(text), text
    for text in ("colour #1f77b4", "E = 1e10", "deadbeef", "N = 1234567", "a 12 x 12 block",
                 "tol=1e-6", "ropelength 16.372", "dsyevr", "the 2nd-order scheme"):
        assert not history_markers(text), text


@pytest.mark.parametrize("page", ["README.md"] + sorted(p.relative_to(REPO).as_posix()
                                                       for p in (REPO / "docs").rglob("*.md")))
def test_user_pages_hold_no_history(page):
    assert history_markers((REPO / page).read_text(encoding="utf-8")) == [], page


def test_docstrings_hold_no_history():
    hits = []
    for path in sorted((REPO / "jaxrod").rglob("*.py")):
        for name, doc in _docstrings(path):
            hits += [(str(path.relative_to(REPO)), name, kind, text) for kind, text in history_markers(doc)]
    assert hits == []
