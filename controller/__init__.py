"""Everything that runs on the boat: model, parameters, identification, detection, NMPC.

Imports no other canalnav package (DESIGN.md, package boundaries).
"""
