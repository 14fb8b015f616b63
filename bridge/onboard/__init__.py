"""What runs on the boat beside a real ArduPilot Rover: the link, the onboard loop, sessions.

`link` (the MAVLink connection and protocol), `boot_clock` (the autopilot's time since boot
on our clock), `ekf_state` (the EKF's messages as our state), `preflight` (would the
autopilot obey our overrides?), `loop` (`canalnav bridge`: start-up and the NMPC at 10 Hz),
`step_log` (its CSV logs and status line), `maneuvers` (`canalnav maneuvers --connect`).
Imports only `shared/` and `lidar/` of `bridge`: never a simulator.
"""
