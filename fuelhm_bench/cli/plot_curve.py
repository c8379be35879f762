"""``fuelhm-bench plot-curve``: draw velocity-gain curves (paper Figs. 4, 5 and 8)."""

from __future__ import annotations

import argparse
import sys

from fuelhm_bench.cli._common import check_output
from fuelhm_bench.errors import DataFormatError


def register(sub) -> None:
    p = sub.add_parser("plot-curve", help="plot the velocity-gain curve of recorded flights",
                       description="Draw the in-flight velocity-gain curve (control current vs cylinder "
                                   "velocity from the differentiated LVDT position): raw points and the "
                                   "local-mean smoothing (paper Fig. 4); --annotate marks the indicators "
                                   "(Fig. 5); --overlay adds curves from other files, e.g. under "
                                   "degradation (Fig. 8).")
    p.add_argument("flights", help="flight file (.parquet, .csv, .csv.gz; format: docs/data-format.md)")
    p.add_argument("--flight", action="append", default=None, metavar="ID",
                   help="flight id to draw (repeatable; default: the first flight of the file)")
    p.add_argument("--annotate", action="store_true", help="mark the 10 indicators on the curve (Fig. 5)")
    p.add_argument("--overlay", action="append", default=[], metavar="FILE[=LABEL]",
                   help="overlay the first flight of another file as a smoothed curve (Fig. 8; repeatable)")
    p.add_argument("--title", default=None, help="figure title")
    p.add_argument("--force", action="store_true", help="overwrite the output file")
    p.add_argument("--out", required=True, help="output image (.png, .pdf or .svg)")
    p.set_defaults(func=run)


def _select(flights, wanted, source):
    if not flights:
        raise DataFormatError(f"{source}: no usable flight (all were rejected).")
    if not wanted:
        return [flights[0]]
    by_id = {str(f.flight_id): f for f in flights}
    chosen = []
    for w in wanted:
        if w not in by_id:
            shown = ", ".join(list(by_id)[:10])
            raise DataFormatError(f"{source}: no usable flight with id '{w}'. Available: {shown}"
                                  f"{', ...' if len(by_id) > 10 else ''}.")
        chosen.append(by_id[w])
    return chosen


def _load(path):
    from fuelhm_bench.io import read_flights, split_flights

    flights, rejected = split_flights(read_flights(path), source=str(path), min_current_range_ma=0.0)
    for r in rejected:
        print(f"warning: {r}", file=sys.stderr)
    return flights


def _curve(f, source, annotate):
    """Raw points, smoothed curve and indicators of one flight; refuses a flight with nothing to draw."""
    from fuelhm_bench.cli._common import naming_file

    with naming_file(source):  # an extraction error names the flight, not the file it came from
        return _curve_of(f, source, annotate)


def _curve_of(f, source, annotate):
    from fuelhm_bench.cli._common import extraction_config
    from fuelhm_bench.indicators import extract_indicators, velocity_gain_curve, velocity_points

    config = extraction_config(f)
    i, v = velocity_points(f.time_s, f.current_ma, f.position_mm, config, flight_id=f.flight_id)
    if i.size == 0:
        raise DataFormatError(
            f"{source}: flight {f.flight_id!r} has no usable velocity-gain point: all its {f.n_samples} samples are "
            "masked (end stops, current limits, recording gaps or fast current steps), so there is nothing to "
            "draw. Check the columns' units (s, mA, mm) and that the current moves the rod.")
    curve = velocity_gain_curve(f.time_s, f.current_ma, f.position_mm, config, flight_id=f.flight_id)
    inds = extract_indicators(f.time_s, f.current_ma, f.position_mm, config, flight_id=f.flight_id) \
        if annotate else None
    return i, v, curve, inds


def run(args: argparse.Namespace) -> int:
    import numpy as np

    from fuelhm_bench.indicators.plot import velocity_gain_figure
    from fuelhm_bench.io.outputs import atomic_output

    inputs = {"FLIGHTS": args.flights, **{f"--overlay {spec}": spec.partition("=")[0] for spec in args.overlay}}
    out = check_output(args.out, force=args.force, kind="image", what="figure", inputs=inputs)
    chosen = _select(_load(args.flights), args.flight, args.flights)
    curves, labels, inds = [], [], []
    pts_i, pts_v = [], []
    for f in chosen:
        i, v, curve, ind = _curve(f, args.flights, args.annotate)
        pts_i.append(i)
        pts_v.append(v)
        curves.append(curve)
        labels.append(f"flight {f.flight_id}")
        inds.append(ind)
    for spec in args.overlay:
        path, _, label = spec.partition("=")
        f = _select(_load(path), None, path)[0]
        _, _, curve, ind = _curve(f, path, args.annotate)
        curves.append(curve)
        labels.append(label or path)
        inds.append(ind)
    current = np.concatenate(pts_i)
    velocity = np.concatenate(pts_v)
    if len(curves) == 1:
        fig = velocity_gain_figure(current, velocity, curves[0], inds[0], labels=labels, title=args.title)
    else:
        fig = velocity_gain_figure(current, velocity, curves, inds if args.annotate else None, labels=labels,
                                   title=args.title)
    with atomic_output(out, force=args.force, option="--out") as tmp:
        fig.savefig(tmp, dpi=130)
    print(f"wrote {out} ({len(curves)} curve{'s' if len(curves) > 1 else ''}, {current.size} raw points)")
    return 0
