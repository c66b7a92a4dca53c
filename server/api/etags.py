"""A stored network's versions in HTTP's words: ETag, If-Match and the 412 of a stale write.

The core names one version of one network by its fingerprint (`core.networks`); HTTP
carries it as an entity tag, the fingerprint in quotes. A write's `If-Match` (and its
`expected_version`) become what the write expects of the network, and a write the core
finds stale is answered 412 with the network's current version and tag.
"""

from __future__ import annotations

from fastapi import status
from fastapi.responses import JSONResponse

from core.networks import ExpectedVersion, StaleVersionError


def etag(fingerprint: str) -> str:
    """The entity tag of a network's version: its fingerprint, quoted."""
    return f'"{fingerprint}"'


def expected(if_match: str | None, version: int | None) -> ExpectedVersion | None:
    """What a write expects of the network: If-Match's tags and/or a version (None: nothing).

    Weak tags (`W/"..."`) compare as strong ones, a tag without its quotes as the quoted one
    (a client that dropped them means the same tag), and `*` takes any version.
    """
    if if_match is None and version is None:
        return None
    fingerprints = None
    if if_match is not None:
        tags = [t.strip().removeprefix("W/") for t in if_match.split(",") if t.strip()]
        if "*" not in tags:
            fingerprints = tuple(_unquoted(t) for t in tags)
    return ExpectedVersion(version, fingerprints)


def _unquoted(tag: str) -> str:
    return tag[1:-1] if len(tag) > 1 and tag[0] == tag[-1] == '"' else tag


def stale(exc: StaleVersionError) -> JSONResponse:
    """The 412 of a write based on a version no longer current: the current one, and why."""
    tag = etag(exc.fingerprint)
    if exc.expected is not None:
        at = f"version {exc.current}, not {exc.expected}"
    else:
        at = f"version {exc.current} ({tag}), which If-Match does not name"
    detail = (
        f"network {exc.network!r} is at {at}: another write came first; read it again (GET) "
        "and reapply the change"
    )
    return JSONResponse(
        {"detail": detail, "version": exc.current, "etag": tag},
        status_code=status.HTTP_412_PRECONDITION_FAILED,
        headers={"ETag": tag},
    )
