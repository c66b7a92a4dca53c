"""Imported first by the outside worlds' environment tests: skips them without the extra."""

from __future__ import annotations

import pytest

from core.outside.world import INSTALL_HINT

try:
    import irsim  # noqa: F401
    import minigrid  # noqa: F401
except ImportError as e:
    pytest.skip(
        f"{e.name} is not installed: `{INSTALL_HINT}` installs the srlab[worlds] extra "
        "(MiniGrid, ir-sim); `make test-worlds` runs these tests",
        allow_module_level=True,
    )
