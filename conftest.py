"""Repository-level pytest configuration: doctest collection of the package modules.

The test command collects the doctests of ``fuelhm_bench`` and ``baselines`` (``--doctest-modules``,
``testpaths`` in pyproject.toml). Collecting a module's doctests imports it, so a module whose
top-level imports need an optional dependency that is not installed (an extra such as PyOD or Dask)
would break collection. Such a module is left out of doctest collection here (the
extra's own tests skip themselves with ``pytest.importorskip``). A module whose missing
import is a *required* dependency or part of the project is not left out: that is a real error.
"""

from __future__ import annotations

import ast
import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parent
_PACKAGES = ("fuelhm_bench", "baselines")
_PROJECT_ROOTS = {"fuelhm_bench", "baselines", "tests"}


def _top_level_imports(path: Path) -> set[str]:
    try:
        tree = ast.parse(path.read_text(encoding="utf-8"))
    except (OSError, SyntaxError, ValueError):
        return set()  # let the normal collection report it
    names = set()
    for node in tree.body:
        if isinstance(node, ast.Import):
            names.update(alias.name.split(".")[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names.add(node.module.split(".")[0])
    return names - _PROJECT_ROOTS


def missing_optional_imports(path: Path) -> list[str]:
    """Top-level third-party imports of ``path`` that are not installed."""
    missing = []
    for name in sorted(_top_level_imports(path)):
        try:
            found = importlib.util.find_spec(name) is not None
        except (ImportError, ValueError):
            found = False
        if not found:
            missing.append(name)
    return missing


def pytest_ignore_collect(collection_path, config):
    path = Path(collection_path)
    if path.suffix != ".py" or not config.getoption("doctestmodules", False):
        return None
    try:
        rel = path.resolve().relative_to(ROOT)
    except ValueError:
        return None
    if rel.parts[0] not in _PACKAGES:
        return None
    return True if missing_optional_imports(path) else None
