"""Storage adapters: SQLAlchemy models, migrations and the `RunStore` implementation."""

from server.persistence.db import database_url, make_engine, make_sessionmaker
from server.persistence.migrate import alembic_config, downgrade, upgrade
from server.persistence.orm import Base
from server.persistence.seed import SeedReport, seed_catalog
from server.persistence.sqlalchemy_repo import SqlAlchemyRunStore

__all__ = [
    "Base",
    "SeedReport",
    "SqlAlchemyRunStore",
    "alembic_config",
    "database_url",
    "downgrade",
    "make_engine",
    "make_sessionmaker",
    "seed_catalog",
    "upgrade",
]
