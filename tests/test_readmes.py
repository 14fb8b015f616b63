"""The READMEs beside the code: every relative link names a file of the checkout and, with
`#anchor`, a heading of that file (GitHub's anchors); every `Usage:` line names a `canalnav`
command and only options its `--help` lists."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LINK = re.compile(r"\]\(([^)\s]+)\)")


def _readmes() -> list[Path]:
    return sorted(p for p in ROOT.rglob("README.md")
                  if not any(part.startswith(".") for part in p.relative_to(ROOT).parts))


def _anchors(path: Path) -> set[str]:
    """GitHub's anchor of each heading: lower case, punctuation but '-' and '_' dropped,
    spaces as '-'."""
    text = re.sub(r"```.*?```", "", path.read_text(), flags=re.S)
    heads = re.findall(r"^#{1,6} (.+)$", text, re.M)
    return {re.sub(r"[^\w\- ]", "", h.strip().lower()).replace(" ", "-") for h in heads}


def test_the_package_readmes_are_there():
    names = {str(p.relative_to(ROOT)) for p in _readmes()}
    assert {"README.md", "controller/README.md", "fmu/README.md", "scenarios/README.md",
            "scenarios/cosim/README.md", "bridge/README.md", "bridge/sitl/README.md"} <= names


def test_every_relative_link_in_a_readme_resolves():
    bad = []
    for readme in _readmes():
        for target in LINK.findall(readme.read_text()):
            if re.match(r"[a-z]+:", target):
                continue  # https:, mailto:
            path, _, anchor = target.partition("#")
            dest = (readme.parent / path).resolve() if path else readme
            where = f"{readme.relative_to(ROOT)}: {target}"
            if not dest.exists():
                bad.append(f"{where}: no such file")
            elif anchor and (dest.suffix != ".md" or anchor not in _anchors(dest)):
                bad.append(f"{where}: no such heading")
    assert not bad, bad


def _parser_of(parser, words):
    """The sub-parser of `canalnav WORDS...`; KeyError when a word is no subcommand."""
    for word in words:
        sub = next(a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction")
        parser = sub.choices[word]
    return parser


def test_every_usage_line_names_a_command_and_options_it_has():
    from bridge.main import build_parser

    root, bad, seen = build_parser(), [], 0
    for readme in _readmes():
        for usage in re.findall(r"^Usage: `(canalnav [^`]*)`", readme.read_text(), re.M):
            seen += 1
            words = []
            for word in usage.split()[1:]:
                try:
                    _parser_of(root, words + [word])
                except (KeyError, StopIteration):
                    break
                words.append(word)
            if not words:
                bad.append(f"{readme.relative_to(ROOT)}: {usage}: no such command")
                continue
            text = _parser_of(root, words).format_help()
            bad += [f"{readme.relative_to(ROOT)}: canalnav {' '.join(words)} has no {option}"
                    for option in re.findall(r"(?<![\w-])(--?[a-zA-Z][\w-]*)", usage)
                    if option not in text]
    assert seen >= 15 and not bad, (seen, bad)


def _toml_blocks(readme: Path) -> list[str]:
    return re.findall(r"^```toml\n(.*?)^```", readme.read_text(), re.S | re.M)


def test_every_scenario_example_in_a_readme_loads(tmp_path):
    """Every ```toml block of the READMEs: a whole scenario file loads as it is
    (load_scenario); a block of alternatives ("replaces the tables of the same name above") is
    completed with the README's last whole example's [scenario], and its [canal] and [route]
    where the block gives none; a study file loads as one in scenarios/studies/ (its paths
    are relative to it). A [lidar] table is checked as the bridge reads it."""
    import tomllib

    from bridge.lidar.config import parse_lidar_table
    from scenarios.scenario_file import load_scenario, scenario_from_table
    from scenarios.studies.sweep_spec import parse_study

    seen = 0
    for readme in _readmes():
        example = None
        for i, block in enumerate(_toml_blocks(readme), 1):
            where = f"{readme.relative_to(ROOT)}, toml block {i}"
            data = tomllib.loads(block)
            if "study" in data:
                study = parse_study(block, ROOT / "scenarios" / "studies" / "readme_example.toml")
                assert study.runs, where
            elif {"scenario", "canal", "route"} <= data.keys():
                path = tmp_path / f"block{i}.toml"
                path.write_text(block)
                scenario = load_scenario(path)
                example = data
            else:
                assert example is not None, f"{where}: alternatives before a whole example"
                full = {"scenario": example["scenario"]}
                full.update({k: example[k] for k in ("canal", "route") if k not in data})
                full.update(data)
                scenario = scenario_from_table(full, where)
            if "study" not in data and scenario.lidar_table is not None:
                parse_lidar_table(scenario.lidar_table, where, "lidar.", tmp_path)
            seen += 1
    assert seen >= 5, seen
