"""MAVLink: the link to an ArduPilot Rover autopilot, two simulated autopilots, the command line.

Rooms: `onboard/` (what runs on the boat beside a real autopilot), `shared/` (what both ends
of the link agree on), `autopilot_sim/` (a simulated ArduPilot Rover), `sitl/` (the boat as
ArduPilot SITL's physics), `lidar/` (LiDAR sources), `commands/` and `main.py` (the `canalnav`
command line). Nothing outside `bridge` imports it; see bridge/README.md.
"""
