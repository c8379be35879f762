"""The doctests run in the default test command, and optional extras cannot break their collection."""

from __future__ import annotations

import importlib.util
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _repo_conftest():
    spec = importlib.util.spec_from_file_location("_repo_conftest", ROOT / "conftest.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_default_run_collects_the_package_doctests():
    options = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["pytest"]["ini_options"]
    assert "--doctest-modules" in options["addopts"]
    assert {"tests", "fuelhm_bench", "baselines"} <= set(options["testpaths"])


def test_a_module_needing_a_missing_extra_is_left_out_of_doctest_collection(tmp_path):
    conftest = _repo_conftest()
    module = tmp_path / "adapter.py"
    module.write_text("import numpy\nimport surely_not_installed_xyz.sub\nfrom fuelhm_bench import errors\n\n"
                      "def f():\n    import also_missing_but_lazy\n")
    assert conftest.missing_optional_imports(module) == ["surely_not_installed_xyz"]
    plain = tmp_path / "plain.py"
    plain.write_text("import numpy, scipy\nfrom fuelhm_baselines import _common\n")
    assert conftest.missing_optional_imports(plain) == []
