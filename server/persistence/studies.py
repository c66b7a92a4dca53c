"""Studies and their participants in the database (`core.studies.StudyRepository`).

Each method is one transaction. The recruiters' ids live in `participant_identities`
only; the study's secret is read here, to make pseudonyms, and never leaves.

A participant found by their token once they train (their run is theirs for good) is kept
for `TOKEN_CACHE_S` (`recent_token`): every request of theirs is authorised by it, and a
query each would cost more than the request. Any write through the repository forgets them
all. Another service sharing the database may finish them meanwhile; the routes that
depend on it (rewards, their page) check the budget on the run itself.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterator, Sequence
from contextlib import AbstractContextManager, contextmanager
from datetime import UTC, datetime

from sqlalchemy import delete, func, select
from sqlalchemy.orm import Session

from core.studies import (
    Answer,
    AnsweredError,
    Assignment,
    NewParticipant,
    Participant,
    ParticipantExistsError,
    ParticipantStatus,
    StaleConsentError,
    Study,
    StudyExistsError,
    StudySpec,
    UnknownStudyError,
    assign,
    pseudonym,
)
from server.persistence.db import transaction
from server.persistence.orm import (
    ParticipantIdentityRow,
    ParticipantRow,
    QuestionnaireAnswerRow,
    StudyRow,
)

ANONYMOUS = "anonymous:"
"""What an anonymous participant's pseudonym is made from, before their token's digest."""
TOKEN_CACHE_S = 60.0
"""How long a participant read by their token is answered from memory, once they train."""
SETTLED = frozenset({ParticipantStatus.TRAINING, ParticipantStatus.DONE})
"""Participants kept: those before (invited, consented) change on their next steps."""
TOKEN_CACHE_MAX = 100_000
"""The most participants kept; past it, all are forgotten (and read again as they call)."""


def _utc(when: datetime) -> datetime:
    return when if when.tzinfo is not None else when.replace(tzinfo=UTC)


def _spec(row: StudyRow) -> StudySpec:
    return StudySpec(
        name=row.name,
        conditions=tuple(row.conditions),
        assignment=Assignment(row.assignment),
        budget_episodes=row.budget_episodes,
        budget_s=row.budget_s,
        consent_text=row.consent_text,
        consent_version=row.consent_version,
        questionnaire=tuple(row.questionnaire),
        completion_code=row.completion_code,
        redirect_url=row.redirect_url,
    )


def _participant(row: ParticipantRow, study: str) -> Participant:
    return Participant(
        id=row.id,
        study=study,
        pseudonym=row.pseudonym,
        status=ParticipantStatus(row.status),
        condition=row.condition,
        run_id=row.run_id,
        consent_version=row.consent_version,
        consented_at=None if row.consented_at is None else _utc(row.consented_at),
        created_at=_utc(row.created_at),
    )


def _study(s: Session, row: StudyRow) -> Study:
    counts: dict[str, int] = dict(
        s.execute(
            select(ParticipantRow.status, func.count())
            .where(ParticipantRow.study_id == row.id)
            .group_by(ParticipantRow.status)
        ).all()
    )
    progress = {status: counts.get(status.value, 0) for status in ParticipantStatus}
    return Study(row.id, _spec(row), _utc(row.created_at), progress)


def _study_row(s: Session, name: str) -> StudyRow:
    row = s.scalar(select(StudyRow).where(StudyRow.name == name))
    if row is None:
        raise UnknownStudyError(f"no study named {name!r}")
    return row


class SqlAlchemyStudyRepository:
    """`core.studies.StudyRepository` in SQL."""

    def __init__(self, sessions: Callable[[], Session]) -> None:
        self._sessions = sessions
        self._recent: dict[str, tuple[float, tuple[Participant, Study]]] = {}
        self._recent_lock = threading.Lock()
        self._writes = 0
        """Writes begun: a read that saw another write begin keeps nothing."""

    def _transaction(self, what: str, *, write: bool) -> AbstractContextManager[Session]:
        if write:
            return self._writing(what)
        return transaction(self._sessions, what, write=False)

    @contextmanager
    def _writing(self, what: str) -> Iterator[Session]:
        """A write transaction; the participants kept by token are forgotten either side."""
        self._forget()
        try:
            with transaction(self._sessions, what, write=True) as s:
                yield s
        finally:
            self._forget()

    def _forget(self) -> None:
        with self._recent_lock:
            self._writes += 1
            self._recent.clear()

    def create(self, spec: StudySpec, secret: str) -> Study:
        """Store a new study; `StudyExistsError` when its name is taken."""
        with self._transaction(f"creating study {spec.name!r}", write=True) as s:
            if s.scalar(select(StudyRow.id).where(StudyRow.name == spec.name)) is not None:
                raise StudyExistsError(f"a study named {spec.name!r} exists already")
            row = StudyRow(
                name=spec.name,
                conditions=list(spec.conditions),
                assignment=spec.assignment.value,
                budget_episodes=spec.budget_episodes,
                budget_s=spec.budget_s,
                consent_text=spec.consent_text,
                consent_version=spec.consent_version,
                questionnaire=list(spec.questionnaire),
                completion_code=spec.completion_code,
                redirect_url=spec.redirect_url,
                secret=secret,
            )
            s.add(row)
            s.flush()
            s.refresh(row)
            return _study(s, row)

    def studies(self) -> tuple[Study, ...]:
        """Every study, oldest first."""
        with self._transaction("listing studies", write=False) as s:
            rows = s.scalars(select(StudyRow).order_by(StudyRow.id)).all()
            return tuple(_study(s, r) for r in rows)

    def get(self, name: str) -> Study:
        """A study by name; `UnknownStudyError` when there is none."""
        with self._transaction(f"reading study {name!r}", write=False) as s:
            return _study(s, _study_row(s, name))

    def add_participants(
        self, name: str, entries: Sequence[NewParticipant]
    ) -> tuple[Participant, ...]:
        """Invite participants; an external id already in the study adds no one."""
        with self._transaction(f"adding participants to study {name!r}", write=True) as s:
            study = _study_row(s, name)
            named = [e.external_id for e in entries if e.external_id is not None]
            if len(set(named)) < len(named):
                twice = next(i for i in named if named.count(i) > 1)
                raise ParticipantExistsError(f"external id {twice!r} is given twice")
            made = []
            for entry in entries:
                identity = entry.external_id or ANONYMOUS + entry.token_digest
                alias = pseudonym(study.secret, identity)
                taken = select(ParticipantRow.id).where(
                    ParticipantRow.study_id == study.id, ParticipantRow.pseudonym == alias
                )
                if s.scalar(taken) is not None:
                    raise ParticipantExistsError(
                        f"external id {entry.external_id!r} is a participant of study "
                        f"{name!r} already"
                    )
                row = ParticipantRow(
                    study_id=study.id, pseudonym=alias, token_hash=entry.token_digest
                )
                s.add(row)
                s.flush()
                if entry.external_id is not None:
                    s.add(
                        ParticipantIdentityRow(
                            participant_id=row.id, study_id=study.id, external_id=entry.external_id
                        )
                    )
                made.append(row)
            s.flush()
            for row in made:
                s.refresh(row)
            return tuple(_participant(r, name) for r in made)

    def participants(self, name: str) -> tuple[Participant, ...]:
        """A study's participants, in the order they were added."""
        with self._transaction(f"listing participants of study {name!r}", write=False) as s:
            study = _study_row(s, name)
            rows = s.scalars(
                select(ParticipantRow)
                .where(ParticipantRow.study_id == study.id)
                .order_by(ParticipantRow.id)
            ).all()
            return tuple(_participant(r, name) for r in rows)

    def by_token(self, digest: str) -> tuple[Participant, Study] | None:
        """The participant whose token has this digest, and their study."""
        with self._recent_lock:
            writes = self._writes
        with self._transaction("reading a participant", write=False) as s:
            row = s.scalar(select(ParticipantRow).where(ParticipantRow.token_hash == digest))
            if row is None:
                return None
            study = s.get_one(StudyRow, row.study_id)
            found = _participant(row, study.name), _study(s, study)
        with self._recent_lock:
            if self._writes == writes and found[0].status in SETTLED:  # no write meanwhile
                if len(self._recent) >= TOKEN_CACHE_MAX:
                    self._recent.clear()
                self._recent[digest] = (time.monotonic(), found)
        return found

    def recent_token(self, digest: str) -> tuple[Participant, Study] | None:
        """`by_token`'s answer of the last `TOKEN_CACHE_S`, without a query; None if none.

        Only participants who train (or are done) are kept.
        """
        with self._recent_lock:
            kept = self._recent.get(digest)
        if kept is None or time.monotonic() - kept[0] > TOKEN_CACHE_S:
            return None
        return kept[1]

    def _row(self, s: Session, participant_id: int) -> tuple[ParticipantRow, StudyRow]:
        row = s.get_one(ParticipantRow, participant_id)
        return row, s.get_one(StudyRow, row.study_id)

    def consent(self, participant_id: int, version: str) -> Participant:
        """Record consent and assign a condition (kept if consented already)."""
        with self._transaction("recording consent", write=True) as s:
            row, study = self._row(s, participant_id)
            # Consents to one study assign one at a time (SQLite: its write lock already).
            s.execute(select(StudyRow.id).where(StudyRow.id == study.id).with_for_update())
            if row.condition is not None:
                return _participant(row, study.name)
            if version != study.consent_version:
                raise StaleConsentError(
                    f"consent_version {version!r} is not the study's consent "
                    f"(version {study.consent_version!r}): read it again"
                )
            counts: dict[str | None, int] = dict(
                s.execute(
                    select(ParticipantRow.condition, func.count())
                    .where(
                        ParticipantRow.study_id == study.id, ParticipantRow.condition.is_not(None)
                    )
                    .group_by(ParticipantRow.condition)
                ).all()
            )
            row.condition = assign(_spec(study), {str(k): v for k, v in counts.items()})
            row.consent_version = version
            row.consented_at = datetime.now(UTC)
            row.status = ParticipantStatus.CONSENTED.value
            s.flush()
            return _participant(row, study.name)

    def set_run(self, participant_id: int, run_id: int) -> Participant:
        """Give a consented participant their run."""
        with self._transaction("assigning a participant's run", write=True) as s:
            row, study = self._row(s, participant_id)
            row.run_id = run_id
            row.status = ParticipantStatus.TRAINING.value
            s.flush()
            return _participant(row, study.name)

    def finish(self, participant_id: int) -> Participant:
        """Mark a participant done."""
        with self._transaction("finishing a participant", write=True) as s:
            row, study = self._row(s, participant_id)
            row.status = ParticipantStatus.DONE.value
            s.flush()
            return _participant(row, study.name)

    def delete_identities(self, name: str) -> int:
        """Delete the study's external id to pseudonym mapping."""
        with self._transaction(f"deleting the identities of study {name!r}", write=True) as s:
            study = _study_row(s, name)
            gone = s.execute(
                delete(ParticipantIdentityRow).where(ParticipantIdentityRow.study_id == study.id)
            )
            return int(gone.rowcount)  # type: ignore[attr-defined]

    def answer(self, participant_id: int, answers: Sequence[str]) -> tuple[Answer, ...]:
        """Store a participant's answers, once (`AnsweredError` after)."""
        with self._transaction("storing a participant's answers", write=True) as s:
            row, study = self._row(s, participant_id)
            # One participant's answers at a time (SQLite: its write lock already).
            s.execute(
                select(ParticipantRow.id).where(ParticipantRow.id == row.id).with_for_update()
            )
            given = select(QuestionnaireAnswerRow.question_no).where(
                QuestionnaireAnswerRow.participant_id == row.id
            )
            if s.scalar(given.limit(1)) is not None:
                raise AnsweredError("this participant has answered the questionnaire already")
            questions = list(study.questionnaire)
            assert len(answers) == len(questions), "the route checks the count"
            now = datetime.now(UTC)
            rows = [
                QuestionnaireAnswerRow(
                    participant_id=row.id, question_no=n, question=q, answer=a, answered_at=now
                )
                for n, (q, a) in enumerate(zip(questions, answers, strict=True), 1)
            ]
            s.add_all(rows)
            s.flush()
            return tuple(_answer(r, row.pseudonym) for r in rows)

    def answers(self, name: str, participant_id: int | None = None) -> tuple[Answer, ...]:
        """A study's answers by participant and question (or one participant's)."""
        with self._transaction(f"reading the answers of study {name!r}", write=False) as s:
            study = _study_row(s, name)
            query = (
                select(QuestionnaireAnswerRow, ParticipantRow.pseudonym)
                .join(ParticipantRow, ParticipantRow.id == QuestionnaireAnswerRow.participant_id)
                .where(ParticipantRow.study_id == study.id)
                .order_by(ParticipantRow.id, QuestionnaireAnswerRow.question_no)
            )
            if participant_id is not None:
                query = query.where(ParticipantRow.id == participant_id)
            return tuple(_answer(r, alias) for r, alias in s.execute(query))


def _answer(row: QuestionnaireAnswerRow, alias: str) -> Answer:
    return Answer(alias, row.question_no, row.question, row.answer, _utc(row.answered_at))
