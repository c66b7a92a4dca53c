"""Run Alembic's migrations from code (the server's start, tests) and seed the catalogue."""

from __future__ import annotations

import sysconfig
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from sqlalchemy import exc as sa_exc

import server
from core.errors import StorageError
from server.persistence.db import database_url, make_engine, make_sessionmaker, parse_database_url
from server.persistence.seed import SeedReport, seed_catalog

if TYPE_CHECKING:
    from alembic.config import Config

# Alembic is imported where it is used: every process that stores runs imports this
# package, and only the ones that migrate need Alembic (0.8 s of start-up here).

SOURCE_TREE = Path(server.__file__).resolve().parent.parent
"""The folder holding the `server` package: a checkout's root, with alembic.ini and
migrations/ beside it."""
SHARED_DATA = Path(sysconfig.get_path("data")) / "share" / "srlab"
"""Where a wheel of srlab installs alembic.ini and migrations/ (pyproject's shared-data)."""


def find_migrations(places: Sequence[Path] = (SOURCE_TREE, SHARED_DATA)) -> Path:
    """The first of `places` that holds migrations/ (with its env.py): a checkout or a wheel.

    `StorageError` naming where it looked when none does.
    """
    for place in places:
        if (place / "migrations" / "env.py").is_file():
            return place
    looked = ", ".join(str(p) for p in places)
    raise StorageError(f"srlab's migrations are not installed: no migrations/env.py in {looked}")


ROOT = find_migrations()
"""Where alembic.ini and migrations/ live."""


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
