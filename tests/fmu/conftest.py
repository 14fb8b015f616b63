"""Both FMUs built once per session, from scratch (gcc only, no cache) in a temporary folder."""

import pytest

from fmu.build import build_fmu


@pytest.fixture(scope="session")
def fmus(tmp_path_factory):
    folder = tmp_path_factory.mktemp("fmus")
    return {v: build_fmu(folder / f"boat{v}.fmu", v, use_cache=False) for v in (2, 3)}


@pytest.fixture(params=[2, 3], ids=["fmi2", "fmi3"])
def fmu_path(request, fmus):
    return fmus[request.param]
