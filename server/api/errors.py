"""The error responses every operation may give, for /openapi.json."""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, Field


class FieldErrorPublic(BaseModel):
    """One thing wrong with a request's input (a 422), and where."""

    loc: list[str | int] = Field(description="where: body, query, path or header, then the field")
    msg: str
    type: str


class ErrorPublic(BaseModel):
    """Every error: what was wrong, for people; a 422 lists each field that was wrong."""

    detail: str | list[FieldErrorPublic]


class StalePublic(ErrorPublic):
    """A write refused because it was based on a version that is no longer current."""

    version: int
    etag: str


ERRORS: dict[int | str, dict[str, Any]] = {
    400: {"model": ErrorPublic, "description": "a request the service cannot take (bad Host)"},
    401: {"model": ErrorPublic, "description": "a write without the bearer token"},
    403: {"model": ErrorPublic, "description": "a write from another site (Origin)"},
    404: {"model": ErrorPublic, "description": "no such run, network, stimulus or behaviour"},
    409: {"model": ErrorPublic, "description": "not in this state (a reward to a stopped run)"},
    408: {"model": ErrorPublic, "description": "the body did not arrive in time"},
    413: {"model": ErrorPublic, "description": "the body is over the size limit"},
    422: {"model": ErrorPublic, "description": "bad input: `detail` lists each field"},
    429: {"model": ErrorPublic, "description": "over a rate or run limit"},
    503: {"model": ErrorPublic, "description": "storage is failing"},
}
