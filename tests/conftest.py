"""Shared fixtures: the shipped catalogue and its compiled logical sensors."""

from __future__ import annotations

import os
import shutil
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
from browser import chromium
from fakes import InMemoryRunStore, InspectableRunStore
from liveserver import LiveServer, live_server
from playwright.sync_api import Browser, ConsoleMessage, Error, Page, expect
from sqlalchemy import Engine, create_engine, text
from sqlalchemy.engine import make_url

from core.brain.catalog import Catalog, load_catalog
from core.brain.sensors import StimulusDetector, compile_detector
from server.persistence import SqlAlchemyRunStore, make_engine, make_sessionmaker, upgrade


@pytest.fixture(scope="session", autouse=True)
def _cache_dir(tmp_path_factory: pytest.TempPathFactory) -> Iterator[None]:
    """Caches (the placement probe's) go to a temporary folder, never to the home's."""
    old = os.environ.get("SRLAB_CACHE_DIR")
    os.environ["SRLAB_CACHE_DIR"] = str(tmp_path_factory.mktemp("cache"))
    yield
    if old is None:
        os.environ.pop("SRLAB_CACHE_DIR", None)
    else:
        os.environ["SRLAB_CACHE_DIR"] = old


@pytest.fixture(scope="session")
def catalog() -> Catalog:
    """srlab's own catalogue (immutable, so one per session)."""
    return load_catalog()


@pytest.fixture(scope="session")
def detector(catalog: Catalog) -> StimulusDetector:
    """Every logical sensor of the catalogue compiled into one function."""
    return compile_detector(catalog)


@pytest.fixture(scope="session")
def path_catalog() -> Catalog:
    """srlab's catalogue under its path-based camera obstacle definition."""
    return load_catalog(sensors="path")


@pytest.fixture(scope="session")
def path_detector(path_catalog: Catalog) -> StimulusDetector:
    """The path-definition catalogue's logical sensors compiled into one function."""
    return compile_detector(path_catalog)


@pytest.fixture(scope="session")
def paper_catalog() -> Catalog:
    """srlab's catalogue under the paper's Fig. 10 camera obstacle definition."""
    return load_catalog(sensors="paper")


@pytest.fixture(scope="session")
def paper_detector(paper_catalog: Catalog) -> StimulusDetector:
    """The paper-definition catalogue's logical sensors compiled into one function."""
    return compile_detector(paper_catalog)


POSTGRES_URL_VARIABLE = "SRLAB_TEST_POSTGRES_URL"


@pytest.fixture(scope="session")
def postgres_url() -> str:
    """The test PostgreSQL server (`make test` starts one); skips without, fails in CI."""
    url = os.environ.get(POSTGRES_URL_VARIABLE, "").strip()
    if url:
        return url
    if os.environ.get("CI", "").lower() == "true":
        pytest.fail(
            f"{POSTGRES_URL_VARIABLE} is not set: CI must test storage on PostgreSQL "
            "(`make test` starts a server with scripts/pg-test-server.sh)"
        )
    pytest.skip(
        f"{POSTGRES_URL_VARIABLE} is not set: run `make test`, or "
        f"`export {POSTGRES_URL_VARIABLE}=$(scripts/pg-test-server.sh start)`"
    )


@contextmanager
def fresh_postgres_database(server_url: str) -> Iterator[str]:
    """A new, empty database on the server of `server_url`, dropped afterwards."""
    name = f"srlab_t_{uuid.uuid4().hex[:12]}"
    admin = create_engine(make_url(server_url), isolation_level="AUTOCOMMIT")
    try:
        with admin.connect() as c:
            c.exec_driver_sql(f'CREATE DATABASE "{name}"')
        try:
            yield make_url(server_url).set(database=name).render_as_string(hide_password=False)
        finally:
            with admin.connect() as c:
                c.exec_driver_sql(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)')
    finally:
        admin.dispose()


@pytest.fixture(scope="module")
def postgres_database(postgres_url: str) -> Iterator[str]:
    """A fresh, empty PostgreSQL database for one test module."""
    with fresh_postgres_database(postgres_url) as url:
        yield url


@pytest.fixture(scope="session")
def migrated_sqlite(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A SQLite file migrated to head and seeded once, for tests to copy."""
    path = tmp_path_factory.mktemp("template") / "srlab.db"
    upgrade(f"sqlite:///{path}")
    return path


@pytest.fixture
def sqlite_engine(migrated_sqlite: Path, tmp_path: Path) -> Iterator[Engine]:
    """An engine on a fresh copy of the migrated SQLite database."""
    path = tmp_path / "srlab.db"
    shutil.copyfile(migrated_sqlite, path)
    engine = make_engine(f"sqlite:///{path}")
    yield engine
    engine.dispose()


@pytest.fixture(scope="module")
def postgres_engine(postgres_database: str) -> Iterator[Engine]:
    """An engine on this module's PostgreSQL database, migrated to head and seeded."""
    upgrade(postgres_database)
    engine = make_engine(postgres_database)
    yield engine
    engine.dispose()


@pytest.fixture
def clean_postgres_engine(postgres_engine: Engine) -> Engine:
    """The module's PostgreSQL engine with no runs left by an earlier test."""
    with postgres_engine.begin() as c:
        c.execute(text("DELETE FROM runs"))
    return postgres_engine


@pytest.fixture(params=["memory", "sqlite", "postgresql"])
def store(request: pytest.FixtureRequest, catalog: Catalog) -> InspectableRunStore:
    """Each implementation of `RunStore`, for the one contract suite they all pass."""
    if request.param == "memory":
        return InMemoryRunStore(catalog)
    engine_fixture = "sqlite_engine" if request.param == "sqlite" else "clean_postgres_engine"
    engine: Engine = request.getfixturevalue(engine_fixture)
    return SqlAlchemyRunStore(make_sessionmaker(engine))


@pytest.fixture
def anyio_backend() -> str:
    """API tests run on asyncio, as the service does."""
    return "asyncio"


# --- browser tests (tests/web) -------------------------------------------------------


@pytest.fixture(scope="module")
def browser() -> Iterator[Browser]:
    """Chromium for one module: Playwright's sync API holds an asyncio loop in this thread
    while it is open, so it must close before a worker (pytest-xdist) runs an anyio test."""
    with chromium() as b:
        yield b


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[LiveServer]:
    with live_server(tmp_path_factory.mktemp("web") / "web.db") as s:
        yield s


BROWSER_WAIT_MS = 90_000
"""How long a page's waits and `expect` may take: a bound for a hung page, not a speed test
(on a 2-core machine under load a page's first render took over 30 s)."""
expect.set_options(timeout=BROWSER_WAIT_MS)


@contextmanager
def sized_page(browser: Browser, width: int = 1280, height: int = 800) -> Iterator[Page]:
    """A fresh page of that window size; a JavaScript error in it fails the test."""
    context = browser.new_context(
        viewport={"width": width, "height": height}, accept_downloads=True
    )
    page = context.new_page()
    errors: list[str] = []

    def on_error(error: Error) -> None:
        errors.append(str(error))

    def on_console(message: ConsoleMessage) -> None:
        # Failed requests the page reports itself (a 409 it shows as a message) are expected.
        if message.type == "error" and "Failed to load resource" not in message.text:
            errors.append(message.text)

    page.on("pageerror", on_error)
    page.on("console", on_console)
    page.set_default_timeout(BROWSER_WAIT_MS)
    try:
        yield page
    finally:
        context.close()
    assert not errors, f"JavaScript errors in the page: {errors}"


@pytest.fixture
def page(browser: Browser) -> Iterator[Page]:
    """A fresh 1280x800 page; a JavaScript error in it fails the test."""
    with sized_page(browser) as page:
        yield page
