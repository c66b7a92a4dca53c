"""Who is calling, and what they may do: the organiser, a study's participant, or anyone.

Every route carries `authorise` (`server.api.routing`). The organiser is who today holds
the service: `SRLAB_TOKEN`'s bearer, or anyone on loopback when no token is set; anyone
else may read and, where writes need no token, write, exactly as before studies. A bearer
token that starts with `PARTICIPANT_PREFIX` is a participant's, and nothing else: an
unknown one is refused (401), and a known one may read and reward its own run, read its
study's participant routes and the catalogue, and nothing more (403), whatever the route.
With `SRLAB_READS=token` anyone else is refused every route but the health check (401).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import StrEnum
from typing import Annotated

from fastapi import Depends, HTTPException, Request, status
from starlette.concurrency import run_in_threadpool

from core.studies import Participant, ParticipantStatus, Study, token_digest
from server.api.deps import StateDep, bearer, holds_token
from server.services.studies import PARTICIPANT_PREFIX

REWARDS_PATH = "/api/runs/{run_id}/rewards"
PARTICIPANT_TAGS = frozenset({"catalog", "health", "participant"})
"""Routes a participant may call besides their run's: their study's, the catalogue's."""
OPEN_TAGS = frozenset({"health"})
"""Routes anyone may read even when reads need a token (`Settings.reads`)."""
SAFE_METHODS = frozenset({"GET", "HEAD"})
SCOPE_KEY = "srlab.principal"


class Role(StrEnum):
    """Who a caller is."""

    ORGANISER = "organiser"
    PARTICIPANT = "participant"
    ANONYMOUS = "anonymous"


@dataclass(frozen=True)
class Principal:
    """The caller: a role, and for a participant, who and in which study."""

    role: Role
    participant: Participant | None = None
    study: Study | None = None

    @property
    def run_id(self) -> int | None:
        """A participant's run (None before they consent, or for anyone else)."""
        return None if self.participant is None else self.participant.run_id


def _unknown() -> HTTPException:
    return HTTPException(
        status.HTTP_401_UNAUTHORIZED,
        "this participant token is not known here (a mistyped link, or its study is gone)",
        headers={"WWW-Authenticate": "Bearer"},
    )


async def principal(request: Request, state: StateDep) -> Principal:
    """The caller, resolved once per request."""
    # In the request's own scope: `request.state` may be shared by requests (lifespan state).
    known: Principal | None = request.scope.get(SCOPE_KEY)
    if known is not None:
        return known
    given = bearer(request)
    if given is not None and given.startswith(PARTICIPANT_PREFIX):
        studies = state.studies
        digest = token_digest(given)
        found = None if studies is None else studies.recent_token(digest)
        if found is None and studies is not None:
            found = await run_in_threadpool(studies.by_token, digest)
        if found is None:
            raise _unknown()
        who = Principal(Role.PARTICIPANT, *found)
    else:
        organiser = holds_token(state.settings, given)
        who = Principal(Role.ORGANISER if organiser else Role.ANONYMOUS)
    request.scope[SCOPE_KEY] = who
    return who


PrincipalDep = Annotated[Principal, Depends(principal)]


def _forbidden(detail: str) -> HTTPException:
    return HTTPException(status.HTTP_403_FORBIDDEN, detail)


async def authorise(request: Request, who: PrincipalDep, state: StateDep) -> None:
    """Refuse a participant what is not theirs (403); the organiser nothing.

    Anyone else, everything but the health check when reads need a token (401).
    """
    route = request.scope.get("route")
    if who.role is Role.ANONYMOUS:
        tags = set(getattr(route, "tags", ()))
        if state.settings.reads == "token" and not tags & OPEN_TAGS:
            raise HTTPException(
                status.HTTP_401_UNAUTHORIZED,
                "reads need a token here (SRLAB_READS=token): `Authorization: Bearer "
                "<SRLAB_TOKEN>`, or a participant's token for their own run",
                headers={"WWW-Authenticate": "Bearer"},
            )
        return
    if who.participant is None:
        return
    path: str = getattr(route, "path", request.url.path)
    method = request.method
    if "{run_id}" in path:
        asked = request.path_params.get("run_id")
        own = who.participant.run_id
        if own is None or asked != str(own):
            mine = "no run yet (consent first)" if own is None else f"run {own}"
            raise _forbidden(
                f"a participant's token may use only their own run ({mine}), not run {asked}"
            )
        if method in SAFE_METHODS:
            return
        if method == "POST" and path == REWARDS_PATH:
            if who.participant.status is ParticipantStatus.DONE:
                raise _forbidden("this participant's budget is spent: no more rewards")
            return
        raise _forbidden(
            f"a participant may read and reward their run, not {method} {path} (the organiser's)"
        )
    tags = set(getattr(route, "tags", ()))
    if method in SAFE_METHODS | {"POST"} and tags & PARTICIPANT_TAGS:
        if method == "POST" and "participant" not in tags:
            raise _forbidden(f"a participant's token may not {method} {path}")
        return
    if method in SAFE_METHODS and path == "/api/runs":
        return  # their own run only (`list_runs`)
    raise _forbidden(f"a participant's token may not {method} {path}")


Authorise = Depends(authorise)


async def organiser(who: PrincipalDep) -> None:
    """Only the organiser: a participant's token is refused (403), anyone else asked (401).

    For what holds every participant's data (studies, exports): without a token set, the
    organiser is whoever is on loopback, as for writes.
    """
    if who.role is Role.ORGANISER:
        return
    if who.role is Role.PARTICIPANT:
        raise _forbidden("this is the organiser's: a participant's token may not use it")
    raise HTTPException(
        status.HTTP_401_UNAUTHORIZED,
        "this is the organiser's: `Authorization: Bearer <SRLAB_TOKEN>`",
        headers={"WWW-Authenticate": "Bearer"},
    )


Organiser = Depends(organiser)
"""A route's dependency: the organiser's alone."""
