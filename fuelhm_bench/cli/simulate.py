"""``fuelhm-bench simulate``: simulate a fleet and write flights plus a labels table (docs/data-format.md)."""

from __future__ import annotations

import argparse
import dataclasses

from fuelhm_bench.cli._common import check_output, non_negative_int, positive_float, positive_int, progress_bar
from fuelhm_bench.errors import ParameterError


def add_model_arguments(p: argparse.ArgumentParser) -> None:
    """Arguments selecting the model: --model, --effect, --frame-rate, --noise-um, --adc-bits."""
    p.add_argument("--model", metavar="YAML", help="model parameter file (e.g. from 'calibrate'); default nominal")
    p.add_argument("--effect", action="append", default=[], metavar="ID[:PARAM=VALUE,...]",
                   help="switch on an optional physical effect (repeatable), e.g. rod_friction:coulomb_n=200")
    p.add_argument("--frame-rate", type=positive_float, default=None, metavar="HZ",
                   help="FADEC frame / sample rate [Hz] (default 100)")
    p.add_argument("--noise-um", type=float, default=None, metavar="UM", help="LVDT noise standard deviation [um]")
    p.add_argument("--adc-bits", type=int, default=None, metavar="BITS", help="LVDT ADC resolution (0: none)")


def model_from_args(args: argparse.Namespace):
    """Build the nominal model from the model arguments."""
    from fuelhm_bench.physics.effects import parse_effect_spec
    from fuelhm_bench.physics.model import LoopModel, load_model

    model = load_model(args.model) if args.model else LoopModel()
    for spec in args.effect:
        model = model.with_effect(parse_effect_spec(spec))
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

    mode, sep, value = spec.partition(":")
    if not sep:
        raise ParameterError(f"--degrade '{spec}': expected MODE:INTENSITY, e.g. internal_leakage:0.5.")
    try:
        f = float(value)
    except ValueError:
        raise ParameterError(f"--degrade '{spec}': the intensity must be a number in [0, 1]. Got '{value}' instead.") from None
    clean = validate_intensities({mode.strip(): f}, where="--degrade")
    return next(iter(clean.items()))


def register(sub) -> None:
    p = sub.add_parser("simulate", help="simulate a fleet of units over flights (flight file + labels, docs/data-format.md)",
                       description="Simulate N units flying M flights each, with optional degradations and "
                                   "effects; writes the flight table and a labels table beside it "
                                   "(flights.parquet -> flights.labels.parquet).")
    p.add_argument("--units", type=positive_int, default=2, help="number of units (default 2)")
    p.add_argument("--flights", type=positive_int, default=5, help="flights per unit (default 5)")
    p.add_argument("--minutes", type=positive_float, default=60.0, help="flight duration [min] (default 60)")
    p.add_argument("--seed", type=non_negative_int, default=0, help="master seed (default 0)")
    p.add_argument("--degrade", action="append", default=[], metavar="MODE:INTENSITY",
                   help="degradation with its maximum intensity in [0, 1] (repeatable)")
    p.add_argument("--onset", default="0-0", metavar="MIN-MAX",
                   help="onset flight of the degradations, drawn uniformly per unit (default 0-0: from the first flight)")
    p.add_argument("--growth", choices=("step", "linear", "exponential"), default="step",
                   help="growth law from the onset (default step)")
    p.add_argument("--ramp-flights", type=positive_int, default=10, help="flights from onset to maximum (default 10)")
    p.add_argument("--dispersion", type=float, default=1.0, help="scale of the manufacturing dispersion (default 1)")
    add_model_arguments(p)
    p.add_argument("--batch-size", type=positive_int, default=8, help="flights simulated together (memory bound)")
    p.add_argument("--force", action="store_true", help="overwrite existing output files")
    p.add_argument("--out", required=True, help="output flight file (.parquet, .csv or .csv.gz)")
    p.set_defaults(func=run)


def parse_onset(text: str) -> tuple[int, int]:
    lo, sep, hi = text.partition("-")
    try:
        a, b = int(lo), int(hi if sep else lo)
    except ValueError:
        raise ParameterError(f"--onset must be MIN-MAX with integers >= 0. Got '{text}' instead.") from None
    if a < 0 or b < a:
        raise ParameterError(f"--onset must be MIN-MAX with 0 <= MIN <= MAX. Got '{text}' instead.")
    return a, b


def run(args: argparse.Namespace) -> int:
    from fuelhm_bench.flights.fleet import FleetConfig, build_units, flights_frame, iter_flights, labels_frame
    from fuelhm_bench.flights.mission import MissionProfile
    from fuelhm_bench.flights.schedule import ModeSchedule
    from fuelhm_bench.io import FlightWriter, labels_path_for
    from fuelhm_bench.physics.model import Dispersion

    model = model_from_args(args)
    onset_min, onset_max = parse_onset(args.onset)
    schedules = []
    for spec in args.degrade:
        mode, f = parse_degrade(spec)
        if f > 0:
            schedules.append(ModeSchedule(mode, 1.0, onset_min, onset_max, args.growth, args.ramp_flights, f))
    mission = MissionProfile(duration_s=args.minutes * 60.0, frame_s=model.controller.frame_s)
    config = FleetConfig(n_units=args.units, n_flights=args.flights, mission=mission, nominal=model,
                         dispersion=dataclasses.replace(Dispersion(), scale=args.dispersion),
                         schedules=tuple(schedules), seed=args.seed)
    out = check_output(args.out, force=args.force)
    check_output(labels_path_for(out), force=args.force)
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
