"""The image and the compose stack, built and run for real, with podman.

No outside image can be pulled here, so scripts/podman-bases.sh makes stand-ins for
python:3.11-slim-bookworm and postgres:16-bookworm from Debian's packages. The Dockerfile
is built as it stands, its base given as the build argument it declares; the image runs
alone on SQLite; docker-compose.yml runs under podman-compose, with only the two images'
names overridden, and serves a run and a reward on PostgreSQL that outlive a restart of
both containers. Without podman the tests skip, unless SRLAB_REQUIRE_PODMAN=1 (CI).
"""

from __future__ import annotations

import hashlib
import json
import os
import secrets
import shutil
import subprocess
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NoReturn

import httpx
import pytest
import yaml
from liveharness import wait_status
from test_docker import PASSWORD, ROOT, TOKEN, dockerfile, env_file

from bench.liveserver import free_port

# Each test builds or starts containers: more than a few seconds, even with every layer cached.
pytestmark = pytest.mark.slow

HEALTHY_S = 240.0
"""A bound for a hung container, not a speed goal: the stack is healthy in ~10 s alone."""
PYTHON_DEFAULT = "python:3.11-slim-bookworm"


def unavailable(message: str) -> NoReturn:
    """Skip, or fail where podman is required (CI sets SRLAB_REQUIRE_PODMAN=1)."""
    if os.environ.get("SRLAB_REQUIRE_PODMAN") == "1":
        pytest.fail(message)
    pytest.skip(message)


def podman(
    *args: str, check: bool = True, timeout: float = 120
) -> subprocess.CompletedProcess[str]:
    """`podman ARGS`; with `check`, its failure fails the test with what it said."""
    done = subprocess.run(
        ["podman", *args], capture_output=True, text=True, timeout=timeout, check=False
    )
    if check:
        assert done.returncode == 0, f"podman {' '.join(args)}:\n{done.stderr[-3000:]}"
    return done


def inspect(kind: str, name: str) -> dict[str, Any]:
    """`podman KIND inspect NAME`, parsed."""
    found: list[dict[str, Any]] = json.loads(podman(kind, "inspect", name).stdout)
    return found[0]


def wait_healthy(container: str) -> None:
    """Run the container's healthcheck until it passes.

    Podman schedules healthchecks with systemd timers; without systemd (this machine, CI)
    nothing runs them, so the test does, as docker's scheduler would.
    """
    deadline = time.monotonic() + HEALTHY_S
    while True:
        done = podman("healthcheck", "run", container, check=False, timeout=60)
        if done.returncode == 0:
            return
        if time.monotonic() > deadline:
            logs = podman("logs", "--tail", "40", container, check=False)
            said = f"{done.stdout}\n{logs.stdout}{logs.stderr}"
            pytest.fail(f"{container} never became healthy: {said}")
        time.sleep(1)


def api_client(port: int) -> httpx.Client:
    """A client of the service published on 127.0.0.1:`port`, with the token."""
    return httpx.Client(
        base_url=f"http://127.0.0.1:{port}",
        headers={"Authorization": f"Bearer {TOKEN}"},
        timeout=30,
        trust_env=False,
    )


@dataclass(frozen=True)
class Bases:
    """The stand-ins' names, as scripts/podman-bases.sh prints them."""

    python: str
    postgres: str


@pytest.fixture(scope="module")
def bases() -> Bases:
    """The stand-in base images, built by the script if missing or stale (`make test` has)."""
    if shutil.which("podman") is None:
        unavailable("podman is missing: 'apt-get install -y podman debootstrap' (make test does)")
    done = subprocess.run(
        ["bash", str(ROOT / "scripts" / "podman-bases.sh")],
        capture_output=True,
        text=True,
        timeout=1800,
        check=False,
    )
    names = dict(line.split("=", 1) for line in done.stdout.splitlines() if "=" in line)
    if done.returncode != 0 or not {"PYTHON_IMAGE", "POSTGRES_IMAGE"} <= names.keys():
        unavailable(f"no stand-in base images: {done.stderr.strip()[-2000:]}")
    return Bases(names["PYTHON_IMAGE"], names["POSTGRES_IMAGE"])


@pytest.fixture(scope="module")
def image(bases: Bases) -> Iterator[str]:
    """The Dockerfile's image, built on the stand-in base; its other defaults as they are.

    Tagged per work tree, so that two clones testing at once do not swap images. It is
    removed afterwards with the layers only it has (the copy of /app alone is ~550 MB, and
    each clone CI makes has a tag of its own); the build stage's layers stay as podman's
    build cache, so the next build reinstalls no dependency unless uv.lock changed.
    """
    tag = f"localhost/srlab-test:{hashlib.sha256(str(ROOT).encode()).hexdigest()[:12]}"
    podman("rmi", "--force", tag, check=False)  # left by a run that never got to its end
    # Docker's format: the OCI format has no HEALTHCHECK, and podman would drop it.
    build = ["podman", "build", "--format", "docker", "--tag", tag]
    done = subprocess.run(
        [*build, "--build-arg", f"PYTHON_IMAGE={bases.python}", str(ROOT)],
        capture_output=True,
        text=True,
        timeout=1800,
        check=False,
    )
    assert done.returncode == 0, f"{done.stdout[-4000:]}\n{done.stderr[-3000:]}"
    yield tag
    podman("rmi", "--force", tag, check=False)


@pytest.fixture
def container() -> Iterator[str]:
    """A name for a container the test runs; it is removed afterwards, whatever happened."""
    name = f"srlab-test-{secrets.token_hex(4)}"
    yield name
    podman("rm", "--force", "--time", "5", name, check=False)


def test_the_image_builds_as_the_dockerfile_says_with_only_its_base_substituted(
    image: str,
) -> None:
    assert dockerfile().args["PYTHON_IMAGE"] == PYTHON_DEFAULT  # what docker users get
    built = inspect("image", image)
    config = built["Config"]
    assert config["User"] == "srlab"
    assert config["Cmd"] == dockerfile().cmd
    assert built["Healthcheck"]["Test"] == ["CMD", *dockerfile().healthcheck]
    assert set(config["ExposedPorts"]) == {"8000/tcp", "8080/tcp"}
    assert "SRLAB_HOST=0.0.0.0" in config["Env"]
    # /app has what the Dockerfile copies and the venv, nothing else.
    listed = podman("run", "--rm", "--entrypoint", "ls", image, "-A", "/app").stdout.split()
    assert set(listed) == {
        ".venv",
        "README.md",
        "alembic.ini",
        "core",
        "migrations",
        "pyproject.toml",
        "server",
        "uv.lock",
        "web",
    }


def test_the_image_refuses_to_start_without_a_token(image: str, container: str) -> None:
    done = podman("run", "--name", container, image, check=False, timeout=120)
    assert done.returncode == 2, done.stderr[-3000:]
    assert "set SRLAB_TOKEN" in done.stderr and "Traceback" not in done.stderr


def test_the_image_alone_serves_sqlite_and_takes_writes_only_with_the_token(
    image: str, container: str
) -> None:
    port = free_port()
    podman(
        "run", "--detach", "--name", container, "--env", f"SRLAB_TOKEN={TOKEN}",
        "--publish", f"127.0.0.1:{port}:8000", image,
    )  # fmt: skip
    wait_healthy(container)
    with api_client(port) as api:
        health = api.get("/api/health").json()
        assert (health["status"], health["database"]) == ("ok", "sqlite")
        anonymous = api.post("/api/runs", json={"condition": "kp"}, headers={"Authorization": ""})
        assert anonymous.status_code == 401
        created = api.post("/api/runs", json={"condition": "kp", "episodes": 1})
        assert created.status_code == 201, created.text
    assert podman("exec", container, "id", "-un").stdout.strip() == "srlab"
    assert "srlab.db" in podman("exec", container, "ls", "/data").stdout.split()


@dataclass(frozen=True)
class Stack:
    """docker-compose.yml under podman-compose, as one project with the stand-in images."""

    argv: list[str]
    project: str
    port: int
    viser_port: int
    env: dict[str, str]

    def compose(self, *args: str, check: bool = True) -> subprocess.CompletedProcess[str]:
        """`podman-compose ARGS` on the project."""
        done = subprocess.run(
            [*self.argv, *args],
            capture_output=True,
            text=True,
            env=self.env,
            timeout=300,
            check=False,
        )
        if check:
            assert done.returncode == 0, f"podman-compose {' '.join(args)}:\n{done.stderr[-3000:]}"
        return done

    def container(self, service: str) -> str:
        """The name of `service`'s container."""
        filters = ["--filter", f"label=io.podman.compose.project={self.project}"]
        filters += ["--filter", f"label=io.podman.compose.service={service}"]
        names = podman("ps", "--all", *filters, "--format", "{{.Names}}").stdout.split()
        assert len(names) == 1, names
        return names[0]


def podman_compose() -> str:
    """The podman-compose scripts/system-deps.sh installs into .tools/, or one on PATH."""
    tools = ROOT / ".tools" / "bin" / "podman-compose"
    found = str(tools) if tools.exists() else shutil.which("podman-compose")
    if found is None:
        unavailable("podman-compose is missing: run scripts/system-deps.sh (make test does)")
    return found


@pytest.fixture
def stack(bases: Bases, image: str, tmp_path: Path) -> Iterator[Stack]:
    """The compose project; its containers, pod, network and volume go afterwards."""
    project = f"srlabtest{secrets.token_hex(4)}"
    port, viser_port = free_port(), free_port()
    dotenv = env_file(
        tmp_path,
        SRLAB_TOKEN=TOKEN,
        POSTGRES_PASSWORD=PASSWORD,
        SRLAB_PORT=str(port),
        SRLAB_VISER_PORT=str(viser_port),
    )
    standins = tmp_path / "standins.yml"
    services = {"db": {"image": bases.postgres}, "srlab": {"image": image}}
    standins.write_text(yaml.safe_dump({"services": services}))
    files = ["-f", str(ROOT / "docker-compose.yml"), "-f", str(standins)]
    argv = [podman_compose(), "--project-name", project, "--env-file", str(dotenv), *files]
    # Only the .env file sets compose's variables, as on a user's machine.
    env = {
        k: v
        for k, v in os.environ.items()
        if not k.startswith(("SRLAB_", "POSTGRES_", "COMPOSE_", "DOCKER_", "PODMAN_"))
    }
    made = Stack(argv, project, port, viser_port, env)
    try:
        yield made
    finally:
        made.compose("down", "--volumes", check=False)
        # Whatever `down` left behind (it failed, or never ran), by the project's label.
        label = f"label=io.podman.compose.project={project}"
        left = podman("ps", "--all", "--quiet", "--filter", label, check=False).stdout.split()
        if left:
            podman("rm", "--force", "--time", "5", *left, check=False)
        podman("pod", "rm", "--force", "--ignore", f"pod_{project}", check=False)
        for kind in ("volume", "network"):
            left = podman(kind, "ls", "--quiet", "--filter", label, check=False).stdout.split()
            if left:
                podman(kind, "rm", "--force", *left, check=False)


def start_in_order(stack: Stack) -> tuple[str, str]:
    """`up`: the database, then, once its healthcheck passes, the service; their names.

    `depends_on: condition: service_healthy` needs podman 4.6 (`podman wait
    --condition=healthy`); before it podman-compose starts the service at once. The wait
    for the database stands for the condition.
    """
    stack.compose("up", "--detach", "db")
    db = stack.container("db")
    wait_healthy(db)  # compose's pg_isready, in the stand-in
    stack.compose("up", "--detach")
    srlab = stack.container("srlab")
    wait_healthy(srlab)
    return db, srlab


def test_the_compose_stack_keeps_an_acknowledged_reward_across_a_restart_of_both(
    stack: Stack,
) -> None:
    db, srlab = start_in_order(stack)
    published = podman("port", srlab).stdout.splitlines()
    assert sorted(published) == sorted(
        f"{p}/tcp -> 127.0.0.1:{p}" for p in (stack.port, stack.viser_port)
    ), "published on this machine only, as the compose file's default says"

    with api_client(stack.port) as api:
        health = api.get("/api/health").json()
        assert (health["status"], health["database"]) == ("ok", "postgresql")
        anonymous = api.post("/api/runs", json={"condition": "kp"}, headers={"Authorization": ""})
        assert anonymous.status_code == 401
        created = api.post("/api/runs", json={"condition": "kp", "mode": "realtime", "hz": 10})
        assert created.status_code == 201, created.text
        run_id = created.json()["id"]
        assert api.post(f"/api/runs/{run_id}/start").status_code == 200
        wait_status(api, run_id, "running")
        ack = api.post(f"/api/runs/{run_id}/rewards", json={"value": 0.5, "note": "before"})
        assert ack.status_code == 202, ack.text
        reward_id = ack.json()["id"]

    started = {c: inspect("container", c)["State"]["StartedAt"] for c in (db, srlab)}
    # Both containers restart as docker compose restarts them: the service stops before the
    # database it stores into, and starts once the database is healthy again. (podman-compose
    # stops and starts every service at once, so the test goes service by service.)
    stack.compose("stop", "srlab")
    logs = podman("logs", srlab)
    log = logs.stdout + logs.stderr
    assert "Application shutdown complete" in log and "Traceback" not in log, log[-3000:]
    stack.compose("stop", "db")
    stack.compose("start", "db")
    wait_healthy(db)
    stack.compose("start", "srlab")
    wait_healthy(srlab)
    for name, before in started.items():
        assert inspect("container", name)["State"]["StartedAt"] != before, name

    with api_client(stack.port) as api:
        rewards = api.get(f"/api/runs/{run_id}/rewards").json()
        assert rewards["count"] == 1, rewards
        assert [(r["id"], r["value"], r["note"]) for r in rewards["data"]] == [
            (reward_id, 0.5, "before")
        ]
        # SIGTERM interrupted the run; it resumes and takes rewards again.
        assert api.get(f"/api/runs/{run_id}").json()["status"] == "interrupted"
        assert api.post(f"/api/runs/{run_id}/start").status_code == 200
        wait_status(api, run_id, "running")
        again = api.post(f"/api/runs/{run_id}/rewards", json={"value": -0.5, "note": "after"})
        assert again.status_code == 202, again.text

    # An upgrade's `down` and `up` make new containers: the rewards live in the named volume.
    stack.compose("down")
    start_in_order(stack)
    with api_client(stack.port) as api:
        after = api.get(f"/api/runs/{run_id}/rewards")
        assert after.status_code == 200, after.text
        assert {r["id"] for r in after.json()["data"]} == {reward_id, again.json()["id"]}
