"""Schemathesis's own CLI over /openapi.json of a live `srlab serve`, every phase: 0 failures.

`st run` runs its four phases as a user of the tool would: the schema's examples, its
coverage cases (each keyword's boundaries, and values just outside them), fuzzing and
stateful sequences along the document's links, with every check (no 5xx, responses and
headers as documented, schema-valid requests accepted and schema-violating ones refused).
SRLAB_FUZZ_EXAMPLES (50) bounds the cases of an operation in each generated phase,
SRLAB_STATEFUL_EXAMPLES (50) the stateful scenarios; `make reliability` raises both. The
event stream is left out: a live stream does not end, so it has tests of its own.
"""

from __future__ import annotations

import json
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
from reliability_report import count, record

ROOT = Path(__file__).resolve().parents[3]
EXAMPLES = int(os.environ.get("SRLAB_FUZZ_EXAMPLES", "50"))
STATEFUL = int(os.environ.get("SRLAB_STATEFUL_EXAMPLES", "50"))
"""Scenarios the stateful phase tries (it follows the document's links)."""
SEED = 1
PHASES = ("examples", "coverage", "fuzzing", "stateful")
ACCEPTED = ["2xx", "3xx", "401", "403", "404", "409", "429"]
"""What a schema-valid request may be answered: done, or refused for the state it found."""
HANG_S = 3600
"""A guard for a hung run, not a timing: the full-size run takes about 20 minutes."""


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


def _toml(value: object) -> str:
    return json.dumps(value)  # a JSON string or list of strings is TOML too


def config(doc: dict[str, Any], report: Path) -> str:
    """Schemathesis's configuration for this document: what each operation may answer.

    A schema-valid write may also get 412 where the document declares it: If-Match or
    expected_version names a version that is no longer current, which no schema can rule
    out. `b` of /api/comparisons names one run for each of `a`: JSON Schema cannot say that
    two lists have one length, so lists of two lengths are a 422 naming the rule.
    """
    stale = sorted(
        op["operationId"]
        for item in doc["paths"].values()
        for op in item.values()
        if isinstance(op, dict) and "412" in op.get("responses", {})
    )
    assert stale, "no operation declares 412"
    return f"""
seed = {SEED}
continue-on-failure = true
request-timeout = 30
[cache]
enabled = false
[generation]
max-examples = {EXAMPLES}
database = "none"
[phases.stateful.generation]
max-examples = {STATEFUL}
[reports.json]
enabled = true
path = {_toml(str(report))}
[checks.positive_data_acceptance]
expected-statuses = {_toml(ACCEPTED)}

[[operations]]
include-operation-id = {_toml(stale)}
checks.positive_data_acceptance.expected-statuses = {_toml([*ACCEPTED, "412"])}

[[operations]]
include-path = "/api/comparisons"
checks.positive_data_acceptance.expected-statuses = {_toml([*ACCEPTED, "422"])}
"""


def test_every_phase_of_schemathesis_finds_nothing(base_url: str, tmp_path: Path) -> None:
    doc = httpx.get(f"{base_url}/openapi.json", timeout=10).json()
    report = tmp_path / "report.json"
    settings = tmp_path / "schemathesis.toml"
    settings.write_text(config(doc, report))
    cli = [sys.executable, "-c", "from schemathesis.cli import schemathesis; schemathesis()"]
    command = [
        *cli,
        "--config-file",
        str(settings),
        "run",
        f"{base_url}/openapi.json",
        "--phases",
        ",".join(PHASES),
        "--exclude-path-regex",
        "/events$",
        "--no-color",
    ]
    # In tmp_path: the CLI writes what it keeps between runs into its working directory.
    done = subprocess.run(
        command, cwd=tmp_path, capture_output=True, text=True, timeout=HANG_S, check=False
    )
    assert report.exists(), done.stdout[-5000:] + done.stderr[-3000:]
    run = json.loads(report.read_text())
    cases = run["test_cases"]
    tested = run["operations"]["tested"]
    links = sum(
        len(r.get("links", {}))
        for item in doc["paths"].values()
        for op in item.values()
        if isinstance(op, dict)
        for r in op.get("responses", {}).values()
    )
    record(
        "schemathesis, every phase",
        f"schemathesis's CLI (`st run`, {', '.join(PHASES)}) over every operation of "
        f"/openapi.json but the event stream ({tested}), up to {count(EXAMPLES)} cases an "
        f"operation in each generated phase and {count(STATEFUL)} stateful scenarios along "
        f"the document's {links} links, against a live srlab serve",
        f"{count(cases['generated'])} cases; {cases['unique_failures']} failures, "
        f"{cases['errored']} errors; every phase "
        + ("passed" if all(p["status"] == "success" for p in run["phases"].values()) else "not"),
    )
    failures = done.stdout[done.stdout.find("FAILURES") :][:8000]
    assert done.returncode == 0 and run["exit_code"] == 0, failures or done.stdout[-5000:]
    assert cases["unique_failures"] == cases["errored"] == 0, failures
    assert {name: p["status"] for name, p in run["phases"].items()} == dict.fromkeys(
        PHASES, "success"
    ), run["phases"]
    assert tested >= 40, run["operations"]
    # A pattern the fuzzer drops is a rule of the schema it never checks.
    assert run["warnings"]["unsupported_regex"] == [], run["warnings"]["unsupported_regex"]
