"""Trainer studies: a study's rules, its participants, and the store they need.

A study assigns each consenting participant a condition and one run; its participants are
known by a pseudonym (an HMAC of the study's secret and the recruiter's id), and the
mapping back to that id is kept apart so it can be deleted on its own. The rules here are
pure; the server draws the random parts (secrets, tokens) and stores the rows.
"""

from __future__ import annotations

import hashlib
import hmac
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import datetime
from enum import StrEnum
from typing import Protocol

from core.errors import RunStateError, UnknownNameError


class UnknownStudyError(UnknownNameError):
    """A study name that does not exist."""


class StudyExistsError(RunStateError):
    """A study's name is taken."""


class ParticipantExistsError(RunStateError):
    """An external id is already a participant of the study."""


class StaleConsentError(RunStateError):
    """A participant consented to a consent text that is no longer the study's."""


class AnsweredError(RunStateError):
    """A participant's questionnaire is answered already (answers are given once)."""


class Assignment(StrEnum):
    """How a consenting participant's condition is chosen."""

    BALANCED = "balanced"
    """The condition with the fewest participants so far; ties by the study's order."""
    FIXED = "fixed"
    """The study's first condition, for everyone."""


class ParticipantStatus(StrEnum):
    """Where a participant is in the study."""

    INVITED = "invited"
    CONSENTED = "consented"
    """Consented and assigned a condition; their run is not made yet."""
    TRAINING = "training"
    DONE = "done"


@dataclass(frozen=True, slots=True)
class StudySpec:
    """What an organiser decides about a study.

    Exactly one budget is set: episodes finished, or seconds of the run's clock.
    """

    name: str
    conditions: tuple[str, ...]
    assignment: Assignment = Assignment.BALANCED
    budget_episodes: int | None = None
    budget_s: float | None = None
    consent_text: str = ""
    consent_version: str = "1"
    questionnaire: tuple[str, ...] = ()
    completion_code: str | None = None
    redirect_url: str | None = None


@dataclass(frozen=True, slots=True)
class Study:
    """A stored study, with how many of its participants are at each status."""

    id: int
    spec: StudySpec
    created_at: datetime
    progress: Mapping[ParticipantStatus, int]


@dataclass(frozen=True, slots=True)
class Participant:
    """A stored participant: never their external id, which only the mapping holds."""

    id: int
    study: str
    pseudonym: str
    status: ParticipantStatus
    condition: str | None
    run_id: int | None
    consent_version: str | None
    consented_at: datetime | None
    created_at: datetime


@dataclass(frozen=True, slots=True)
class Answer:
    """A participant's answer to one question of their study's questionnaire."""

    participant: str
    """Their pseudonym."""
    question_no: int
    """The question's place in the questionnaire, from 1."""
    question: str
    answer: str
    answered_at: datetime


@dataclass(frozen=True, slots=True)
class NewParticipant:
    """Who to add: a recruiter's id (None for an anonymous participant) and the token's digest."""

    external_id: str | None
    token_digest: str


def pseudonym(secret: str, identity: str) -> str:
    """A participant's pseudonym: HMAC-SHA256 of the study's secret and their id, in hex."""
    return hmac.new(secret.encode(), identity.encode(), hashlib.sha256).hexdigest()


def token_digest(token: str) -> str:
    """What is stored of a participant's token: its SHA-256, in hex."""
    return hashlib.sha256(token.encode()).hexdigest()


def assign(spec: StudySpec, counts: Mapping[str, int]) -> str:
    """The condition the next consenting participant gets, given how many each has."""
    if spec.assignment is Assignment.FIXED:
        return spec.conditions[0]
    return min(spec.conditions, key=lambda c: (counts.get(c, 0), spec.conditions.index(c)))


def budget_spent(spec: StudySpec, episodes: int, ticks: int, hz: float) -> bool:
    """Whether a participant's run has used up the study's budget."""
    if spec.budget_episodes is not None:
        return episodes >= spec.budget_episodes
    assert spec.budget_s is not None
    return ticks / hz >= spec.budget_s


class StudyRepository(Protocol):
    """Studies, their participants and the pseudonym mapping, stored.

    Unknown studies raise `UnknownStudyError`; a taken name `StudyExistsError`.
    """

    def create(self, spec: StudySpec, secret: str) -> Study:
        """Store a new study with its HMAC secret (never read back out)."""
        ...

    def studies(self) -> tuple[Study, ...]:
        """Every study, oldest first."""
        ...

    def get(self, name: str) -> Study:
        """A study by name."""
        ...

    def add_participants(
        self, name: str, entries: Sequence[NewParticipant]
    ) -> tuple[Participant, ...]:
        """Invite participants; their pseudonyms are made from the study's secret.

        An external id already in the study (or twice in `entries`) raises
        `ParticipantExistsError` and adds no one.
        """
        ...

    def participants(self, name: str) -> tuple[Participant, ...]:
        """A study's participants, in the order they were added."""
        ...

    def by_token(self, digest: str) -> tuple[Participant, Study] | None:
        """The participant whose token has this digest, and their study; None if none."""
        ...

    def recent_token(self, digest: str) -> tuple[Participant, Study] | None:
        """`by_token`'s answer if it was read lately, without waiting on storage; else None.

        A request's authorisation asks this first and `by_token` only when it answers None.
        """
        ...

    def consent(self, participant_id: int, version: str) -> Participant:
        """Record consent to `version` and assign a condition, in one step.

        `StaleConsentError` when `version` is not the study's; a participant who has
        consented already keeps their condition (and run).
        """
        ...

    def set_run(self, participant_id: int, run_id: int) -> Participant:
        """Give a consented participant their run: they are training."""
        ...

    def finish(self, participant_id: int) -> Participant:
        """Mark a participant done (their budget is spent)."""
        ...

    def delete_identities(self, name: str) -> int:
        """Delete the study's external id to pseudonym mapping; how many rows went."""
        ...

    def answer(self, participant_id: int, answers: Sequence[str]) -> tuple[Answer, ...]:
        """Store a participant's answers, one per question of the questionnaire, in order.

        `AnsweredError` when they have answered already (nothing is stored then).
        """
        ...

    def answers(self, name: str, participant_id: int | None = None) -> tuple[Answer, ...]:
        """A study's answers by participant (in the order they were added) and question.

        Only one participant's when `participant_id` is given.
        """
        ...
