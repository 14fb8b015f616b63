"""Where the controller's segments come from: known walls, or the simulated LiDAR + detection."""

from __future__ import annotations

import numpy as np

from scenarios.world import CanalWorld


class KnownWalls:
    """The paper's simulation assumption: the true walls within `range_m` are known exactly."""

    name = "known-walls"

    def __init__(self, world: CanalWorld, range_m: float = 50.0):
        self.world = world
        self.range_m = range_m

    def segments(self, time_s, true_state, estimated_state) -> np.ndarray:
        return self.world.segments_near(np.asarray(true_state)[:2], self.range_m)
