"""Shared test helpers."""

from __future__ import annotations

import pytest
import yaml
from sizes import tiny_scenario_data


def _tiny_scenario(tmp_path, name="tiny", base="paper_2012"):
    """A shipped scenario file shrunk to the tiny sizes of ``sizes.py`` (written to ``tmp_path``)."""
    from fuelhm_bench.scenarios import shipped_scenario_files

    files = shipped_scenario_files()
    src = files[base] if isinstance(files, dict) else next(p for p in files if f"{base}.yaml" in str(p))
    data = tiny_scenario_data(yaml.safe_load(open(src)))
    data["name"] = name
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


@pytest.fixture
def tiny_scenario():
    """Factory: ``tiny_scenario(tmp_path, name="tiny", base="paper_2012") -> Path`` of a shrunk scenario."""
    return _tiny_scenario


@pytest.fixture(autouse=True, scope="session")
def _isolated_cache(tmp_path_factory):
    """Keep the simulation cache of the environment and runner out of the user's home directory."""
    import os

    previous = os.environ.get("FUELHM_BENCH_CACHE")
    os.environ["FUELHM_BENCH_CACHE"] = str(tmp_path_factory.mktemp("fuelhm-cache"))
    yield
    if previous is None:
        os.environ.pop("FUELHM_BENCH_CACHE", None)
    else:
        os.environ["FUELHM_BENCH_CACHE"] = previous
