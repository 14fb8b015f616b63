"""The READMEs beside the code: every relative link names a file of the checkout and, with
`#anchor`, a heading of that file (GitHub's anchors); every `Usage:` line and every command
line shown names a `canalnav` command and only options its `--help` lists, and each command's
Usage lines name all of them; every option in prose exists; every scenario (and study)
example in a ```toml block loads."""

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


OPTION = re.compile(r"(?<![\w-])(--[a-zA-Z][\w-]*)")
# options of other programs the READMEs show: pip, fmpy, ArduPilot's sim_vehicle.py and waf, dask,
# OMSimulator (an option of ours by one of these names would be checked as ours)
OTHER_TOOLS = {"--no-deps", "--target", "--output-file", "--output-variables", "--show-plot",
               "--output-interval", "--start-values", "--stop-time", "--model",
               "--custom-location", "--add-param-file", "--sim-port-out", "--nthreads",
               "--stopTime", "--board"}


def _commands(parser, words=()):
    """Every `canalnav WORDS...` that runs something (no subcommands of its own)."""
    subs = [a for a in parser._actions if a.__class__.__name__ == "_SubParsersAction"]
    if not subs and words:
        yield words, parser
    for sub in subs:
        for name, child in sub.choices.items():
            yield from _commands(child, (*words, name))


def _command_words(root, line: str) -> list[str]:
    words = []
    for word in line.split()[1:]:
        try:
            _parser_of(root, words + [word])
        except (KeyError, StopIteration):
            break
        words.append(word)
    return words


def _command_lines(readme: Path) -> list[str]:
    """`canalnav ...` as the README shows it: code spans, and lines of sh blocks."""
    text = readme.read_text()
    lines = re.findall(r"`(?:\.venv/bin/)?(canalnav [^`]*)`", text)
    for block in re.findall(r"```(?:sh|bash)\n(.*?)```", text, re.S):
        for line in block.splitlines():
            m = re.search(r"(?:\.venv/bin/)?(canalnav .*)", line)
            if m:
                lines.append(re.split(r" #|&&|;", m.group(1))[0])
    return lines


def test_every_command_line_in_a_readme_uses_options_its_command_has():
    """Issue 35: every `canalnav COMMAND ... --option` the READMEs show (in code spans and
    shell blocks, not only Usage lines) names an option of that command's --help."""
    from bridge.main import build_parser

    root, bad, seen = build_parser(), [], 0
    for readme in _readmes():
        for line in _command_lines(readme):
            words = _command_words(root, line)
            if not words:
                continue  # `canalnav COMMAND --help` in prose, a command named loosely
            text = _parser_of(root, words).format_help()
            for option in OPTION.findall(line):
                seen += 1
                if option not in text:
                    bad.append(f"{readme.relative_to(ROOT)}: `{line}`: canalnav "
                               f"{' '.join(words)} has no {option}")
    assert seen >= 150 and not bad, (seen, bad)


def test_every_option_a_readme_names_is_one_of_ours_or_a_named_tools():
    """An option in prose (`--resume`, `--origin=`) is an option of some canalnav command
    (a renamed or dropped option fails here) or of another program the README shows."""
    from bridge.main import build_parser

    ours = {o for _, p in _commands(build_parser()) for a in p._actions
            for o in a.option_strings}
    bad = []
    for readme in _readmes():
        text = readme.read_text()
        bad += [f"{readme.relative_to(ROOT)}: {o}" for o in sorted(set(OPTION.findall(text)))
                if o not in ours and o not in OTHER_TOOLS]
    assert not bad, bad


def test_every_command_has_usage_lines_naming_each_of_its_options():
    """Issue 35: "many options in --help are missing from the README's command lines". Each
    command that runs something has a `Usage:` line, and its Usage lines together name every
    option of its --help (the long form, or its short one)."""
    from bridge.main import build_parser

    root = build_parser()
    usages: dict[tuple, list[str]] = {}
    for readme in _readmes():
        for usage in re.findall(r"^Usage: `(canalnav [^`]*)`", readme.read_text(), re.M):
            usages.setdefault(tuple(_command_words(root, usage)), []).append(usage)
    bad = []
    for words, parser in _commands(root):
        name = f"canalnav {' '.join(words)}"
        lines = usages.get(words)
        if not lines:
            bad.append(f"{name}: no Usage line")
            continue
        shown = set(re.findall(r"(?<![\w-])(--?[a-zA-Z][\w-]*)", " ".join(lines)))
        for action in parser._actions:
            if action.option_strings and "-h" not in action.option_strings \
                    and not shown & set(action.option_strings):
                bad.append(f"{name}: {'/'.join(action.option_strings)} in --help, not in Usage")
    assert not bad, bad
