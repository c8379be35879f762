"""Helpers shared by the command modules (argument types, progress bars, output paths)."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from fuelhm_bench.io.outputs import check_output_dir as _check_output_dir
from fuelhm_bench.io.outputs import check_output_path


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


def check_output(path: str | Path, *, force: bool, option: str = "--out") -> Path:
    """Check an output file given on the command line (see :func:`fuelhm_bench.io.outputs.check_output_path`)."""
    return check_output_path(path, overwrite=force, option=option)


def check_output_dir(path: str | Path, *, force: bool = True, names=(), option: str = "--out") -> Path:
    """Create an output directory (see :func:`fuelhm_bench.io.outputs.check_output_dir`)."""
    return _check_output_dir(path, force=force, names=names, option=option)


def extraction_config(flight):
    """The indicator extraction configuration of one recorded flight.

    The default (:class:`~fuelhm_bench.indicators.ExtractionConfig`), except for
    flights recorded on a virtual bench without end stops (every sample's
    ``phase`` is :data:`fuelhm_bench.io.BENCH_PHASE`, as ``fuelhm-bench sweep``
    writes): their rod travels beyond the 0-60 mm stroke, so the end stops are
    placed beyond the observed positions and the end-stop mask keeps every sample.

    Parameters
    ----------
    flight : fuelhm_bench.io.FlightArrays
        The flight.

    Returns
    -------
    ExtractionConfig
    """
    import dataclasses

    import numpy as np

    from fuelhm_bench.indicators import ExtractionConfig
    from fuelhm_bench.io import BENCH_PHASE

    config = ExtractionConfig()
    phase = flight.extras.get("phase")
    if phase is None or not np.all(phase == BENCH_PHASE):
        return config
    margin = 2.0 * config.end_stop_margin_mm + 1.0
    x = flight.position_mm
    return dataclasses.replace(config, stroke_limits_mm=(float(x.min()) - margin, float(x.max()) + margin))
