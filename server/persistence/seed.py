"""Seed the catalogue into the database: sensors, stimuli, behaviours and knowledge sets.

Idempotent: rows that already match are left alone, so seeding twice changes nothing. A
built-in network is refreshed from the catalogue only while it is at version 1 (never
edited); whoever edits a network bumps `networks.version` and appends a `network_versions`
row, and from then on seeding never touches it, nor any network a user made.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from sqlalchemy import exc as sa_exc
from sqlalchemy import select
from sqlalchemy.orm import Session

from core.brain.catalog import Catalog, KnowledgeSet, load_catalog
from core.errors import StorageError
from server.persistence.orm import (
    AssociationRow,
    BehaviourRow,
    LogicalSensorRow,
    NetworkRow,
    NetworkVersionRow,
    StimulusRow,
    motion_columns,
)

SEEDED_NOTE = "seeded from the catalogue"


@dataclass(frozen=True, slots=True)
class SeedReport:
    """What a seeding changed, as counts of rows added and updated (networks as a whole)."""

    added: int = 0
    updated: int = 0

    @property
    def changed(self) -> bool:
        """Whether seeding wrote anything."""
        return bool(self.added or self.updated)


class _Counter:
    def __init__(self) -> None:
        self.added = 0
        self.updated = 0

    def sync(self, session: Session, row: Any, exists: bool, values: dict[str, Any]) -> None:
        """Give `row` these values, counting an insert or a real change."""
        changed = False
        for key, value in values.items():
            if not exists or getattr(row, key) != value:
                setattr(row, key, value)
                changed = True
        if not exists:
            session.add(row)
            self.added += 1
        elif changed:
            self.updated += 1


def _snapshot(ks: KnowledgeSet) -> dict[str, Any]:
    """A knowledge set as `network_versions.snapshot` keeps a network."""
    return {
        "name": ks.name,
        "description": ks.description,
        "associations": sorted(
            (
                {
                    "stimulus": a.stimulus,
                    "behaviour": a.behaviour,
                    "strength": a.strength,
                    "source": a.source,
                    "locked": a.locked,
                }
                for a in ks.associations
            ),
            key=lambda a: (a["stimulus"], a["behaviour"]),
        ),
    }


def _seed(session: Session, catalog: Catalog) -> SeedReport:
    count = _Counter()
    sensors = {r.name: r for r in session.scalars(select(LogicalSensorRow))}
    for i, spec in enumerate(catalog.sensors):
        sensor = sensors.get(spec.name)
        values = {
            "name": spec.name,
            "position": i,
            "physical": list(spec.physical),
            "processing": spec.processing,
            "objective": spec.objective,
            "level": spec.level,
            "priority": spec.priority,
            "weight": spec.weight,
        }
        row = sensor or LogicalSensorRow()
        count.sync(session, row, sensor is not None, values)
        sensors[spec.name] = row
    session.flush()

    stimuli = {r.name: r for r in session.scalars(select(StimulusRow))}
    for st in catalog.stimuli:
        srow = stimuli.get(st.name)
        values = {
            "name": st.name,
            "position": st.id,
            "sensor_id": sensors[st.sensor].id,
            "objective": st.objective,
            "level": st.level,
            "priority": st.priority,
            "rule": [[c.as_data() for c in alt] for alt in st.rule],
        }
        count.sync(session, srow or StimulusRow(), srow is not None, values)
    behaviours = {
        r.name: r
        for r in session.scalars(select(BehaviourRow).where(BehaviourRow.run_id.is_(None)))
    }
    for b in catalog.behaviours:
        brow = behaviours.get(b.name)
        values = {
            "name": b.name,
            "position": b.id,
            **motion_columns(b),
            "synthesized": b.synthesized,
        }
        count.sync(session, brow or BehaviourRow(), brow is not None, values)
    session.flush()

    stimulus_ids = dict(session.execute(select(StimulusRow.name, StimulusRow.id)).all())
    behaviour_ids = dict(
        session.execute(
            select(BehaviourRow.name, BehaviourRow.id).where(BehaviourRow.run_id.is_(None))
        ).all()
    )
    for ks in catalog.knowledge.values():
        snapshot = _snapshot(ks)
        network = session.scalars(select(NetworkRow).where(NetworkRow.name == ks.name)).first()
        if network is None:
            network = NetworkRow(name=ks.name, description=ks.description, builtin=True, version=1)
            session.add(network)
            session.flush()
            session.add(
                NetworkVersionRow(
                    network_id=network.id, version=1, snapshot=snapshot, note=SEEDED_NOTE
                )
            )
            count.added += 1
        elif network.builtin and network.version == 1:
            first = session.scalars(
                select(NetworkVersionRow).where(
                    NetworkVersionRow.network_id == network.id, NetworkVersionRow.version == 1
                )
            ).first()
            if first is not None and first.snapshot == snapshot:
                continue
            if first is None:
                session.add(
                    NetworkVersionRow(
                        network_id=network.id, version=1, snapshot=snapshot, note=SEEDED_NOTE
                    )
                )
            else:
                first.snapshot = snapshot
            network.description = ks.description
            for old in session.scalars(
                select(AssociationRow).where(AssociationRow.network_id == network.id)
            ):
                session.delete(old)
            session.flush()
            count.updated += 1
        else:
            continue
        for a in ks.associations:
            session.add(
                AssociationRow(
                    network_id=network.id,
                    stimulus_id=stimulus_ids[a.stimulus],
                    behaviour_id=behaviour_ids[a.behaviour],
                    strength=a.strength,
                    source=a.source,
                    locked=a.locked,
                )
            )
    return SeedReport(count.added, count.updated)


def seed_catalog(sessions: Callable[[], Session], catalog: Catalog | None = None) -> SeedReport:
    """Seed `catalog` (srlab's own by default) in one transaction."""
    catalog = catalog or load_catalog()
    session = sessions()
    try:
        report = _seed(session, catalog)
        session.commit()
        return report
    except (sa_exc.DBAPIError, sa_exc.TimeoutError) as e:
        session.rollback()
        detail = getattr(e, "orig", None) or e
        raise StorageError(f"storage failed while seeding the catalogue: {detail}") from e
    except BaseException:
        session.rollback()
        raise
    finally:
        session.close()
