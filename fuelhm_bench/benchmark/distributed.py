"""Leaderboard tasks on a Dask cluster: a local one (``--jobs N``) or an existing one (``--scheduler``).

The task graph: one **data build** per (scenario, seed)
(:func:`~fuelhm_bench.benchmark.leaderboard.build_data`, which fills the
simulation cache), on which every **evaluation** of that (scenario, seed)
depends (:func:`~fuelhm_bench.benchmark.leaderboard.evaluate_task`: it reads the
built data from the cache and runs the method sealed on the worker). A worker
keeps the evaluation it prepared (its own build's, or the first one it loaded)
for the next evaluations of that (scenario, seed) it runs. Results
come back to the client, which alone writes the store as they complete, so an
interrupted distributed run resumes like a local one.

A local cluster uses worker *processes* (one thread each) listening on the
loopback interface only. For several machines, start a scheduler and workers
yourself (``dask scheduler`` on one host, ``dask worker tcp://HOST:8786
--nthreads 1`` on the others, e.g. over SSH, or with dask-jobqueue on a batch
system) with a cache directory every worker can read (``--cache-dir`` on a
shared file system), and pass ``--scheduler tcp://HOST:8786``.
"""

from __future__ import annotations

import threading
from collections import OrderedDict

from fuelhm_bench.errors import FuelHMError, ParameterError

__all__ = ["run_distributed"]

#: Prepared evaluations kept by a worker process, keyed by (scenario, seed, fidelity, scale, cache dir,
#: flight minutes): a data build leaves its evaluation there, and the evaluations that land on the same
#: worker use it instead of loading the data again (each load costs CPU-seconds).
_EVALUATIONS: OrderedDict = OrderedDict()
_EVALUATIONS_SIZE = 2
_EVALUATIONS_LOCK = threading.Lock()
_KEY_LOCKS: dict = {}


#: Environment of the local cluster's worker processes, set before they start (see :func:`_client`).
WORKER_ENVIRONMENT: dict[str, str] = {"MALLOC_ARENA_MAX": "1"}


def _client(jobs: int, scheduler: str | None):
    try:
        from dask.distributed import Client, LocalCluster
    except ImportError:  # pragma: no cover - distributed is a dependency
        raise FuelHMError("--jobs/--scheduler need the 'distributed' package (pip install distributed).") from None
    if scheduler is not None:
        try:
            return Client(scheduler, timeout="20s"), None
        except (OSError, TimeoutError, ValueError) as exc:
            raise ParameterError(f"--scheduler {scheduler}: cannot connect to a Dask scheduler there: {exc}") from None
    if not (isinstance(jobs, int) and jobs >= 1):
        raise ParameterError(f"--jobs must be an integer >= 1. Got {jobs!r} instead.")
    import dask

    # A worker runs its tasks on a thread, and glibc gives each new thread its own malloc arena, whose
    # freed flight-sized arrays go back to the system and fault in again: a data build took 15 % more
    # CPU there than on a main thread (2.3 times the page faults). With one arena every thread uses
    # the main heap, kept by tune_allocator. glibc reads the variable when the worker starts, hence
    # the nanny's environment before the spawn (docs/methods.md: the same for workers you start).
    with dask.config.set({f"distributed.nanny.pre-spawn-environ.{k}": v for k, v in WORKER_ENVIRONMENT.items()}):
        cluster = LocalCluster(n_workers=jobs, threads_per_worker=1, processes=True, host="127.0.0.1",
                               dashboard_address=None, silence_logs=40)
    from fuelhm_bench.methods.sandbox import protect_process

    client = Client(cluster)
    protect_process()  # the client and scheduler, then every nanny and worker: sealed methods cannot read them
    client.run(protect_process, nanny=True)
    client.run(protect_process)
    return client, cluster


def run_distributed(todo, kwargs: dict, done, *, jobs: int = 2, scheduler: str | None = None) -> None:
    """Run ``todo`` tasks on Dask; ``done(record, tables)`` is called in this process as each one completes."""
    from dask.distributed import as_completed

    client, cluster = _client(jobs, scheduler)
    try:
        builds = {}
        futures = []
        cost = _build_costs(todo)
        for t in sorted(todo, key=lambda t: -cost[t.scenario]):  # longest builds first (Dask priority too)
            group = (t.scenario, t.seed, t.fidelity, t.scale)
            if group not in builds:
                builds[group] = client.submit(_build_data, t.scenario, t.seed, t.fidelity, t.scale,
                                              kwargs["cache_dir"], kwargs["flight_minutes"], pure=False,
                                              key=f"data-{t.scenario_id}-{t.seed}-{t.key[:8]}",
                                              priority=cost[t.scenario])
            futures.append(client.submit(_evaluate_after, builds[group], t, kwargs, pure=False,
                                         key=f"eval-{t.key[:16]}", priority=cost[t.scenario] + 1e6))
        for future in as_completed(futures):
            try:
                record, tables = future.result()
            except Exception as exc:  # noqa: BLE001 - a worker lost or a data build failed
                raise FuelHMError(f"A distributed task failed: {type(exc).__name__}: {exc}") from None
            done(record, tables)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _build_costs(todo) -> dict:
    """Simulated flight-hours of each scenario's data build (scored and training fleets), for ordering.

    A leaderboard's makespan on a few workers is set by its longest data builds
    (``all_modes`` simulates four times as much as ``paper_2012``): they start
    first, and an evaluation, once its data is built, goes before any build.
    """
    from fuelhm_bench.scenarios import load_scenario

    costs = {}
    for t in todo:
        if t.scenario not in costs:
            try:
                costs[t.scenario] = float(load_scenario(t.scenario).run_cost().flight_hours)
            except Exception:  # noqa: BLE001 - ordering only; the build itself reports the problem
                costs[t.scenario] = 0.0
    return costs


def _evaluation(scenario, seed, fidelity, scale, cache_dir, flight_minutes):
    """This worker's prepared evaluation of (scenario, seed), loaded once (:data:`_EVALUATIONS`).

    The worker holds it as it holds it during an evaluation anyway: the method runs in its own sealed
    process (:mod:`fuelhm_bench.methods.sandbox`), which never shares this process's memory.
    """
    from fuelhm_bench.benchmark.harness import prepare_evaluation

    key = (str(scenario), seed, fidelity, float(scale), None if cache_dir is None else str(cache_dir), flight_minutes)
    with _EVALUATIONS_LOCK:
        lock = _KEY_LOCKS.setdefault(key, threading.Lock())
    with lock:  # a worker with several threads loads each key once
        with _EVALUATIONS_LOCK:
            evaluation = _EVALUATIONS.get(key)
            if evaluation is not None:
                _EVALUATIONS.move_to_end(key)
                return evaluation
        evaluation = prepare_evaluation(scenario, fidelity=fidelity, seed=seed, scale=scale, cache_dir=cache_dir,
                                        flight_minutes=flight_minutes)
        with _EVALUATIONS_LOCK:
            _EVALUATIONS[key] = evaluation
            while len(_EVALUATIONS) > _EVALUATIONS_SIZE:
                _EVALUATIONS.popitem(last=False)
    return evaluation


def _build_data(scenario: str, seed: int, fidelity, scale: float, cache_dir=None, flight_minutes=None) -> dict:
    """:func:`~fuelhm_bench.benchmark.leaderboard.build_data` on a worker, which keeps the evaluation it prepared.

    The worker's zygote (the interpreter its sealed methods fork from) starts first and imports its
    modules meanwhile.
    """
    from fuelhm_bench.methods.sandbox import prestart_zygote

    prestart_zygote()
    ev = _evaluation(scenario, seed, fidelity, scale, cache_dir, flight_minutes)
    return {"test": ev.n_flights, "fit": len(ev.fit_indicators), "calibration": len(ev.calibration_indicators),
            "fidelity": ev.fidelity}


def _evaluate_after(_built: dict, task, kwargs: dict):
    from fuelhm_bench.benchmark.leaderboard import evaluate_task

    evaluation = _evaluation(task.scenario, task.seed, task.fidelity, task.scale, kwargs["cache_dir"],
                             kwargs["flight_minutes"])
    return evaluate_task(task, evaluation=evaluation, **kwargs)
