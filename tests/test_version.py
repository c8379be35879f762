"""The package version has one source (``fuelhm_bench.__version__``, read by pyproject.toml)."""

from __future__ import annotations

import importlib.metadata
import re
import subprocess
import sys

import fuelhm_bench


def test_version_is_the_installed_metadata_and_the_cli_prints_it():
    installed = importlib.metadata.version("fuelhm-bench")
    assert fuelhm_bench.__version__ == installed
    assert re.fullmatch(r"\d+\.\d+\.\d+", installed)
    out = subprocess.run([sys.executable, "-m", "fuelhm_bench.cli", "--version"], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == f"fuelhm-bench {installed}"


def test_pyproject_does_not_repeat_the_version():
    import tomllib
    from pathlib import Path

    data = tomllib.loads((Path(__file__).resolve().parents[1] / "pyproject.toml").read_text())
    assert "version" not in data["project"] and "version" in data["project"]["dynamic"]
    assert data["tool"]["setuptools"]["dynamic"]["version"] == {"attr": "fuelhm_bench.__version__"}
