"""Named networks (the S-R editor's subject) in the database."""

from __future__ import annotations

from collections.abc import Callable

from sqlalchemy import select
from sqlalchemy.orm import Session

from core.errors import UnknownNameError
from core.ports import NetworkPair
from server.persistence.orm import AssociationRow, BehaviourRow, NetworkRow, StimulusRow


class SqlAlchemyNetworkRepository:
    """Stored networks and their associations, by name."""

    def __init__(self, sessions: Callable[[], Session]) -> None:
        self._sessions = sessions

    def pairs(self, name: str) -> tuple[NetworkPair, ...]:
        """A network's associations; `UnknownNameError` when there is no such network."""
        with self._sessions() as s:
            network_id = s.scalar(select(NetworkRow.id).where(NetworkRow.name == name))
            if network_id is None:
                raise UnknownNameError(f"unknown network {name!r}")
            rows = s.execute(
                select(
                    StimulusRow.name,
                    BehaviourRow.name,
                    AssociationRow.strength,
                    AssociationRow.source,
                    AssociationRow.locked,
                )
                .join(StimulusRow, StimulusRow.id == AssociationRow.stimulus_id)
                .join(BehaviourRow, BehaviourRow.id == AssociationRow.behaviour_id)
                .where(AssociationRow.network_id == network_id)
                .order_by(AssociationRow.id)
            ).all()
        return tuple(
            NetworkPair(st, be, strength, src, locked) for st, be, strength, src, locked in rows
        )
