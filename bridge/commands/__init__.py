"""`canalnav` subcommands owned by `bridge`, one module each.

A module here defines `register(subparsers)` to add its subcommand and/or
`register_bench(bench_subparsers)` to add a `canalnav bench` target; each parser sets
`func=handler`, a function of the parsed arguments returning the exit status. Heavy
imports (casadi, cv2, fmpy) go inside the handlers so that `canalnav --help` stays fast.
"""
