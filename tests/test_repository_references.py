"""The project owns its documents: nothing in the repository cites a design file it does not ship.

The physics and the data format are described in ``docs/physics.md`` and ``docs/data-format.md``;
code, docs, README and tests point there, never at the old design notes or at a path outside the
repository.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: Citations of files outside the repository (spelled in pieces so that this file does not match).
FORBIDDEN = re.compile("|".join([r"\bPHYSICS" + r"\.md\b", r"\bDATA" + r"\.md\b", r"\.\./" + "shared",
                                 "/work/" + "shared"]))

_TEXT_SUFFIXES = {".py", ".md", ".yaml", ".yml", ".toml", ".txt", ".cfg", ".ini", ".json", ".html", ".rst"}
_SKIP_DIRS = {".git", ".venv", "venv", "build", "dist", "__pycache__", ".pytest_cache", "node_modules",
              ".benchmarks", "out"}


def _project_files() -> list[Path]:
    files = []
    for folder, dirs, names in os.walk(ROOT):
        dirs[:] = [d for d in dirs if d not in _SKIP_DIRS and not d.endswith(".egg-info")]
        for name in names:
            path = Path(folder) / name
            rel = path.relative_to(ROOT).as_posix()
            if path.suffix in _TEXT_SUFFIXES or rel in {".ci/run", "README"}:
                files.append(path)
    return files


def test_the_scan_covers_the_repository():
    names = {p.relative_to(ROOT).as_posix() for p in _project_files()}
    assert {"README.md", ".ci/run", "pyproject.toml", "fuelhm_bench/__init__.py", "docs/data-format.md",
            "tests/conftest.py"} <= names


def test_no_file_cites_a_document_outside_the_repository():
    offenders = []
    for path in _project_files():
        rel = path.relative_to(ROOT).as_posix()
        for number, line in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
            if FORBIDDEN.search(line):
                offenders.append(f"{rel}:{number}: {line.strip()[:100]}")
    assert not offenders, ("cite docs/physics.md or docs/data-format.md instead:\n" + "\n".join(offenders))


def test_the_data_format_document_describes_the_implemented_columns():
    """docs/data-format.md names every column and rule the io module defines."""
    from fuelhm_bench.io import NUMERIC_COLUMNS, OPTIONAL_COLUMNS, REQUIRED_COLUMNS

    text = (ROOT / "docs" / "data-format.md").read_text(encoding="utf-8")
    for column in (*REQUIRED_COLUMNS, *OPTIONAL_COLUMNS):
        assert f"`{column}`" in text, column
    for column, unit in NUMERIC_COLUMNS.items():
        row = next(line for line in text.splitlines() if line.startswith(f"| `{column}`"))
        assert unit.replace("degC", "°C") in row, (column, unit)
    source = (ROOT / "fuelhm_bench" / "io" / "flights.py").read_text(encoding="utf-8")
    for rule in sorted(set(re.findall(r"^([FP]\d)\. ", source, flags=re.M))):
        assert f"**{rule}.**" in text, rule
