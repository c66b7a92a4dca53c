"""The core stays pure: no adapters, no wall clock, no global random state."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

import core

CORE = Path(core.__file__).parent
FORBIDDEN_PACKAGES = {
    "fastapi",
    "starlette",
    "sqlalchemy",
    "alembic",
    "viser",
    "uvicorn",
    "httpx",
    "pydantic",
    "pydantic_settings",
    "ray",
    "server",
}
CLOCK_MODULES = {"time", "datetime"}
CLOCK_CALLS = {
    ("time", "time"),
    ("time", "time_ns"),
    ("time", "sleep"),
    ("time", "monotonic"),
    ("time", "perf_counter"),
    ("datetime", "now"),
    ("datetime", "utcnow"),
    ("datetime", "today"),
    ("date", "today"),
}
NUMPY_SEEDED = {"default_rng", "SeedSequence", "Generator", "PCG64", "BitGenerator"}
"""numpy.random names that build an instance RNG rather than use the global one."""
ENGINE = CORE / "engine"
"""The engine's package: the one part of core that paces by the clock."""


def core_files() -> list[Path]:
    return sorted(p for p in CORE.rglob("*.py") if "__pycache__" not in p.parts)


def dotted(node: ast.expr) -> str:
    """`a.b.c` for an attribute chain on a name, '' otherwise."""
    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    if not isinstance(node, ast.Name):
        return ""
    parts.append(node.id)
    return ".".join(reversed(parts))


def violations(source: str, label: str, *, is_engine: bool = False) -> list[str]:
    """What in `source` breaks the core's purity, as "label:line: what" strings."""
    tree = ast.parse(source, filename=label)
    found = []
    for node in ast.walk(tree):
        where = f"{label}:{getattr(node, 'lineno', 0)}"
        if isinstance(node, ast.Import):
            for alias in node.names:
                top = alias.name.split(".")[0]
                if top in FORBIDDEN_PACKAGES:
                    found.append(f"{where}: imports {alias.name}")
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            top = node.module.split(".")[0]
            names = {a.name for a in node.names}
            if top in FORBIDDEN_PACKAGES:
                found.append(f"{where}: imports from {node.module}")
            elif node.module == "random" and not is_engine:
                found.append(f"{where}: imports {sorted(names)} from the global random module")
            elif top in CLOCK_MODULES and not is_engine:
                for name in names:
                    if (node.module.split(".")[-1], name) in CLOCK_CALLS:
                        found.append(f"{where}: imports the clock {node.module}.{name}")
        elif isinstance(node, ast.Attribute) and not is_engine:
            chain = dotted(node)
            parts = chain.split(".")
            if len(parts) >= 2 and tuple(parts[-2:]) in CLOCK_CALLS:
                found.append(f"{where}: reads the clock with {chain}")
            if parts[0] == "random" and len(parts) == 2:
                found.append(f"{where}: uses the global random module ({chain})")
            if (
                len(parts) == 3
                and parts[0] in {"np", "numpy"}
                and parts[1] == "random"
                and parts[2] not in NUMPY_SEEDED
            ):
                found.append(f"{where}: uses numpy's global random state ({chain})")
    return found


def test_core_files_are_found() -> None:
    names = {p.name for p in core_files()}
    assert {"simulation.py", "world.py", "brain.py", "memory.py"} <= names


@pytest.mark.parametrize("path", core_files(), ids=lambda p: str(p.relative_to(CORE)))
def test_core_module_is_pure(path: Path) -> None:
    label = str(path.relative_to(CORE.parent))
    source = path.read_text(encoding="utf-8")
    assert violations(source, label, is_engine=ENGINE in path.parents) == []


@pytest.mark.parametrize(
    "source",
    [
        "import fastapi",
        "from sqlalchemy.orm import Session",
        "import pydantic.v1",
        "import time\nt = time.time()",
        "import time\ntime.sleep(1)",
        "from time import perf_counter",
        "import datetime\nd = datetime.datetime.now()",
        "from datetime import datetime\nd = datetime.now()",
        "import random\nx = random.random()",
        "from random import choice",
        "import numpy as np\nnp.random.seed(1)",
    ],
)
def test_the_checker_catches_violations(source: str) -> None:
    assert violations(source, "probe.py") != []


@pytest.mark.parametrize("source", ["import time\nt = time.time()", "import random"])
def test_the_engine_may_read_the_clock(source: str) -> None:
    assert violations(source, "engine.py", is_engine=True) == []


def test_the_checker_allows_instance_rngs() -> None:
    source = "import numpy as np\nrng = np.random.default_rng(np.random.SeedSequence([1]))\n"
    assert violations(source, "ok.py") == []


BRAIN = CORE / "brain"
PHYSICS_PACKAGES = {"pymunk", "numba"}
PHYSICS_MODULES = {"core.sim.world", "core.sim._kernel"}
"""The pymunk world and its numba kernels; the brain uses `core.sim.types` instead."""
LEAF_MODULES = [CORE / "events.py", CORE / "commands.py"]
"""Modules the brain imports, which must not import back up into the brain."""


def brain_files() -> list[Path]:
    return sorted(BRAIN.glob("*.py"))


def imported_modules(source: str, label: str) -> list[tuple[int, str]]:
    """Every absolute module `source` imports, as (line, dotted name); `from a import b` gives
    both `a` and `a.b` (b may be a submodule)."""
    found = []
    for node in ast.walk(ast.parse(source, filename=label)):
        if isinstance(node, ast.Import):
            found += [(node.lineno, alias.name) for alias in node.names]
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            found.append((node.lineno, node.module))
            found += [(node.lineno, f"{node.module}.{alias.name}") for alias in node.names]
    return found


def physics_imports(source: str, label: str) -> list[str]:
    """What in `source` imports pymunk, numba or the pymunk world."""
    return [
        f"{label}:{line}: imports {name}"
        for line, name in imported_modules(source, label)
        if name.split(".")[0] in PHYSICS_PACKAGES or name in PHYSICS_MODULES
    ]


def brain_imports(source: str, label: str) -> list[str]:
    """What in `source` imports from the brain."""
    return [
        f"{label}:{line}: imports {name}"
        for line, name in imported_modules(source, label)
        if name == "core.brain" or name.startswith("core.brain.")
    ]


@pytest.mark.parametrize("path", brain_files(), ids=lambda p: p.name)
def test_the_brain_does_not_import_physics(path: Path) -> None:
    label = str(path.relative_to(CORE.parent))
    assert physics_imports(path.read_text(encoding="utf-8"), label) == []


@pytest.mark.parametrize("path", LEAF_MODULES, ids=lambda p: p.name)
def test_no_import_runs_back_up_into_the_brain(path: Path) -> None:
    label = str(path.relative_to(CORE.parent))
    assert brain_imports(path.read_text(encoding="utf-8"), label) == []


@pytest.mark.parametrize(
    "source",
    [
        "import pymunk",
        "import numba.core",
        "from numba import njit",
        "from core.sim.world import MotorCommand",
        "from core.sim import world",
        "from core.sim import _kernel as k",
    ],
)
def test_the_physics_checker_catches_imports(source: str) -> None:
    assert physics_imports(source, "probe.py") != []


@pytest.mark.parametrize(
    "source",
    ["from core.brain.memory import Credit", "import core.brain.brain", "from core import brain"],
)
def test_the_brain_checker_catches_imports(source: str) -> None:
    assert brain_imports(source, "probe.py") != []


def test_the_checkers_allow_the_plain_types() -> None:
    source = "from core.sim.types import MotorCommand\nfrom core.sim.channels import Channel\n"
    assert physics_imports(source, "ok.py") == []
    assert brain_imports("from core.events import Credit\n", "ok.py") == []


def test_importing_the_brain_loads_no_physics() -> None:
    """Each brain module, imported in a fresh interpreter, leaves pymunk and numba unloaded
    (this catches what the source check cannot: a package `__init__` that loads them)."""
    modules = [f"core.brain.{p.stem}" for p in brain_files()]
    script = (
        "import importlib, sys\n"
        f"for name in {modules!r}:\n"
        "    importlib.import_module(name)\n"
        f"    loaded = sorted(m for m in {sorted(PHYSICS_PACKAGES)!r} if m in sys.modules)\n"
        "    if loaded:\n"
        "        print(name, 'loads', *loaded)\n"
        "        break\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", script],
        cwd=CORE.parent,
        capture_output=True,
        text=True,
        check=False,
        timeout=120,
    )
    assert done.returncode == 0, done.stderr
    assert done.stdout == ""


OUTSIDE_CORE = ("server", "bench", "scripts")


def engine_sim_reads(source: str, label: str) -> list[str]:
    """Every `<x>.sim` attribute read in `source`: outside core, a run is read by its view."""
    tree = ast.parse(source, filename=label)
    return [
        f"{label}:{node.lineno}: {dotted(node) or node.attr}"
        for node in ast.walk(tree)
        if isinstance(node, ast.Attribute) and node.attr == "sim"
    ]


def test_nothing_outside_core_reaches_into_an_engines_simulation() -> None:
    root = CORE.parent
    found = [
        hit
        for package in OUTSIDE_CORE
        for path in sorted((root / package).rglob("*.py"))
        if "__pycache__" not in path.parts
        for hit in engine_sim_reads(path.read_text(encoding="utf-8"), str(path.relative_to(root)))
    ]
    assert found == [], "read a run through RunEngine.view(), not engine.sim"


def test_the_sim_check_catches_a_read() -> None:
    assert engine_sim_reads("tick = engine.sim.tick_count", "probe.py") != []
    assert engine_sim_reads("import core.sim.world\nview = engine.view()", "probe.py") == []
