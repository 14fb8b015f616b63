"""MAVLink: the link to an ArduRover-style autopilot, a simulated autopilot, SITL physics.

Nothing imports `bridge` except the command-line entry point (`bridge.main`).
"""
