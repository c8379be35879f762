"""Reading the YAML a user writes (model files, leaderboard files, ``--param`` values): one loader.

PyYAML follows YAML 1.1, where a number in exponent notation without a dot (``1e-3``, ``5E2``) is a
*string*; YAML 1.2, JSON and every user expect a number. :class:`SafeLoader` is PyYAML's safe
loader (no Python objects) that reads those as floats too. :func:`read_yaml` reads a file with it
and turns every way the file can be unreadable (missing, a directory, not UTF-8 text, not YAML) into
one error naming the file. Scenario files have their own, stricter reader
(:mod:`fuelhm_bench.scenarios.loader`), built on the same loader.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import yaml

from fuelhm_bench.filetypes import check_file_type

__all__ = ["SafeLoader", "read_yaml", "safe_load"]


class SafeLoader(yaml.SafeLoader):
    """``yaml.SafeLoader`` that also reads ``1e-3``-style plain scalars as floats (YAML 1.2)."""


SafeLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$"),
    list("-+0123456789."))


def safe_load(text: str) -> Any:
    """Parse one YAML document with :class:`SafeLoader`."""
    return yaml.load(text, Loader=SafeLoader)  # noqa: S506 - SafeLoader subclass


def read_yaml(path, what: str, error: type[Exception], *, max_bytes: int = 1_000_000) -> Any:
    """The document of the YAML file ``path`` (``what`` names it in messages: "model file"...).

    Raises
    ------
    error
        When the file cannot be read, its name does not end in ``.yaml`` / ``.yml``
        (:mod:`fuelhm_bench.filetypes`), it is larger than ``max_bytes``, not UTF-8 text or not
        YAML; the message names the file (and the line, for YAML errors).
    """
    path = Path(path)
    try:
        size = path.stat().st_size
        if size > max_bytes:
            raise error(f"{path}: a {what} must be at most {max_bytes} bytes. Got {size} bytes instead.")
        if not path.is_dir():
            check_file_type(path, "yaml", what=what, error=error)  # (a flight file is not read as YAML)
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise error(f"{path}: cannot read the {what}: it is not UTF-8 text (a binary file?).") from None
    except OSError as exc:
        raise error(f"Cannot read the {what} {path}: {exc.strerror or exc}.") from None
    try:
        return safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" (line {mark.line + 1})" if mark is not None else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise error(f"{path}: not valid YAML{where}: {problem}.") from None
