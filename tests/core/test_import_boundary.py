"""The core stays pure: no adapters, no wall clock, no global random state."""

from __future__ import annotations

import ast
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
ENGINE = CORE / "engine.py"


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
    assert violations(path.read_text(encoding="utf-8"), label, is_engine=path == ENGINE) == []


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
