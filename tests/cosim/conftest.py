"""The short-bend scenario's navigation FMUs and system, built once per session."""

from dataclasses import replace
from pathlib import Path

import pytest

from scenarios.scenario_file import parse_scenario


@pytest.fixture(scope="session")
def short_bend_file(tmp_path_factory, short_bend_toml) -> Path:
    path = tmp_path_factory.mktemp("scenario") / "short_bend.toml"
    path.write_text(short_bend_toml)
    return path


@pytest.fixture(scope="session")
def short_bend(short_bend_file):
    return parse_scenario(short_bend_file.read_text(), str(short_bend_file), short_bend_file)


@pytest.fixture(scope="session")
def nav_fmus(tmp_path_factory, short_bend_file) -> dict:
    from scenarios.cosim.build import build_navigation_fmu

    folder = tmp_path_factory.mktemp("nav")
    return {v: build_navigation_fmu(short_bend_file, folder / f"nav{v}.fmu", v) for v in (2, 3)}


@pytest.fixture(scope="session")
def system_dir(tmp_path_factory, short_bend_file) -> Path:
    from scenarios.cosim.system import write_system

    folder = tmp_path_factory.mktemp("system")
    write_system(short_bend_file, folder)
    return folder


def shortened(scenario, duration_s: float):
    return replace(scenario, duration_s=duration_s)
