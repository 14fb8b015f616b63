"""The closed loop on simulation time, its controllers, its log, and running a scenario."""
