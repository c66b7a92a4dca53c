"""What the studies' routes and `srlab study` share: a study's spec, and inviting people.

Both take the organiser's input through the same schemas (`server.schemas.studies`), so
the command line refuses what the API refuses, with the same rules.
"""

from __future__ import annotations

import secrets
from collections.abc import Sequence
from dataclasses import dataclass

from core.ports import RunQueries
from core.studies import (
    Assignment,
    NewParticipant,
    Participant,
    ParticipantStatus,
    Study,
    StudyRepository,
    StudySpec,
    budget_spent,
    token_digest,
)
from server.schemas.studies import EpisodeBudget, StudyCreate, TimeBudget

PARTICIPANT_PREFIX = "srp_"
"""How a participant's token starts: what tells it from the organiser's."""


def study_spec(body: StudyCreate) -> StudySpec:
    """The study a validated request (or command line) describes."""
    return StudySpec(
        name=body.name, conditions=tuple(body.conditions),
        assignment=Assignment(body.assignment),
        budget_episodes=body.budget.episodes if isinstance(body.budget, EpisodeBudget) else None,
        budget_s=body.budget.seconds if isinstance(body.budget, TimeBudget) else None,
        consent_text=body.consent_text,
        consent_version=body.consent_version, questionnaire=tuple(body.questionnaire),
        completion_code=body.completion_code, redirect_url=body.redirect_url,
    )  # fmt: skip


def new_study(studies: StudyRepository, body: StudyCreate) -> Study:
    """Store the study; its pseudonyms' secret is drawn here and never served."""
    return studies.create(study_spec(body), secrets.token_hex(32))


@dataclass(frozen=True, slots=True)
class Invited:
    """A participant just invited, with what exists only now: their token and link."""

    participant: Participant
    external_id: str | None
    token: str
    link: str


def participant_link(service: str, token: str) -> str:
    """A participant's link on the service at `service` (its base URL)."""
    return f"{service.rstrip('/')}/#/study/{token}"


def invite(
    studies: StudyRepository, name: str, external_ids: Sequence[str | None], service: str
) -> list[Invited]:
    """Invite one participant per entry (None: anonymous); each token is drawn here.

    Only the tokens' digests are stored: the answer is the one place a token is seen.
    """
    tokens = [PARTICIPANT_PREFIX + secrets.token_urlsafe(32) for _ in external_ids]
    pairs = zip(external_ids, tokens, strict=True)
    entries = [NewParticipant(i, token_digest(t)) for i, t in pairs]
    made = studies.add_participants(name, entries)
    return [
        Invited(p, i, t, participant_link(service, t))
        for p, i, t in zip(made, external_ids, tokens, strict=True)
    ]


def settle_stored(studies: StudyRepository, runs: RunQueries, name: str) -> tuple[Participant, ...]:
    """A study's participants, those whose stored run has spent the budget marked done.

    What the shell reads, without the service: its runs as last stored.
    """
    spec = studies.get(name).spec
    out = []
    for p in studies.participants(name):
        if p.status is ParticipantStatus.TRAINING and p.run_id is not None:
            run = runs.run_summary(p.run_id)
            if budget_spent(spec, run.totals.episodes, run.totals.ticks, run.spec.hz):
                p = studies.finish(p.id)
        out.append(p)
    return tuple(out)
