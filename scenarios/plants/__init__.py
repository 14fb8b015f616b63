"""The closed loop's plant interface and its homes: the Python model, the boat FMU."""
