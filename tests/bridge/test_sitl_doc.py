"""bridge/sitl/README.md: its commands are the ones `canalnav sitl-physics` prints for its scenario."""

from __future__ import annotations

import re
from pathlib import Path

from bridge.main import build_parser, main

ROOT = Path(__file__).resolve().parents[2]


def _commands() -> list[str]:
    """The shell commands of bridge/sitl/README.md's first code block, continuation lines joined."""
    text = (ROOT / "bridge" / "sitl" / "README.md").read_text()
    block = re.search(r"```sh\n(.*?)```", text, re.S).group(1)
    joined = re.sub(r"\\\n\s*", "", block)
    return [line.strip() for line in joined.splitlines() if line.strip() and not line.startswith("#")]


def test_the_commands_in_the_sitl_readme_are_what_sitl_physics_prints(capsys, monkeypatch):
    physics, sitl, bridge = _commands()
    assert physics.startswith("canalnav sitl-physics ") and sitl.startswith("sim_vehicle.py ")
    assert " -N " in sitl  # no rebuild: it would need the network (issue 37, 5)
    assert bridge.startswith("canalnav bridge ")
    monkeypatch.chdir(ROOT)  # the paths in the commands are relative to the checkout
    args = physics.split()[1:] + ["--port", "0", "--duration", "0.1"]
    assert main(args) == 0
    printed, then = capsys.readouterr().out.strip().splitlines()
    printed_sitl = printed.split("start SITL with: ", 1)[1]
    parm = str(ROOT / "bridge" / "sitl" / "sitl_boat.parm")
    assert sitl.replace("/path/to/canalnav/bridge/sitl/sitl_boat.parm", parm) == re.sub(
        r' (-A "--sim-port-out=\d+"|-I \d+)', "", printed_sitl)  # the doc uses the default
    # port; --port 0 takes a free one, printed as an instance (-I N) when it is 9002 + 10 N
    assert then == f"then drive it with: {bridge}"
    ns = build_parser().parse_args(bridge.split()[1:])  # and the bridge's options parse
    assert ns.origin == "-35.363261,149.16523,584" and ns.mode == "MANUAL" and ns.arm
