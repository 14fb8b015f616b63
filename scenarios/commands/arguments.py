"""Option types the subcommands share: argparse `type=` functions that turn a bad value into
argparse's one-line usage error (naming the option) instead of a traceback."""

from __future__ import annotations

import argparse


def whole_number(minimum: int = 0):
    """The type of an option that takes a whole number >= `minimum` (a seed, a count)."""

    def parse(text: str) -> int:
        try:
            n = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected a whole number >= {minimum}, got {text!r}") from None
        if n < minimum:
            raise argparse.ArgumentTypeError(f"must be >= {minimum}, got {n}")
        return n

    parse.__name__ = f"whole number >= {minimum}"  # (argparse names the type in some errors)
    return parse


seed_number = whole_number(0)  # numpy's generators take no negative seeds


def assignment(text: str):
    """The type of `--set`: PATH=VALUE, the value read as TOML (a bare word is a string)."""
    from scenarios.studies.overrides import parse_assignment

    try:
        return parse_assignment(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def case_numbers(text: str) -> tuple[int, ...]:
    """The type of an option that takes case numbers: "3,69,129", ranges "0-49", or both
    ("0-9,48"); ascending, each once."""
    numbers = set()
    for part in text.split(","):
        lo, dash, hi = part.strip().partition("-")
        try:
            a = int(lo)
            b = int(hi) if dash else a
        except ValueError:
            raise argparse.ArgumentTypeError(
                f"expected case numbers like 3,69,129 or 0-49, got {text!r}") from None
        if a < 0 or b < a:
            raise argparse.ArgumentTypeError(
                f"case numbers are whole numbers >= 0, a range low-high, got {part.strip()!r}")
        numbers.update(range(a, b + 1))
    return tuple(sorted(numbers))
