"""The `canalnav` console script: one subcommand per job, each owned by its package.

Subcommands are discovered in `<package>.commands.*` (see `controller/commands/__init__.py`).
This module lives in `bridge` because `bridge` is the one package allowed to import all others.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import re
import sys

from controller.errors import CanalnavError

PACKAGES = ("controller", "fmu", "scenarios", "bridge")


def _command_modules():
    for package in PACKAGES:
        commands = importlib.import_module(f"{package}.commands")
        for info in sorted(pkgutil.iter_modules(commands.__path__), key=lambda m: m.name):
            yield importlib.import_module(f"{package}.commands.{info.name}")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="canalnav",
        description="Autonomous navigation of a boat in a narrow canal: boat model and "
        "identification, FMUs, LiDAR detection, NMPC, scenarios and a MAVLink bridge.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    bench = sub.add_parser(
        "bench", help="measure speed; prints JSON",
        description="Benchmarks. Each target prints one JSON object on standard output.",
    )
    bench_sub = bench.add_subparsers(dest="target", metavar="TARGET", required=True)
    for module in _command_modules():
        if hasattr(module, "register"):
            module.register(sub)
        if hasattr(module, "register_bench"):
            module.register_bench(bench_sub)
    return parser


_NUMBERS = re.compile(r"^-\d*\.?\d+(,-?\d*\.?\d+)+$")


def _join_negative_values(argv: list[str]) -> list[str]:
    """`--origin -35.3,149.1` as `--origin=-35.3,149.1`: argparse takes a value that starts
    with '-' and holds a comma for an option, and says only "expected one argument"."""
    out = []
    for token in argv:
        if out and out[-1].startswith("--") and "=" not in out[-1] and _NUMBERS.match(token):
            out[-1] = f"{out[-1]}={token}"
        else:
            out.append(token)
    return out


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    given = list(sys.argv[1:] if argv is None else argv)
    args = parser.parse_args(_join_negative_values(given))
    args.argv = given  # the command line as typed (summary.json records it)
    try:
        return int(args.func(args) or 0)
    except CanalnavError as exc:
        print(f"canalnav {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"canalnav {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
