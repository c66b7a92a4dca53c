"""The network editor's writes, and live edits: a change reaching the runs it concerns.

A write is stored off the event loop (a `NetworkRepository` is synchronous, and ticking
runs never wait on the database); with `live` what it changed then reaches every running
or paused run started from that very network (by its identity, never by its name, which a
later network may take), at the run's next tick boundary. The routes translate HTTP to
these calls and back; the editor's rules are `core.networks`'.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Iterable, MutableMapping, Sequence
from dataclasses import dataclass
from typing import Any, Protocol, TypeVar

from starlette.concurrency import run_in_threadpool

from core.commands import EditAssociation
from core.errors import RunStateError, StorageError
from core.networks import AssociationChange, ExpectedVersion, NetworkEdit, StoredNetwork
from core.ports import ACTIVE, NetworkPair, NetworkRepository
from server.runtime import LiveRun as Live

log = logging.getLogger("srlab.networks")
_T = TypeVar("_T")


class Engines(Protocol):
    """The service's runs (`server.runtime.Runs`)."""

    def engines(self) -> Iterable[Live]:
        """Every engine this process has."""
        ...


@dataclass(frozen=True, slots=True)
class Written:
    """A write's outcome and the ids of the running runs its changes reached (live)."""

    edit: NetworkEdit
    live_runs: list[int]


def edit_command(change: AssociationChange) -> EditAssociation:
    """The engine command that makes a run's network undergo `change`."""
    after = change.after
    if after is None:
        return EditAssociation(change.stimulus, change.behaviour, None)
    return EditAssociation(
        change.stimulus, change.behaviour, after.strength, after.source, after.locked
    )


async def _push(engine: Live, edits: Sequence[EditAssociation]) -> bool:
    # Queued together, the edits land at the same tick boundary, in order.
    results = await engine.edit_all(edits)
    failed = [r for r in results if isinstance(r, BaseException)]
    for r in failed:
        if not isinstance(r, RunStateError | StorageError):
            raise r
        log.warning("live edit of run %s not applied: %s", engine.run_id, r)
    return not failed


class NetworkService:
    """Stored networks' writes and their live edits.

    `run_networks` overrides `RunSpec.network_id` of the runs here whose network was
    deleted while they ran (None), shared with the app (`AppState.run_networks`).
    """

    def __init__(
        self,
        networks: NetworkRepository,
        engines: Engines,
        run_networks: MutableMapping[int, int | None],
    ) -> None:
        self._networks = networks
        self._engines = engines
        self._run_networks = run_networks

    @staticmethod
    async def _call(fn: Callable[..., _T], *args: Any, **kwargs: Any) -> _T:
        """A repository call off the event loop, so ticking runs never wait on the database."""
        return await run_in_threadpool(fn, *args, **kwargs)

    def started_from(self, engine: Live, network: StoredNetwork) -> bool:
        """Whether a run was started from this very network (not an earlier one of its name).

        A run keeps its network's id (`RunSpec.network_id`, stored with the run); deleting
        the network clears it, in the store (its foreign key) and here for the engines
        running (SQLite may give the id to the next network).
        """
        if engine.spec.network != network.name:
            return False
        network_id = self._run_networks.get(engine.run_id, engine.spec.network_id)
        return network_id is not None and network_id == network.id

    async def fan_out(
        self, network: StoredNetwork, changes: Iterable[AssociationChange], live: bool = True
    ) -> list[int]:
        """Give every running run started from `network` the same changes (`live` only).

        Returns the ids of the runs that took them all, sorted.
        """
        edits = [edit_command(c) for c in changes]
        if not live or not edits:
            return []
        targets = [
            e
            for e in self._engines.engines()
            if e.status in ACTIVE and self.started_from(e, network)
        ]
        reached = await asyncio.gather(*(_push(e, edits) for e in targets))
        return sorted(e.run_id for e, ok in zip(targets, reached, strict=True) if ok)

    async def create(
        self,
        name: str,
        *,
        description: str = "",
        base: str | None = "innate",
        associations: Iterable[NetworkPair] = (),
        note: str = "",
    ) -> StoredNetwork:
        """A new, editable network (see `NetworkRepository.create`)."""
        return await self._call(
            self._networks.create,
            name,
            description=description,
            base=base,
            associations=list(associations),
            note=note,
        )

    async def import_network(
        self,
        name: str,
        associations: Iterable[NetworkPair],
        *,
        description: str = "",
        replace: bool = False,
        force: bool = False,
        note: str = "",
        expected: ExpectedVersion | None = None,
        live: bool = False,
    ) -> Written:
        """Store an imported network; a replaced one's changes reach its runs (`live`)."""
        edit = await self._call(
            self._networks.import_network,
            name,
            list(associations),
            description=description,
            replace=replace,
            force=force,
            note=note,
            expected=expected,
        )
        live_runs = await self.fan_out(edit.network, () if edit.created else edit.changes, live)
        return Written(edit, live_runs)

    async def delete(self, name: str, *, expected: ExpectedVersion | None = None) -> None:
        """Delete a network; runs started from it keep their copy and get no more live edits.

        A network made later under its name is another one.
        """
        network = await self._call(self._networks.get, name)
        await self._call(self._networks.delete, name, expected=expected)
        for engine in self._engines.engines():
            if self.started_from(engine, network):
                self._run_networks[engine.run_id] = None  # its network is gone

    async def add_association(
        self,
        name: str,
        pair: NetworkPair,
        *,
        note: str = "",
        expected: ExpectedVersion | None = None,
        live: bool = False,
    ) -> Written:
        """Add an association the network lacks; it reaches the network's runs (`live`)."""
        edit = await self._call(
            self._networks.add_association, name, pair, note=note, expected=expected
        )
        return Written(edit, await self.fan_out(edit.network, edit.changes, live))

    async def put_association(
        self,
        name: str,
        stimulus: str,
        behaviour: str,
        *,
        strength: float | None = None,
        source: str | None = None,
        locked: bool | None = None,
        force: bool = False,
        note: str = "",
        expected: ExpectedVersion | None = None,
        live: bool = False,
    ) -> Written:
        """Set an association; with `live` the network's runs get it as it now is.

        They get it even when the stored network did not change (a way to push a stored
        edit to them later).
        """
        edit = await self._call(
            self._networks.put_association,
            name,
            stimulus,
            behaviour,
            strength=strength,
            source=source,
            locked=locked,
            force=force,
            note=note,
            expected=expected,
        )
        pair = next(
            p
            for p in edit.network.associations
            if (p.stimulus, p.behaviour) == (stimulus, behaviour)
        )
        current = AssociationChange(stimulus, behaviour, None, pair)
        return Written(edit, await self.fan_out(edit.network, [current], live))

    async def remove_association(
        self,
        name: str,
        stimulus: str,
        behaviour: str,
        *,
        force: bool = False,
        note: str = "",
        expected: ExpectedVersion | None = None,
        live: bool = False,
    ) -> Written:
        """Remove an association; the removal reaches the network's runs (`live`)."""
        edit = await self._call(
            self._networks.remove_association,
            name,
            stimulus,
            behaviour,
            force=force,
            note=note,
            expected=expected,
        )
        return Written(edit, await self.fan_out(edit.network, edit.changes, live))

    async def revert(
        self,
        name: str,
        version: int,
        *,
        force: bool = False,
        note: str = "",
        expected: ExpectedVersion | None = None,
        live: bool = False,
    ) -> Written:
        """Make the network what it was at `version`; what changed reaches its runs (`live`)."""
        edit = await self._call(
            self._networks.revert, name, version, force=force, note=note, expected=expected
        )
        return Written(edit, await self.fan_out(edit.network, edit.changes, live))
