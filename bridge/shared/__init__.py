"""What both ends of the MAVLink link agree on: the boat side and the simulated autopilots.

`ardupilot` (ArduPilot Rover's modes, RC conventions, parameter names, SITL's home),
`signing` (MAVLink 2 signing keys from a file), `clock` (the real and the virtual clock
everything in `bridge` reads time through), `boat_physics` (the boat FMU as an autopilot's
physics). Imports no other room of `bridge`.
"""
