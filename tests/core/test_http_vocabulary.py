"""The core speaks its own words: HTTP's (ETag, If-Match, preconditions, statuses) are the API's.

`server/api/` maps the core's values and errors to HTTP (a network's fingerprint to an
ETag, `StaleVersionError` to 412, `CoreError`s to their statuses); a core module that
named them would tie the core to one transport.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

import core

CORE = Path(core.__file__).parent
STATUSES = "400|401|403|404|405|408|409|410|412|413|415|422|428|429|500|502|503|504"
HTTP_WORDS = re.compile(
    r"\bHTTP\b"  # upper case: a URL's "http://" is not the protocol talking
    r"|(?i:(?<![a-z])e-?tags?(?![a-z])|\bentity[ -]tags?\b|\bif-(none-)?match\b|\bif_match\b"
    r"|\bprecondition)"
    rf"|(?<![\w.,])({STATUSES})(?![\w.,])"
)
"""HTTP's vocabulary: the protocol, entity tags and their headers, preconditions, and the
status numbers the API answers (as numbers standing alone, not inside 0.412 or 1,404)."""


def core_files() -> list[Path]:
    return sorted(p for p in CORE.rglob("*.py") if "__pycache__" not in p.parts)


def http_words(source: str, label: str) -> list[str]:
    """Each HTTP word in `source` (code, strings, comments), as "label:line: word"."""
    return [
        f"{label}:{number}: {m.group(0)}"
        for number, line in enumerate(source.splitlines(), 1)
        for m in HTTP_WORDS.finditer(line)
    ]


@pytest.mark.parametrize("path", core_files(), ids=lambda p: str(p.relative_to(CORE)))
def test_core_module_speaks_no_http(path: Path) -> None:
    label = str(path.relative_to(CORE.parent))
    assert http_words(path.read_text(encoding="utf-8"), label) == []


@pytest.mark.parametrize(
    "source",
    [
        '"""Answered with HTTP 412."""',
        "etag: str = ''",
        "def etag_of(n): ...",
        "# the ETag of a version",
        "raise StaleError('which If-Match does not name')",
        "if_match = None",
        "class Precondition: ...",
        "expected: Precondition | None = None",
        '"""A conflict (answered 409)."""',
        "status_code = 404",
        "# refused with a 422 naming the field",
        "the entity tag of one version",
    ],
)
def test_the_checker_catches_http_words(source: str) -> None:
    assert http_words(source, "probe.py") != []


@pytest.mark.parametrize(
    "source",
    [
        "fingerprint: str = ''",
        "raise StaleVersionError(name, version, fingerprint)",
        "gap = 0.412  # metres",
        "pairs = 1,404",
        "n_steps = (128, 256, 512)",
        "size = 4096",
        "see https://example.org/paper.pdf",
        "x_409 = 1",
    ],
)
def test_the_checker_allows_the_cores_words(source: str) -> None:
    assert http_words(source, "ok.py") == []
