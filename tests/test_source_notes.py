"""Docstrings and comments say what the code does and why, not when: none in mexgen_gcs/ or sim/
cites a commit hash, a calendar date, or a repository file that does not exist (history goes in
commit messages and docs/results/)."""

from __future__ import annotations

import io
import re
import tokenize
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]

#: a 7-40 digit hex word (with at least one digit) within a few words of "commit"
COMMIT = re.compile(r"\bcommit(?:s|ted)?\b\W+(?:\w+\W+){0,3}?(?=[0-9a-f]*\d)[0-9a-f]{7,40}\b"
                    r"|\b(?=[0-9a-f]*\d)[0-9a-f]{7,40}\b\W+(?:\w+\W+){0,2}?commit", re.I)
#: a calendar date, ISO style (an impossible one such as 2020-99-99 is an example, not a date)
DATE = re.compile(r"\b20\d\d-(?:0[1-9]|1[0-2])-(?:0[1-9]|[12]\d|3[01])\b")
#: a path from the repository's root to a file
PATH = re.compile(r"\b(?:tests|docs|mexgen_gcs|sim|scripts|missions|examples)/[\w./-]*\w"
                  r"\.(?:py|md|yaml|yml|json|tcss)\b")


def notes(source: str) -> list[tuple[int, str]]:
    """(line, text) of every comment and string literal (docstrings included) of a module."""
    found = []
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type in (tokenize.COMMENT, tokenize.STRING):
            found.append((tok.start[0], tok.string))
    return found


def problems(source: str, root: Path) -> list[str]:
    out = []
    for line, text in notes(source):
        if m := COMMIT.search(text):
            out.append(f"{line}: cites a commit: {m.group(0)!r}")
        if m := DATE.search(text):
            out.append(f"{line}: cites a date: {m.group(0)!r}")
        for path in PATH.findall(text):
            if not (root / path).exists():
                out.append(f"{line}: names a file that does not exist: {path}")
    return out


def test_the_checker_finds_what_it_looks_for() -> None:
    bad = ('"""Faster since commit 5d970ce (measured 2026-11-26).\n\n'
           'Tested in tests/core/test_nowhere.py."""\n'
           "x = 1  # as 88278d5's commit message says\n"
           'y = "see docs/cli.md"  # exists\n'
           "z = '2020-99-99'  # an impossible date: an example of bad input\n")
    found = problems(bad, REPO)
    assert len(found) == 4, found
    assert any("5d970ce" in f for f in found)
    assert any("88278d5" in f for f in found)
    assert any("2026-11-26" in f for f in found)
    assert any("tests/core/test_nowhere.py" in f for f in found)
    assert problems("commit = 'abcdefg'  # a commit of deadbee? no digits, not a hash\n",
                    REPO) == []


def test_no_docstring_or_comment_cites_a_commit_a_date_or_a_missing_file() -> None:
    files = sorted([*(REPO / "mexgen_gcs").rglob("*.py"), *(REPO / "sim").rglob("*.py")])
    assert len(files) > 50
    found = [f"{path.relative_to(REPO)}:{p}" for path in files
             for p in problems(path.read_text(encoding="utf-8"), REPO)]
    assert found == []
