"""The cosim extra (pythonfmu, pythonfmu3, libcosimpy): present, or one error naming it."""

from __future__ import annotations

import importlib

from controller.errors import InputError

COSIM_EXTRA = "pip install 'canalnav[cosim]'"


def require(module: str, what: str):
    """The module, or an InputError saying that `what` needs the cosim extra."""
    try:
        return importlib.import_module(module)
    except ImportError:
        raise InputError(f"{what} needs {module.split('.')[0]}, in the cosim extra: "
                         f"{COSIM_EXTRA}") from None
