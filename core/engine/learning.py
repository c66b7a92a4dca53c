"""The brain's changes as storage records: what an applied reward or an edit changed.

The brain speaks in catalogue ids; storage keeps names (a run's catalogue grows when KP
synthesises a behaviour, and a stored name means the same thing in every run). These
functions read the simulation on the event loop, right after the change, and return the
`LearningUpdate` the writer commits.
"""

from __future__ import annotations

from core.brain.brain import RewardOutcome
from core.brain.catalog import SOURCES
from core.brain.network import Association
from core.commands import EditAssociation
from core.events import AssociationDemoted, AssociationPromoted
from core.ports import BehaviourSpec, LearningUpdate, NetworkPair
from core.run.simulation import Simulation


def pair(sim: Simulation, a: Association) -> NetworkPair:
    """An association of the running network, by name."""
    cat = sim.brain.catalog
    return NetworkPair(
        cat.stimuli[a.stimulus].name,
        cat.behaviours[a.behaviour].name,
        a.strength,
        a.source,
        a.locked,
    )


def apply_edit(sim: Simulation, edit: EditAssociation) -> LearningUpdate:
    """Change the running network as `edit` says; returns what changed."""
    brain = sim.brain
    s = brain.catalog.stimulus(edit.stimulus).id
    b = brain.catalog.behaviour(edit.behaviour).id
    if edit.strength is None:
        brain.network.remove(s, b, force=True)
        return LearningUpdate(network_removals=((edit.stimulus, edit.behaviour),))
    source = edit.source if edit.source in SOURCES else "dp"
    assoc = Association(s, b, edit.strength, source, edit.locked)
    brain.network.put(assoc, force=True)
    return LearningUpdate(network_upserts=(pair(sim, assoc),))


def learning_update(sim: Simulation, outcome: RewardOutcome) -> LearningUpdate:
    """What an applied reward changed: LTM and RLTM values, the network, new behaviours."""
    brain = sim.brain
    cat = brain.catalog
    s = [x.name for x in cat.stimuli]
    b = [x.name for x in cat.behaviours]
    ltm = {
        (s[c.stimulus], b[c.behaviour]): brain.ltm.reliability(c.stimulus, c.behaviour)
        for c in outcome.credits
    }
    rltm = {(s[p.stimulus], b[p.behaviour]): p.after for p in outcome.propagated}
    upserts: list[NetworkPair] = []
    removals: list[tuple[str, str]] = []
    for ch in outcome.changes:
        if isinstance(ch, AssociationPromoted):
            a = brain.network.get(ch.stimulus, ch.behaviour)
            if a is not None:
                upserts.append(pair(sim, a))
        elif isinstance(ch, AssociationDemoted):
            removals.append((s[ch.stimulus], b[ch.behaviour]))
    # Strength changes of pairs already in the network follow their reliability.
    for (st, be), v in {**ltm, **rltm}.items():
        a = brain.network.get(cat.stimulus(st).id, cat.behaviour(be).id)
        if a is not None and a.source in ("learned", "kp") and a.strength == v:
            p = pair(sim, a)
            if p not in upserts:
                upserts.append(p)
    added = tuple(
        BehaviourSpec(x.name, x.family, x.speed_mps, x.turn_dps, x.ticks, x.mode)
        for p in outcome.propagated
        if p.synthesized
        for x in (cat.behaviours[p.behaviour],)
    )
    return LearningUpdate(ltm, rltm, tuple(upserts), tuple(removals), added)
