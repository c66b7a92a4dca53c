"""Trainer studies: what an organiser sends and reads, and what a participant sees."""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Literal

from pydantic import BaseModel, Field, field_validator

from server.schemas.common import Strict, Text
from server.schemas.runs import EngineCondition

ParticipantStatusName = Literal["invited", "consented", "training", "done"]
StudyName = Field(min_length=1, max_length=100, pattern=r"^[A-Za-z0-9][A-Za-z0-9._-]*$")


class EpisodeBudget(Strict):
    EXAMPLES = ({"episodes": 5},)

    episodes: int = Field(ge=1, le=100_000, description="done after this many episodes")


class TimeBudget(Strict):
    EXAMPLES = ({"seconds": 600},)

    seconds: float = Field(
        ge=1, le=86_400, description="done after this many seconds of their run's clock"
    )


class StudyCreate(Strict):
    EXAMPLES = (
        {
            "name": "pilot",
            "conditions": ["trainer", "rp"],
            "budget": {"episodes": 5},
            "consent_text": "You will train a simulated robot for about ten minutes.",
            "consent_version": "1",
            "completion_code": "C0DE42",
        },
    )

    name: str = StudyName
    conditions: list[EngineCondition] = Field(
        min_length=1,
        max_length=20,
        description="the conditions to assign, in order, each once",
        json_schema_extra={"uniqueItems": True},
    )
    assignment: Literal["balanced", "fixed"] = Field(
        "balanced",
        description="balanced: the condition with the fewest participants so far (ties by "
        "order); fixed: the first condition for everyone",
    )
    budget: EpisodeBudget | TimeBudget = Field(
        description="each participant's: episodes finished, or seconds of their run"
    )
    consent_text: str = Field(min_length=1, max_length=20_000)
    consent_version: str = Field("1", min_length=1, max_length=100)
    questionnaire: list[Text] = Field(
        default_factory=list, max_length=50, description="short questions, shown after consent"
    )
    completion_code: str | None = Field(None, min_length=1, max_length=100)
    redirect_url: str | None = Field(
        None, max_length=2000, pattern=r"^https?://", description="where a finished one goes"
    )

    @field_validator("conditions")
    @classmethod
    def _each_once(cls, v: list[str]) -> list[str]:
        if len(set(v)) < len(v):
            raise ValueError("each condition once")
        return v


class StudyPublic(BaseModel):
    id: int
    name: str
    conditions: list[str]
    assignment: Literal["balanced", "fixed"]
    budget_episodes: int | None
    budget_s: float | None
    consent_text: str
    consent_version: str
    questionnaire: list[str]
    completion_code: str | None
    redirect_url: str | None
    created_at: datetime
    progress: dict[ParticipantStatusName, int] = Field(
        description="how many participants are at each status"
    )


class StudiesPublic(BaseModel):
    data: list[StudyPublic]
    count: int


ExternalId = Annotated[Text, Field(min_length=1, max_length=200)]


class ParticipantsNamed(Strict):
    EXAMPLES = ({"external_ids": ["prolific-5f1c", "prolific-77ab"]},)

    external_ids: list[ExternalId] = Field(
        min_length=1,
        max_length=1000,
        description="recruiters' ids, each once (kept apart from the pseudonyms, deletable)",
    )


class ParticipantsAnonymous(Strict):
    EXAMPLES = ({"count": 3},)

    count: int = Field(ge=1, le=1000, description="this many anonymous participants")


class ParticipantPublic(BaseModel):
    id: int
    pseudonym: str
    status: ParticipantStatusName
    condition: str | None
    run_id: int | None
    consent_version: str | None
    consented_at: datetime | None
    episodes_done: int | None = Field(
        None, description="while they train, the episodes their run has finished (else null)"
    )
    seconds_done: float | None = Field(
        None,
        description="while they train, the seconds of their run's clock: its ticks at its rate",
    )


class ParticipantsPublic(BaseModel):
    data: list[ParticipantPublic]
    count: int


class ParticipantInvited(ParticipantPublic):
    token: str = Field(description="the participant's token: shown this once, never again")
    link: str = Field(description="the participant's link (`/#/study/<token>`)")


class ParticipantsInvited(BaseModel):
    data: list[ParticipantInvited]
    count: int


class IdentitiesDeleted(BaseModel):
    deleted: int = Field(description="how many external ids were deleted")


class ConsentCreate(Strict):
    EXAMPLES = ({"consent_version": "1"},)

    consent_version: str = Field(
        min_length=1, max_length=100, description="the version of the consent text they read"
    )


class AnswersCreate(Strict):
    """A participant's answers to their study's questionnaire, one per question, in order."""

    EXAMPLES = ({"answers": ["Hard at first, then easier."]},)

    answers: list[Annotated[Text, Field(min_length=1, max_length=2000)]] = Field(
        min_length=1, max_length=100, description="one answer per question, in their order"
    )


class ParticipantView(BaseModel):
    study: str
    pseudonym: str
    status: ParticipantStatusName
    consent_text: str
    consent_version: str
    questionnaire: list[str]
    condition: str | None
    run_id: int | None
    budget_episodes: int | None
    budget_s: float | None
    answered: bool = Field(description="whether they have answered the questionnaire")
    completion_code: str | None = Field(
        description="shown once their budget is spent and the questionnaire (if any) answered"
    )
    redirect_url: str | None = Field(description="shown once their budget is spent")
