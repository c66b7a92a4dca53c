"""Imported first by the baseline tests: skips their module without the baselines extra."""

from __future__ import annotations

import pytest

from core.learners.baselines import INSTALL_HINT

try:
    import stable_baselines3  # noqa: F401
    import torch  # noqa: F401
except ImportError as e:
    pytest.skip(
        f"{e.name} is not installed: `{INSTALL_HINT}` installs the srlab[baselines] extra "
        "(stable-baselines3 on a CPU-only torch); `make test-baselines` runs these tests",
        allow_module_level=True,
    )
