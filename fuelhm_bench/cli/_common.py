"""Helpers shared by the command modules (argument types, progress bars, output paths)."""

from __future__ import annotations

import argparse
import contextlib
import os
import re
import sys
from collections.abc import Iterator
from pathlib import Path

from fuelhm_bench.io.outputs import atomic_directory  # noqa: F401 - the commands' output folders
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
    """argparse type: an integer in [0, 2**63 - 1] (a seed, a count: what the results store can hold)."""
    from fuelhm_bench.scenarios.schema import MAX_SEED

    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be an integer >= 0, got '{text}'") from None
    if not 0 <= value <= MAX_SEED:
        raise argparse.ArgumentTypeError(f"must be an integer in [0, {MAX_SEED}], got {value}")
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


def bounded(kind: type, low: float | None = None, high: float | None = None, unit: str = "", *,
            open_low: bool = False):
    """argparse type: a finite ``kind`` (int or float) in ``[low, high]`` (``(low, high]`` with
    ``open_low``), with a message naming the range.

    Examples
    --------
    >>> bounded(float, 2, 1440, "min")("30")
    30.0
    >>> bounded(int, 1, 10)("0")
    Traceback (most recent call last):
    argparse.ArgumentTypeError: must be an integer in [1, 10]. Got 0 instead.
    """
    noun = "an integer" if kind is int else "a number"
    if low is not None and high is not None:
        rng = f" in {'(' if open_low else '['}{low:g}, {high:g}]"
    elif low is not None:
        rng = f" {'>' if open_low else '>='} {low:g}"
    else:
        rng = f" <= {high:g}" if high is not None else ""
    allowed = f"{noun}{rng}{' ' + unit if unit else ''}"

    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"must be {allowed}. Got '{text}' instead.") from None
        below = low is not None and (value <= low if open_low else value < low)
        if value != value or value in (float("inf"), float("-inf")) or below or (high is not None and value > high):
            raise argparse.ArgumentTypeError(f"must be {allowed}. Got {text} instead.")
        return value

    parse.__name__ = f"{noun} {rng.strip()}"  # argparse names the type in some messages
    return parse


def check_run_budget(units: int, flights: int, minutes: float, frame_rate_hz: float = 100.0, *,
                     what: str | None = None) -> None:
    """Refuse a simulation above the run budget (flight-hours), with its estimate.

    The budget and its opt-in are those of scenarios
    (:func:`fuelhm_bench.scenarios.run_budget`: ``FUELHM_RUN_BUDGET_FLIGHT_HOURS``).
    ``units x flights`` flights of ``minutes`` are simulated; ``what`` says how
    the command's options make them (default: ``--units U x --flights F x --minutes M``).

    Raises
    ------
    ParameterError
        Naming the options, the estimate and how to allow it.
    """
    import math

    from fuelhm_bench.errors import ParameterError
    from fuelhm_bench.scenarios import RUN_BUDGET_ENV, RunCost, run_budget

    cost = RunCost(flight_hours=units * flights * minutes / 60.0, frame_rate_hz=frame_rate_hz)
    budget, origin = run_budget(None)
    if cost.flight_hours > budget:
        raise ParameterError(
            f"{what or f'--units {units} x --flights {flights} x --minutes {minutes:g}'} is "
            f"{cost.flight_hours:.4g} flight-hours "
            f"({cost.describe()}), above the run budget of {budget:g} flight-hours ({origin}). To allow it, set "
            f"{RUN_BUDGET_ENV}={math.ceil(cost.flight_hours)}.")


def usable_flights(path) -> list:
    """The flights of a measured-data file that pass the per-flight rules (docs/data-format.md §2.2).

    Each rejected flight is reported on stderr as a warning; a file none of whose flights is usable
    raises :class:`~fuelhm_bench.errors.DataFormatError` naming the file, how many flights were
    rejected and the first reason (a command never goes on with nothing, nor fails later with a
    message that hides why).
    """
    from fuelhm_bench.errors import DataFormatError
    from fuelhm_bench.io import read_flights, split_flights

    flights, rejected = split_flights(read_flights(path), source=str(path))
    for r in rejected:
        print(f"warning: {r}", file=sys.stderr)
    if not flights:
        raise DataFormatError(f"{path}: every flight of the file was rejected ({len(rejected)} flight(s)), so there "
                              f"is nothing to analyse. The first: {rejected[0].reason}" if rejected else
                              f"{path}: the file holds no flight.")
    return flights


@contextlib.contextmanager
def naming_file(path) -> Iterator[None]:
    """Errors about the data of the file ``path`` name it.

    A :class:`~fuelhm_bench.errors.DataFormatError` or :class:`~fuelhm_bench.errors.NumericalError`
    raised in the block (the analysis of the file's flights: too little excitation, too few samples...)
    whose message does not name the file is raised again, same class, as ``"<path>: <message>"``: the
    user learns which file to look at. Errors about options are left alone (they name the option).

    Examples
    --------
    >>> from fuelhm_bench.errors import DataFormatError
    >>> with naming_file("sw.parquet"):
    ...     raise DataFormatError("flight 0: 4 sample(s)")
    Traceback (most recent call last):
    fuelhm_bench.errors.DataFormatError: sw.parquet: flight 0: 4 sample(s)
    """
    from fuelhm_bench.errors import DataFormatError, NumericalError

    try:
        yield
    except (DataFormatError, NumericalError) as exc:
        if str(path) in str(exc):
            raise
        try:
            renamed = type(exc)(f"{path}: {exc}")
        except TypeError:  # a subclass with another signature
            renamed = DataFormatError(f"{path}: {exc}")
        raise renamed from None


def progress_bar(total: int, desc: str, unit: str = "flight"):
    """A tqdm progress bar on stderr, silent when stderr is not a terminal or in CI."""
    from tqdm.auto import tqdm

    disable = not sys.stderr.isatty() or os.environ.get("CI") == "true" or os.environ.get("FUELHM_NO_PROGRESS")
    return tqdm(total=total, desc=desc, unit=unit, disable=bool(disable), file=sys.stderr)


def check_output(path: str | Path, *, force: bool, option: str = "--out", kind: str | None = None,
                 what: str = "output file", inputs=None) -> Path:
    """Check an output file given on the command line, before any work.

    The one check of every command's output files (see
    :func:`fuelhm_bench.io.outputs.check_output_path`): named for what is written there
    (``kind``: a key of :data:`fuelhm_bench.filetypes.FILE_TYPES`, e.g. ``"yaml"`` or ``"image"``),
    not one of the command's ``inputs`` (``{"FLIGHTS": path, "--model": path}``; even with
    ``--force``), not existing unless ``force``.
    """
    return check_output_path(path, overwrite=force, option=option, kind=kind, what=what, inputs=inputs)


def check_output_dir(path: str | Path, *, force: bool = True, names=(), option: str = "--out", inputs=None) -> Path:
    """Create an output directory (see :func:`fuelhm_bench.io.outputs.check_output_dir`); none of ``names``
    in it may be one of the command's ``inputs``."""
    return _check_output_dir(path, force=force, names=names, option=option, inputs=inputs)


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


# ----------------------------------------------------------------------------- option names in messages
def _same(v: float) -> float:
    return v


def _inverse(v: float) -> float:
    return 1.0 / v if v else float("inf")


#: Internal parameter names -> (command-line option, internal value -> option value, option unit,
#: decreasing). Errors of the lower layers name internal fields (``MissionProfile.duration_s``); the
#: command line rewrites them to name the option the user typed (``--minutes``), in its unit.
FIELD_OPTIONS: dict[str, tuple] = {
    "MissionProfile.duration_s": ("--minutes", lambda v: v / 60.0, "min", False),
    "MissionProfile.frame_s": ("--frame-rate", _inverse, "Hz", True),
    "ControllerParams.frame_s": ("--frame-rate", _inverse, "Hz", True),
    "FlightInputs.frame_s": ("--frame-rate", _inverse, "Hz", True),
    "VelocityGainSweep.frame_s": ("--frame-rate", _inverse, "Hz", True),
    "LvdtParams.noise_std_m": ("--noise-um", lambda v: v * 1e6, "um", False),
    "LvdtParams.adc_bits": ("--adc-bits", _same, "", False),
    "Dispersion.scale": ("--dispersion", _same, "", False),
    "FleetConfig.n_units": ("--units", _same, "", False),
    "FleetConfig.n_flights": ("--flights", _same, "", False),
    "FleetConfig.seed": ("--seed", _same, "", False),
    "ModeSchedule.ramp_flights": ("--ramp-flights", _same, "", False),
    "VelocityGainSweep.current_min_a": ("--min-ma", lambda v: v * 1e3, "mA", False),
    "VelocityGainSweep.current_max_a": ("--max-ma", lambda v: v * 1e3, "mA", False),
    "VelocityGainSweep.ramp_duration_s": ("--ramp-seconds", _same, "s", False),
    "VelocityGainSweep.n2_frac": ("--n2-pct", lambda v: v * 100.0, "%", False),
    "VelocityGainSweep.cycles": ("--cycles", _same, "", False),
    "DiscrepancyConfig.holdout_fraction": ("--holdout", _same, "", False),
    "DiscrepancyConfig.n_jobs": ("--jobs", _same, "", False),
    "DiscrepancyConfig.candidates": ("--candidates", _same, "", False),
    "DiscrepancyConfig.seed": ("--seed", _same, "", False),
    "CalibrationConfig.seed": ("--seed", _same, "", False),
    "DriftSweep.parameters": ("--parameters", _same, "", False),
    "DriftSweep.magnitudes": ("--magnitudes", _same, "", False),
    "DriftSweep.tolerance": ("--tolerance", _same, "", False),
}

_TEMPLATE = re.compile(r"^The '(?P<name>[^']+)' parameter(?: of (?P<owner>[A-Za-z_][\w.]*))? must be "
                       r"(?P<allowed>.*)\. Got (?P<given>.*) instead\.(?P<rest>.*)$", re.S)
_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
_ONE_SIDED = re.compile(rf"^(?P<op>>=|>|<=|<) (?P<x>{_NUM})$")
_INTERVAL = re.compile(rf"^(?P<noun>(?:an integer |a number |a finite number )?)in (?P<lb>[\[(])(?P<a>{_NUM}), "
                       rf"(?P<b>{_NUM})(?P<rb>[\])])$")
_FLIP = {">=": "<=", ">": "<", "<=": ">=", "<": ">", "[": "]", "(": ")", "]": "[", ")": "("}


def _convert_allowed(allowed: str, convert, unit: str, decreasing: bool) -> str | None:
    """``allowed`` (internal units) in the option's units, for simple ranges; None otherwise."""
    unit = f" {unit}" if unit else ""
    m = _ONE_SIDED.match(allowed)
    if m:
        op = _FLIP[m["op"]] if decreasing else m["op"]
        return f"{op} {convert(float(m['x'])):.6g}{unit}"
    m = _INTERVAL.match(allowed)
    if m:
        a, b = convert(float(m["a"])), convert(float(m["b"]))
        lb, rb = m["lb"], m["rb"]
        if decreasing:
            a, b, lb, rb = b, a, _FLIP[rb], _FLIP[lb]
        return f"{m['noun']}in {lb}{a:.6g}, {b:.6g}{rb}{unit}"
    return None


def option_message(message: str, args: argparse.Namespace) -> str:
    """Rewrite an error that names an internal field to name the command-line option instead.

    Parameters
    ----------
    message : str
        The error message (the project's template "The 'x' parameter [of Y] must be Z. Got W instead.").
    args : argparse.Namespace
        The parsed command line; only options of the running command are named.

    Returns
    -------
    str
        ``"--minutes must be >= 2 min. Got 0.5 instead."``, or ``message`` unchanged when it names
        no field of :data:`FIELD_OPTIONS` that this command has.
    """
    m = _TEMPLATE.match(message)
    if not m:
        return message
    name = f"{m['owner']}.{m['name']}" if m["owner"] else m["name"]
    if name not in FIELD_OPTIONS:
        return message
    option, convert, unit, decreasing = FIELD_OPTIONS[name]
    dest = option.lstrip("-").replace("-", "_")
    if not hasattr(args, dest):
        return message
    typed = getattr(args, dest)
    typed = ",".join(map(str, typed)) if isinstance(typed, (list, tuple)) else typed
    converted = _convert_allowed(m["allowed"], convert, unit, decreasing)
    if converted is None and convert is _same and not unit:  # the option is the field itself: its words apply
        converted = m["allowed"]
    elif converted is None:
        converted = f"such that {name} is {m['allowed']} (it was {m['given']})"
    shown = f"{typed:g}" if isinstance(typed, float) else str(typed)
    return f"{option} must be {converted}. Got {shown} instead.{m['rest']}"


#: ``--scale``: the fraction of a scenario's test units kept (above 1 would be capped at its units).
scale_fraction = bounded(float, 0.0, 1.0, open_low=True)

#: ``--minutes`` overriding a scenario's flight duration; the lower bound depends on the scenario
#: (engine start + 1 min) and is checked with it.
flight_minutes = bounded(float, 0.0, 1440.0, "min", open_low=True)  # 1440: scenarios.schema.MAX_DURATION_MIN
