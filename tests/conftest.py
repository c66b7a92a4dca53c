"""Shared fixtures: the shipped catalogue and its compiled logical sensors."""

from __future__ import annotations

import os
import uuid
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
from apphelpers import migrated_copy, migrated_template
from browser import chromium
from fakes import InMemoryRunStore, InspectableRunStore
from hypothesis import settings
from liveharness import servers
from playwright.sync_api import Browser, ConsoleMessage, Error, Page, expect
from sqlalchemy import Engine, create_engine, text
from sqlalchemy.engine import make_url
from xdist.remote import Producer
from xdist.scheduler import LoadScopeScheduling
from xdist.scheduler.protocol import Scheduling

from bench.liveserver import LiveServer, live_server
from core.brain.catalog import Catalog, load_catalog
from core.brain.sensors import StimulusDetector, compile_detector
from server.persistence import SqlAlchemyRunStore, make_engine, make_sessionmaker, upgrade

# CI runs the property tests on the same examples every time (seeded from each test), so a
# submission is judged on its code, not on the examples a random search happened to draw;
# a local run keeps searching afresh. `SRLAB_HYPOTHESIS_PROFILE=ci` gives CI's locally.
settings.register_profile("ci", derandomize=True, database=None)
if os.environ.get("SRLAB_HYPOTHESIS_PROFILE", "ci" if os.environ.get("CI") == "true" else ""):
    settings.load_profile(os.environ.get("SRLAB_HYPOTHESIS_PROFILE") or "ci")


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
def migrated_sqlite() -> Path:
    """A SQLite file migrated to head and seeded once, for tests to copy."""
    return migrated_template()


@pytest.fixture
def sqlite_engine(migrated_sqlite: Path, tmp_path: Path) -> Iterator[Engine]:
    """An engine on a fresh copy of the migrated SQLite database."""
    engine = make_engine(migrated_copy(tmp_path / "srlab.db"))
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


@pytest.fixture(params=["local", pytest.param("process", marks=pytest.mark.slow)])
def each_link(request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> str:
    """Runs the test once with the runs' host on the service's loop and once in a process.

    `settings_for` reads ``SRLAB_ENGINES`` as `srlab serve` does: a module whose tests use
    this (`pytestmark`) drives the same API over both links (`server.runtime`). The process
    link's copy is slow: each test starts an engines' process.
    """
    monkeypatch.setenv("SRLAB_ENGINES", request.param)
    return str(request.param)


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


@pytest.fixture
def start_server() -> Iterator[Callable[..., LiveServer]]:
    """`bench.liveserver.start_server` for a test that starts and stops servers itself:
    one it leaves running (a failed assertion) is killed when the test ends."""
    with servers() as start:
        yield start


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


# --- markers, and the order of a parallel run ----------------------------------------
# The markers are registered in pyproject.toml; `make test-unit` deselects all six. Most are
# given here, by directory, module or fixture; a slow test in an otherwise quick module
# carries `@pytest.mark.slow` itself.

TESTS = Path(__file__).resolve().parent
DIRECTORY_MARKERS = {
    "web": "browser",
    "reliability": "reliability",
    "deploy": "docker",
    "ros2": "slow",  # a fake robot in a subprocess, ticks in realtime
}
MODULE_MARKERS = {"web/test_node.py": "node"}
"""Modules marked otherwise than their directory: the web client's node tests need no Chromium."""
PG_FIXTURES = frozenset(
    {"postgres_url", "postgres_database", "postgres_engine", "clean_postgres_engine"}
)
"""A test that uses one of these, or a parameter "postgresql" (the storage back-ends), is `pg`."""
SLOW_FIXTURES = frozenset({"server", "browser", "image"})
"""A live `srlab serve` (conftest's and two modules' own), Chromium, the rebuilt image."""
SLOW_MODULES = frozenset(
    {
        "core/lab/test_deep_curve.py",  # a script in a subprocess
        "reliability/test_crash.py",
        "reliability/test_load.py",
        "reliability/test_long_day.py",
        "reliability/test_serve_kill.py",
        "reliability/test_sigterm.py",
        "reliability/test_storage_errors.py",
        "benches/test_benches.py",  # each bench in a subprocess
        "server/test_e2e_serve.py",
        "server/test_listening_sockets.py",
        "server/runtime/test_process_link.py",  # each test starts an engines' process
        "server/test_proxy.py",
        "server/backends/test_ray_backend.py",
        "server/api/test_schemathesis.py",
        "server/api/test_slow_clients.py",
        "server/viewer/test_viewer_malformed.py",
        "server/viewer/test_viewer_serve.py",
    }
)
"""Modules whose every test starts a server, a subprocess or Ray, or fuzzes the API."""


@pytest.hookimpl(tryfirst=True)  # before `-m` deselects and xdist groups
def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    for item in items:
        module = item.path.resolve().relative_to(TESTS).as_posix()
        params = getattr(item, "callspec", None)
        names = set(getattr(item, "fixturenames", ()))
        if marker := MODULE_MARKERS.get(module) or DIRECTORY_MARKERS.get(module.split("/", 1)[0]):
            item.add_marker(marker)
        if names & PG_FIXTURES or (params and "postgresql" in params.params.values()):
            item.add_marker("pg")
        if module in SLOW_MODULES or names & SLOW_FIXTURES:
            item.add_marker("slow")
    if hasattr(config, "workerinput"):  # a pytest-xdist worker: the longest units first
        items.sort(key=_first_rank)


# Under `pytest -n N --dist loadfile` (make test) this file's scheduler hands the workers
# units of work: a module's tests go together (its module fixtures are set up once), like
# loadfile's, except the tests below, which are units of their own; and the long units
# start first, so that no long test starts late and ends the run alone.

ALONE = frozenset(
    {
        "tests/reliability/test_load.py",
        "tests/reliability/test_long_day.py",
        "tests/reliability/test_serve_kill.py",
        "tests/reliability/test_storage_errors.py",
        "tests/server/test_proxy.py",
        "tests/server/viewer/test_viewer_serve.py",
        "tests/server/cli/test_run_cli.py::test_a_signal_stops_a_realtime_run_cleanly_and_it_resumes",
        "tests/web/test_viewer.py",  # 1-2 minutes a test: a server each pays
        # Browser tests with a server of their own, in modules that share one.
        "tests/web/test_console.py::test_the_page_recovers_when_the_server_restarts",
        "tests/web/test_console_trainer.py::"
        "test_offline_messages_do_not_pile_up_and_go_when_the_service_is_back",
        "tests/web/test_editor_day.py::test_runs_wait_for_a_free_slot_and_say_so",
    }
)
"""Modules whose tests are units one by one, and single tests (all their parameters)."""
LONGEST_FIRST = (
    "tests/reliability/test_crash.py",
    "tests/server/api/test_schemathesis.py",
    "tests/deploy/test_podman.py",  # builds the image, then the compose stack: 1-2 min
    "tests/web/test_viewer.py",
    "tests/web/test_console.py::test_the_page_recovers_when_the_server_restarts",
    "tests/web/test_console.py",
    "tests/reliability/test_serve_kill.py",
    "tests/reliability/test_sigterm.py",
    "tests/reliability/test_long_day.py",
    "tests/web/test_console_trainer.py::"
    "test_offline_messages_do_not_pile_up_and_go_when_the_service_is_back",
    "tests/web/test_editor_day.py",
    "tests/reliability/test_storage_errors.py",
    "tests/deploy/test_docker.py",
    "tests/server/viewer/test_viewer_serve.py",
    "tests/server/cli/test_run_cli.py::test_a_signal_stops_a_realtime_run_cleanly_and_it_resumes",
    "tests/web/test_console_trainer.py",
    "tests/reliability/test_load.py",
    "tests/server/test_proxy.py",
)
"""Modules and tests in the order their units start, longest first (a module's own unit
goes with its first entry); the rest follow in collection order. From the durations of a
full run (`--durations=0`)."""


def _module_and_test(nodeid: str) -> tuple[str, str]:
    module, _, rest = nodeid.partition("::")
    return module, f"{module}::{rest.split('[', 1)[0]}"


def _first_rank(item: pytest.Item) -> int:
    ranks = [LONGEST_FIRST.index(u) for u in _module_and_test(item.nodeid) if u in LONGEST_FIRST]
    return min(ranks, default=len(LONGEST_FIRST))


class ModulesLongestFirst(LoadScopeScheduling):  # type: ignore[misc]  # xdist is untyped
    """`--dist loadfile` with the units of `ALONE`, in the workers' (sorted) order."""

    def __init__(self, config: pytest.Config, log: Producer | None = None) -> None:
        super().__init__(config, log)
        config.option.loadscopereorder = False  # keep the order the workers collected

    def _split_scope(self, nodeid: str) -> str:
        module, test = _module_and_test(nodeid)
        return nodeid if module in ALONE or test in ALONE else module


def pytest_xdist_make_scheduler(config: pytest.Config, log: Producer) -> Scheduling | None:
    return ModulesLongestFirst(config, log) if config.getvalue("dist") == "loadfile" else None
