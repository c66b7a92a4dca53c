"""The placement probe's results, cached on disk per world, sensor definition and settings.

A probe takes seconds and depends only on the world, the stimuli's rules and the
behaviours (`core.lab.probe.fingerprint`), so its result is kept in ``SRLAB_CACHE_DIR``
(default ``~/.cache/srlab``) under ``probe/<world>-<sensors>-<fingerprint>.json`` and
reused until any of them changes. A cache that cannot be read or written is ignored.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from core.lab.probe import ProbeResult, fingerprint, probe
from core.run.setup import Setup


def cache_dir() -> Path:
    """Where cached results go."""
    root = os.environ.get("SRLAB_CACHE_DIR") or os.path.join(Path.home(), ".cache", "srlab")
    return Path(root) / "probe"


def cached_probe(setup: Setup, k: int = 20, seed: int = 0) -> tuple[ProbeResult, bool]:
    """The probe of `setup`, from the cache when it is there; (result, whether cached)."""
    setup = setup.resolved()
    key = fingerprint(setup, k, seed)
    path = cache_dir() / f"{setup.world_name}-{setup.sensors_name}-{key}.json"
    try:
        return ProbeResult.from_dict(json.loads(path.read_text())), True
    except (OSError, ValueError, KeyError, TypeError, AssertionError):
        pass
    result = probe(setup, k, seed)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp")
        tmp.write_text(json.dumps(result.as_dict(), indent=1) + "\n")
        tmp.replace(path)
    except OSError:
        pass  # a read-only home: the result is still good, only not kept
    return result, False
