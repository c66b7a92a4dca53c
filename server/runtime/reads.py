"""What the service reads of its runs: their public state from a `RunState`, and the KP inspector.

`run_of_state` answers `GET /api/runs/{id}` from the run's last `RunState`, without asking
the run. The KP inspector is a query (`InspectKp`): its handler runs where the run ticks,
on its view, between two steps of its tasks, and answers a value; `QUERIES` is what a
`RunHost` answers beyond the core's own queries.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

from core.brain.propagation import KnowledgePropagation, KpLog, KpProvenance, steer_angle
from core.engine import RunView
from core.engine.build import reaction_seconds
from core.engine.messages import Query, RunState
from core.ports import NOT_ENDED, RunSpec, RunTotals
from core.run.conditions import CONDITIONS
from server.runtime.host import QueryHandler
from server.schemas import (
    KpAssociationPublic,
    KpPerceptPublic,
    KpProvenancePublic,
    KpPublic,
    KpRunSpanPublic,
    KpSourcePublic,
    LiveState,
    RltmPointPublic,
    RstmPublic,
    RstmRecordPublic,
    RunPublic,
)


def _ms(x: float) -> float | None:
    return None if math.isnan(x) else x * 1000


def live_state(state: RunState) -> LiveState:
    """A running run's live figures."""
    figures = state.figures
    return LiveState(
        tick=state.tick,
        episode=state.episode,
        hz=state.hz,
        ticks_run=figures.ticks_run,
        lateness_p99_ms=_ms(figures.lateness_p99_s),
        lateness_max_ms=_ms(figures.lateness_max_s),
        overruns=figures.overruns,
        reward_ack_p99_ms=_ms(figures.reward_ack_p99_s),
        ticks_by_origin=dict(state.ticks_by_origin),
    )


def run_public(
    run_id: int,
    spec: RunSpec,
    status_value: str,
    error: str | None,
    totals: RunTotals,
    live: LiveState | None,
) -> RunPublic:
    """A run's public state (`live`: its figures while it runs)."""
    params = {k: v for k, v in spec.params.items() if isinstance(v, float | int | bool)}
    return RunPublic(
        id=run_id,
        condition=spec.condition,
        seed=spec.seed,
        episodes=spec.episodes,
        mode=spec.mode.value,
        hz=spec.hz,
        network=spec.network,
        params=params,
        world=spec.world,
        sensors=spec.sensors,
        reaction_window_s=reaction_seconds(spec),
        status=status_value,
        error=error,
        episodes_done=totals.episodes,
        successes=totals.successes,
        ticks=totals.ticks,
        live=live,
    )


def run_of_state(spec: RunSpec, state: RunState) -> RunPublic:
    """A live run's state from its last `RunState`, without asking it or the database.

    A run that has ended has no live figures, whether or not its engine is let go yet: the
    answer does not depend on when that happens.
    """
    live = live_state(state) if state.status in NOT_ENDED else None
    return run_public(state.run_id, spec, state.status.value, state.error, state.totals, live)


def not_kp(run_id: int, condition: str, live: bool) -> KpPublic:
    """The answer for a run whose condition does not propagate."""
    kp = ", ".join(n for n, c in CONDITIONS.items() if c.kp)
    return KpPublic(
        run=run_id,
        condition=condition,
        kp=False,
        live=live,
        reason=(
            f"condition {condition!r} does not run knowledge propagation: no RSTM, no RLTM "
            f"(conditions that do: {kp})"
        ),
    )


def _provenance(kp: KnowledgePropagation, p: KpProvenance, dt_s: float) -> KpProvenancePublic:
    s = [x.name for x in kp.catalog.stimuli]
    b = kp.catalog.behaviours
    return KpProvenancePublic(
        after_tick=p.after_tick,
        sources=[
            KpSourcePublic(
                tick=r.tick,
                sonar_stimulus=s[r.low],
                behaviour=b[r.behaviour].name,
                heading_deg=math.degrees(steer_angle(b[r.behaviour], dt_s)),
            )
            for r in p.sources
        ],
        sum_x=p.sum_x,
        sum_y=p.sum_y,
        heading_deg=math.degrees(p.angle_rad),
        speed_mps=p.speed_mps,
        nearest=b[p.nearest].name,
        nearest_heading_deg=math.degrees(p.nearest_angle_rad),
        behaviour=b[p.behaviour].name,
        resolution=p.resolution,
    )


@dataclass(frozen=True, slots=True)
class InspectKp(Query):
    """The KP inspector's query: answered with a `KpPublic`."""


def kp_of_view(view: RunView, _: InspectKp | None = None) -> KpPublic:
    """A live run's KP inspector, read where it ticks (`InspectKp`'s handler)."""
    kp = view.kp
    if kp is None:
        return not_kp(view.run_id, view.spec.condition, live=True)
    return _kp_live(view.run_id, view, kp)


def _kp_live(run_id: int, view: RunView, kp: KnowledgePropagation) -> KpPublic:
    """Read where the run ticks, between ticks: it changes only there."""
    dt_s = kp.dt_s
    cat = kp.catalog
    s = [x.name for x in cat.stimuli]
    b = [x.name for x in cat.behaviours]
    tick = view.tick
    window = kp.config.window_ticks
    rstm = [
        RstmPublic(
            sensor=sensor,
            records=[
                RstmRecordPublic(
                    tick=r.tick,
                    camera_stimulus=s[r.high],
                    sonar_stimulus=s[r.low],
                    behaviour=b[r.behaviour],
                )
                for r in records
            ],
        )
        for sensor, records in sorted(kp.rstm.items())
    ]
    percepts = [
        KpPerceptPublic(
            objective=objective, camera_stimulus=s[high], tick=t, open=kp.now - t <= window
        )
        for objective, (high, t) in sorted(kp.perceived().items())
    ]
    network = kp.network
    pairs = dict.fromkeys([*kp.log, *kp.rltm])
    for a in network:
        if a.source == "kp":
            pairs.setdefault((a.stimulus, a.behaviour))
    associations = []
    for st, be in pairs:
        log = kp.log.get((st, be)) or KpLog(0)  # one from an earlier engine: no record
        assoc = network.get(st, be)
        associations.append(
            KpAssociationPublic(
                stimulus=s[st],
                behaviour=b[be],
                reliability=kp.rltm.get((st, be), 0.0),
                in_network=assoc is not None and assoc.source == "kp",
                synthesized=cat.behaviours[be].synthesized,
                provenance=[_provenance(kp, p, dt_s) for p in log.provenances],
                history=[
                    RltmPointPublic.model_validate(h, from_attributes=True) for h in log.history
                ],
                runs=[KpRunSpanPublic(first_tick=a, last_tick=z) for a, z in log.runs],
                reasoned=log.reasoned,
                ran_ticks=log.ran_ticks,
            )
        )
    associations.sort(key=lambda x: (not x.in_network, -x.reliability, x.stimulus, x.behaviour))
    made_before = [x for x in associations if not x.provenance]
    reason = None
    if made_before:
        reason = (
            f"{len(made_before)} association(s) predate this engine (the run was resumed): "
            "their provenance was kept only while the earlier engine ran"
        )
    return KpPublic(
        run=run_id,
        condition=view.spec.condition,
        kp=True,
        live=True,
        reason=reason,
        tick=tick,
        window_ticks=window,
        rstm=rstm,
        percepts=percepts,
        associations=associations,
        count=len(associations),
        insert_threshold=kp.config.insert_threshold,
    )


QUERIES: Mapping[type[Query], QueryHandler] = {InspectKp: kp_of_view}
"""The queries of the service's routes a `RunHost` answers, by type."""
