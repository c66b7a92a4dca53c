"""Shared fixtures: the shipped catalogue and its compiled logical sensors."""

from __future__ import annotations

import pytest

from core.brain.catalog import Catalog, load_catalog
from core.brain.sensors import StimulusDetector, compile_detector


@pytest.fixture(scope="session")
def catalog() -> Catalog:
    """srlab's own catalogue (immutable, so one per session)."""
    return load_catalog()


@pytest.fixture(scope="session")
def detector(catalog: Catalog) -> StimulusDetector:
    """Every logical sensor of the catalogue compiled into one function."""
    return compile_detector(catalog)
