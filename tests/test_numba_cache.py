"""Numba's compiled-function caches live outside the installed package (issue: a left-over
``__pycache__`` in site-packages hid a later editable install)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import fuelhm_bench
from fuelhm_bench._numba_cache import numba_cache_dir, user_cache_dir

PACKAGE = Path(fuelhm_bench.__file__).resolve().parent

# Compiles one small cached function of the package (a cold compile takes about a second).
_SCRIPT = """
import numba
import fuelhm_bench
from fuelhm_bench.physics.fluid import orifice_flow
orifice_flow(1e-6, 1e5, 1e4)
print(numba.config.CACHE_DIR)
"""


def _package_cache_files() -> set[Path]:
    return {p for pattern in ("*.nbi", "*.nbc") for p in PACKAGE.rglob(pattern)}


def _run(env_update: dict[str, str]) -> str:
    env = {k: v for k, v in os.environ.items() if k not in ("NUMBA_CACHE_DIR", "FUELHM_BENCH_CACHE")}
    env.update(env_update)
    done = subprocess.run([sys.executable, "-c", _SCRIPT], env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return done.stdout.strip().splitlines()[-1]


def test_caches_go_to_the_user_cache_directory_not_the_package(tmp_path):
    before = _package_cache_files()
    reported = _run({"FUELHM_BENCH_CACHE": str(tmp_path / "fh")})
    assert Path(reported) == tmp_path / "fh" / "numba"
    assert list((tmp_path / "fh" / "numba").rglob("*.nbi")), "no numba index written to the user cache"
    assert _package_cache_files() == before, "numba wrote cache files inside the package directory"


def test_numba_cache_dir_is_honoured(tmp_path):
    before = _package_cache_files()
    reported = _run({"NUMBA_CACHE_DIR": str(tmp_path / "nb"), "FUELHM_BENCH_CACHE": str(tmp_path / "fh")})
    assert Path(reported) == tmp_path / "nb"
    assert list((tmp_path / "nb").rglob("*.nbi"))
    assert not (tmp_path / "fh").exists()
    assert _package_cache_files() == before


def test_default_location_follows_the_platform_cache_folder(tmp_path):
    env = {"XDG_CACHE_HOME": str(tmp_path)}
    if sys.platform.startswith("linux"):
        assert user_cache_dir(env) == tmp_path / "fuelhm-bench"
        assert numba_cache_dir(env) == tmp_path / "fuelhm-bench" / "numba"
    assert numba_cache_dir({"NUMBA_CACHE_DIR": str(tmp_path / "x")}) == tmp_path / "x"
