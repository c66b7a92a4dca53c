"""The database schema as SQLAlchemy 2.0 typed models; `migrations/` creates it."""

from __future__ import annotations

from datetime import datetime
from typing import TYPE_CHECKING, Any, ClassVar

from sqlalchemy import (
    JSON,
    BigInteger,
    CheckConstraint,
    DateTime,
    ForeignKey,
    Index,
    LargeBinary,
    MetaData,
    String,
    Text,
    UniqueConstraint,
    false,
    func,
    text,
)
from sqlalchemy.orm import DeclarativeBase, Mapped, mapped_column

if TYPE_CHECKING:
    from core.brain.catalog import Behaviour
    from core.ports import BehaviourSpec

NAMING_CONVENTION = {
    "ix": "ix_%(column_0_label)s",
    "uq": "uq_%(table_name)s_%(column_0_N_name)s",
    "ck": "ck_%(table_name)s_%(constraint_name)s",
    "fk": "fk_%(table_name)s_%(column_0_name)s_%(referred_table_name)s",
    "pk": "pk_%(table_name)s",
}

SOURCES = ("innate", "dp", "learned", "kp", "expert", "designed")
RUN_STATUSES = ("created", "running", "paused", "finished", "stopped", "interrupted", "failed")
RUN_MODES = ("fast", "realtime")
BEHAVIOUR_MODES = ("align", "steer", "constant")


def _one_of(column: str, values: tuple[str, ...]) -> str:
    return f"{column} IN ({', '.join(repr(v) for v in values)})"


NAME = String(100)


def motion_columns(b: Behaviour | BehaviourSpec) -> dict[str, Any]:
    """A behaviour's motion primitive (the catalogue's or a run's) as its row's columns."""
    names = ("family", "speed_mps", "turn_dps", "ticks", "mode")
    return {name: getattr(b, name) for name in names}


class Base(DeclarativeBase):
    """The one declarative base; its naming convention names every constraint."""

    metadata = MetaData(naming_convention=NAMING_CONVENTION)
    type_annotation_map: ClassVar[dict[Any, Any]] = {
        dict[str, Any]: JSON,
        bytes: LargeBinary,
        datetime: DateTime(timezone=True),
    }


def _created() -> Mapped[datetime]:
    return mapped_column(server_default=func.now())


def _run_fk() -> Mapped[int]:
    return mapped_column(ForeignKey("runs.id", ondelete="CASCADE"), index=True)


class LogicalSensorRow(Base):
    """A logical sensor of the catalogue."""

    __tablename__ = "logical_sensors"

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(NAME, unique=True)
    position: Mapped[int]
    physical: Mapped[list[str]] = mapped_column(JSON)
    processing: Mapped[str] = mapped_column(String(40))
    objective: Mapped[str] = mapped_column(NAME)
    level: Mapped[str] = mapped_column(String(10))
    priority: Mapped[int]
    weight: Mapped[float]

    __table_args__ = (CheckConstraint("level IN ('low', 'high')", name="level"),)


class StimulusRow(Base):
    """A stimulus a logical sensor emits, with its rule."""

    __tablename__ = "stimuli"

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(NAME, unique=True)
    position: Mapped[int]
    sensor_id: Mapped[int] = mapped_column(ForeignKey("logical_sensors.id"), index=True)
    objective: Mapped[str] = mapped_column(NAME)
    level: Mapped[str] = mapped_column(String(10))
    priority: Mapped[int]
    rule: Mapped[list[Any]] = mapped_column(JSON)

    __table_args__ = (CheckConstraint("level IN ('low', 'high')", name="level"),)


class BehaviourRow(Base):
    """A motor primitive: designed (no run) or synthesised by a run's knowledge propagation.

    Designed names are unique; a run's synthesised names are unique within the run.
    """

    __tablename__ = "behaviours"

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(NAME)
    position: Mapped[int]
    family: Mapped[str] = mapped_column(String(40))
    speed_mps: Mapped[float]
    turn_dps: Mapped[float]
    ticks: Mapped[int]
    mode: Mapped[str] = mapped_column(String(20))
    synthesized: Mapped[bool] = mapped_column(server_default=false())
    run_id: Mapped[int | None] = mapped_column(
        ForeignKey("runs.id", ondelete="CASCADE"), index=True
    )

    __table_args__ = (
        UniqueConstraint("run_id", "name"),
        Index(
            "uq_behaviours_designed_name",
            "name",
            unique=True,
            sqlite_where=text("run_id IS NULL"),
            postgresql_where=text("run_id IS NULL"),
        ),
        CheckConstraint(_one_of("mode", BEHAVIOUR_MODES), name="mode"),
        CheckConstraint("ticks >= 1", name="ticks"),
    )


class NetworkRow(Base):
    """A named behaviour network (a knowledge set the editor edits)."""

    __tablename__ = "networks"

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(NAME, unique=True)
    description: Mapped[str] = mapped_column(Text, default="")
    builtin: Mapped[bool] = mapped_column(server_default=false())
    version: Mapped[int] = mapped_column(server_default=text("1"))
    created_at: Mapped[datetime] = _created()
    updated_at: Mapped[datetime] = mapped_column(server_default=func.now(), onupdate=func.now())


class AssociationRow(Base):
    """An S-R association of a named network."""

    __tablename__ = "associations"

    id: Mapped[int] = mapped_column(primary_key=True)
    network_id: Mapped[int] = mapped_column(
        ForeignKey("networks.id", ondelete="CASCADE"), index=True
    )
    stimulus_id: Mapped[int] = mapped_column(ForeignKey("stimuli.id"))
    behaviour_id: Mapped[int] = mapped_column(ForeignKey("behaviours.id"))
    strength: Mapped[float]
    source: Mapped[str] = mapped_column(String(20))
    locked: Mapped[bool] = mapped_column(server_default=false())

    __table_args__ = (
        UniqueConstraint("network_id", "stimulus_id", "behaviour_id"),
        CheckConstraint(_one_of("source", SOURCES), name="source"),
    )


class NetworkVersionRow(Base):
    """One version of a network's edit history: the whole network as JSON."""

    __tablename__ = "network_versions"

    id: Mapped[int] = mapped_column(primary_key=True)
    network_id: Mapped[int] = mapped_column(
        ForeignKey("networks.id", ondelete="CASCADE"), index=True
    )
    version: Mapped[int]
    snapshot: Mapped[dict[str, Any]]
    note: Mapped[str] = mapped_column(Text, default="")
    created_at: Mapped[datetime] = _created()

    __table_args__ = (UniqueConstraint("network_id", "version"),)


class RunRow(Base):
    """A run: its spec, status, counters and last checkpoint."""

    __tablename__ = "runs"

    id: Mapped[int] = mapped_column(primary_key=True)
    condition: Mapped[str] = mapped_column(NAME)
    seed: Mapped[int] = mapped_column(BigInteger)
    episodes: Mapped[int | None]
    mode: Mapped[str] = mapped_column(String(20))
    hz: Mapped[float]
    network: Mapped[str | None] = mapped_column(NAME)
    network_id: Mapped[int | None] = mapped_column(
        ForeignKey("networks.id", ondelete="SET NULL"), index=True
    )
    """The stored network it started from (NULL: a knowledge set, or that network is gone)."""
    params: Mapped[dict[str, Any]]
    world: Mapped[str] = mapped_column(NAME, server_default=text("''"))
    """The world preset's name ('' for a run stored before runs kept it: the default)."""
    sensors: Mapped[str] = mapped_column(NAME, server_default=text("''"))
    """The sensor definition's name ('' for a run stored before runs kept it: the default)."""
    status: Mapped[str] = mapped_column(String(20), index=True)
    error: Mapped[str | None] = mapped_column(Text)
    created_at: Mapped[datetime] = _created()
    started_at: Mapped[datetime | None]
    finished_at: Mapped[datetime | None]
    episodes_done: Mapped[int] = mapped_column(server_default=text("0"))
    successes: Mapped[int] = mapped_column(server_default=text("0"))
    ticks: Mapped[int] = mapped_column(BigInteger, server_default=text("0"))
    checkpoint_episode: Mapped[int | None]
    checkpoint_tick: Mapped[int | None] = mapped_column(BigInteger)
    checkpoint: Mapped[bytes | None]

    __table_args__ = (
        CheckConstraint(_one_of("status", RUN_STATUSES), name="status"),
        CheckConstraint(_one_of("mode", RUN_MODES), name="mode"),
        {"sqlite_autoincrement": True},
    )


class RunAssociationRow(Base):
    """An association of a run's live behaviour network."""

    __tablename__ = "run_associations"

    id: Mapped[int] = mapped_column(primary_key=True)
    run_id: Mapped[int] = _run_fk()
    stimulus_id: Mapped[int] = mapped_column(ForeignKey("stimuli.id"))
    behaviour_id: Mapped[int] = mapped_column(ForeignKey("behaviours.id"))
    strength: Mapped[float]
    source: Mapped[str] = mapped_column(String(20))
    locked: Mapped[bool] = mapped_column(server_default=false())

    __table_args__ = (
        UniqueConstraint("run_id", "stimulus_id", "behaviour_id"),
        CheckConstraint(_one_of("source", SOURCES), name="source"),
    )


class LtmRow(Base):
    """A run's long-term memory: the reliability of one S-R pair."""

    __tablename__ = "ltm"

    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id", ondelete="CASCADE"), primary_key=True)
    stimulus_id: Mapped[int] = mapped_column(ForeignKey("stimuli.id"), primary_key=True)
    behaviour_id: Mapped[int] = mapped_column(ForeignKey("behaviours.id"), primary_key=True)
    reliability: Mapped[float]


class RltmRow(Base):
    """A run's relational long-term memory (knowledge propagation's reliabilities)."""

    __tablename__ = "rltm"

    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id", ondelete="CASCADE"), primary_key=True)
    stimulus_id: Mapped[int] = mapped_column(ForeignKey("stimuli.id"), primary_key=True)
    behaviour_id: Mapped[int] = mapped_column(ForeignKey("behaviours.id"), primary_key=True)
    reliability: Mapped[float]


class EpisodeRow(Base):
    """An episode's summary and compressed trace."""

    __tablename__ = "episodes"

    run_id: Mapped[int] = mapped_column(ForeignKey("runs.id", ondelete="CASCADE"), primary_key=True)
    episode: Mapped[int] = mapped_column(primary_key=True, autoincrement=False)
    outcome: Mapped[str] = mapped_column(String(40))
    cause: Mapped[str | None] = mapped_column(String(100))
    ticks: Mapped[int]
    start_tick: Mapped[int] = mapped_column(BigInteger)
    rewards: Mapped[int]
    trace: Mapped[bytes]


class RewardRow(Base):
    """The reward log: every reward as received, and whether its learning was committed."""

    __tablename__ = "rewards"

    id: Mapped[int] = mapped_column(primary_key=True)
    run_id: Mapped[int] = _run_fk()
    tick: Mapped[int] = mapped_column(BigInteger)
    episode: Mapped[int]
    value: Mapped[float]
    source: Mapped[str] = mapped_column(String(40))
    note: Mapped[str] = mapped_column(Text, default="")
    uid: Mapped[str] = mapped_column(String(64), server_default=text("''"))
    """The reward's id from its arrival (`core.commands.InjectReward.uid`)."""
    tick_seen: Mapped[int | None] = mapped_column(BigInteger)
    """The tick the trainer saw when they pressed (NULL: the paper's rule)."""
    seen_episode: Mapped[int | None]
    window_first: Mapped[int | None] = mapped_column(BigInteger)
    """The first tick the reward could credit (its reaction window's)."""
    window_last: Mapped[int | None] = mapped_column(BigInteger)
    records: Mapped[list[list[int]] | None] = mapped_column(JSON)
    """A stored episode's records it credited, [tick, stimulus id, behaviour id] each
    (NULL: it credited the run's memory)."""
    applied: Mapped[bool] = mapped_column(server_default=false())
    credited: Mapped[int] = mapped_column(server_default=text("0"))
    created_at: Mapped[datetime] = _created()

    __table_args__ = ({"sqlite_autoincrement": True},)


class RunCommandRow(Base):
    """The command log: association edits and other state-changing commands, stamped."""

    __tablename__ = "run_commands"

    id: Mapped[int] = mapped_column(primary_key=True)
    run_id: Mapped[int] = _run_fk()
    tick: Mapped[int] = mapped_column(BigInteger)
    kind: Mapped[str] = mapped_column(String(40))
    payload: Mapped[dict[str, Any]]
    created_at: Mapped[datetime] = _created()

    __table_args__ = ({"sqlite_autoincrement": True},)


STUDY_ASSIGNMENTS = ("balanced", "fixed")
PARTICIPANT_STATUSES = ("invited", "consented", "training", "done")


class StudyRow(Base):
    """A trainer study: its conditions, budget, consent text and HMAC secret."""

    __tablename__ = "studies"

    id: Mapped[int] = mapped_column(primary_key=True)
    name: Mapped[str] = mapped_column(NAME, unique=True)
    conditions: Mapped[list[str]] = mapped_column(JSON)
    assignment: Mapped[str] = mapped_column(String(20))
    budget_episodes: Mapped[int | None]
    budget_s: Mapped[float | None]
    consent_text: Mapped[str] = mapped_column(Text)
    consent_version: Mapped[str] = mapped_column(NAME)
    questionnaire: Mapped[list[str]] = mapped_column(JSON)
    completion_code: Mapped[str | None] = mapped_column(NAME)
    redirect_url: Mapped[str | None] = mapped_column(Text)
    secret: Mapped[str] = mapped_column(String(64))
    """The HMAC key of the pseudonyms: made at creation, never served."""
    created_at: Mapped[datetime] = _created()

    __table_args__ = (
        CheckConstraint(_one_of("assignment", STUDY_ASSIGNMENTS), name="assignment"),
        CheckConstraint("(budget_episodes IS NULL) <> (budget_s IS NULL)", name="one_budget"),
    )


class ParticipantRow(Base):
    """A study's participant, by pseudonym; the token only as its SHA-256."""

    __tablename__ = "participants"

    id: Mapped[int] = mapped_column(primary_key=True)
    study_id: Mapped[int] = mapped_column(ForeignKey("studies.id", ondelete="CASCADE"), index=True)
    pseudonym: Mapped[str] = mapped_column(String(64))
    token_hash: Mapped[str] = mapped_column(String(64), unique=True)
    run_id: Mapped[int | None] = mapped_column(
        ForeignKey("runs.id", ondelete="SET NULL"), index=True
    )
    condition: Mapped[str | None] = mapped_column(NAME)
    consent_version: Mapped[str | None] = mapped_column(NAME)
    consented_at: Mapped[datetime | None]
    status: Mapped[str] = mapped_column(String(20), server_default=text("'invited'"))
    created_at: Mapped[datetime] = _created()

    __table_args__ = (
        UniqueConstraint("study_id", "pseudonym"),
        CheckConstraint(_one_of("status", PARTICIPANT_STATUSES), name="status"),
    )


class QuestionnaireAnswerRow(Base):
    """A participant's answer to one question, with the question as it was asked."""

    __tablename__ = "questionnaire_answers"

    participant_id: Mapped[int] = mapped_column(
        ForeignKey("participants.id", ondelete="CASCADE"), primary_key=True
    )
    question_no: Mapped[int] = mapped_column(primary_key=True)
    question: Mapped[str] = mapped_column(Text)
    answer: Mapped[str] = mapped_column(Text)
    answered_at: Mapped[datetime]


class ParticipantIdentityRow(Base):
    """The mapping from a recruiter's id to a pseudonym, apart so it can be deleted."""

    __tablename__ = "participant_identities"

    participant_id: Mapped[int] = mapped_column(
        ForeignKey("participants.id", ondelete="CASCADE"), primary_key=True
    )
    study_id: Mapped[int] = mapped_column(ForeignKey("studies.id", ondelete="CASCADE"), index=True)
    external_id: Mapped[str] = mapped_column(Text)
