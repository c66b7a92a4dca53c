"""The error responses every operation may give, for /openapi.json."""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel


class ErrorPublic(BaseModel):
    """An error: what was wrong, for people."""

    detail: str


class StalePublic(ErrorPublic):
    """A write refused because it was based on a version that is no longer current."""

    version: int
    etag: str


ERRORS: dict[int | str, dict[str, Any]] = {
    400: {"model": ErrorPublic, "description": "a request the service cannot take (bad Host)"},
    401: {"model": ErrorPublic, "description": "a write without the bearer token"},
    404: {"model": ErrorPublic, "description": "no such run, network, stimulus or behaviour"},
    409: {"model": ErrorPublic, "description": "not in this state (a reward to a stopped run)"},
    413: {"model": ErrorPublic, "description": "the body is over the size limit"},
    429: {"model": ErrorPublic, "description": "over a rate or run limit"},
    503: {"model": ErrorPublic, "description": "storage is failing"},
}
