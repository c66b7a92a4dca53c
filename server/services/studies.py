"""What the studies' routes and `srlab study` share: a study's spec, and inviting people.

Both take the organiser's input through the same schemas (`server.schemas.studies`), so
the command line refuses what the API refuses, with the same rules.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import secrets
from collections.abc import Sequence
from dataclasses import dataclass

from core.engine.messages import RunState, Stop
from core.errors import RunStateError, StorageError
from core.ports import ACTIVE, RunQueries
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
from server.runtime import Runs
from server.schemas.studies import EpisodeBudget, StudyCreate, TimeBudget

log = logging.getLogger("srlab.studies")

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


SETTLE_EVERY_S = 1.0
"""How often `StudyWatch` looks at the participants' runs ticking here."""


def _training(studies: StudyRepository) -> list[tuple[Participant, StudySpec]]:
    """Every participant training on a run, with their study's spec (blocking)."""
    return [
        (p, study.spec)
        for study in studies.studies()
        for p in studies.participants(study.spec.name)
        if p.status is ParticipantStatus.TRAINING and p.run_id is not None
    ]


class StudyWatch:
    """Marks a participant done as soon as their run has spent the budget.

    No one need read: their tab may be closed, and the organiser's page too. Every
    `SETTLE_EVERY_S` it looks at the runs ticking here, and at the last state of each run
    that ended since (`Runs.ended_hooks`: a run may start and end between two looks); a
    run still ticking on a spent time budget is stopped. `flush`, after the runs'
    shutdown, looks once more at the runs it interrupted, so a budget spent just before a
    restart is not lost with the unfinished episode's ticks (storage keeps a run's totals
    as of its last episode).
    """

    def __init__(self, studies: StudyRepository, every_s: float | None = None) -> None:
        self._studies = studies
        self._every_s = SETTLE_EVERY_S if every_s is None else every_s
        self._runs: Runs | None = None
        self._ended: dict[int, RunState] = {}

    def attach(self, runs: Runs) -> None:
        """Watch `runs`: hear each run's end from now on."""
        self._runs = runs
        runs.ended_hooks.append(self._heard_ended)

    def _heard_ended(self, run_id: int, state: RunState) -> None:
        self._ended[run_id] = state

    async def run(self) -> None:
        """Settle every `every_s` until cancelled; a failed look is logged and retried."""
        while True:
            await asyncio.sleep(self._every_s)
            await self.flush()

    async def flush(self) -> None:
        """Settle once now (a failure is logged: the next look, or a read, retries it)."""
        try:
            await self.settle()
        except StorageError as e:  # the store says why in a line; the run's failure has it
            log.error("participants whose budget is spent could not be marked done: %s", e)
        except Exception:
            log.exception("participants whose budget is spent could not be marked done")

    async def settle(self) -> int:
        """One look: mark done whoever's run has spent the budget; how many were."""
        runs = self._runs
        ended, self._ended = self._ended, {}
        states = {live.run_id: live.state for live in (runs.engines() if runs else ())}
        states |= ended  # a run's last state is its final word
        if not states:
            return 0
        try:
            training = await asyncio.to_thread(_training, self._studies)
            done = 0
            for p, spec in training:
                state = None if p.run_id is None else states.get(p.run_id)
                if state is None or not budget_spent(
                    spec, state.totals.episodes, state.totals.ticks, state.hz
                ):
                    continue
                await asyncio.to_thread(self._studies.finish, p.id)
                done += 1
                live = None if runs is None or p.run_id is None else runs.get(p.run_id)
                if live is not None and live.status in ACTIVE:  # a time budget, spent
                    with contextlib.suppress(RunStateError):
                        await live.send(Stop())
            return done
        except BaseException:
            self._ended = ended | self._ended  # heard again at the next look
            raise
