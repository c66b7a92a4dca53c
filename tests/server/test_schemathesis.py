"""Schemathesis over /openapi.json of a live `srlab serve`: no 5xx, responses conform.

At least 100 generated cases per operation (SRLAB_FUZZ_EXAMPLES raises it). The event
stream is left out: a live stream does not end, so it has tests of its own.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import httpx
import pytest
import requests
import schemathesis
from hypothesis import HealthCheck, given, settings
from reliability_report import count, record

ROOT = Path(__file__).resolve().parents[2]
EXAMPLES = int(os.environ.get("SRLAB_FUZZ_EXAMPLES", "100"))
STATEFUL = int(os.environ.get("SRLAB_STATEFUL_EXAMPLES", "10"))
"""Sequences the stateful phase tries (it follows the document's links)."""
ACCEPTED = ["2xx", "3xx", "401", "403", "404", "409", "412", "429"]
CONFIG = schemathesis.config.SchemathesisConfig.from_dict(
    {
        "checks": {
            # A write with a generated If-Match or expected_version is rightly refused with
            # 412: the document says so, and it is not valid data refused.
            "positive_data_acceptance": {"expected-statuses": ACCEPTED}
        },
        "operations": [
            {
                # `b` must be empty or as long as `a` (one run of b per seed of a): JSON
                # Schema cannot say that two lists have one length, so a generated pair of
                # lists that differ is rightly a 422 naming the rule, not valid data refused
                # (found by the full-size run, `make reliability`).
                "include-path": "/api/comparisons",
                "checks": {"positive_data_acceptance": {"expected-statuses": [*ACCEPTED, "422"]}},
            }
        ],
    }
)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port: int = s.getsockname()[1]
        return port


@pytest.fixture(scope="module")
def base_url(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    folder = tmp_path_factory.mktemp("fuzz")
    port = free_port()
    env = {
        **os.environ,
        "SRLAB_DATABASE_URL": f"sqlite:///{folder / 'fuzz.db'}",
        "SRLAB_MAX_RUNS": "1",
        "SRLAB_VISER_PORT": str(free_port()),  # not 8080: another service may hold it
        "SRLAB_REWARD_RATE_PER_S": "1000",
        "SRLAB_REWARD_BURST": "1000",
    }
    server = subprocess.Popen(
        [sys.executable, "-m", "server.cli", "serve", "--port", str(port)],
        cwd=ROOT,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    base = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + 180  # a hang guard: a busy machine starts slowly
        while time.monotonic() < deadline:
            try:
                if httpx.get(f"{base}/api/health", timeout=1).status_code == 200:
                    break
            except httpx.HTTPError:
                time.sleep(0.2)
        else:
            raise AssertionError("srlab serve did not come up")
        # Something for the generated ids to find.
        httpx.post(f"{base}/api/runs", json={"condition": "kp", "episodes": 2}, timeout=10)
        yield base
    finally:
        server.terminate()
        _, err = server.communicate(timeout=30)
        assert b"Traceback" not in err, err.decode()[-3000:]


def test_api_never_errs_and_conforms(base_url: str) -> None:
    schema = schemathesis.openapi.from_url(f"{base_url}/openapi.json", config=CONFIG)
    failures: dict[str, str] = {}
    tested = []
    cases: dict[str, int] = {}
    session = requests.Session()
    for result in schema.get_all_operations():
        ok = getattr(result, "ok", None)
        if ok is None:  # the schema of this operation is invalid
            failures[repr(result)] = str(result.err())  # type: ignore[union-attr]
            continue
        operation = ok()
        if operation.path.endswith("/events"):
            continue
        tested.append(operation.label)

        @given(case=operation.as_strategy())
        @settings(
            max_examples=EXAMPLES,
            deadline=None,
            suppress_health_check=list(HealthCheck),
            database=None,
            derandomize=True,
        )
        def check(case: schemathesis.Case[Any]) -> None:
            label = case.operation.label
            cases[label] = cases.get(label, 0) + 1
            # One kept-alive connection for every case: a connection a case cost the client
            # and the service more than most of its calls did.
            case.call_and_validate(session=session)

        try:
            check()
        except Exception as e:  # collect every operation's failure, then fail once
            failures[operation.label] = f"{type(e).__name__}: {e}"[:1500]
    session.close()
    print(f"{len(tested)} operations, {EXAMPLES} examples each")  # noqa: T201
    counts = sorted(cases.get(label, 0) for label in tested)
    few = sorted(label for label in tested if cases.get(label, 0) < EXAMPLES)
    paths = httpx.get(f"{base_url}/openapi.json", timeout=10).json()["paths"]

    def takes_input(label: str) -> bool:
        method, path = label.split(" ", 1)
        spec = paths[path][method.lower()]
        return bool(spec.get("parameters") or spec.get("requestBody"))

    record(
        "schemathesis over the live API",
        f"every operation of /openapi.json but the event stream ({len(tested)}), up to "
        f"{count(EXAMPLES)} generated cases each, against a live srlab serve: no 5xx, "
        "responses match the schema",
        f"{count(sum(counts))} cases; {len(tested) - len(few)} operations got at least "
        f"{count(EXAMPLES)} each, the {len(few)} without parameters or body "
        f"{'/'.join(sorted({str(cases.get(label, 0)) for label in few})) or '-'} each (one "
        f"distinct input); {len(failures)} operations failed",
    )
    assert not any(takes_input(label) for label in few), "an operation with inputs ran short"
    assert len(tested) >= 15, tested
    assert not failures, "\n\n".join(f"{k}:\n{v}" for k, v in failures.items())


def reset(base_url: str) -> None:
    """Stop every run still going and delete every network a sequence made."""
    with httpx.Client(base_url=base_url, timeout=30) as client:
        offset = 0
        while True:
            page = client.get("/api/runs", params={"offset": offset, "limit": 100}).json()
            for run in page["data"]:
                if run["status"] in ("running", "paused"):
                    client.post(f"/api/runs/{run['id']}/stop")
            offset += len(page["data"])
            if not page["data"] or offset >= page["count"]:
                break
        for network in client.get("/api/networks").json()["data"]:
            if not network["builtin"]:
                client.delete(f"/api/networks/{network['name']}")


def test_stateful_sequences_along_the_links_never_err(base_url: str) -> None:
    """Create -> start -> reward -> read and the rest, chained by the document's links."""
    schema = schemathesis.openapi.from_url(f"{base_url}/openapi.json", config=CONFIG)
    # A live stream does not end.
    machine = schema.exclude(path_regex=r"/events$").as_state_machine()
    # Which calls a sequence can make depends on what earlier answers put in its bundles,
    # and those on the live service's state (a run still running makes the next start a
    # 429). Hypothesis replays sequences and refuses one that drew differently the second
    # time, so each sequence leaves the service as it found it.

    def teardown(self: Any) -> None:
        reset(base_url)

    machine.teardown = teardown  # type: ignore[method-assign]
    reset(base_url)
    machine.TestCase.settings = settings(
        max_examples=STATEFUL,
        stateful_step_count=8,
        deadline=None,
        suppress_health_check=list(HealthCheck),
        database=None,
        derandomize=True,
    )
    links = sum(
        len(r.get("links", {}))
        for item in httpx.get(f"{base_url}/openapi.json", timeout=10).json()["paths"].values()
        for op in item.values()
        for r in op.get("responses", {}).values()
    )
    machine.run()
    record(
        "schemathesis stateful phase",
        f"{count(STATEFUL)} sequences of up to 8 calls along the document's {links} links "
        "(create -> start -> reward -> read, networks), against a live srlab serve",
        "no 5xx, every response matches the schema",
    )
