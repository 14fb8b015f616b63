"""Shared test settings: every test runs offline and seeded."""

import os

import pytest

from scenarios.sensors.perception_pipeline import WORKER_ENV

# Under pytest-xdist every core already runs a test: a LiDAR run's perception worker would
# only add processes (a third more CPU for the same runs); the tests of the worker itself
# ask for it by name.
if os.environ.get("PYTEST_XDIST_WORKER"):
    os.environ.setdefault(WORKER_ENV, "0")

# A short canal with one 30 m radius bend, known walls, d_p = 2 m: long enough to see each
# controller steer, short enough for the default tests (compare, MAVLink end to end).
SHORT_BEND = """
[scenario]
name = "short-bend"
duration_s = 110
seed = 3

[canal]
centre_line = [[0, 0], [60, 0], [110, 30], [140, 30]]
corner_radius_m = 30
width_m = 16

[route]
spacing_m = 15

[sensors]
perception = "known-walls"

[controller]
d_p_m = 2.0
"""


@pytest.fixture(scope="session")
def short_bend_toml() -> str:
    return SHORT_BEND
