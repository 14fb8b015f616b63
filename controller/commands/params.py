"""`canalnav params`: print or write the identified parameter set as TOML."""

from __future__ import annotations


def register(sub) -> None:
    p = sub.add_parser(
        "params", help="print or write the boat's identified parameters (TOML)",
        description="The paper's identified parameter set, with units, as a TOML file that "
        "`--params` options and scenario files accept. With --from, checks and normalises a file.",
    )
    p.add_argument("-o", "--out", help="write to this file instead of standard output")
    p.add_argument("--from", dest="source", help="read this parameter file instead of the defaults")
    p.set_defaults(func=run)


def run(args) -> int:
    from controller.params import IDENTIFIED, BoatParams

    params = BoatParams.from_toml(args.source) if args.source else IDENTIFIED
    text = params.to_toml(
        header="canalnav boat parameters (paper's names; SI units, delta_max in degrees)"
    )
    if args.out:
        with open(args.out, "w") as fh:
            fh.write(text)
    else:
        print(text, end="")
    return 0
