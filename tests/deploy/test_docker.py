"""The container set-up without a container engine: the compose file and the Dockerfile.

`docker-compose config` (Debian's v1, which needs no engine) parses and interpolates
docker-compose.yml as compose would. The tests check the parsed result. Then the image is
rebuilt the Dockerfile's way, without a container: its COPY sources go through
.dockerignore into a folder, and its `uv` steps, its warm-up step, its CMD and its
HEALTHCHECK run there. The service runs on the environment compose resolves, pointed at
a fresh PostgreSQL database, and a run goes through it into PostgreSQL.
"""

from __future__ import annotations

import fnmatch
import importlib.util
import json
import os
import re
import shlex
import shutil
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest
import yaml
from liveharness import wait_status
from sqlalchemy import create_engine, text
from sqlalchemy.engine import make_url

from bench.liveserver import free_port, start_server, stop_server
from server.config import Settings

ROOT = Path(__file__).resolve().parents[2]
TOKEN = "dummytokenforci"
PASSWORD = "dummypassword"

# --------------------------------------------------------------------------- compose


def docker_compose() -> str:
    """The docker-compose binary; skip without it, fail where it is required (CI)."""
    found = shutil.which("docker-compose")
    if found:
        return found
    message = "docker-compose is missing: 'apt-get install -y docker-compose' (make test does)"
    if os.environ.get("SRLAB_REQUIRE_COMPOSE") == "1":
        pytest.fail(message)
    pytest.skip(message)


def compose_config(env_file: Path) -> subprocess.CompletedProcess[str]:
    """`docker-compose config` of the repository's file, interpolated from `env_file` only."""
    env = {
        k: v
        for k, v in os.environ.items()
        if not k.startswith(("SRLAB_", "POSTGRES_", "COMPOSE_", "DOCKER_"))
    }
    argv = [docker_compose(), "-f", str(ROOT / "docker-compose.yml")]
    return subprocess.run(
        [*argv, "--env-file", str(env_file), "config"],
        capture_output=True,
        text=True,
        env=env,
        cwd=ROOT,
        check=False,
        timeout=60,
    )


def env_file(folder: Path, **values: str) -> Path:
    """.env.example with `values` filled in, as a user's .env."""
    lines = []
    for line in (ROOT / ".env.example").read_text().splitlines():
        key = line.split("=", 1)[0]
        lines.append(f"{key}={values.pop(key)}" if key in values else line)
    lines += [f"{k}={v}" for k, v in values.items()]
    path = folder / ".env"
    path.write_text("\n".join(lines) + "\n")
    return path


def resolved(folder: Path, **values: str) -> dict[str, Any]:
    """The compose file as `docker-compose config` resolves it with these .env values."""
    done = compose_config(env_file(folder, **values))
    assert done.returncode == 0, done.stderr
    config: dict[str, Any] = yaml.safe_load(done.stdout)
    return config


@pytest.fixture(scope="module")
def compose(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Any]:
    """The compose file resolved with dummy secrets, as CI has no real .env."""
    folder = tmp_path_factory.mktemp("compose")
    return resolved(folder, SRLAB_TOKEN=TOKEN, POSTGRES_PASSWORD=PASSWORD)


def test_compose_runs_the_service_beside_a_healthy_postgres_with_a_named_volume(
    compose: dict[str, Any],
) -> None:
    services = compose["services"]
    assert set(services) == {"db", "srlab"}
    db, srlab = services["db"], services["srlab"]
    assert re.fullmatch(r"postgres:16(\.\d+)?(-\w+)?", db["image"])
    assert db["environment"]["POSTGRES_PASSWORD"] == PASSWORD
    assert db["healthcheck"]["test"][0] == "CMD-SHELL"
    assert "pg_isready" in db["healthcheck"]["test"][1]
    assert "pgdata" in compose["volumes"]
    assert "pgdata:/var/lib/postgresql/data:rw" in db["volumes"]
    assert "ports" not in db, "PostgreSQL is reached over compose's network only"

    assert Path(srlab["build"]["context"]) == ROOT
    assert srlab["depends_on"] == {"db": {"condition": "service_healthy"}}
    assert srlab["healthcheck"]["test"] == ["CMD", *dockerfile().healthcheck]
    assert srlab["restart"] == db["restart"] == "unless-stopped"


def test_compose_gives_the_service_a_token_and_binds_it_everywhere_inside(
    compose: dict[str, Any], monkeypatch: pytest.MonkeyPatch
) -> None:
    env = compose["services"]["srlab"]["environment"]
    assert env["SRLAB_TOKEN"] == TOKEN
    # The image binds every interface; compose's SRLAB_HOST is where it publishes the ports,
    # and is not passed in (podman-compose would publish on the service's own value).
    assert "SRLAB_HOST" not in env
    image_env = {k: v for k, v in dockerfile().stages[-1].env if k.startswith("SRLAB_")}
    assert image_env["SRLAB_HOST"] == "0.0.0.0"
    url = make_url(env["SRLAB_DATABASE_URL"])
    assert (url.drivername, url.host, url.port, url.database) == (
        "postgresql+psycopg",
        "db",
        5432,
        "srlab",
    )
    assert (url.username, url.password) == ("srlab", PASSWORD)
    for name in [k for k in os.environ if k.startswith("SRLAB_")]:
        monkeypatch.delenv(name)
    for name, value in {**image_env, **env}.items():  # the container's, as docker sets it
        monkeypatch.setenv(name, value)
    settings = Settings()  # from the environment, as the service reads it
    settings.check()  # what `srlab serve` does before it binds
    assert not settings.loopback and settings.writes_need_token
    assert settings.allowed_hosts == ["localhost", "127.0.0.1"]
    without = settings.model_copy(update={"token": None})
    with pytest.raises(ValueError, match="SRLAB_TOKEN"):
        without.check()


def test_compose_publishes_both_ports_on_loopback_unless_told_otherwise(
    compose: dict[str, Any], tmp_path: Path
) -> None:
    assert compose["services"]["srlab"]["ports"] == [
        "127.0.0.1:8000:8000/tcp",
        "127.0.0.1:8080:8080/tcp",
    ]
    opened = resolved(
        tmp_path,
        SRLAB_TOKEN=TOKEN,
        POSTGRES_PASSWORD=PASSWORD,
        SRLAB_HOST="0.0.0.0",
        SRLAB_PORT="9000",
        SRLAB_VISER_PORT="9090",
    )
    srlab = opened["services"]["srlab"]
    assert srlab["ports"] == ["0.0.0.0:9000:9000/tcp", "0.0.0.0:9090:9090/tcp"]
    # Inside it listens everywhere as before (the image's SRLAB_HOST); its ports follow, so
    # the 3D view's link holds.
    assert "SRLAB_HOST" not in srlab["environment"]
    assert srlab["environment"]["SRLAB_PORT"] == "9000"
    assert srlab["environment"]["SRLAB_VISER_PORT"] == "9090"


def test_compose_refuses_to_start_until_both_secrets_are_set(tmp_path: Path) -> None:
    example = compose_config(ROOT / ".env.example")
    assert example.returncode != 0
    assert "set POSTGRES_PASSWORD in .env" in example.stderr or (
        "set SRLAB_TOKEN in .env" in example.stderr
    )
    no_token = compose_config(env_file(tmp_path, POSTGRES_PASSWORD=PASSWORD))
    assert no_token.returncode != 0
    assert "set SRLAB_TOKEN in .env (see .env.example)" in no_token.stderr


def test_env_example_names_every_variable_the_compose_file_reads() -> None:
    used = set(re.findall(r"\$\{(\w+)", (ROOT / "docker-compose.yml").read_text()))
    example = (ROOT / ".env.example").read_text()
    named = set(re.findall(r"^#?(\w+)=", example, flags=re.MULTILINE))
    assert used == named
    ignored = subprocess.run(["git", "check-ignore", "-q", ".env"], cwd=ROOT, check=False)
    assert ignored.returncode == 0, "git ignores .env..."
    assert dockerignored(".env") and not dockerignored(".env.example")  # ...and so does docker


# --------------------------------------------------------------------------- Dockerfile


@dataclass
class Stage:
    """One FROM ... stage: its base, ENV settings, COPY sources and RUN commands."""

    base: str
    name: str | None
    env: list[tuple[str, str]] = field(default_factory=list)
    copies: list[str] = field(default_factory=list)
    runs: list[str] = field(default_factory=list)
    user: str | None = None
    workdir: str | None = None
    instructions: list[tuple[str, str]] = field(default_factory=list)


@dataclass
class Dockerfile:
    """The parts of the Dockerfile the tests run or check."""

    args: dict[str, str]
    stages: list[Stage]
    healthcheck: list[str]
    healthcheck_options: dict[str, str]
    cmd: list[str]
    expose: list[str]


def instructions(source: str) -> Iterator[tuple[str, str]]:
    """(INSTRUCTION, arguments), continuation lines joined and comments dropped."""
    logical = ""
    for raw in source.splitlines():
        line = raw.strip()
        if not line or line.startswith("#"):
            continue
        if line.endswith("\\"):
            logical += line[:-1] + " "
            continue
        logical += line
        keyword, _, rest = logical.partition(" ")
        yield keyword.upper(), rest.strip()
        logical = ""


def dockerfile() -> Dockerfile:
    """The repository's Dockerfile, parsed."""
    args: dict[str, str] = {}
    stages: list[Stage] = []
    health: list[str] = []
    options: dict[str, str] = {}
    cmd: list[str] = []
    expose: list[str] = []
    for keyword, rest in instructions((ROOT / "Dockerfile").read_text()):
        if keyword == "ARG" and not stages:
            name, _, default = rest.partition("=")
            args[name] = default
            continue
        if keyword == "FROM":
            parts = rest.split()
            base = re.sub(r"\$\{(\w+)\}", lambda m: args[m.group(1)], parts[0])
            stages.append(Stage(base, parts[2] if len(parts) > 2 else None))
            continue
        stage = stages[-1]
        stage.instructions.append((keyword, rest))
        if keyword == "ENV":
            for setting in shlex.split(rest):
                key, _, value = setting.partition("=")
                stage.env.append((key, value))
        elif keyword == "COPY" and not rest.startswith("--from"):
            stage.copies += rest.split()[:-1]
        elif keyword == "RUN":
            stage.runs.append(rest)
        elif keyword == "USER":
            stage.user = rest
        elif keyword == "WORKDIR":
            stage.workdir = rest
        elif keyword == "HEALTHCHECK":
            words = rest.split(" CMD ", 1)
            options = dict(o.lstrip("-").split("=", 1) for o in words[0].split())
            health = json.loads(words[1])
        elif keyword == "CMD":
            cmd = json.loads(rest)
        elif keyword == "EXPOSE":
            expose += rest.split()
    return Dockerfile(args, stages, health, options, cmd, expose)


def dockerignored(path: str) -> bool:
    """Whether .dockerignore keeps `path` (relative to the repository) out of the context.

    Docker's rules, as far as this file uses them: the last matching line wins, `!`
    re-includes, a pattern matching a folder excludes what is in it, and `**/` matches
    any depth.
    """
    parts = Path(path).parts
    prefixes = ["/".join(parts[: i + 1]) for i in range(len(parts))]
    excluded = False
    for line in (ROOT / ".dockerignore").read_text().splitlines():
        pattern = line.strip()
        if not pattern or pattern.startswith("#"):
            continue
        negate = pattern.startswith("!")
        pattern = pattern.lstrip("!")
        if pattern.startswith("**/"):
            tail = pattern[3:]
            hit = any(fnmatch.fnmatchcase(p, tail) for p in parts)
        else:
            hit = any(fnmatch.fnmatchcase(p, pattern) for p in prefixes)
        if hit:
            excluded = not negate
    return excluded


def test_the_image_is_multi_stage_slim_python_3_11_and_runs_as_a_user() -> None:
    d = dockerfile()
    assert len(d.stages) == 2
    build, final = d.stages
    assert build.base == final.base
    assert re.fullmatch(r"python:3\.11(\.\d+)?-slim(-\w+)?", final.base)
    assert any(r.startswith("uv sync --frozen --no-dev") for r in build.runs)
    assert ("COPY", "--from=build /app /app") in final.instructions
    assert final.user not in (None, "root", "0")
    assert not any(r.split()[0] in ("pip", "uv", "apt-get") for r in final.runs)
    assert d.cmd == ["srlab", "serve"]
    assert d.healthcheck == ["python", "-m", "server.healthcheck"]
    assert set(d.expose) == {"8000", "8080"}
    assert dict(final.env)["SRLAB_HOST"] == "0.0.0.0"
    # The healthcheck's own timeout outlasts the check's (server/healthcheck.py).
    assert d.healthcheck_options["timeout"] == "5s"


def test_the_dockerignore_keeps_out_secrets_and_clutter_but_not_what_the_image_copies() -> None:
    build = dockerfile().stages[0]
    for source in build.copies:
        assert (ROOT / source).exists(), source
        assert not dockerignored(source), source
    for kept_out in (".env", ".git", ".venv", ".pg", "var", "tests", "core/__pycache__"):
        assert dockerignored(kept_out), kept_out


# --------------------------------------------------------------------------- the image


@dataclass
class Image:
    """The Dockerfile's /app, /data and home folder, built in a temporary folder."""

    app: Path
    data: Path
    home: Path
    env: dict[str, str]
    """The final stage's ENV, its paths moved into the folder."""


def _move(value: str, places: dict[str, Path]) -> str:
    """`value` with the image's absolute paths (/app, /data, /home/srlab) moved."""
    pattern = "|".join(re.escape(p) for p in places)
    return re.sub(rf"(?<![\w.-])({pattern})(?=/|:|$)", lambda m: str(places[m.group(1)]), value)


def _shell(command: str, env: dict[str, str], cwd: Path) -> None:
    done = subprocess.run(
        ["/bin/sh", "-c", command],
        env=env,
        cwd=cwd,
        capture_output=True,
        text=True,
        check=False,
        timeout=600,
    )
    assert done.returncode == 0, f"{command}\n{done.stdout[-2000:]}\n{done.stderr[-3000:]}"


def _uv() -> Path:
    """The uv the Makefile uses: the one on PATH, else the one it installs into .tools/."""
    found = shutil.which("uv")
    uv = Path(found) if found else ROOT / ".tools" / "bin" / "uv"
    assert uv.exists(), "no uv on PATH or in .tools/bin: run `make test`, which installs it"
    return uv


@pytest.fixture(scope="module")
def image(tmp_path_factory: pytest.TempPathFactory) -> Image:
    """The image's contents, made by the Dockerfile's own steps."""
    folder = tmp_path_factory.mktemp("image")
    app, data, home = folder / "app", folder / "data", folder / "home"
    for made in (app, data, home):
        made.mkdir()  # the final stage's useradd and install -d make /home/srlab and /data
    build, final = dockerfile().stages

    def ignore(directory: str, names: list[str]) -> set[str]:
        rel = Path(directory).relative_to(ROOT)
        return {n for n in names if dockerignored(str(rel / n))}

    for source in build.copies:
        src = ROOT / source
        if src.is_dir():
            shutil.copytree(src, app / source, ignore=ignore)
        else:
            shutil.copy2(src, app / source)
    base = {k: v for k, v in os.environ.items() if not k.startswith(("UV_", "VIRTUAL_ENV"))}
    # The build stage's uv steps, on this machine's Python 3.11 instead of the image's, and
    # linking from uv's cache instead of copying (the image copies, for its layers).
    env = {**base, **dict(build.env)}
    env |= {
        "UV_PYTHON": str(Path(os.path.realpath(sys.executable))),
        "UV_PROJECT_ENVIRONMENT": str(app / ".venv"),
        "UV_COMPILE_BYTECODE": "0",
    }
    env.pop("UV_LINK_MODE")
    env["PATH"] = f"{_uv().parent}:{env.get('PATH', '')}"  # the image pip-installs uv
    for command in build.runs:
        if command.startswith(("uv ", ".venv/bin/python ")):
            _shell(command, env, app)
    places = {"/app": app, "/data": data, "/home/srlab": home}
    final_env = {k: _move(os.path.expandvars(v), places) for k, v in final.env}
    final_env["PATH"] = f"{app / '.venv' / 'bin'}:{os.environ['PATH']}"
    run_env = {**base, **final_env}
    for command in final.runs:
        if command.split()[0] != "useradd":
            _shell(command, run_env, app)
    return Image(app, data, home, final_env)


def test_the_image_has_no_dev_tools_and_compiles_its_code_at_build_time(image: Image) -> None:
    bin_dir = image.app / ".venv" / "bin"
    assert (bin_dir / "srlab").exists()
    for dev_tool in ("pytest", "mypy", "ruff"):
        assert not (bin_dir / dev_tool).exists(), dev_tool
    numba_cache = Path(image.env["NUMBA_CACHE_DIR"])
    assert any(numba_cache.rglob("*.nbi")), "the warm-up step cached the sensing kernel"
    # The service's user cannot write beside srlab's modules: they are compiled at build.
    for module in ("core/sim/world.py", "server/serve.py", "server/api/routes/runs.py"):
        source = image.app / module
        assert Path(importlib.util.cache_from_source(str(source))).exists(), module


def _healthcheck(image: Image, port: int) -> subprocess.CompletedProcess[str]:
    """The Dockerfile's HEALTHCHECK command, run as the container would run it."""
    argv = dockerfile().healthcheck
    env = {**os.environ, **image.env, "SRLAB_PORT": str(port)}
    program = shutil.which(argv[0], path=env["PATH"])
    assert program is not None and program.startswith(str(image.app)), program
    return subprocess.run(
        [program, *argv[1:]], env=env, capture_output=True, text=True, timeout=30, check=False
    )


def _service_env(compose: dict[str, Any], image: Image, database: str) -> dict[str, str]:
    """The container's environment: the image's ENV, then compose's, the database moved."""
    env = {**image.env, **compose["services"]["srlab"]["environment"]}
    env["SRLAB_DATABASE_URL"] = database
    return env


def test_the_image_refuses_to_serve_without_a_token(
    image: Image, compose: dict[str, Any], tmp_path: Path
) -> None:
    env = _service_env(compose, image, f"sqlite:///{tmp_path / 'x.db'}")
    del env["SRLAB_TOKEN"]
    program = shutil.which(dockerfile().cmd[0], path=env["PATH"])
    assert program is not None
    done = subprocess.run(
        [program, *dockerfile().cmd[1:]],
        env={**os.environ, **env},
        cwd=image.app,
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode == 2, done.stderr
    assert "set SRLAB_TOKEN" in done.stderr and "Traceback" not in done.stderr


def test_the_image_alone_serves_sqlite_from_its_data_folder(image: Image, tmp_path: Path) -> None:
    port = free_port()
    env = {**image.env, "SRLAB_TOKEN": TOKEN, "SRLAB_VISER_PORT": str(free_port())}
    assert env["SRLAB_DATABASE_URL"] == f"sqlite:///{image.data / 'srlab.db'}"
    program = shutil.which(dockerfile().cmd[0], path=env["PATH"])
    assert program is not None
    server = start_server(
        env["SRLAB_DATABASE_URL"],
        port=port,
        env=env,
        command=[program, *dockerfile().cmd[1:]],
        cwd=image.app,
        log=tmp_path / "serve.log",
        headers={"Authorization": f"Bearer {TOKEN}"},
    )
    try:
        assert _healthcheck(image, port).returncode == 0
        assert server.client.get("/api/health").json()["database"] == "sqlite"
        created = server.client.post("/api/runs", json={"condition": "kp", "episodes": 1})
        assert created.status_code == 201, created.text
    finally:
        stop_server(server)
    assert (image.data / "srlab.db").exists()


def test_the_image_serves_compose_s_configuration_on_postgres(
    image: Image, compose: dict[str, Any], postgres_database: str, tmp_path: Path
) -> None:
    port = free_port()
    env = _service_env(compose, image, postgres_database)
    env |= {"SRLAB_PORT": str(port), "SRLAB_VISER_PORT": str(free_port())}
    unhealthy = _healthcheck(image, port)
    assert unhealthy.returncode == 1 and "srlab unhealthy" in unhealthy.stderr

    cmd = dockerfile().cmd
    program = shutil.which(cmd[0], path=env["PATH"])
    assert program is not None and program.startswith(str(image.app)), program
    server = start_server(
        postgres_database,
        port=port,
        env=env,
        command=[program, *cmd[1:]],
        cwd=image.app,
        log=tmp_path / "serve.log",
        headers={"Authorization": f"Bearer {TOKEN}"},
    )
    try:
        healthy = _healthcheck(image, port)
        assert healthy.returncode == 0, healthy.stderr
        api = server.client
        health = api.get("/api/health").json()
        assert health["database"] == "postgresql"
        # Bound beyond loopback: a write without the token is refused.
        anonymous = api.post("/api/runs", json={"condition": "kp"}, headers={"Authorization": ""})
        assert anonymous.status_code == 401
        if (ROOT / "web" / "index.html").exists():  # the editor is in the image too
            assert api.get("/").status_code == 200
        created = api.post("/api/runs", json={"condition": "kp", "seed": 3, "episodes": 3})
        assert created.status_code == 201, created.text
        run_id = created.json()["id"]
        assert api.post(f"/api/runs/{run_id}/start").status_code == 200
        done = wait_status(api, run_id, "finished")
        assert done["episodes_done"] == 3
    finally:
        log = stop_server(server)
    assert "Application shutdown complete" in log

    engine = create_engine(postgres_database)
    try:
        with engine.connect() as c:
            stored = c.execute(
                text("SELECT status, condition FROM runs WHERE id = :id"), {"id": run_id}
            ).one()
            episodes = c.execute(
                text("SELECT count(*) FROM episodes WHERE run_id = :id"), {"id": run_id}
            ).scalar_one()
            revision = c.execute(text("SELECT version_num FROM alembic_version")).scalar_one()
    finally:
        engine.dispose()
    assert tuple(stored) == ("finished", "kp")
    assert episodes == 3
    assert revision  # `srlab serve` migrated the database before it served
