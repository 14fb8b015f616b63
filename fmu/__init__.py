"""The boat model as FMI 2.0 and 3.0 co-simulation FMUs, generated from `controller.model`.

- `variables`: the variable table, written once (names, value references, units, start values).
- `codegen`: CasADi C of `controller.model.plant_step_function()` and the C view of the table.
- `model_description`: both modelDescription.xml files and FMI 3.0's buildDescription.xml.
- `c/`: the hand-written C: `model.c` (the boat behind one small interface), one wrapper per
  FMI version.
- `build`: gcc, the .fmu archive (binary + sources), the build cache.
- `plant`: `FmuBoat`, the FMU stepped from Python with little overhead.
- `check`, `verify`: fmpy validation and lifecycle checks; comparison with scipy solve_ivp.
"""
