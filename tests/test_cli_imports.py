"""What commands import: the scenario schema and a leaderboard re-run do not pull in plotting or scipy.stats."""

from __future__ import annotations

import json
import subprocess
import sys


def _modules_after(code: str) -> set[str]:
    out = subprocess.run([sys.executable, "-c", code + "\nimport sys, json; print(json.dumps(sorted(sys.modules)))"],
                         capture_output=True, text=True, check=True)
    return set(json.loads(out.stdout.splitlines()[-1]))


def test_the_scenario_schema_and_the_leaderboard_command_import_no_plotting():
    loaded = _modules_after("import fuelhm_bench.scenarios, fuelhm_bench.cli.leaderboard, fuelhm_bench.benchmark.views")
    assert "fuelhm_bench.scoring.config" in loaded
    assert "matplotlib" not in loaded and "scipy.stats" not in loaded


def test_lazy_scoring_names_are_the_functions_not_the_submodules():
    import types

    import fuelhm_bench.scoring as scoring
    from fuelhm_bench.scoring import robustness_table  # loads the submodule named like the function

    from fuelhm_bench.scoring import robustness
    assert callable(robustness_table) and not isinstance(robustness, types.ModuleType)
    assert all(getattr(scoring, name) is not None for name in scoring.__all__)
    assert set(scoring.__all__) <= set(dir(scoring))


def test_data_builds_import_no_plotting():
    # A Dask worker or a sealed method's zygote that loads published knowledge never draws: it must not pay
    # matplotlib's import (about 0.6 CPU-s per process).
    loaded = _modules_after("import fuelhm_bench.benchmark.harness, fuelhm_bench.datasets.knowledge, "
                            "fuelhm_bench.diagnosis")
    assert "fuelhm_bench.diagnosis.signatures" in loaded
    assert "matplotlib" not in loaded
