"""Where numba keeps its compiled-function caches: outside the installed package.

Numba's default (``cache=True``) writes ``__pycache__/*.nbi`` and ``*.nbc`` files
beside the source module, that is inside ``site-packages/fuelhm_bench``. A later
``pip install -e`` removes the package's files but leaves those folders behind,
and Python then finds an empty namespace package ``fuelhm_bench`` that hides the
editable install (``cannot import name '__version__'``). The caches therefore
live in the user's cache directory:

1. ``$NUMBA_CACHE_DIR`` when it is set (numba's own variable, honoured as is);
2. otherwise ``<user cache>/numba``, where ``<user cache>`` is
   ``$FUELHM_BENCH_CACHE`` when set, else the platform's cache folder
   (``$XDG_CACHE_HOME`` or ``~/.cache`` on Linux, ``~/Library/Caches`` on macOS,
   ``%LOCALAPPDATA%`` on Windows) followed by ``fuelhm-bench``.

This module is imported by ``fuelhm_bench/__init__.py`` before any module that
defines a numba function, so the setting is in place before the first compile.

>>> from pathlib import Path
>>> isinstance(numba_cache_dir({"NUMBA_CACHE_DIR": "/tmp/nb"}), Path)
True
>>> numba_cache_dir({"NUMBA_CACHE_DIR": "/tmp/nb"}).as_posix()
'/tmp/nb'
>>> numba_cache_dir({"FUELHM_BENCH_CACHE": "/tmp/fh"}).as_posix()
'/tmp/fh/numba'
"""

from __future__ import annotations

import os
import sys
from collections.abc import Mapping
from pathlib import Path

__all__ = ["configure_numba_cache", "numba_cache_dir", "user_cache_dir"]

#: Environment variable naming the project's cache directory (simulated products and numba caches).
CACHE_ENV_VAR = "FUELHM_BENCH_CACHE"


def user_cache_dir(environ: Mapping[str, str] | None = None) -> Path:
    """The project's user cache directory.

    Parameters
    ----------
    environ : mapping, optional
        Environment to read (default ``os.environ``).

    Returns
    -------
    pathlib.Path
        ``$FUELHM_BENCH_CACHE`` when set, else the platform cache folder + ``fuelhm-bench``.
    """
    env = os.environ if environ is None else environ
    if env.get(CACHE_ENV_VAR):
        return Path(env[CACHE_ENV_VAR])
    if sys.platform == "win32" and env.get("LOCALAPPDATA"):
        base = Path(env["LOCALAPPDATA"])
    elif sys.platform == "darwin":
        base = Path.home() / "Library" / "Caches"
    else:
        base = Path(env["XDG_CACHE_HOME"]) if env.get("XDG_CACHE_HOME") else Path.home() / ".cache"
    return base / "fuelhm-bench"


def numba_cache_dir(environ: Mapping[str, str] | None = None) -> Path:
    """The directory numba's compiled-function caches go to (see the module docstring)."""
    env = os.environ if environ is None else environ
    if env.get("NUMBA_CACHE_DIR"):
        return Path(env["NUMBA_CACHE_DIR"])
    return user_cache_dir(env) / "numba"


def configure_numba_cache() -> Path:
    """Point numba's cache at :func:`numba_cache_dir` and return that directory.

    Sets ``NUMBA_CACHE_DIR`` in ``os.environ`` (read by numba when it is first
    imported) and, when numba is already imported, its ``config.CACHE_DIR``.
    A value the user set is left untouched.
    """
    path = numba_cache_dir()
    os.environ.setdefault("NUMBA_CACHE_DIR", str(path))
    numba = sys.modules.get("numba")
    if numba is not None and getattr(numba, "config", None) is not None:
        numba.config.CACHE_DIR = os.environ["NUMBA_CACHE_DIR"]
    return path


configure_numba_cache()
