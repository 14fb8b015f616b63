"""The boat model as FMI 2.0 and 3.0 co-simulation FMUs, generated from `controller.model`."""
