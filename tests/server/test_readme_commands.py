"""The README's curl commands, run as written by bash against a live `srlab serve`.

A user reaches them after the tour, when the service already holds runs: the commands must
act on the run their first command creates, whatever its id.
"""

from __future__ import annotations

import os
import signal
import subprocess
import threading
import time
from urllib.parse import urlsplit

from bench.liveserver import ROOT, LiveServer

STREAM_WAIT_S = 120.0
"""How long the event stream may take to send a tick: a bound for a hung stream, not a speed
test (a realtime run's first ticks can wait on a busy 2-core machine)."""


def readme_curl_block() -> str:
    """The README's block of curl commands as a bash script: the prompts off."""
    blocks: list[list[str]] = []
    inside = False
    for line in (ROOT / "README.md").read_text().splitlines(keepends=True):
        if line.startswith("```"):
            inside = not inside
            if inside:
                blocks.append([])
        elif inside:
            blocks[-1].append(line.removeprefix("$ "))
    (block,) = [b for b in blocks if any(line.startswith("curl ") for line in b)]
    return "".join(block)


def test_the_readme_curl_commands_act_on_the_run_they_create(server: LiveServer) -> None:
    earlier = server.client.post("/api/runs", json={"condition": "delayed", "mode": "realtime"})
    assert earlier.status_code == 201, earlier.text
    earlier_id = earlier.json()["id"]
    script = readme_curl_block()
    assert "localhost:8000" in script
    with subprocess.Popen(
        ["bash", "-c", script.replace("localhost:8000", urlsplit(server.url).netloc)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,  # the stream's curl goes on until its group is ended
    ) as bash:
        stdout, stderr = bash.stdout, bash.stderr
        assert stdout is not None and stderr is not None
        out: list[str] = []
        reader = threading.Thread(target=lambda: out.extend(iter(stdout.readline, "")))
        reader.start()
        deadline = time.monotonic() + STREAM_WAIT_S
        while "event: tick\n" not in out and bash.poll() is None and time.monotonic() < deadline:
            time.sleep(0.1)
        os.killpg(bash.pid, signal.SIGTERM)
        reader.join()
        errors = stderr.read()

    assert errors == ""
    assert "event: tick\n" in out, f"the event stream sent no tick: {''.join(out)[-2000:]}"
    runs = server.client.get("/api/runs").json()["data"]
    (created,) = [r for r in runs if r["id"] != earlier_id]
    assert (created["condition"], created["status"]) == ("trainer", "running")
    rewards = server.client.get(f"/api/runs/{created['id']}/rewards").json()["data"]
    assert [(r["value"], r["note"]) for r in rewards] == [(1.0, "good stop")]
    assert server.client.get(f"/api/runs/{earlier_id}").json()["status"] == "created"
    assert server.client.get(f"/api/runs/{earlier_id}/rewards").json()["count"] == 0
    assert server.client.post(f"/api/runs/{created['id']}/stop").status_code == 200
