"""Knowledge propagation inspector: a run's RSTM and how each KP association came to be."""

from __future__ import annotations

from starlette.concurrency import run_in_threadpool as io

from core.brain.catalog import Catalog
from core.engine.build import brain_params
from core.params import applicable, configure
from core.ports import RunQueries
from core.run.conditions import CONDITIONS
from core.run.trace import unpack
from server.api.deps import EnginesDep, StateDep, StoreDep
from server.api.routes.runs import RunId
from server.api.routing import resource_router
from server.runtime.reads import InspectKp, not_kp
from server.schemas import (
    KpAssociationPublic,
    KpPublic,
    KpRunSpanPublic,
)

router = resource_router("/runs", tag="kp")
TRACE_EPISODES = 20
"""A stored run's latest episodes whose traces say where its KP associations ran."""


def _stored_runs(
    store: RunQueries, run_id: int, catalog: Catalog
) -> dict[tuple[str, str], list[tuple[int, int]]]:
    """Spans of consecutive ticks where each kp association ran, from the latest traces."""
    stimuli = [s.name for s in catalog.stimuli]
    names = [b.name for b in catalog.behaviours] + [b.name for b in store.behaviours(run_id)]
    _, total = store.episode_summaries_page(run_id, 0, 1)
    page, _ = store.episode_summaries_page(run_id, max(0, total - TRACE_EPISODES), TRACE_EPISODES)
    spans: dict[tuple[str, str], list[tuple[int, int]]] = {}
    for summary in page:
        found = store.episode(run_id, summary.episode)
        running: tuple[str, str] | None = None
        for r in unpack(found.trace) if found is not None and found.trace else ():
            ok = r.origin == "kp" and 0 <= r.released_by < len(stimuli)
            if not ok or not 0 <= r.behaviour < len(names):
                running = None
                continue
            pair = (stimuli[r.released_by], names[r.behaviour])
            runs = spans.setdefault(pair, [])
            if running == pair and runs and runs[-1][1] == r.tick - 1:
                runs[-1] = (runs[-1][0], r.tick)
            else:
                runs.append((r.tick, r.tick))
            running = pair
    return spans


@router.get("/{run_id}/kp")
async def get_run_kp(
    run_id: RunId, store: StoreDep, engines: EnginesDep, state: StateDep
) -> KpPublic:
    """The KP inspector: what the RSTM holds now and how each KP association came to be.

    For a running KP run: each RSTM's records (the sonar responses recorded for a camera
    stimulus), the camera stimuli last perceived, and every pair KP reasoned with its
    provenance (the source behaviours, their vector sum, the primitive it snapped to or
    the one synthesised), its RLTM history and the tick spans where it ran. A run not
    running here answers its stored RLTM and network with a `reason` (provenance is kept
    in the running engine only); a run whose condition does not propagate answers
    `kp: false` with a `reason`. 404 for an unknown run.
    """
    view: KpPublic | None = await engines.ask(run_id, InspectKp())
    if view is not None:
        return view
    run = await io(store.run_summary, run_id)
    condition = CONDITIONS.get(run.spec.condition)
    if condition is None or not condition.kp:
        return not_kp(run_id, run.spec.condition, live=False)
    _, config = configure(condition, applicable(condition, brain_params(run.spec)))
    rltm = await io(store.rltm, run_id)
    network = {
        (p.stimulus, p.behaviour): p for p in await io(store.network, run_id) if p.source == "kp"
    }
    ran = await io(_stored_runs, store, run_id, state.catalog)
    associations = [
        KpAssociationPublic(
            stimulus=st, behaviour=be, reliability=v, in_network=(st, be) in network,
            synthesized=be.startswith("kp_"), provenance=[], history=[],
            runs=[KpRunSpanPublic(first_tick=a, last_tick=z) for a, z in ran.get((st, be), [])],
            reasoned=0, ran_ticks=sum(z - a + 1 for a, z in ran.get((st, be), [])),
        )
        for (st, be), v in sorted(rltm.items(), key=lambda kv: (-kv[1], kv[0]))
    ]  # fmt: skip
    associations.sort(key=lambda x: not x.in_network)
    return KpPublic(
        run=run_id,
        condition=run.spec.condition,
        kp=True,
        live=False,
        reason=(
            f"run {run_id} is {run.status.value}, not running here: the RSTM and each "
            "association's provenance and history are kept while it runs; these are its "
            "RLTM reliabilities and network as last committed, and where each ran in its "
            f"latest {TRACE_EPISODES} stored episodes"
        ),
        associations=associations,
        count=len(associations),
        insert_threshold=config.kp.insert_threshold,
    )
