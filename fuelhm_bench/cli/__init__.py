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
    "validate", "schema", "discrepancy", "fidelity", "export", "score", "drift_sweep",
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


def _is_interrupt(exc: BaseException) -> bool:
    """Whether ``exc`` is, or wraps, a Ctrl-C.

    An interrupt that arrives while numba-compiled code runs surfaces, when the
    call returns, as ``SystemError: CPUDispatcher(...) returned a result with an
    exception set`` whose cause is the ``KeyboardInterrupt``.
    """
    seen: set[int] = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False


_INTERRUPTED = {"seen": False, "done": False}


def _on_sigint(signum, frame) -> None:  # pragma: no cover - exercised by a subprocess test
    _INTERRUPTED["seen"] = True
    raise KeyboardInterrupt


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``fuelhm-bench`` console script.

    Exit status: 0 on success, 2 for bad input (one ``error: ...`` line naming
    the file, field or option; argparse usage errors, a missing command and the
    invalid files of ``validate`` too), 3 when a method of ``evaluate`` /
    ``leaderboard`` did not finish ok, 4 when ``fidelity`` misses a target, 130 on Ctrl-C
    (one line; outputs are written atomically, so no partial file is left that
    looks complete).
    """
    import signal
    import threading

    if threading.current_thread() is threading.main_thread():
        previous = signal.signal(signal.SIGINT, _on_sigint)
    else:  # pragma: no cover - signals can only be handled in the main thread
        previous = None
    _INTERRUPTED.update(seen=False, done=False)
    try:
        return _run(argv)
    except KeyboardInterrupt:
        return _interrupted()
    except SystemError as exc:
        if _INTERRUPTED["seen"] or _is_interrupt(exc):
            return _interrupted()
        raise
    finally:
        if previous is not None and not _INTERRUPTED["done"]:
            signal.signal(signal.SIGINT, previous)


def _interrupted() -> int:
    import signal
    import threading

    if threading.current_thread() is threading.main_thread():
        # Handled: a late or repeated SIGINT (e.g. re-raised by a native library's handler) must not
        # turn the clean exit 130 into a death by signal.
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        _INTERRUPTED["done"] = True
    print("fuelhm-bench: interrupted (Ctrl-C); no partial output was published.", file=sys.stderr)
    return 130


def _run(argv: list[str] | None) -> int:
    from fuelhm_bench.cli._common import option_message

    parser = build_parser()
    wants_json = "--json" in (sys.argv[1:] if argv is None else list(argv))
    if wants_json:  # a command-line mistake must still give its one JSON object (the message also on stderr)
        import contextlib
        import io

        captured = io.StringIO()
        try:
            with contextlib.redirect_stderr(captured):
                args = parser.parse_args(argv)
        except SystemExit as exc:
            sys.stderr.write(captured.getvalue())
            if exc.code not in (0, None):
                lines = [ln for ln in captured.getvalue().splitlines() if ln.strip()]
                _json_error(lines[-1] if lines else "invalid command line", int(exc.code))
            raise
        sys.stderr.write(captured.getvalue())
    else:
        args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        print("error: give a COMMAND (listed above).", file=sys.stderr)
        return 2
    try:
        return int(args.func(args) or 0)
    except FuelHMError as exc:
        if args.debug:
            raise
        message = option_message(str(exc), args)
        print(f"error: {message}", file=sys.stderr)
        if getattr(args, "json", False):
            _json_error(message, 2)
        return 2


def _json_error(message: str, status: int) -> None:
    """The one JSON object of a ``--json`` command that failed: ``{"error": ..., "exit_status": ...}`` on stdout."""
    import json

    print(json.dumps({"verdict": None, "error": message, "exit_status": status}))


def console_main() -> None:  # pragma: no cover - the console script; tested through a subprocess
    """The ``fuelhm-bench`` console script: :func:`main`, then exit with its status.

    After a Ctrl-C the process ends at once with status 130 (streams flushed,
    outputs already discarded): interpreter finalization would restore the
    default SIGINT action, and a late second SIGINT (some native libraries
    re-raise the signal) would then kill the process instead of exiting 130.
    """
    import os

    code = main()
    if code == 130:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(130)
    sys.exit(code)


if __name__ == "__main__":  # pragma: no cover
    console_main()
