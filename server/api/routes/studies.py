"""Trainer studies: the organiser's routes, and a participant's own (by their token)."""

from __future__ import annotations

import contextlib
from typing import Annotated

from fastapi import Depends, HTTPException, Path, Request, status
from fastapi.exceptions import RequestValidationError
from starlette.concurrency import run_in_threadpool as io

from core.engine.messages import Stop
from core.errors import RunStateError
from core.studies import (
    Participant,
    ParticipantStatus,
    Study,
    StudyRepository,
    StudySpec,
    budget_spent,
)
from server.api.access import Organiser, Principal, PrincipalDep
from server.api.deps import EnginesDep, StateDep, StoreDep
from server.api.routes.runs import run_now, view_link
from server.api.routing import resource_router
from server.schemas.common import Text
from server.schemas.runs import RunPublic, ViewChosen
from server.schemas.studies import (
    AnswersCreate,
    ConsentCreate,
    IdentitiesDeleted,
    ParticipantInvited,
    ParticipantPublic,
    ParticipantsAnonymous,
    ParticipantsInvited,
    ParticipantsNamed,
    ParticipantsPublic,
    ParticipantView,
    StudiesPublic,
    StudyCreate,
    StudyPublic,
)
from server.services.runspec import run_spec
from server.services.studies import invite, new_study

router = resource_router("/studies", tag="studies")
participant_router = resource_router("/participant", tag="participant")
StudyName = Annotated[Text, Path(max_length=100, description="a study's name")]
PARTICIPANT_HZ = 10.0
"""A participant's run ticks in realtime at this rate."""


async def _studies(state: StateDep) -> StudyRepository:
    if state.studies is None:
        raise RunStateError("this service's storage keeps no studies")
    return state.studies


StudiesDep = Annotated[StudyRepository, Depends(_studies)]


async def _participant(who: PrincipalDep) -> Principal:
    if who.participant is None:
        raise HTTPException(
            status.HTTP_401_UNAUTHORIZED,
            "this needs a participant's token: `Authorization: Bearer <token of their link>`",
            headers={"WWW-Authenticate": "Bearer"},
        )
    return who


ParticipantDep = Annotated[Principal, Depends(_participant)]


def study_public(study: Study) -> StudyPublic:
    """A study as answered: never its secret."""
    s = study.spec
    return StudyPublic(
        id=study.id, name=s.name, conditions=list(s.conditions), assignment=s.assignment.value,
        budget_episodes=s.budget_episodes, budget_s=s.budget_s, consent_text=s.consent_text,
        consent_version=s.consent_version, questionnaire=list(s.questionnaire),
        completion_code=s.completion_code, redirect_url=s.redirect_url,
        created_at=study.created_at,
        progress={k.value: v for k, v in study.progress.items()},
    )  # fmt: skip


def training_run(p: Participant) -> int | None:
    """The run `p` trains, their budget not spent yet (None: they do not train)."""
    return p.run_id if p.status is ParticipantStatus.TRAINING else None


def participant_public(p: Participant, run: RunPublic | None = None) -> ParticipantPublic:
    """A participant as the organiser sees them: by pseudonym, never an external id.

    With their `run` as it is now, how much of the budget they have spent.
    """
    return ParticipantPublic(
        id=p.id, pseudonym=p.pseudonym, status=p.status.value, condition=p.condition,
        run_id=p.run_id, consent_version=p.consent_version, consented_at=p.consented_at,
        episodes_done=None if run is None else run.episodes_done,
        seconds_done=None if run is None else round(run.ticks / run.hz, 1),
    )  # fmt: skip


@router.post("", status_code=status.HTTP_201_CREATED, dependencies=[Organiser])
async def create_study(body: StudyCreate, studies: StudiesDep) -> StudyPublic:
    """Create a study; its pseudonyms' secret is made here and never served."""
    return study_public(await io(new_study, studies, body))


@router.get("", dependencies=[Organiser])
async def list_studies(studies: StudiesDep, store: StoreDep, engines: EnginesDep) -> StudiesPublic:
    """Every study with its progress (participants per status), oldest first."""
    for found in await io(studies.studies):
        await settle_study(found.spec.name, studies, store, engines)
    data = [study_public(s) for s in await io(studies.studies)]
    return StudiesPublic(data=data, count=len(data))


@router.get("/{name}", dependencies=[Organiser])
async def get_study(
    name: StudyName, studies: StudiesDep, store: StoreDep, engines: EnginesDep
) -> StudyPublic:
    """A study with its progress (participants per status, done as soon as spent)."""
    await settle_study(name, studies, store, engines)
    return study_public(await io(studies.get, name))


@router.get("/{name}/participants", dependencies=[Organiser])
async def list_participants(
    name: StudyName, studies: StudiesDep, store: StoreDep, engines: EnginesDep
) -> ParticipantsPublic:
    """A study's participants by pseudonym, in the order they were added.

    Beside each who trains, how far their run has got: its episodes and seconds so far
    (a run stored mid-episode counts only its finished episodes, so once done, a
    participant's status says it).
    """
    settled = await settle_study(name, studies, store, engines)
    data = [participant_public(p, run) for p, run in settled]
    return ParticipantsPublic(data=data, count=len(data))


@router.post("/{name}/participants", status_code=status.HTTP_201_CREATED, dependencies=[Organiser])
async def add_participants(
    name: StudyName,
    body: ParticipantsNamed | ParticipantsAnonymous,
    studies: StudiesDep,
    request: Request,
) -> ParticipantsInvited:
    """Invite participants by recruiter's id, or N anonymous ones.

    Each one's link and token are answered here, once only: only their digest is stored.
    """
    ids: list[str | None] = (
        list(body.external_ids) if isinstance(body, ParticipantsNamed) else [None] * body.count
    )
    made = await io(invite, studies, name, ids, str(request.base_url))
    data = [
        ParticipantInvited(
            **participant_public(i.participant).model_dump(), token=i.token, link=i.link
        )
        for i in made
    ]
    return ParticipantsInvited(data=data, count=len(data))


@router.delete("/{name}/identities", dependencies=[Organiser])
async def delete_identities(name: StudyName, studies: StudiesDep) -> IdentitiesDeleted:
    """Delete the study's external id to pseudonym mapping (the pseudonyms stay)."""
    return IdentitiesDeleted(deleted=await io(studies.delete_identities, name))


async def settle(
    p: Participant, spec: StudySpec, studies: StudyRepository, store: StoreDep, engines: EnginesDep
) -> tuple[Participant, RunPublic | None]:
    """A participant as they are now: done once their run has spent the budget.

    Whoever reads first (the participant, or the organiser watching progress) marks it,
    from the run as it is (live here, else as stored): right after a restart too, and
    whether or not the participant's tab is still open. With the run read, while they
    still train (None otherwise).
    """
    run_id = training_run(p)
    if run_id is None:
        return p, None
    run = await run_now(store, engines, run_id)
    if not budget_spent(spec, run.episodes_done, run.ticks, run.hz):
        return p, run
    done = await io(studies.finish, p.id)
    live = engines.get(run_id)
    if live is not None:  # a time budget: the run would go on ticking for no one
        with contextlib.suppress(RunStateError):
            await live.send(Stop())
    return done, None


async def settle_study(
    name: str, studies: StudyRepository, store: StoreDep, engines: EnginesDep
) -> tuple[tuple[Participant, RunPublic | None], ...]:
    """A study's participants in the order they were added, each settled (`settle`)."""
    spec = (await io(studies.get, name)).spec
    found = await io(studies.participants, name)
    return tuple([await settle(p, spec, studies, store, engines) for p in found])


async def current(
    who: Principal, studies: StudyRepository, store: StoreDep, engines: EnginesDep
) -> Participant:
    """The calling participant as they are now (`settle`)."""
    assert who.participant is not None and who.study is not None
    return (await settle(who.participant, who.study.spec, studies, store, engines))[0]


def _view(who: Principal, p: Participant, answered: bool) -> ParticipantView:
    assert who.study is not None
    s = who.study.spec
    # The code comes once the budget is spent and the questionnaire, if any, answered.
    done = p.status is ParticipantStatus.DONE and (answered or not s.questionnaire)
    return ParticipantView(
        study=s.name, pseudonym=p.pseudonym, status=p.status.value,
        consent_text=s.consent_text, consent_version=s.consent_version,
        questionnaire=list(s.questionnaire), condition=p.condition, run_id=p.run_id,
        budget_episodes=s.budget_episodes, budget_s=s.budget_s, answered=answered,
        completion_code=s.completion_code if done else None,
        redirect_url=s.redirect_url if done else None,
    )  # fmt: skip


async def _answered(studies: StudyRepository, p: Participant) -> bool:
    if p.status is not ParticipantStatus.DONE:
        return False  # no one answers before their training is done: no need to ask
    return bool(await io(studies.answers, p.study, p.id))


@participant_router.get("")
async def get_participant(
    who: ParticipantDep, studies: StudiesDep, store: StoreDep, engines: EnginesDep
) -> ParticipantView:
    """The caller's study: consent text, questionnaire, their run, and once done, the code."""
    p = await current(who, studies, store, engines)
    return _view(who, p, await _answered(studies, p))


@participant_router.post("/consent")
async def consent(
    body: ConsentCreate,
    who: ParticipantDep,
    studies: StudiesDep,
    store: StoreDep,
    engines: EnginesDep,
) -> ParticipantView:
    """Consent to the version read: a condition is assigned and their run made and started.

    409 when that version is no longer the study's. Consenting again answers the same
    run (and starts it if it could not start before, e.g. at the cap on running runs).
    """
    assert who.participant is not None and who.study is not None
    p = await io(studies.consent, who.participant.id, body.consent_version)
    if p.run_id is None:
        assert p.condition is not None
        spec = run_spec(
            condition=p.condition,
            seed=int(p.pseudonym[:7], 16),  # the participant's, reproducibly
            episodes=who.study.spec.budget_episodes,
            mode="realtime",
            hz=PARTICIPANT_HZ,
        )
        run_id = await io(engines.create, spec, None)
        p = await io(studies.set_run, p.id, run_id)
    assert p.run_id is not None
    run = await run_now(store, engines, p.run_id)
    if run.status in ("created", "interrupted") and p.status is ParticipantStatus.TRAINING:
        await engines.start(p.run_id)  # 429 at the cap: consenting again starts it
        await engines.started(p.run_id)
    return _view(who, p, await _answered(studies, p))


@participant_router.post(
    "/view-ticket",
    responses={409: {"description": "no run yet (consent first), or the 3D view is off"}},
)
async def view_ticket(
    request: Request,
    who: ParticipantDep,
    state: StateDep,
    studies: StudiesDep,
    store: StoreDep,
    engines: EnginesDep,
) -> ViewChosen:
    """The 3D view of the caller's own run, read-only: its URL with a one-time ticket.

    The ticket is good once, for a minute, on that run's view alone; the view exchanges
    it for a cookie that lets this browser watch that run (no other run, no run list, no
    controls). 409 before they consent (no run yet) or when the service has no 3D view.
    """
    p = await current(who, studies, store, engines)
    if p.run_id is None:
        raise HTTPException(status.HTTP_409_CONFLICT, "no run yet: consent first")
    return view_link(request, state, p.run_id, organiser=False)


@participant_router.post("/answers", status_code=status.HTTP_201_CREATED)
async def answer(
    body: AnswersCreate,
    who: ParticipantDep,
    studies: StudiesDep,
    store: StoreDep,
    engines: EnginesDep,
) -> ParticipantView:
    """Answer the study's questionnaire, once, after training: then the completion code.

    422 unless there is one answer per question; 409 when the study has no questionnaire,
    the participant's budget is not spent yet, or they have answered already.
    """
    assert who.study is not None
    questions = who.study.spec.questionnaire
    if not questions:
        raise RunStateError(f"study {who.study.spec.name!r} has no questionnaire")
    if len(body.answers) != len(questions):
        raise RequestValidationError(
            [
                {
                    "type": "value_error",
                    "loc": ["body", "answers"],
                    "msg": f"{len(body.answers)} answers for {len(questions)} questions: "
                    "give one answer per question, in their order",
                    "input": body.answers,
                }
            ]
        )
    p = await current(who, studies, store, engines)
    if p.status is not ParticipantStatus.DONE:
        raise RunStateError("the questionnaire comes once your training is done")
    await io(studies.answer, p.id, body.answers)
    return _view(who, p, answered=True)
