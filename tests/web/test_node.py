"""The web client's own tests (`web/test/*.test.js`) under node's test runner.

They load the DOM-free modules (the editor's sync queue) and read the others as text, so
they need node and nothing from npm: `node --test web/test/` runs them alone.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
NODE = shutil.which("node")


def test_the_web_clients_node_tests_pass() -> None:
    if NODE is None:
        message = "node is missing: 'apt-get install -y nodejs' (18 or later) runs web/test/"
        if os.environ.get("SRLAB_REQUIRE_NODE") == "1":
            pytest.fail(message)
        pytest.skip(message)
    files = sorted(str(p.relative_to(ROOT)) for p in (ROOT / "web" / "test").glob("*.test.js"))
    assert files, "web/test/ has node tests"
    done = subprocess.run(
        [NODE, "--test", *files], cwd=ROOT, capture_output=True, text=True, timeout=300
    )
    report = done.stdout + done.stderr
    assert done.returncode == 0, report
    passed = re.search(r"^# pass (\d+)$", report, re.M)
    assert passed and int(passed[1]) > 0, report
