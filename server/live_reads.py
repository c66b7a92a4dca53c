"""What the service reads from a live run, and the controls it sends: run on the engines' loop.

`LiveRun.read` and `LiveRun.control` take a function of the run. With the engines in a
process of their own, the function is pickled there and unpickling it imports its module.
These functions live here, in a module that imports neither FastAPI nor viser, and the
engines' process loads it at its start (`server.engine_process.PRELOADED`): a function of a
route module would import that module, FastAPI with it, on the engines' loop at a route's
first read of a run, holding every ticking run for some 170 ms (three overruns of a 20 Hz
run).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

from core.brain.propagation import KnowledgePropagation, KpLog, KpProvenance, steer_angle
from core.conditions import CONDITIONS
from core.engine import RunEngine, RunView
from core.errors import SimulationStateError
from core.ports import NOT_ENDED, Mode, RunSpec, RunTotals
from core.simulation import Snapshot
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


def live_state(view: RunView) -> LiveState:
    """A running run's live figures."""
    stats = view.stats
    return LiveState(
        tick=view.tick,
        episode=view.episode,
        hz=view.hz,
        ticks_run=stats.ticks,
        lateness_p99_ms=_ms(stats.lateness_s.percentile(99)),
        lateness_max_ms=_ms(stats.lateness_s.max),
        overruns=stats.overruns,
        reward_ack_p99_ms=_ms(stats.reward_ack_s.percentile(99)),
        ticks_by_origin=dict(view.ticks_by_origin),
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
        status=status_value,
        error=error,
        episodes_done=totals.episodes,
        successes=totals.successes,
        ticks=totals.ticks,
        live=live,
    )


def run_of_view(view: RunView) -> RunPublic:
    """A live run's state, without touching the database.

    Read on the engines' loop (`LiveRun.read`): one consistent state of the run. A run that
    has ended has no live figures, whether or not its engine is let go yet: the answer does
    not depend on when that happens.
    """
    live = live_state(view) if view.status in NOT_ENDED else None
    return run_public(view.run_id, view.spec, view.status.value, view.error, view.totals, live)


@dataclass(frozen=True, slots=True)
class Guarded:
    """An action taken only if the run's status is one of `allowed`; else why not.

    A class, not a closure: it is pickled when the engines run in a process of their own.
    """

    run_id: int
    allowed: tuple[str, ...]
    action: Callable[[RunEngine], str | None]

    def __call__(self, engine: RunEngine) -> str | None:
        """Take the action, or say why not."""
        if engine.status.value not in self.allowed:
            return f"run {self.run_id} is {engine.status.value}"
        return self.action(engine)


def set_rate(hz: float, engine: RunEngine) -> str | None:
    """A realtime run's new tick rate, from its next tick; a fast run's refusal."""
    if engine.spec.mode is not Mode.REALTIME:
        return f"run {engine.run_id} is fast: it has no rate"
    engine.set_rate(hz)
    return None


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


def kp_of_view(run_id: int, view: RunView) -> KpPublic:
    """A live run's answer, read on the engines' loop (`LiveRun.read`)."""
    kp = view.kp
    if kp is None:
        return not_kp(run_id, view.spec.condition, live=True)
    return _kp_live(run_id, view, kp)


def _kp_live(run_id: int, view: RunView, kp: KnowledgePropagation) -> KpPublic:
    """Read on the engines' loop, between ticks (`LiveRun.read`): it changes only there."""
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


def latest(view: RunView) -> tuple[Snapshot, RunTotals, bool] | None:
    """The run's latest tick, its totals and its KP flag (None: no episode yet)."""
    try:
        snap = view.snapshot
    except SimulationStateError:  # not reset yet
        return None
    return snap, view.totals, view.released_by_kp(snap)
