"""A simulated ArduPilot Rover (boat frame) speaking MAVLink, for tests and `canalnav run`.

`rover` (`AutopilotSim`: the firmware's behaviour over MAVLink), `ekf` (its noisy
navigation estimate), `params` (its parameter table), `rc` (RC input and overrides),
`streams` (message rates), `log` and `dataflash` (its onboard .BIN log), `lossy_relay` (a
faulty UDP link for fault tests), `plant` (`--plant mavlink-sim`: the boat side and this
autopilot in one lock-step loop, the one module here that imports `onboard/`).
"""
