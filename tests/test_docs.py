"""The docs, code and web assets describe the product as it is: no work diary, short pages.

History lives in `git log`. A sentence that names a session of work or one of the project's
issues reads as a diary entry and goes stale the day it is written; these checks refuse
it wherever a reader of the product looks (the docs, except the generated `docs/results/`,
the web client and the code), and keep the pages of figures and of the suite short enough
to be read as one table and what it means.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

CHECKED = ("docs", "web", "core", "server", "bench")
"""The folders a reader of the product reads (their text files, recursively)."""

GENERATED = (ROOT / "docs" / "results",)
"""Folders written by the experiments themselves, left as they are written."""

THIRD_PARTY = "vendor"
"""A folder of code vendored from elsewhere, which keeps its authors' words."""

TEXT = {".md", ".py", ".js", ".css", ".html", ".toml", ".txt", ".json", ".svg"}
"""Suffixes of the files read: text a person writes (binary assets and caches are not)."""

_ORDINALS = (
    "first|second|third|fourth|fifth|sixth|seventh|eighth|ninth|tenth|eleventh|twelfth"
    "|thirteenth|fourteenth|fifteenth|sixteenth"
)
DIARY = re.compile(
    rf"\b(session (number|[0-9]+)|({_ORDINALS}) session|this session|issue #?[0-9]+)\b",
    re.IGNORECASE,
)
"""The words of a work diary: a numbered session, "this session", an issue's number."""

SHORT_PAGES = {"docs/benchmarks.md": 250, "docs/testing.md": 250, "README.md": 350}
"""Pages kept under a number of lines: the figures, the suite, the front page."""


def checked_files() -> list[Path]:
    """Every text file under `CHECKED`, outside `GENERATED`, vendored code and caches."""
    files = []
    for folder in CHECKED:
        for path in sorted((ROOT / folder).rglob("*")):
            if (
                path.is_file()
                and path.suffix in TEXT
                and "__pycache__" not in path.parts
                and THIRD_PARTY not in path.parts
                and not any(path.is_relative_to(g) for g in GENERATED)
            ):
                files.append(path)
    return files


def diary_words(text: str) -> list[str]:
    """Each line of `text` holding a diary's words, with its number."""
    return [
        f"{n}: {line.strip()}"
        for n, line in enumerate(text.splitlines(), start=1)
        if DIARY.search(line)
    ]


@pytest.mark.parametrize(
    ("line", "diary"),
    [
        ("measured in the ninth session", True),
        ("This session's change", True),
        ("a figure from issue 17's long day", True),
        ("see issue #36", True),
        ("Session 12 found it", True),
        ("a SQLAlchemy session commits it", False),
        ("each viewer's session on the run", False),
        ("the issue's sweep", False),
        ("a reward's note: undo of #12", False),
    ],
)
def test_the_diary_pattern_tells_history_from_the_words_of_the_product(
    line: str, diary: bool
) -> None:
    assert bool(DIARY.search(line)) is diary


def test_the_checked_folders_hold_text_files() -> None:
    relative = {p.relative_to(ROOT).as_posix() for p in checked_files()}
    for expected in ("docs/benchmarks.md", "web/index.html", "core/__init__.py"):
        assert expected in relative
    assert not any(r.startswith("docs/results/") for r in relative)


def test_no_doc_code_or_web_asset_reads_as_a_work_diary() -> None:
    found = {
        path.relative_to(ROOT).as_posix(): lines
        for path in checked_files()
        if (lines := diary_words(path.read_text(encoding="utf-8", errors="replace")))
    }
    assert not found, "history belongs in git log, not in the product:\n" + "\n".join(
        f"{path}:{line}" for path, lines in found.items() for line in lines
    )


@pytest.mark.parametrize(("page", "most"), sorted(SHORT_PAGES.items()))
def test_the_pages_of_figures_and_of_the_suite_stay_short(page: str, most: int) -> None:
    lines = len((ROOT / page).read_text(encoding="utf-8").splitlines())
    assert lines < most, f"{page} has {lines} lines, at most {most - 1}"
