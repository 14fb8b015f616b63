"""Errors that reach the user as one clear line instead of a traceback.

Every package raises `InputError` (or a subclass) for bad input: a malformed file, a NaN
where a number belongs, an impossible configuration. The message names the problem: the
file, the field or column, and the offending value. The `canalnav` entry point prints it
and exits with status 2.
"""

from __future__ import annotations


class CanalnavError(Exception):
    """Base of every error canalnav raises on purpose."""


class InputError(CanalnavError, ValueError):
    """Bad input from a user: a file, a field, a value. The message says which."""


class SolverError(CanalnavError, RuntimeError):
    """An optimiser failed in a way its caller must act on (e.g. stop the boat)."""


def finite_number(value, what: str) -> float:
    """`value` as a finite float, or an InputError naming `what` and the value."""
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{what}: expected a number, got {value!r}") from None
    if x != x or x in (float("inf"), float("-inf")):
        raise InputError(f"{what}: must be finite, got {value!r}")
    return x


def where(file: object = None, line: int | None = None, column: str | int | None = None) -> str:
    """Format a location prefix like ``runs/a.csv:12: column 'u':`` for error messages."""
    parts = []
    if file is not None:
        loc = str(file)
        if line is not None:
            loc += f":{line}"
        parts.append(loc)
    elif line is not None:
        parts.append(f"line {line}")
    if column is not None:
        parts.append(f"column {column!r}")
    return ": ".join(parts) + (": " if parts else "")
