"""The simulated LiDAR behind `--lidar sim`: the scenario's canal seen at the reported pose."""

from __future__ import annotations

import numpy as np


class SimLidarSource:
    """The scenario's canal seen by the simulated LiDAR (scenarios.sensors.lidar) at the given
    pose and time: obstacles removed by then are gone, the scenario's vessels are where they
    are on the run's clock (seconds since the bridge took control).

    On the bridge that pose is the autopilot's EKF estimate (the bridge knows no other), so
    the simulated walls sit where the boat believes it is: navigation errors do not shift the
    detected segments as they would on a real boat. A plant that knows the true pose can wrap
    its own source.
    """

    name = "sim"

    def __init__(self, scenario, seed: int | None = None):
        from scenarios.sensors.lidar import LidarSimulator

        seed = scenario.seed if seed is None else int(seed)
        self.simulator = LidarSimulator(scenario.world, seed=seed * 7919 + 3)

    @property
    def viewpoints(self) -> tuple:
        """(x_m, y_m, height_m) of each simulated unit in the body frame (see `MergedLidar`)."""
        return tuple((m.x_m, m.y_m, m.height_m) for m in self.simulator.config.mounts)

    def scan(self, time_s: float, pose) -> np.ndarray:
        p = np.asarray(pose, float).reshape(-1)
        speed = float(p[3]) if len(p) > 3 else 0.0
        t = float(time_s)
        return self.simulator.scan(p[:3], speed_mps=speed, time_s=t,
                                   extra_obstacles=self.simulator.world.vessel_obstacles(t))
