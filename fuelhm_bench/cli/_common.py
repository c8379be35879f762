"""Helpers shared by the command modules (argument types, progress bars, output paths)."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from fuelhm_bench.errors import OutputPathError


def positive_int(text: str) -> int:
    """argparse type: an integer >= 1."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer >= 1, got '{text}'") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be an integer >= 1, got {value}")
    return value


def non_negative_int(text: str) -> int:
    """argparse type: an integer >= 0."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer >= 0, got '{text}'") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be an integer >= 0, got {value}")
    return value


def positive_float(text: str) -> float:
    """argparse type: a finite number > 0."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a number > 0, got '{text}'") from None
    if not value > 0 or value != value or value == float("inf"):
        raise argparse.ArgumentTypeError(f"must be a finite number > 0, got {text}")
    return value


def progress_bar(total: int, desc: str, unit: str = "flight"):
    """A tqdm progress bar on stderr, silent when stderr is not a terminal or in CI."""
    from tqdm.auto import tqdm

    disable = not sys.stderr.isatty() or os.environ.get("CI") == "true" or os.environ.get("FUELHM_NO_PROGRESS")
    return tqdm(total=total, desc=desc, unit=unit, disable=bool(disable), file=sys.stderr)


def check_output(path: str | Path, *, force: bool) -> Path:
    """Check an output file path: refuse to overwrite without ``--force``, create parents."""
    path = Path(path)
    if path.exists() and path.is_dir():
        raise OutputPathError(f"{path} is a directory; give a file name.")
    if path.exists() and not force:
        raise OutputPathError(f"{path} exists; refusing to overwrite it (pass --force).")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputPathError(f"Cannot create the directory of {path}: {exc.strerror or exc}.") from None
    if not os.access(path.parent, os.W_OK):
        raise OutputPathError(f"Cannot write to {path.parent} (permission denied).")
    return path


def check_output_dir(path: str | Path) -> Path:
    """Create an output directory (existing files inside are only replaced by name)."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise OutputPathError(f"{path} exists and is not a directory.")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputPathError(f"Cannot create the output directory {path}: {exc.strerror or exc}.") from None
    if not os.access(path, os.W_OK):
        raise OutputPathError(f"Cannot write to {path} (permission denied).")
    return path
