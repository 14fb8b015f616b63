"""Canal scenarios: the world, simulated sensors, the closed loop, metrics and plots."""
