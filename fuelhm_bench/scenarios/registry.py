"""Shipped scenarios: lookup by name or ``name-vN``, as Gymnasium's registry does for environments.

The shipped files live in the top-level ``scenarios/`` directory of the source
tree; ``pyproject.toml`` maps that directory to the package
``fuelhm_bench.scenarios.shipped`` so that a wheel carries them. Each file is
``<name>.yaml`` and holds the *current* version of that scenario; every lower
version is retired. Asking for a retired version names the current one, asking
for an unknown name lists the shipped ones with a did-you-mean suggestion.
"""

from __future__ import annotations

import importlib.resources
import re
from importlib.resources.abc import Traversable
from pathlib import Path

from fuelhm_bench.errors import ScenarioError, UnknownNameError
from fuelhm_bench.scenarios._fields import suggest
from fuelhm_bench.scenarios.loader import load_scenario_file, parse_scenario
from fuelhm_bench.scenarios.schema import NAME_PATTERN, Scenario

__all__ = ["list_scenarios", "load_scenario", "shipped_scenario_files"]

_PACKAGE = "fuelhm_bench.scenarios.shipped"
_ID = re.compile(rf"^(?P<name>{NAME_PATTERN})(?:-v(?P<version>\d+))?$")


def _shipped_directory() -> Traversable:
    """The directory of the shipped YAML files (source tree first, then the installed package)."""
    root = Path(__file__).resolve().parents[2]
    source_dir = root / "scenarios"
    if source_dir.is_dir() and (root / "pyproject.toml").is_file() and (root / "fuelhm_bench").is_dir():
        return source_dir  # a source checkout (plain or editable install)
    return importlib.resources.files(_PACKAGE)


def shipped_scenario_files() -> dict[str, Traversable]:
    """``{name: file}`` of the shipped scenarios, sorted by name."""
    directory = _shipped_directory()
    files = {p.name[:-len(".yaml")]: p for p in directory.iterdir() if p.is_file() and p.name.endswith(".yaml")}
    return dict(sorted(files.items()))


def list_scenarios() -> tuple[str, ...]:
    """Names of the shipped scenarios, sorted.

    Examples
    --------
    >>> "all_modes" in list_scenarios()
    True
    """
    return tuple(shipped_scenario_files())


def _looks_like_path(text: str) -> bool:
    return "/" in text or "\\" in text or text.endswith((".yaml", ".yml")) or Path(text).is_file()


def load_scenario(name_or_path: str | Path) -> Scenario:
    """Load a shipped scenario by name (``"all_modes"``, ``"all_modes-v1"``) or a YAML file by path.

    Parameters
    ----------
    name_or_path : str or pathlib.Path
        A shipped name, optionally with a version suffix ``-vN``, or the path
        of a scenario file (anything containing a path separator, ending in
        ``.yaml``/``.yml`` or naming an existing file).

    Returns
    -------
    Scenario

    Raises
    ------
    UnknownNameError
        The name is not shipped (the message lists the shipped names and
        suggests the closest).
    ScenarioError
        A retired (or future) version was asked for (the message names the
        current id), or the file fails validation.
    """
    if isinstance(name_or_path, Path) or _looks_like_path(str(name_or_path)):
        return load_scenario_file(name_or_path)
    text = str(name_or_path)
    files = shipped_scenario_files()
    m = _ID.match(text)
    base = m.group("name") if m else text
    if base not in files:
        names = ", ".join(files) or "none"
        hint = suggest(base, files)
        raise UnknownNameError(f"Unknown scenario '{text}'. Shipped scenarios: {names}.{' ' + hint if hint else ''} "
                               f"(A file path must end in .yaml or contain a '/'.)")
    file = files[base]
    scenario = parse_scenario(file.read_text(encoding="utf-8"), source=_display(file), file_name=base)
    if m and m.group("version") is not None:
        asked = int(m.group("version"))
        if asked < scenario.version:
            raise ScenarioError(f"Scenario '{text}' is retired; the current version is '{scenario.id}'. Load "
                                f"'{scenario.id}' (or '{base}'); versions are bumped whenever a change alters "
                                f"simulated data or scores, so results of different versions are not comparable.")
        if asked > scenario.version:
            raise ScenarioError(f"Scenario '{text}' does not exist; the current version is '{scenario.id}'.")
    return scenario


def _display(file: Traversable) -> str:
    """How a shipped file is named in messages: relative to the working directory when possible."""
    path = Path(str(file))
    try:
        return str(path.relative_to(Path.cwd()))
    except ValueError:
        return str(path)
