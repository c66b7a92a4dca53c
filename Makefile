# srlab: `make run` and `make test` do the whole set-up on a fresh machine.
# uv is installed into .tools/ with pip when it is not on PATH; the project's venv is .venv/.
SHELL := /bin/bash
PYTHON ?= python3
UV := $(shell command -v uv 2>/dev/null || echo .tools/bin/uv)
VENV := .venv
BIN := $(VENV)/bin

.PHONY: help install install-run install-baselines install-worlds install-ros2 run test test-unit test-fast test-baselines test-worlds test-ros2 lint typecheck hooks format bench bench-ros2 bench-results reliability screenshots migrate revision pg pg-stop up down clean

help:
	@echo "make run | install-run | test | test-unit | install-baselines | test-baselines | install-worlds | test-worlds | install-ros2 | test-ros2 | lint | typecheck | hooks | format | bench | bench-results | reliability | screenshots | migrate | revision m=... | pg | pg-stop | up | down | clean"

.tools/bin/uv:
	$(PYTHON) -m venv .tools && .tools/bin/pip install --quiet 'uv>=0.4,<1'

# Two sets of packages in the one .venv, each behind a stamp of its own:
# - `make run`'s (install-run): the project and what the service and the CLI import, with no
#   dev group (pytest, mypy, Playwright, moviepy's ffmpeg ...) and no extra (Ray). Synced
#   --inexact: it adds what is missing and removes nothing, so `make run` after `make test`
#   keeps the test tools (and a baselines install) instead of deleting them.
# - everything else's (install): the dev group and the ray extra (the tests run the Ray
#   backend on a local instance), synced exactly as uv.lock says, so the suite runs on
#   exactly the locked set; `make test` after `make run` adds the rest.
# Bytecode is compiled once here: every `srlab serve` and CLI the tests start would
# otherwise compile its imports again where .pyc files are not written (~3 s a process).
RUN_SYNCED := $(VENV)/.synced-run
DEV_SYNCED := $(VENV)/.synced-dev

$(RUN_SYNCED): pyproject.toml uv.lock | $(UV)
	$(UV) sync --frozen --no-dev --inexact --compile-bytecode --quiet
	@touch $@

$(DEV_SYNCED): pyproject.toml uv.lock | $(UV)
	$(UV) sync --frozen --extra ray --compile-bytecode --quiet
	@touch $@

# The project's own modules are compiled too, on every target that starts Python: the
# environment may set PYTHONDONTWRITEBYTECODE (this machine's does), and then each
# `srlab serve`, store or engines process, CLI and test worker compiled core/ and server/
# again (about 1 s of CPU a process). A stale .pyc is never used: Python checks its source.
install-run: $(RUN_SYNCED)
	@$(BIN)/python -m compileall -q -j0 core server migrations

install: $(DEV_SYNCED)
	@$(BIN)/python -m compileall -q -j0 core server bench migrations tests

# The optional srlab[baselines] extra (stable-baselines3, DQN and PPO) on a CPU-only torch,
# into .venv, without CUDA's ~5 GB: torch from a CPU wheel in $$TORCH_WHEELS (default pip's
# find-links, /opt/wheels) or PyTorch's CPU index, then the extra at uv.lock's versions.
# `make test` never installs it (its baseline tests skip; CI runs `make test-baselines`
# after it); a later `make install` that re-syncs removes it again, `make run` keeps it.
install-baselines: install
	bash scripts/install-baselines.sh $(UV) $(BIN)/python

# The optional srlab[worlds] extra (MiniGrid, ir-sim: `srlab outside`, core/outside/) into
# .venv at uv.lock's versions, keeping what is there (--inexact). `make test` never installs
# it (tests/worlds' environment tests skip; CI runs `make test-worlds` after it); a later
# `make install` that re-syncs removes it again, `make run` keeps it.
install-worlds: install
	$(UV) sync --frozen --extra ray --extra worlds --inexact --compile-bytecode --quiet

# The optional srlab[ros2] extra (rclpy and Fast DDS wheels, server/robots/ros2.py) into .venv at
# uv.lock's versions. `make test` never installs it (tests/ros2 skip); `make test-ros2` does.
install-ros2: install
	bash scripts/install-ros2.sh $(UV) $(BIN)/python

# Set-up, then the service on http://127.0.0.1:8000 (it migrates and seeds ./var/srlab.db).
run: install-run
	@echo "CLI: $(BIN)/srlab (or \`source $(BIN)/activate\` for plain \`srlab\`, or \`uv run --no-dev srlab\`)"
	$(BIN)/srlab serve

# ESLint for web/ (eslint.config.js) at package-lock.json's versions, into node_modules/
# from the npm registry; node and npm are Debian's (scripts/node-deps.sh).
NODE_SYNCED := node_modules/.synced

$(NODE_SYNCED): package.json package-lock.json
	bash scripts/node-deps.sh
	npm ci --no-audit --no-fund --loglevel=error
	@touch $@

lint: install $(NODE_SYNCED)
	$(BIN)/ruff check .
	$(BIN)/ruff format --check .
	node_modules/.bin/eslint --max-warnings 0

typecheck: install
	$(BIN)/mypy

# lint's and typecheck's checks before each commit (.pre-commit-config.yaml), in .git/hooks.
hooks: install
	$(BIN)/pre-commit install

# Chromium (browser tests) and docker-compose (config check) come from Debian: the first
# script installs them as root, or says what to install.
# The storage tests run on SQLite and on a throwaway PostgreSQL server on 127.0.0.1, which
# the script installs (as root) when missing, starts for pytest and stops afterwards.
# The suite runs on $(WORKERS) pytest-xdist workers (its tests mostly wait on servers and pages,
# so more workers than cores pay); tests/conftest.py's scheduler keeps a module's tests on
# one worker and starts the longest first. `make test WORKERS=0` runs it in one process.
# It measures branch coverage of core/ and server/ (pyproject.toml) and prints the total last:
# a figure, not a gate; `.venv/bin/coverage report` then lists the files by coverage.
WORKERS ?= 4
test: lint typecheck
	bash scripts/system-deps.sh
	bash scripts/podman-bases.sh >/dev/null
	bash scripts/pg-test-server.sh run -- $(BIN)/pytest -n $(WORKERS) --dist loadfile --cov --cov-report=
	@echo "branch coverage of core/ and server/: $$($(BIN)/coverage report --format=total)%"

# The quick tests (docs/testing.md): no live server, subprocess, browser, PostgreSQL, Docker or node.
UNIT := not slow and not browser and not reliability and not pg and not docker and not node
test-unit: install
	$(BIN)/pytest -m "$(UNIT)" -n 2 -q

test-fast: test-unit

test-baselines: install-baselines
	$(BIN)/pytest tests/baselines -q

test-worlds: install-worlds
	$(BIN)/pytest tests/worlds -q -n 2

# The ROS 2 adapter against a fake AmigoBot node, all inside a network namespace of its own
# with only loopback up (scripts/loopback-netns.sh), so no DDS traffic leaves the machine.
test-ros2: install-ros2
	bash scripts/loopback-netns.sh $(BIN)/pytest tests/ros2 -q

format: install
	$(BIN)/ruff format .
	$(BIN)/ruff check --fix .

# The reliability suite at full size (~25 min; CI runs it small): kill -9 and SIGTERM of
# srlab serve, storage faults, overload, a 50 MB body, schemathesis. It prints a table of
# what held and writes it to docs/reliability.md.
reliability: install
	bash scripts/pg-test-server.sh run -- $(BIN)/python -m tests.reliability.suite

# The README's pictures of the editor and the console, retaken in Debian's Chromium.
screenshots: install
	bash scripts/system-deps.sh
	$(BIN)/python scripts/screenshots.py

# `bash scripts/results.sh` timed into a scratch folder, against its goal of 30 minutes on
# 2 cores (the deep baselines included when the srlab[baselines] extra is installed).
bench-results: install
	$(BIN)/python -m bench.experiment --only results --jobs 2

# bench/ros2.py: the ROS 2 adapter's sensor-to-command latency and dropped commands against
# the fake AmigoBot, in a loopback-only namespace (10,000 ticks at 20 Hz: about 9 minutes).
bench-ros2: install-ros2
	bash scripts/loopback-netns.sh $(BIN)/python -m bench.ros2 $(ARGS)

bench: install
	$(BIN)/python -m bench.ticks
	$(BIN)/python -m bench.experiment
	$(BIN)/python -m bench.sweep
	$(BIN)/python -m bench.engine
	$(BIN)/python -m bench.instructions
	$(BIN)/python -m bench.slices
	$(BIN)/python -m bench.store
	$(BIN)/python -m bench.service
	$(BIN)/python -m bench.studies --trainers 64
	$(BIN)/python -m bench.viewer

migrate: install
	$(BIN)/python -c "from server.persistence import upgrade; upgrade()"

revision: install
	$(BIN)/alembic revision --autogenerate -m "$(m)"

pg:
	bash scripts/pg-test-server.sh start

pg-stop:
	bash scripts/pg-test-server.sh stop

# The service and PostgreSQL in containers: needs Docker and a .env (see .env.example).
COMPOSE ?= docker compose
up:
	$(COMPOSE) up -d --build

down:
	$(COMPOSE) down

clean: pg-stop
	rm -rf $(VENV) .tools .mypy_cache .ruff_cache .pytest_cache .pg node_modules
