"""The ``fuelhm-bench`` command line.

Each command lives in its own module of this package exposing
``register(subparsers)`` (adds its parser and sets ``func``). Errors derived
from :class:`~fuelhm_bench.errors.FuelHMError` are printed as one clean line
(``error: ...``) with exit status 2; ``--debug`` shows the traceback.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from fuelhm_bench import __version__
from fuelhm_bench.errors import FuelHMError

#: Command modules, in the order of ``--help``.
COMMAND_MODULES = (
    "simulate", "sweep", "plot_curve", "indicators", "itl", "calibrate", "paper", "evaluate", "leaderboard",
    "validate", "schema", "discrepancy", "drift_sweep",
)


def build_parser() -> argparse.ArgumentParser:
    """The top-level parser with every available command registered."""
    parser = argparse.ArgumentParser(
        prog="fuelhm-bench",
        description="Health-monitoring benchmark for a turbofan fuel-system actuation loop "
                    "(Lamoureux, Masse & Mechbal, IEEE PHM 2012).")
    parser.add_argument("--version", action="version", version=f"fuelhm-bench {__version__}")
    parser.add_argument("--debug", action="store_true", help="show full tracebacks on errors")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name in COMMAND_MODULES:
        try:
            module = importlib.import_module(f"fuelhm_bench.cli.{name}")
        except ModuleNotFoundError as exc:
            if exc.name == f"fuelhm_bench.cli.{name}":
                continue  # command not available in this build
            raise
        module.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``fuelhm-bench`` console script."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 1
    try:
        return int(args.func(args) or 0)
    except FuelHMError as exc:
        if args.debug:
            raise
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
