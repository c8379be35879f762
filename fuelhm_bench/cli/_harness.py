"""Options shared by ``evaluate`` and ``leaderboard``: limits, store, resume, Dask."""

from __future__ import annotations

import argparse
import contextlib
from collections.abc import Iterator
from pathlib import Path

from fuelhm_bench.cli._common import bounded, non_negative_int, positive_int
from fuelhm_bench.errors import OutputPathError


def limit_type(field: str):
    """argparse type of the command-line limit ``field`` of :class:`~fuelhm_bench.methods.sandbox.Limits`
    (``wall_s``, ``cpu_s``, ``memory_mb``, ``log_kb``): a number in its allowed range, with its unit."""
    from fuelhm_bench.methods.sandbox import LIMIT_MAX

    low, unit = {"wall_s": (0.001, "s"), "cpu_s": (0.001, "s"), "memory_mb": (256.0, "MiB"),
                 "log_kb": (1.0, "KiB")}[field]
    return bounded(float, low, LIMIT_MAX[field], unit)


def add_run_options(p: argparse.ArgumentParser) -> None:
    """Limits, results store, resume and Dask options."""
    g = p.add_argument_group("limits per method (defaults: the leaderboard file's, else CPU time = wall time, 4096 MiB, "
                                  "1024 KiB of log)")
    g.add_argument("--cpu-time", type=limit_type("cpu_s"), default=None, metavar="S", help="CPU-time limit [s]")
    g.add_argument("--memory", type=limit_type("memory_mb"), default=None, metavar="MIB",
                   help="address-space limit of the method's process [MiB] (>= 256)")
    g.add_argument("--log-size", type=limit_type("log_kb"), default=None, metavar="KIB",
                   help="cut each method's stdout/stderr log at this size [KiB] (default 1024)")
    g = p.add_argument_group("results store and resume")
    g.add_argument("--store", default=None,
                   help="SQLite results store, .sqlite, .sqlite3 or .db (default: <out>/results.sqlite)")
    g.add_argument("--rerun", action="store_true", help="evaluate again entries already in the store")
    g.add_argument("--force", action="store_true",
                   help="write into a non-empty output folder that holds no results store")
    g = p.add_argument_group("parallel and distributed runs (Dask)")
    g.add_argument("--jobs", type=positive_int, default=1,
                   help="worker processes of a local Dask cluster on the loopback interface (1: in this process, "
                        "which simulates the data not yet cached on every CPU)")
    g.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="address of an existing Dask scheduler (tcp://host:8786); see docs/methods.md")
    g.add_argument("--method-seed", type=non_negative_int, default=0, help="random_state passed to fit")
    g.add_argument("--secret-seeds", type=secret_seed_count, default=None, metavar="K",
                   help="evaluate on K secret master seeds instead of the public ones (drawn once, kept in the "
                        "results store, reused on resume): public seeds let a submission rebuild the scored "
                        "fleet from the scenario file; use this to rank untrusted submissions")
    g.add_argument("--cache-dir", default=None,
                   help="cache of simulated knowledge and flights (default: $FUELHM_BENCH_CACHE or "
                        "~/.cache/fuelhm-bench; shared by every worker of a remote cluster)")


def secret_seed_count(text: str) -> int:
    """``--secret-seeds``: an integer in [1, MAX_SECRET_SEEDS] (the bound imported when parsing, not at start-up)."""
    from fuelhm_bench.benchmark.leaderboard import MAX_SECRET_SEEDS

    return bounded(int, 1, MAX_SECRET_SEEDS)(text)


def limits_from(args, base: dict) -> dict:
    """The config's limits with the command-line overrides."""
    out = dict(base)
    for opt, name in (("cpu_time", "cpu_s"), ("memory", "memory_mb"), ("log_size", "log_kb")):
        value = getattr(args, opt)
        if value is not None:
            out[name] = value
    if "memory_mb" in out and out["memory_mb"] < 256:
        from fuelhm_bench.errors import ParameterError

        raise ParameterError(f"--memory must be >= 256 MiB. Got {out['memory_mb']:g} instead.")
    return out


@contextlib.contextmanager
def results_dir(out, store: str | None, force: bool) -> Iterator[Path]:
    """:func:`check_results_dir`, and the folder it created removed again if the run fails before writing
    anything there (a scenario that does not load left an empty --out behind)."""
    existed = Path(out).exists()
    path = check_results_dir(out, store, force)
    try:
        yield path
    except BaseException:
        if not existed and path.is_dir() and not any(path.iterdir()):
            path.rmdir()
        raise


def check_results_dir(out: Path, store: str | None, force: bool) -> Path:
    """The output folder: new, empty, or holding a results store (resume); anything else needs --force."""
    from fuelhm_bench.benchmark.store import default_store_path
    from fuelhm_bench.cli._common import check_output_dir

    from fuelhm_bench.filetypes import check_file_type

    out = Path(out)
    if store:  # (an SQLite database is not written under another type's name, e.g. the scenario's)
        check_file_type(store, "sqlite", what="results store", option="--store", writing=True, error=OutputPathError)
    if out.is_dir() and any(out.iterdir()) and not force:
        has_store = Path(store).is_file() if store else default_store_path(out).is_file()
        if not has_store:
            raise OutputPathError(f"{out} is not empty and holds no results store; refusing to write into it "
                                  f"(pass --force, or choose another --out).")
    return check_output_dir(out)
