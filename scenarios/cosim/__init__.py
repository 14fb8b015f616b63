"""The navigation stack in someone else's co-simulation: the navigation as an FMU (FMI 2.0 and
3.0, pythonfmu), the system of it and the boat FMU (OSP and SSP), and its run through libcosim
(`canalnav fmu build-controller`, `fmu system`, `cosim`; see README.md here)."""
