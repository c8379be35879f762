"""``fuelhm-bench indicators``: the 10 on-board indicators of every flight of a file."""

from __future__ import annotations

import argparse
import sys

from fuelhm_bench.cli._common import check_output, extraction_config, progress_bar
from fuelhm_bench.io.outputs import atomic_output


def register(sub) -> None:
    p = sub.add_parser("indicators", help="extract the 10 indicators of every flight (one row per flight)",
                       description="Extract the velocity-gain curve and the 10 indicators of the paper's Table I "
                                   "(X1, Y1, X2, Y2, Inb, I0, Hys0, G_in, G_out, G_null) from every flight of a "
                                   "flight file (docs/data-format.md). Output: one row per flight with flight_id, unit_id (when "
                                   "present), the indicators, their validity flags and the reason of any NaN. "
                                   "Flights that break its per-flight rules are listed on stderr and kept as rows with "
                                   "every indicator invalid.")
    p.add_argument("flights", help="flight file (.parquet, .csv, .csv.gz)")
    p.add_argument("--force", action="store_true", help="overwrite the output file")
    p.add_argument("--out", required=True, help="output table (.parquet, .csv or .csv.gz)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import pandas as pd

    from fuelhm_bench.indicators import extract_table
    from fuelhm_bench.io import read_flights, split_flights

    out = check_output(args.out, force=args.force, kind="table", what="indicator table",
                       inputs={"FLIGHTS": args.flights})
    flights, rejected = split_flights(read_flights(args.flights), source=str(args.flights))
    rows = []
    with progress_bar(len(flights), "extracting") as bar:
        for start in range(0, len(flights), 64):
            chunk = flights[start:start + 64]
            configs = [extraction_config(f) for f in chunk]
            if all(c == configs[0] for c in configs):
                rows.append(extract_table(chunk, configs[0], on_error="flag"))
            else:  # bench recordings (no end stops) mixed with flights: one configuration each
                rows += [extract_table([f], c, on_error="flag") for f, c in zip(chunk, configs)]
            bar.update(len(chunk))
    table = pd.concat(rows, ignore_index=True) if rows else pd.DataFrame()
    if rejected:
        from fuelhm_bench.indicators import table_columns
        from fuelhm_bench.taxonomy import INDICATOR_NAMES

        rej = pd.DataFrame({"flight_id": [r.flight_id for r in rejected]})
        if "unit_id" in table.columns or any(r.unit_id is not None for r in rejected):
            rej["unit_id"] = [r.unit_id for r in rejected]
        for name in INDICATOR_NAMES:
            rej[name] = float("nan")
            rej[f"{name}_valid"] = False
        rej["n_points"] = 0
        rej["quality_reason"] = [f"rejected: {r.reason}" for r in rejected]
        table = pd.concat([table, rej[[c for c in table_columns("unit_id" in rej) if c in rej]]], ignore_index=True)
        for r in rejected:
            print(f"warning: {r}", file=sys.stderr)
    _refuse_meaningless(table, args.flights)
    with atomic_output(out, force=args.force, option="--out") as tmp:
        if out.suffix.lower() == ".parquet":
            table.to_parquet(tmp, index=False)
        else:  # .csv, or .csv.gz (compression inferred from the name)
            table.to_csv(tmp, index=False)
    n_ok = int((table["quality_reason"] == "").sum()) if len(table) else 0
    print(f"wrote {len(table)} rows to {out} ({n_ok} flights with all 10 indicators valid, "
          f"{len(rejected)} rejected)")
    return 0


def _refuse_meaningless(table, source) -> None:
    """No table is written when no flight has a single valid indicator (it would mean nothing)."""
    from fuelhm_bench.errors import DataFormatError
    from fuelhm_bench.taxonomy import INDICATOR_NAMES

    valid = table[[f"{n}_valid" for n in INDICATOR_NAMES]].to_numpy(dtype=bool) if len(table) else None
    if valid is not None and valid.any():
        return
    reasons = table["quality_reason"].value_counts() if len(table) else None
    top = f" Most common reason ({reasons.iloc[0]} of {len(table)} flights): {reasons.index[0]}" \
        if reasons is not None and len(reasons) else ""
    raise DataFormatError(f"{source}: no flight has a single valid indicator, so no table is written.{top}")
