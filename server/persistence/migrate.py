"""Run Alembic's migrations from code (the server's start, tests) and seed the catalogue."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from sqlalchemy import exc as sa_exc

from core.errors import StorageError
from server.persistence.db import database_url, make_engine, make_sessionmaker, parse_database_url
from server.persistence.seed import SeedReport, seed_catalog

if TYPE_CHECKING:
    from alembic.config import Config

# Alembic is imported where it is used: every process that stores runs imports this
# package, and only the ones that migrate need Alembic (0.8 s of start-up here).

ROOT = Path(__file__).resolve().parents[2]
"""The repository: alembic.ini and migrations/ live there."""


def alembic_config(url: str | None = None) -> Config:
    """Alembic's configuration for `url` (default: `database_url()`)."""
    from alembic.config import Config

    ini = ROOT / "alembic.ini"
    config = Config(str(ini)) if ini.exists() else Config()
    config.set_main_option("script_location", str(ROOT / "migrations"))
    # ConfigParser interpolates '%': a password with one must not break the URL.
    config.set_main_option("sqlalchemy.url", (url or database_url()).replace("%", "%%"))
    config.attributes["configure_logger"] = False
    return config


def upgrade(url: str | None = None, *, seed: bool = True) -> SeedReport | None:
    """Migrate the database to the newest schema, then seed the catalogue into it."""
    url = url or database_url()
    shown = parse_database_url(url).render_as_string(hide_password=True)
    try:
        from alembic import command

        command.upgrade(alembic_config(url), "head")
        if not seed:
            return None
        engine = make_engine(url)
        try:
            return seed_catalog(make_sessionmaker(engine))
        finally:
            engine.dispose()
    except sa_exc.DBAPIError as e:  # unreachable, refused, unwritable: say so, in one line
        detail = str(e.orig).strip().splitlines()[0] if e.orig is not None else str(e)
        raise StorageError(f"database {shown!r}: {detail}") from e


def downgrade(url: str | None, revision: str) -> None:
    """Migrate the database down to `revision` (``base`` empties it)."""
    from alembic import command

    command.downgrade(alembic_config(url), revision)
