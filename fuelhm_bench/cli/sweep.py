"""``fuelhm-bench sweep``: the paper's velocity-gain sweep (slow open-loop current ramp)."""

from __future__ import annotations

import argparse

from fuelhm_bench.cli._common import bounded, check_output, non_negative_int, positive_float
from fuelhm_bench.errors import ParameterError

#: Largest sweep written, in samples (about 0.5 GB in memory).
MAX_SAMPLES = 10_000_000
from fuelhm_bench.cli.simulate import add_model_arguments, model_from_args, parse_degrade


def register(sub) -> None:
    p = sub.add_parser("sweep", help="velocity-gain sweep of a model (paper section IV.B)",
                       description="Ramp the current slowly from the lower to the upper saturation and back, "
                                   "open loop, on a virtual bench without end stops, and write the result in the "
                                   "flight format (one flight; the rod position is the true one of the virtual "
                                   "bench, phase 'bench_sweep' marks it, and the true velocity is in an extra "
                                   "'velocity_true_mm_s' column).")
    p.add_argument("--min-ma", type=bounded(float, -100.0, 100.0, "mA"), default=-12.0,
                   help="lowest current [mA] (default -12)")
    p.add_argument("--max-ma", type=bounded(float, -100.0, 100.0, "mA"), default=12.0,
                   help="highest current [mA] (default 12)")
    p.add_argument("--ramp-seconds", type=bounded(float, 0.1, 3600.0, "s"), default=60.0,
                   help="duration of each one-way ramp [s], in [0.1, 3600]")
    p.add_argument("--cycles", type=bounded(int, 1, 100), default=1, help="up-and-down cycles, in [1, 100] (default 1)")
    p.add_argument("--n2-pct", type=positive_float, default=82.0, help="engine speed, sets supply pressure [%%]")
    p.add_argument("--degrade", action="append", default=[], metavar="MODE:INTENSITY",
                   help="degradation intensity in [0, 1] (repeatable)")
    p.add_argument("--seed", type=non_negative_int, default=None,
                   help="not used: the sweep file records the true rod position (refused when given)")
    add_model_arguments(p)
    p.add_argument("--force", action="store_true", help="overwrite the output file")
    p.add_argument("--out", required=True, help="output file (.parquet, .csv or .csv.gz)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import numpy as np
    import pandas as pd

    from fuelhm_bench.flights.sweep import VelocityGainSweep, run_sweep
    from fuelhm_bench.io import BENCH_PHASE, write_flights

    n_samples = 2 * args.cycles * args.ramp_seconds * (args.frame_rate or 100.0)
    if n_samples > MAX_SAMPLES:
        raise ParameterError(f"--cycles {args.cycles} x 2 x --ramp-seconds {args.ramp_seconds:g} at "
                             f"{args.frame_rate or 100.0:g} Hz is {n_samples:.3g} samples; the sweep must be at most "
                             f"{MAX_SAMPLES:.0e} samples (shorter ramps or fewer cycles).")
    if args.max_ma <= args.min_ma:
        raise ParameterError(f"--max-ma must be > --min-ma ({args.min_ma:g} mA). Got {args.max_ma:g} instead.")
    unused = [opt for opt, value in (("--noise-um", args.noise_um), ("--adc-bits", args.adc_bits),
                                     ("--seed", args.seed)) if value is not None]
    if unused:  # they would be accepted and change nothing
        raise ParameterError(f"{', '.join(unused)}: a sweep records the true rod position (a virtual bench without "
                             f"the LVDT), so the sensor's noise, resolution and noise seed do not apply; leave "
                             f"{'it' if len(unused) == 1 else 'them'} out.")
    out_path = check_output(args.out, force=args.force, kind="table", what="flight file",
                            inputs={"--model": args.model})
    model = model_from_args(args)
    model = model.degraded(dict(parse_degrade(s) for s in args.degrade))
    sweep = VelocityGainSweep(current_min_a=args.min_ma * 1e-3, current_max_a=args.max_ma * 1e-3,
                              ramp_duration_s=args.ramp_seconds, n2_frac=args.n2_pct / 100.0,
                              frame_s=model.controller.frame_s, cycles=args.cycles)
    res = run_sweep(model, sweep, seed=0)  # (the seed only draws the LVDT noise, which the file does not carry)
    out = res.output
    n = len(out.time_s)
    frame = pd.DataFrame({
        "flight_id": np.zeros(n, dtype=np.int64),
        "time_s": out.time_s,
        "current_mA": out.current_a * 1e3,
        # Virtual bench without end stops: the rod travels far beyond the LVDT range, so
        # the file carries the true (noise-free, unquantized) rod position.
        "position_mm": out.true_position_m * 1e3,
        "n2_pct": np.full(n, args.n2_pct),
        "velocity_true_mm_s": out.true_velocity_m_s * 1e3,
        # Declares the bench without end stops (rule F6 of fuelhm_bench.io.flights; no end-stop mask).
        "phase": np.full(n, BENCH_PHASE, dtype=object),
    })
    write_flights(frame, out_path, overwrite=args.force)
    print(f"wrote a {n}-sample velocity-gain sweep to {out_path}")
    return 0
