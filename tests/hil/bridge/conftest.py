"""Fixtures of the bridge tests (the plant is a test double, see bridge_plant_double.py)."""

from __future__ import annotations

import pytest
from bridge_plant_double import FirstOrderPlantDouble

from hil.bench.benches.bridge import LockstepBridge


@pytest.fixture
def plant() -> FirstOrderPlantDouble:
    return FirstOrderPlantDouble()


@pytest.fixture
def bench(plant: FirstOrderPlantDouble) -> LockstepBridge:
    b = LockstepBridge(plant)
    plant.now = b.clock.now
    return b
