"""Changing a scenario key by its dotted path (`current.east_mps`, `plant.boat.Nr`,
`obstacle[1].remove_at_s`) before the scenario is checked, for studies and `canalnav run --set`.

An override is applied to the parsed TOML document, so every check of the scenario file
applies to the new value exactly as if it had been written there; a path that names no key
of the schema is caught by the same check that catches a typo in a file. Errors say which
override was at fault, naming where it was given (a study file's field, a command-line option).
"""

from __future__ import annotations

import copy
import re
import tomllib
from pathlib import Path

from controller.errors import InputError

_PART = re.compile(r"([A-Za-z_][A-Za-z0-9_-]*)((?:\[\d+\])*)$")


def parse_path(path: str) -> tuple:
    """('current', 'east_mps') from 'current.east_mps'; an index for an array of tables:
    'obstacle[1].z_top_m' -> ('obstacle', 1, 'z_top_m'). ValueError when malformed."""
    if not isinstance(path, str) or not path:
        raise ValueError("an override path is a dotted scenario key such as current.east_mps")
    out: list = []
    for part in path.split("."):
        m = _PART.match(part)
        if m is None:
            raise ValueError(f"{path!r} is not a dotted scenario key (such as current.east_mps "
                             "or obstacle[0].z_top_m)")
        out.append(m.group(1))
        out.extend(int(i) for i in re.findall(r"\[(\d+)\]", m.group(2)))
    return tuple(out)


def format_path(parts: tuple) -> str:
    """The inverse of `parse_path`, in the scenario file's own naming of fields."""
    text = ""
    for p in parts:
        text += f"[{p}]" if isinstance(p, int) else (f".{p}" if text else p)
    return text


def apply_overrides(document: dict, overrides) -> dict:
    """A deep copy of a parsed scenario document with each (path, value) set; tables on the
    way that the file does not have are created (the schema decides whether the key exists).
    ValueError naming the path when it runs into a value that is not a table or past the end
    of an array of tables."""
    doc = copy.deepcopy(document)
    for path, value in overrides:
        parts = parse_path(path)
        node = doc
        for depth, key in enumerate(parts[:-1]):
            here = format_path(parts[:depth + 1])
            nxt = parts[depth + 1]
            if isinstance(key, int):
                if not isinstance(node, list) or key >= len(node):
                    size = len(node) if isinstance(node, list) else 0
                    raise ValueError(f"{here}: the scenario has {size} of these tables")
                node = node[key]
            else:
                if not isinstance(node, dict):
                    raise ValueError(f"{format_path(parts[:depth])} is a value, not a table")
                if key not in node:
                    if isinstance(nxt, int):
                        raise ValueError(f"{here}: the scenario has no [[{here}]] tables")
                    node[key] = {}
                node = node[key]
            if isinstance(nxt, int) and not isinstance(node, list):
                raise ValueError(f"{here} is not an array of tables ([[{here}]])")
            if not isinstance(nxt, int) and not isinstance(node, dict):
                raise ValueError(f"{here} is a value, not a table")
        last = parts[-1]
        if isinstance(last, int):
            if last >= len(node):
                raise ValueError(f"{format_path(parts)}: the scenario has {len(node)} of these "
                                 "tables")
        node[last] = copy.deepcopy(value)
    return doc


def _is_unknown_key(message: str, parts: tuple) -> bool:
    """Whether a scenario error says that the override's key is not in the schema."""
    name = format_path(parts)
    last = parts[-1] if isinstance(parts[-1], str) else ""
    return ((f"'{name}'" in message and ("unknown" in message or "belongs to" in message))
            or (f"unknown boat parameter {last!r}" in message))


def scenario_with_overrides(text: str, source: str, overrides, files: dict | None = None,
                            given_at=None, path: Path | None = None):
    """The scenario of `text` with the (path, value) overrides applied. `given_at(path)`
    names where an override came from (e.g. "study.toml: field 'overrides.current.east_mps'");
    a bad override is an InputError starting there, then the scenario's own complaint."""
    from scenarios.scenario_file import parse_toml, scenario_from_table

    given_at = given_at or (lambda p: f"override {p}")
    overrides = tuple(overrides)
    document = parse_toml(text, source)
    if not overrides:
        return scenario_from_table(document, source, path, files)
    try:
        changed = apply_overrides(document, overrides)
    except ValueError as exc:
        bad = _culprit(document, overrides)
        raise InputError(f"{given_at(bad)}: names no scenario key ({source}: {exc})") from None
    try:
        return scenario_from_table(changed, source, path, files)
    except InputError as exc:
        blame = _blame(document, overrides, source, path, files, str(exc))
        if blame is None:  # only the combination fails (or the file itself)
            values = ", ".join(f"{p} = {v!r}" for p, v in overrides)
            raise InputError(f"{source} with {values}: {exc}") from None
        p, v, msg = blame
        if _is_unknown_key(msg, parse_path(p)):
            raise InputError(f"{given_at(p)}: names no scenario key ({msg})") from None
        raise InputError(f"{given_at(p)}: value {v!r}: {msg}") from None


def _culprit(document: dict, overrides) -> str:
    """The first override whose path cannot be placed in the document."""
    for p, v in overrides:
        try:
            apply_overrides(document, [(p, v)])
        except ValueError:
            return p
    return overrides[0][0]


def _blame(document, overrides, source, path, files, message):
    """(path, value, error) of the override the error is about: one it names, else the
    first that fails on its own; None when each is fine alone."""
    from scenarios.scenario_file import scenario_from_table

    for p, v in overrides:
        parts = parse_path(p)
        if f"'{format_path(parts)}'" in message or _is_unknown_key(message, parts):
            return p, v, message
    for p, v in overrides:
        try:
            scenario_from_table(apply_overrides(document, [(p, v)]), source, path, files)
        except InputError as exc:
            return p, v, str(exc)
    return None


def parse_value(text: str):
    """A command-line value as TOML would read it (0.2, 4, true, [1, 2], "text"); anything
    that is not a TOML value is taken as a string (so `--set controller.type=los-pid`)."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def parse_assignment(text: str) -> tuple[str, object]:
    """'current.east_mps=0.2' -> ('current.east_mps', 0.2); ValueError when malformed."""
    path, sep, value = text.partition("=")
    path = path.strip()
    if not sep or not value.strip():
        raise ValueError(f"expected PATH=VALUE (such as current.east_mps=0.2), got {text!r}")
    parse_path(path)
    return path, parse_value(value.strip())


def toml_value(value) -> str:
    """A value as a TOML literal (for a command that reproduces a run)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(value)
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{" + ", ".join(f"{k} = {toml_value(v)}" for k, v in value.items()) + "}"
    raise TypeError(f"no TOML literal for {value!r}")
