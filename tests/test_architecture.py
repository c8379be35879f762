"""The package's floors: no upward import between layers, one list of installed packages."""

from __future__ import annotations

import ast
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "fuelhm_bench"

#: Layers, lowest first. A module may import its own package and packages of strictly lower layers.
LAYERS = (
    ("errors", "taxonomy", "_numba_cache"),
    ("filetypes",),  # what a file is from its name: every reader and writer of user files asks it
    ("yamlfiles",),
    ("__init__",),
    ("io", "physics", "indicators", "diagnosis"),
    ("methods",),  # the method interface and its adapters use the diagnosis statistics
    ("flights", "scoring"),
    ("scenarios", "calibration"),
    ("datasets",),
    ("envs",),
    ("benchmark", "validation"),
    ("cli",),
    ("testing",),  # fixtures for tests: nothing in the product imports them
)
RANK = {name: i for i, layer in enumerate(LAYERS) for name in layer}


def _imports(path: Path):
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            yield from (a.name for a in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            yield node.module


def _package_of(path: Path) -> str:
    rel = path.relative_to(PACKAGE).parts
    return rel[0].removesuffix(".py")


def test_every_package_has_a_layer():
    names = {p.name for p in PACKAGE.iterdir() if p.is_dir() and (p / "__init__.py").exists()}
    names |= {p.stem for p in PACKAGE.glob("*.py")}
    assert names <= set(RANK), f"add {sorted(names - set(RANK))} to LAYERS"


@pytest.mark.parametrize("path", sorted(PACKAGE.rglob("*.py")), ids=lambda p: str(p.relative_to(ROOT)))
def test_no_upward_import(path):
    src = _package_of(path)
    for module in _imports(path):
        if not module.startswith("fuelhm_bench."):
            continue
        dst = module.split(".")[1]
        if dst == src or dst not in RANK:
            continue
        assert RANK[dst] < RANK[src], (f"{path.relative_to(ROOT)} (layer {RANK[src]}, {src}) imports {module} "
                                       f"(layer {RANK[dst]}): lower floors never import higher or sibling ones; "
                                       f"pass a callback down instead")


def test_installed_packages_match_the_source_tree():
    listed = set(tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"])
    found = {".".join(p.relative_to(ROOT).parent.parts) for p in PACKAGE.rglob("__init__.py")}
    found |= {"fuelhm_bench.scenarios.shipped", "fuelhm_baselines"}
    assert listed == found


def test_shipped_baselines_install_under_their_own_name():
    import fuelhm_baselines

    assert Path(fuelhm_baselines.__file__).parent.name == "baselines"
    mapping = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-dir"]
    assert mapping["fuelhm_baselines"] == "baselines"
