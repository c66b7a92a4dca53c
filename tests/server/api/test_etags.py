"""A network's versions in HTTP's words: fingerprints as ETags, If-Match, a stale write's 412."""

from __future__ import annotations

import json

import pytest

from core.networks import ExpectedVersion, StaleVersionError
from server.api.etags import etag, expected, stale


@pytest.mark.parametrize(
    ("if_match", "version", "want"),
    [
        (None, None, None),
        (None, 3, ExpectedVersion(3)),
        ('"v3-ab"', None, ExpectedVersion(None, ("v3-ab",))),
        ("v3-ab", None, ExpectedVersion(None, ("v3-ab",))),  # the quotes dropped
        ('W/"v3-ab" , "v4-cd"', 2, ExpectedVersion(2, ("v3-ab", "v4-cd"))),
        ("*", None, ExpectedVersion()),
        ('"v9-0", *', 3, ExpectedVersion(3)),
    ],
)
def test_if_match_becomes_what_a_write_expects(
    if_match: str | None, version: int | None, want: ExpectedVersion | None
) -> None:
    assert expected(if_match, version) == want


def test_a_fingerprint_is_quoted_as_an_etag() -> None:
    assert etag("v3-1a2b3c4d5e6f") == '"v3-1a2b3c4d5e6f"'


@pytest.mark.parametrize(
    ("error", "detail"),
    [
        (
            StaleVersionError("mine", 3, "v3-x", 2),
            "network 'mine' is at version 3, not 2: another write came first; read it again "
            "(GET) and reapply the change",
        ),
        (
            StaleVersionError("mine", 3, "v3-x"),
            "network 'mine' is at version 3 (\"v3-x\"), which If-Match does not name: another "
            "write came first; read it again (GET) and reapply the change",
        ),
    ],
)
def test_a_stale_write_is_answered_412_with_the_current_tag(
    error: StaleVersionError, detail: str
) -> None:
    answer = stale(error)
    assert answer.status_code == 412 and answer.headers["etag"] == '"v3-x"'
    assert json.loads(bytes(answer.body)) == {"detail": detail, "version": 3, "etag": '"v3-x"'}
