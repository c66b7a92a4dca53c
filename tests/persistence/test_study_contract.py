"""One contract for the study store, on SQLite and PostgreSQL: studies, participants, consent."""

from __future__ import annotations

from dataclasses import replace

import pytest
from contracthelpers import SPEC
from sqlalchemy import Engine, select, text

from core.errors import UnknownNameError
from core.studies import (
    AnsweredError,
    Assignment,
    NewParticipant,
    ParticipantExistsError,
    ParticipantStatus,
    StaleConsentError,
    StudyExistsError,
    StudyRepository,
    StudySpec,
    UnknownStudyError,
    pseudonym,
    token_digest,
)
from server.persistence import SqlAlchemyRunStore, make_sessionmaker
from server.persistence.orm import ParticipantIdentityRow, ParticipantRow, StudyRow
from server.persistence.studies import SqlAlchemyStudyRepository

SECRET = "s3cret"
STUDY = StudySpec(
    name="pilot",
    conditions=("trainer", "rp"),
    budget_episodes=3,
    consent_text="You train a robot.",
    consent_version="v2",
    questionnaire=("How hard was it?",),
    completion_code="C0DE",
)


@pytest.fixture(params=["sqlite", "postgresql"])
def engine(request: pytest.FixtureRequest) -> Engine:
    if request.param == "sqlite":
        found: Engine = request.getfixturevalue("sqlite_engine")
        return found
    engine: Engine = request.getfixturevalue("clean_postgres_engine")
    with engine.begin() as c:  # the module's database: no study an earlier test made
        c.execute(text("DELETE FROM studies"))
    return engine


@pytest.fixture
def studies(engine: Engine) -> StudyRepository:
    return SqlAlchemyStudyRepository(make_sessionmaker(engine))


def invite(studies: StudyRepository, *ids: str | None) -> list[int]:
    entries = [NewParticipant(i, token_digest(f"token-{i}-{n}")) for n, i in enumerate(ids)]
    return [p.id for p in studies.add_participants("pilot", entries)]


def test_create_stores_the_spec_and_no_participants(studies: StudyRepository) -> None:
    made = studies.create(STUDY, SECRET)

    assert made.spec == STUDY and studies.get("pilot") == made
    assert dict(made.progress) == dict.fromkeys(ParticipantStatus, 0)
    assert made.created_at.tzinfo is not None
    assert [s.spec.name for s in studies.studies()] == ["pilot"]


def test_create_a_taken_name_raises_and_keeps_the_first(studies: StudyRepository) -> None:
    studies.create(STUDY, SECRET)

    with pytest.raises(StudyExistsError):
        studies.create(StudySpec("pilot", ("kp",), budget_s=60.0), "other")

    assert studies.get("pilot").spec == STUDY


def test_unknown_study_is_an_unknown_name(studies: StudyRepository) -> None:
    assert issubclass(UnknownStudyError, UnknownNameError)
    for call in (
        lambda: studies.get("nope"),
        lambda: studies.participants("nope"),
        lambda: studies.delete_identities("nope"),
        lambda: studies.add_participants("nope", [NewParticipant("a", "d")]),
    ):
        with pytest.raises(UnknownStudyError):
            call()


def test_participants_are_stored_by_pseudonym_and_token_digest(
    studies: StudyRepository, engine: Engine
) -> None:
    studies.create(STUDY, SECRET)

    invite(studies, "prolific-1", None)

    first, anonymous = studies.participants("pilot")
    assert first.pseudonym == pseudonym(SECRET, "prolific-1")
    assert anonymous.pseudonym != first.pseudonym and len(anonymous.pseudonym) == 64
    assert {p.status for p in (first, anonymous)} == {ParticipantStatus.INVITED}
    assert studies.get("pilot").progress[ParticipantStatus.INVITED] == 2
    with engine.connect() as c:
        rows = c.execute(select(ParticipantRow.token_hash)).scalars().all()
        ids = c.execute(select(ParticipantIdentityRow.external_id)).scalars().all()
    assert sorted(rows) == sorted(
        [token_digest("token-prolific-1-0"), token_digest("token-None-1")]
    )
    assert ids == ["prolific-1"]  # the anonymous participant has no mapping


def test_an_external_id_twice_adds_no_one(studies: StudyRepository) -> None:
    studies.create(STUDY, SECRET)
    invite(studies, "a")

    with pytest.raises(ParticipantExistsError, match="'a'"):
        invite(studies, "b", "a")
    with pytest.raises(ParticipantExistsError, match="twice"):
        invite(studies, "c", "c")

    assert [p.pseudonym for p in studies.participants("pilot")] == [pseudonym(SECRET, "a")]


def test_by_token_finds_the_participant_and_their_study(studies: StudyRepository) -> None:
    studies.create(STUDY, SECRET)
    [pid] = invite(studies, "a")

    found = studies.by_token(token_digest("token-a-0"))

    assert found is not None and found[0].id == pid and found[1].spec == STUDY
    assert studies.by_token(token_digest("nobody")) is None


def _training(studies: StudyRepository, engine: Engine) -> int:
    """A study whose one participant ("a", token "token-a-0") trains; their id."""
    studies.create(STUDY, SECRET)
    [pid] = invite(studies, "a")
    studies.consent(pid, "v2")
    studies.set_run(pid, SqlAlchemyRunStore(make_sessionmaker(engine)).create_run(SPEC, ()))
    return pid


def test_a_training_participant_read_by_token_is_kept_until_a_write(
    studies: StudyRepository, engine: Engine
) -> None:
    pid = _training(studies, engine)
    digest = token_digest("token-a-0")
    assert studies.recent_token(digest) is None  # never read

    read = studies.by_token(digest)

    assert read is not None and studies.recent_token(digest) == read
    assert studies.recent_token(token_digest("nobody")) is None
    studies.finish(pid)  # any write forgets what was kept
    assert studies.recent_token(digest) is None
    again = studies.by_token(digest)
    assert again is not None and again[0].status is ParticipantStatus.DONE
    assert studies.recent_token(digest) == again


def test_a_participant_before_training_is_read_each_time(studies: StudyRepository) -> None:
    studies.create(STUDY, SECRET)
    [pid] = invite(studies, "a")
    digest = token_digest("token-a-0")
    assert studies.by_token(digest) is not None
    assert studies.recent_token(digest) is None  # invited: consent is their next step
    studies.consent(pid, "v2")
    assert studies.by_token(digest) is not None
    assert studies.recent_token(digest) is None  # consented: their run comes next


def test_a_kept_participant_is_read_again_after_the_cache_time(
    engine: Engine, monkeypatch: pytest.MonkeyPatch
) -> None:
    from server.persistence import studies as module

    here = SqlAlchemyStudyRepository(make_sessionmaker(engine))
    elsewhere = SqlAlchemyStudyRepository(make_sessionmaker(engine))  # another service's
    pid = _training(here, engine)
    digest = token_digest("token-a-0")
    clock = [1000.0]
    monkeypatch.setattr("server.persistence.studies.time.monotonic", lambda: clock[0])
    assert here.by_token(digest) is not None
    elsewhere.finish(pid)

    clock[0] += module.TOKEN_CACHE_S  # still kept: the other service's write is not seen
    kept = here.recent_token(digest)
    assert kept is not None and kept[0].status is ParticipantStatus.TRAINING
    clock[0] += 0.001
    assert here.recent_token(digest) is None  # too old: read again
    fresh = here.by_token(digest)
    assert fresh is not None and fresh[0].status is ParticipantStatus.DONE


def test_consent_assigns_balanced_conditions_in_order(studies: StudyRepository) -> None:
    studies.create(STUDY, SECRET)
    ids = invite(studies, "a", "b", "c", "d", "e")

    conditions = [studies.consent(i, "v2").condition for i in ids]

    assert conditions == ["trainer", "rp", "trainer", "rp", "trainer"]
    assert studies.get("pilot").progress[ParticipantStatus.CONSENTED] == 5


def test_consent_fixed_assigns_the_first_condition(studies: StudyRepository) -> None:
    studies.create(StudySpec("pilot", ("kp", "dp"), Assignment.FIXED, budget_s=30.0), SECRET)
    ids = invite(studies, "a", "b", "c")

    assert {studies.consent(i, "1").condition for i in ids} == {"kp"}


def test_consent_to_a_stale_version_raises_and_changes_nothing(
    studies: StudyRepository,
) -> None:
    studies.create(STUDY, SECRET)
    [pid] = invite(studies, "a")

    with pytest.raises(StaleConsentError, match="'v2'"):
        studies.consent(pid, "v1")

    [p] = studies.participants("pilot")
    assert (p.status, p.condition, p.consent_version) == (ParticipantStatus.INVITED, None, None)


def test_consent_again_keeps_the_condition_and_run(
    studies: StudyRepository, engine: Engine
) -> None:
    studies.create(STUDY, SECRET)
    [pid] = invite(studies, "a")
    first = studies.consent(pid, "v2")
    run_id = SqlAlchemyRunStore(make_sessionmaker(engine)).create_run(SPEC, ())

    training = studies.set_run(pid, run_id)
    again = studies.consent(pid, "v2")

    assert (training.status, training.run_id) == (ParticipantStatus.TRAINING, run_id)
    assert (again.condition, again.run_id) == (first.condition, run_id)
    assert again.consented_at is not None and again.consent_version == "v2"
    done = studies.finish(pid)
    assert done.status is ParticipantStatus.DONE
    assert studies.get("pilot").progress[ParticipantStatus.DONE] == 1


def test_delete_identities_deletes_only_the_mapping(
    studies: StudyRepository, engine: Engine
) -> None:
    studies.create(STUDY, SECRET)
    invite(studies, "a", "b", None)

    assert studies.delete_identities("pilot") == 2

    assert len(studies.participants("pilot")) == 3
    with engine.connect() as c:
        assert c.execute(select(ParticipantIdentityRow)).all() == []
        assert c.execute(select(StudyRow.secret)).scalar_one() == SECRET
    assert studies.delete_identities("pilot") == 0


def test_answers_are_stored_once_by_pseudonym_in_question_order(
    studies: StudyRepository,
) -> None:
    studies.create(replace(STUDY, questionnaire=("How hard?", "Again?")), SECRET)
    first, second, _ = invite(studies, "a", "b", "c")

    given = studies.answer(second, ["Hard.", "No"])
    studies.answer(first, ["Easy.", "Yes"])
    with pytest.raises(AnsweredError):
        studies.answer(second, ["Changed my mind.", "Yes"])

    names = {p.id: p.pseudonym for p in studies.participants("pilot")}
    every = studies.answers("pilot")
    assert [(a.participant, a.question_no, a.question, a.answer) for a in every] == [
        (names[first], 1, "How hard?", "Easy."),
        (names[first], 2, "Again?", "Yes"),
        (names[second], 1, "How hard?", "Hard."),
        (names[second], 2, "Again?", "No"),
    ]
    assert studies.answers("pilot", second) == given
    assert all(a.answered_at.tzinfo is not None for a in every)
    with pytest.raises(UnknownStudyError):
        studies.answers("nope")
