"""How a process opens the service's storage: SQLAlchemy, in that process.

The service's composition root (`server.bootstrap`) and the engines' process
(`server.runtime.process`) both open storage from the settings; this module is what they
share, without the HTTP side the root also builds.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

from core.ports import NetworkRepository, RunQueries
from core.studies import StudyRepository
from server.config import Settings
from server.persistence.db import DatabaseCheck, make_engine, make_sessionmaker
from server.persistence.networks import SqlAlchemyNetworkRepository
from server.persistence.sqlalchemy_repo import SqlAlchemyRunStore
from server.persistence.studies import SqlAlchemyStudyRepository


class DatabaseProbe(Protocol):
    """What /api/health asks of storage."""

    def check(self) -> str:
        """Read from the database (a `StorageError` if it cannot); the dialect's name."""
        ...


@dataclass(frozen=True)
class Storage:
    """Where the service keeps runs and networks, and how it lets them go."""

    runs: RunQueries
    networks: NetworkRepository
    database: DatabaseProbe
    close: Callable[[], None]
    """Blocking: called once, after the last write."""
    studies: StudyRepository | None = None
    """Trainer studies and their participants (None: this storage keeps none)."""


StorageFactory = Callable[[Settings], Storage]
"""Blocking: opens the storage `settings` name (called in a thread)."""


def open_storage(settings: Settings) -> Storage:
    """SQLAlchemy on `settings.database_url`, in this process."""
    engine = make_engine(settings.database_url)
    sessions = make_sessionmaker(engine)
    return Storage(
        SqlAlchemyRunStore(sessions),
        SqlAlchemyNetworkRepository(sessions),
        DatabaseCheck(engine),
        engine.dispose,
        SqlAlchemyStudyRepository(sessions),
    )
