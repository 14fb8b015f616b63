"""The boat FMU as the physics of ArduPilot's own SITL (`canalnav sitl-physics`).

`json_physics` (SITL's JSON interface: servo packets in, the boat's state out),
`sitl_boat.parm` (the ArduRover parameters for the boat), README.md (how to run it).
Imports `shared/`, and `onboard/` only for the bridge command line it prints.
"""
