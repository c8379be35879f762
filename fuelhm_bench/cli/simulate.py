"""``fuelhm-bench simulate``: simulate a fleet and write flights plus a labels table (docs/data-format.md)."""

from __future__ import annotations

import argparse
import dataclasses

from fuelhm_bench.cli._common import (
    bounded,
    check_output,
    check_run_budget,
    non_negative_int,
    positive_int,
    progress_bar,
)
from fuelhm_bench.errors import ParameterError

#: Bounds of the fleet options (those of scenario files, fuelhm_bench.scenarios).
MAX_UNITS = 10_000
MAX_FLIGHTS = 10_000
#: Flight duration bounds [min]: the engine start (60 s) plus one minute, and 24 h.
MIN_MINUTES = 2.0
MAX_MINUTES = 1440.0


def add_model_arguments(p: argparse.ArgumentParser) -> None:
    """Arguments selecting the model: --model, --effect, --frame-rate, --noise-um, --adc-bits."""
    p.add_argument("--model", metavar="YAML", help="model parameter file (e.g. from 'calibrate'); default nominal")
    p.add_argument("--effect", action="append", default=[], metavar="ID[:PARAM=VALUE,...]",
                   help="switch on an optional physical effect (repeatable), e.g. rod_friction:coulomb_n=200")
    p.add_argument("--frame-rate", type=bounded(float, 1.0, 1e4, "Hz"), default=None, metavar="HZ",
                   help="FADEC frame / sample rate [Hz], in [1, 10000] (default 100)")
    from fuelhm_bench.physics.lvdt import MAX_NOISE_STD_M

    p.add_argument("--noise-um", type=bounded(float, 0.0, 1e6 * MAX_NOISE_STD_M, "um"), default=None, metavar="UM",
                   help=f"LVDT noise standard deviation [um], in [0, {1e6 * MAX_NOISE_STD_M:g}]")
    p.add_argument("--adc-bits", type=bounded(int, 0, 24), default=None, metavar="BITS",
                   help="LVDT ADC resolution, in [0, 24] (0: none)")


def model_from_args(args: argparse.Namespace):
    """Build the nominal model from the model arguments."""
    from fuelhm_bench.physics.effects import parse_effect_spec
    from fuelhm_bench.physics.model import LoopModel, load_model

    from fuelhm_bench.errors import FuelHMError

    model = load_model(args.model) if args.model else LoopModel()
    given: dict[str, str] = {}
    for spec in args.effect:
        try:
            effect = parse_effect_spec(spec)
        except FuelHMError as exc:
            reason = str(exc).removeprefix(f"Effect spec '{spec}': ")
            raise ParameterError(f"--effect {spec!r}: {reason} The form is ID[:PARAM=VALUE,...], e.g. "
                                 "rod_friction:coulomb_n=200.") from None
        if effect.id in given:  # (one would silently replace the other)
            raise ParameterError(f"--effect {effect.id} is given twice ({given[effect.id]!r} and {spec!r}); give each "
                                 f"effect once, with all its parameters: ID:PARAM=VALUE,PARAM=VALUE.")
        given[effect.id] = spec
        model = model.with_effect(effect)
    if args.frame_rate is not None:
        model = model.with_parameters({"controller.frame_s": 1.0 / args.frame_rate})
    if args.noise_um is not None:
        model = model.with_parameters({"lvdt.noise_std_m": args.noise_um * 1e-6})
    if args.adc_bits is not None:
        model = model.with_parameters({"lvdt.adc_bits": args.adc_bits})
    return model


def parse_degrade(spec: str) -> tuple[str, float]:
    """Parse ``MODE:INTENSITY``."""
    from fuelhm_bench.physics.degradations import validate_intensities

    from fuelhm_bench.errors import UnknownNameError

    mode, sep, value = spec.partition(":")
    if not sep:
        raise ParameterError(f"--degrade '{spec}': expected MODE:INTENSITY, e.g. internal_leakage:0.5.")
    try:
        f = float(value)
    except ValueError:
        f = float("nan")
    if not 0.0 <= f <= 1.0:
        shown = value if f == f else f"'{value}'"  # a number as typed, anything else quoted
        raise ParameterError(f"--degrade '{spec}': the intensity must be a number in [0, 1]. Got {shown} instead.")
    try:
        clean = validate_intensities({mode.strip(): f}, where="--degrade")
    except UnknownNameError as exc:
        raise UnknownNameError(f"--degrade '{spec}': {exc}") from None
    return next(iter(clean.items()))


def register(sub) -> None:
    p = sub.add_parser("simulate", help="simulate a fleet of units over flights (flight file + labels, docs/data-format.md)",
                       description="Simulate N units flying M flights each, with optional degradations and "
                                   "effects; writes the flight table and a labels table beside it "
                                   "(flights.parquet -> flights.labels.parquet).")
    p.add_argument("--units", type=bounded(int, 1, MAX_UNITS), default=2,
                   help=f"number of units, in [1, {MAX_UNITS}] (default 2)")
    p.add_argument("--flights", type=bounded(int, 1, MAX_FLIGHTS), default=5,
                   help=f"flights per unit, in [1, {MAX_FLIGHTS}] (default 5)")
    p.add_argument("--minutes", type=bounded(float, MIN_MINUTES, MAX_MINUTES, "min"), default=60.0,
                   help=f"flight duration [min], in [{MIN_MINUTES:g}, {MAX_MINUTES:g}] (default 60); "
                        "units x flights x minutes is limited by the run budget (FUELHM_RUN_BUDGET_FLIGHT_HOURS)")
    p.add_argument("--seed", type=non_negative_int, default=0, help="master seed (default 0)")
    p.add_argument("--degrade", action="append", default=[], metavar="MODE:INTENSITY",
                   help="degradation with its maximum intensity in [0, 1] (repeatable)")
    p.add_argument("--onset", default=None, metavar="MIN-MAX",
                   help="onset flight of the degradations, drawn uniformly per unit (default 0-0: from the first flight)")
    p.add_argument("--growth", choices=("step", "linear", "exponential"), default="step",
                   help="growth law from the onset (default step)")
    p.add_argument("--ramp-flights", type=bounded(int, 1, MAX_FLIGHTS), default=10,
                   help="flights from onset to maximum (default 10)")
    # 3 = physics.model.MAX_DISPERSION_SCALE (the parser loads no simulator; tests/test_cli_errors.py compares them)
    p.add_argument("--dispersion", type=bounded(float, 0.0, 3.0), default=1.0,
                   help="scale of the manufacturing dispersion, in [0, 3] (default 1); lower for a model near "
                        "a parameter's bound")
    add_model_arguments(p)
    p.add_argument("--batch-size", type=positive_int, default=8, help="flights simulated together (memory bound)")
    p.add_argument("--force", action="store_true", help="overwrite existing output files")
    p.add_argument("--out", required=True, help="output flight file (.parquet, .csv or .csv.gz)")
    p.set_defaults(func=run)


def parse_onset(text: str, n_flights: int | None = None) -> tuple[int, int]:
    """Parse ``--onset MIN-MAX`` (0-based flight indices), within ``n_flights`` flights when given."""
    lo, sep, hi = text.partition("-")
    try:
        a, b = int(lo), int(hi if sep else lo)
    except ValueError:
        raise ParameterError(f"--onset must be MIN-MAX with integers >= 0. Got '{text}' instead.") from None
    if a < 0 or b < a:
        raise ParameterError(f"--onset must be MIN-MAX with 0 <= MIN <= MAX. Got '{text}' instead.")
    if n_flights is not None and b > n_flights - 1:
        raise ParameterError(f"--onset must be MIN-MAX with MAX <= --flights - 1 = {n_flights - 1} (onsets are "
                             f"0-based flight indices; a later onset would never start). Got '{text}' instead.")
    return a, b


def run(args: argparse.Namespace) -> int:
    # Option checks first: a misuse is refused before the simulator is loaded.
    check_run_budget(args.units, args.flights, args.minutes,
                     args.frame_rate if args.frame_rate is not None else 100.0)
    onset = "0-0" if args.onset is None else args.onset
    onset_min, onset_max = parse_onset(onset, args.flights) if args.degrade else parse_onset(onset)
    if not args.degrade and args.onset is not None:
        raise ParameterError(f"--onset {args.onset} applies to the degradations of --degrade, and none is given.")
    out = check_output(args.out, force=args.force, kind="table", what="flight file", inputs={"--model": args.model})

    from fuelhm_bench.flights.fleet import FleetConfig, build_units, flights_frame, iter_flights, labels_frame
    from fuelhm_bench.flights.mission import MissionProfile
    from fuelhm_bench.flights.schedule import ModeSchedule
    from fuelhm_bench.io import FlightWriter, labels_path_for
    from fuelhm_bench.physics.model import Dispersion, dispersion_error, max_dispersion_scale

    model = model_from_args(args)
    schedules, seen = [], {}
    for spec in args.degrade:
        mode, f = parse_degrade(spec)
        if mode in seen:  # (the labels would hold both schedules of one mode)
            raise ParameterError(f"--degrade {mode} is given twice ({seen[mode]!r} and {spec!r}); give each mode once.")
        seen[mode] = spec
        if f > 0:
            schedules.append(ModeSchedule(mode, 1.0, onset_min, onset_max, args.growth, args.ramp_flights, f))
    mission = MissionProfile(duration_s=args.minutes * 60.0, frame_s=model.controller.frame_s)
    limit = max_dispersion_scale(model)
    if args.dispersion > limit:
        error = dispersion_error(model, dataclasses.replace(Dispersion(), scale=args.dispersion))
        raise ParameterError(f"--dispersion must be in [0, {limit:g}] for this model (every unit it can manufacture "
                             f"must be valid; at 3 standard deviations: {error}). Got {args.dispersion:g} instead.")
    dispersion = dataclasses.replace(Dispersion(), scale=args.dispersion)
    config = FleetConfig(n_units=args.units, n_flights=args.flights, mission=mission, nominal=model,
                         dispersion=dispersion, schedules=tuple(schedules), seed=args.seed)
    check_output(labels_path_for(out), force=args.force, kind="table", what="labels file",
                 inputs={"--model": args.model})
    units = {u.unit_id: u for u in build_units(config)}
    hidden = ",".join(e.id for e in model.effects)
    total = args.units * args.flights
    with FlightWriter(out, overwrite=args.force) as writer, progress_bar(total, "simulating") as bar:
        for batch in iter_flights(config, batch_size=args.batch_size, progress=bar.update):
            writer.write(flights_frame(batch))
            writer.write_labels(labels_frame(batch, units, hidden))
    print(f"wrote {total} flights ({args.units} units x {args.flights}) of {args.minutes:g} min to {out} "
          f"and labels to {labels_path_for(out)}")
    return 0
