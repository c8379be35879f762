"""Evaluate methods on scenarios and seeds, store every result, rank them (the leaderboard).

``fuelhm-bench evaluate`` (one scenario) and ``fuelhm-bench leaderboard`` (a
configuration file, ``leaderboard/methods.yaml``) both call :func:`run_board`:

1. the **tasks**: one per (method setting, scenario, seed), each with its
   content key (:func:`~fuelhm_bench.benchmark.store.evaluation_key`); the keys
   already in the results store are skipped (``rerun=True`` forces them), so a
   run killed at any moment and started again evaluates only what is missing;
2. per (scenario, seed), the **data build** (published knowledge, training and
   scored flights: :func:`~fuelhm_bench.benchmark.harness.prepare_evaluation`,
   cached on disk) is done once and shared by every method;
3. each **evaluation** runs the method sealed
   (:func:`~fuelhm_bench.benchmark.harness.run_in_env`), scores it and returns a
   record and its tables, which this process alone writes to the store;
4. the **views** (:mod:`fuelhm_bench.benchmark.views`) are rebuilt from the store.

Steps 2 and 3 run in this process (``jobs=1``), or as tasks on a Dask cluster:
a local one with ``jobs`` worker processes, or an existing one at ``scheduler``.
"""

from __future__ import annotations

import dataclasses
import math
import sys
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pandas as pd

from fuelhm_bench.errors import FuelHMError, ParameterError, ScenarioError, show_value

__all__ = ["LeaderboardConfig", "LeaderboardEntry", "Task", "evaluate_task", "plan_tasks", "run_board"]


@dataclass(frozen=True)
class LeaderboardEntry:
    """A method of the leaderboard: ``module:Class`` and its hyperparameters (sorted ``(name, value)`` pairs)."""

    method: str
    params: tuple = ()


#: Most secret seeds a run may ask for (each is a full evaluation of every method on every scenario).
MAX_SECRET_SEEDS = 100


@dataclass(frozen=True)
class LeaderboardConfig:
    """What a leaderboard run evaluates.

    Parameters
    ----------
    methods : tuple of LeaderboardEntry
    scenarios : tuple of str
        Shipped names or YAML paths.
    seeds : tuple of int, default=(None,)
        Master seeds (None: the scenario's own).
    scale : float, default=1.0
        Multiplies the number of test units, > 0.
    timeout_s : float, default=900.0
        Wall-time limit per method and scenario [s].
    fidelity : {"physics", "surrogate"} or None, default=None
        None: each scenario's own.
    limits : dict, default={}
        Other limits per method: ``cpu_s``, ``memory_mb``, ``log_kb``
        (:class:`~fuelhm_bench.methods.sandbox.Limits`).
    secret_seeds : int, default=0
        When > 0, evaluate on that many secret master seeds instead of ``seeds``: drawn from the
        operating system at the first run and kept in the results store
        (:meth:`~fuelhm_bench.benchmark.store.ResultStore.secret_seeds`). Public seeds let a
        submission rebuild the scored fleet from the public scenario file; use secret ones for a
        ranking of untrusted submissions.
    """

    methods: tuple
    scenarios: tuple
    seeds: tuple = (None,)
    scale: float = 1.0
    timeout_s: float = 900.0
    fidelity: str | None = None
    limits: tuple = ()
    secret_seeds: int = 0

    @classmethod
    def from_yaml(cls, path) -> LeaderboardConfig:
        """Load ``leaderboard/methods.yaml`` (safe loader; errors name the file and field)."""
        from fuelhm_bench.methods.sandbox import Limits

        from fuelhm_bench.yamlfiles import read_yaml

        path = Path(path)
        data = read_yaml(path, "leaderboard file", ScenarioError)
        if not isinstance(data, dict):
            raise ScenarioError(f"{path}: a leaderboard file is a mapping with 'methods' and 'scenarios'.")
        allowed = {"methods", "scenarios", "seeds", "secret_seeds", "scale", "timeout_s", "fidelity", "limits"}
        for key in data:
            if key not in allowed:
                import difflib

                close = difflib.get_close_matches(str(key), sorted(allowed), n=1)
                raise ScenarioError(f"{path}: unknown key '{key}'. Allowed: {', '.join(sorted(allowed))}."
                                    + (f" Did you mean '{close[0]}'?" if close else ""))
        from fuelhm_bench.methods.loading import entry_point_problem

        import difflib

        for key in ("methods", "scenarios"):
            if not isinstance(data.get(key), list) or not data.get(key):
                raise ScenarioError(f"{path}: '{key}' must be a non-empty list. Got {data.get(key)!r} instead.")
        methods = []
        for i, m in enumerate(data["methods"]):
            if isinstance(m, dict):
                for k in m:
                    if k not in ("method", "params"):
                        close = difflib.get_close_matches(str(k), ["method", "params"], n=1)
                        raise ScenarioError(f"{path}: methods[{i}]: unknown key {k!r}. Allowed: method, params."
                                            + (f" Did you mean '{close[0]}'?" if close else ""))
            spec = m if isinstance(m, str) else m.get("method") if isinstance(m, dict) else None
            if isinstance(spec, str) and (problem := entry_point_problem(spec)) is not None:
                field = f"methods[{i}]" if isinstance(m, str) else f"methods[{i}].method"
                raise ScenarioError(f"{path}: {field} {problem}")
            if isinstance(m, str):
                methods.append(LeaderboardEntry(m))
            elif isinstance(m, dict) and isinstance(m.get("method"), str):
                params = m.get("params") or {}
                if not isinstance(params, dict):
                    raise ScenarioError(f"{path}: methods[{i}].params must be a mapping. Got {params!r} instead.")
                bad = [k for k in params if not (isinstance(k, str) and k.isidentifier())]
                if bad:
                    raise ScenarioError(f"{path}: methods[{i}].params: hyperparameter names must be Python names. "
                                        f"Got {bad[0]!r} instead.")
                methods.append(LeaderboardEntry(m["method"], tuple(sorted(params.items()))))
            else:
                raise ScenarioError(f"{path}: methods[{i}] must be 'module:Class' or {{method: ..., params: ...}}. "
                                    f"Got {m!r} instead.")
        scenarios = data["scenarios"]
        if not all(isinstance(s, str) and s for s in scenarios):
            raise ScenarioError(f"{path}: scenarios must be names or YAML paths. Got {scenarios!r} instead.")
        for field, items in (("methods", methods), ("scenarios", scenarios)):
            seen = set()
            for i, item in enumerate(items):
                if repr(item) in seen:
                    raise ScenarioError(f"{path}: {field}[{i}] repeats an earlier entry ({_entry_text(item)}): it "
                                        f"would be evaluated and listed twice.")
                seen.add(repr(item))
        fidelity = data.get("fidelity")
        if fidelity not in (None, "physics", "surrogate"):
            raise ScenarioError(f"{path}: fidelity must be one of physics, surrogate or null. Got {fidelity!r} instead.")
        from fuelhm_bench.scenarios.schema import MAX_SEED

        seeds = data.get("seeds", [None])
        if not isinstance(seeds, list) or not seeds or not all(
                s is None or (isinstance(s, int) and not isinstance(s, bool) and 0 <= s <= MAX_SEED) for s in seeds):
            raise ScenarioError(f"{path}: seeds must be a non-empty list of integers in [0, {MAX_SEED}] or null (null: "
                                f"each scenario's own master seed), e.g. [null] or [1, 2]. Got {seeds!r} instead.")
        if len(set(seeds)) < len(seeds):
            raise ScenarioError(f"{path}: seeds repeats a seed: {seeds!r}.")
        secret = data.get("secret_seeds", 0)
        if not (isinstance(secret, int) and not isinstance(secret, bool) and 0 <= secret <= MAX_SECRET_SEEDS):
            raise ScenarioError(f"{path}: secret_seeds must be an integer in [0, {MAX_SECRET_SEEDS}] (how many secret "
                                f"master seeds to evaluate on). Got {show_value(secret)} instead.")
        if secret and "seeds" in data:
            raise ScenarioError(f"{path}: give seeds or secret_seeds, not both (secret_seeds replaces the public "
                                f"seeds).")
        scale = _number(path, "scale", data.get("scale", 1.0), positive=True)
        if scale > 1.0:
            raise ScenarioError(f"{path}: scale is the fraction of each scenario's test units kept, in (0, 1]. Got "
                                f"{show_value(scale)} instead.")
        timeout = _number(path, "timeout_s", data.get("timeout_s", 900.0), positive=True)
        limits = data.get("limits") or {}
        if isinstance(limits, dict) and "wall_s" in limits:
            raise ScenarioError(f"{path}: limits.wall_s: the wall-time limit is the file's timeout_s "
                                f"(timeout_s: {show_value(limits['wall_s'])}).")
        try:
            Limits.coerce({**limits, "wall_s": timeout} if isinstance(limits, dict) else limits, f"{path}: limits")
        except ParameterError as exc:
            raise ScenarioError(str(exc)) from None
        return cls(tuple(methods), tuple(str(s) for s in scenarios), tuple(seeds), scale, timeout, fidelity,
                   tuple(sorted(limits.items())), secret)


def _entry_text(item) -> str:
    if isinstance(item, LeaderboardEntry):
        return item.method + (f" with {dict(item.params)}" if item.params else "")
    return str(item)


def _number(path, field: str, value, *, positive: bool) -> float:
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
    if not ok or (positive and value <= 0):
        raise ScenarioError(f"{path}: {field} must be a finite number > 0. Got {value!r} instead.")
    return float(value)


# --------------------------------------------------------------------------- tasks
@dataclass(frozen=True)
class Task:
    """One evaluation to run: a method setting on a scenario and seed, and its store key."""

    key: str
    method: str
    params: tuple
    shared_params: tuple
    scenario: str
    scenario_id: str
    seed: int
    fidelity: str | None
    scale: float
    source_hash: str = ""

    @property
    def params_dict(self) -> dict:
        """The setting's own hyperparameters."""
        return dict(self.params)

    @property
    def short(self) -> str:
        """First 8 hex digits of the key of the setting (method + parameters), for folder names."""
        import hashlib

        from fuelhm_bench.benchmark.store import typed_json

        blob = typed_json({"method": self.method, "params": dict(self.params), "shared": dict(self.shared_params)})
        return hashlib.sha256(blob.encode()).hexdigest()[:8]


def plan_tasks(config: LeaderboardConfig, shared_params: dict | None = None) -> list[Task]:
    """Every (method setting, scenario, seed) of ``config`` with its content key."""
    from fuelhm_bench import __version__
    from fuelhm_bench.benchmark.store import evaluation_key
    from fuelhm_bench.datasets.cache import recipe_digest
    from fuelhm_bench.methods.sandbox import source_hash
    from fuelhm_bench.scenarios import load_scenario

    shared = tuple(sorted((shared_params or {}).items()))
    hashes = {m.method: source_hash(m.method) for m in config.methods}
    tasks = []
    ids: dict[str, str] = {}
    for scenario in config.scenarios:
        sc = load_scenario(scenario)
        digest = recipe_digest(sc)  # an edited copy of a shipped file keeps its name and version
        if sc.id in ids:  # one id, one set of report folders and rows in the views
            same = "the same scenario" if recipe_digest(load_scenario(ids[sc.id])) == digest else "different scenarios"
            raise ScenarioError(f"Scenarios '{ids[sc.id]}' and '{scenario}' are {same} with the same name and version "
                                f"({sc.id}): their results would share report folders and leaderboard rows. "
                                + ("List it once." if same == "the same scenario" else
                                   "Give the edited copy its own name (and file name) or a new version."))
        ids[sc.id] = str(scenario)
        for seed in config.seeds:
            s = int(sc.seeds.master if seed is None else seed)
            fidelity = config.fidelity or sc.fidelity
            for m in config.methods:
                params = {**dict(m.params), **({"shared": dict(shared)} if shared else {})}
                key = evaluation_key(method=m.method, params=params, source_hash=hashes[m.method], scenario=sc.id,
                                     seed=s, fidelity=fidelity, scale=config.scale, package_version=__version__,
                                     scenario_digest=digest)
                tasks.append(Task(key, m.method, m.params, shared, scenario, sc.id, s, fidelity, config.scale,
                                  hashes[m.method]))
    return tasks


def build_data(scenario: str, seed: int, fidelity: str | None, scale: float, cache_dir=None,
               flight_minutes=None) -> dict:
    """The data build of one (scenario, seed) (cached on disk); returns its flight counts."""
    from fuelhm_bench.benchmark.harness import prepare_evaluation

    ev = prepare_evaluation(scenario, fidelity=fidelity, seed=seed, scale=scale, cache_dir=cache_dir,
                            flight_minutes=flight_minutes)
    return {"test": ev.n_flights, "fit": len(ev.fit_indicators), "calibration": len(ev.calibration_indicators),
            "fidelity": ev.fidelity}


def evaluate_task(task: Task, *, limits: dict, method_seed: int = 0, cache_dir=None, flight_minutes=None,
                  log_dir=None, deny=(), progress=None, evaluation=None) -> tuple[dict, dict]:
    """Run one task sealed, score it; returns ``(record, tables)`` for the store (never raises for the method)."""
    from fuelhm_bench.benchmark.harness import prepare_evaluation, run_in_env
    from fuelhm_bench.benchmark.store import provenance
    from fuelhm_bench.scoring import headline_kpis, robustness, undefined_kpis

    if evaluation is None:
        evaluation = prepare_evaluation(task.scenario, fidelity=task.fidelity, seed=task.seed, scale=task.scale,
                                        cache_dir=cache_dir, flight_minutes=flight_minutes)
    log_path = None
    if log_dir is not None:
        Path(log_dir).mkdir(parents=True, exist_ok=True)
        log_path = Path(log_dir) / f"{task.key[:16]}.log"
    common = {"random_state": method_seed, "limits": limits, "params": task.params_dict,
              "shared_params": dict(task.shared_params), "deny": deny}
    outcome = run_in_env(task.method, evaluation, log_path=log_path, progress=progress, **common)
    tables: dict[str, pd.DataFrame] = {}
    kpis: dict = {}
    status, message = outcome.status, outcome.message
    if outcome.ok:
        try:
            card = outcome.score()
            kp = headline_kpis(card)
            kp["cost_kusd"] = outcome.cost_kusd
            for name, value in statistics(card, seed=task.seed).items():  # (Series.update ignores new keys)
                kp[name] = value
            tables = {"decisions": outcome.decisions, "labels": outcome.labels, "episodes": outcome.episodes,
                      "healthy_scores": pd.DataFrame({"score": outcome.healthy_scores})}
            if evaluation.nominal is not None:  # robustness: same method, same fleet without the drift
                nom = run_in_env(task.method, evaluation.nominal, **common)
                if nom.ok:
                    kp["robustness"] = robustness(nom.score(), card)
                    tables.update({"nominal_decisions": nom.decisions, "nominal_labels": nom.labels,
                                   "nominal_healthy_scores": pd.DataFrame({"score": nom.healthy_scores})})
                else:
                    message = f"robustness not measured: nominal run {nom.status}: {nom.message}"
            kpis = {k: (None if v != v else float(v)) for k, v in kp.items()}
            if kpis.get("summary_score") is None and not message:
                message = f"summary score undefined: {undefined_kpis(card)['summary_score']}"
        except FuelHMError as exc:
            status, message, tables = "invalid", f"{task.method}: its output cannot be scored: {exc}", {}
    record = {"key": task.key, "method": task.method,
              "params": {**task.params_dict, **({"shared": dict(task.shared_params)} if task.shared_params else {})},
              "source_hash": task.source_hash, "scenario": task.scenario_id, "seed": task.seed, "fidelity": evaluation.fidelity,
              "scale": task.scale, "status": status, "message": message.splitlines()[0] if message else "",
              "kpis": kpis, "method_params": outcome.params, "fit_seconds": outcome.fit_seconds,
              "decide_seconds": outcome.decide_seconds, "seconds": outcome.seconds,
              "provenance": {**provenance(), "sandbox": outcome.sandbox}}
    record["package_version"] = record["provenance"]["package_version"]
    return record, tables


def statistics(card, *, seed: int = 0, n_resamples: int = 1000) -> dict:
    """Unit-bootstrap intervals of the headline KPIs and guilt calibration of a scored run.

    Returns ``{"<kpi>_ci_low": ..., "<kpi>_ci_high": ..., "brier": ..., "ece": ...}``
    (:func:`fuelhm_bench.scoring.bootstrap.scorecard_intervals`,
    :func:`fuelhm_bench.scoring.calibration.guilt_calibration`).
    """
    from fuelhm_bench.scoring.bootstrap import scorecard_intervals
    from fuelhm_bench.scoring.calibration import guilt_calibration

    out = {}
    for _, row in scorecard_intervals(card, n_resamples=n_resamples, random_state=seed).iterrows():
        out[f"{row['kpi']}_ci_low"], out[f"{row['kpi']}_ci_high"] = row["ci_low"], row["ci_high"]
    cal = guilt_calibration(card.flights)
    out.update({"brier": cal["brier"], "ece": cal["ece"]})
    return out


# --------------------------------------------------------------------------- the run
def _check_modules_visible(config: LeaderboardConfig, hidden: dict) -> None:
    """Refuse, before any data is built, a method whose module lies in a folder sealed methods cannot read.

    ``hidden`` maps a description of each folder (naming its option) to its resolved path. The
    results and the simulation cache are hidden from sealed methods (docs/methods.md, section 7),
    so a module saved inside one of them cannot be imported there: ``--out .`` with the method's
    module in the working directory is the usual way to get here.
    """
    from fuelhm_bench.datasets.cache import default_cache_dir
    from fuelhm_bench.methods.sandbox import locate_module

    folders = {"the default simulation cache": Path(default_cache_dir()).resolve(), **hidden}
    for entry in dict.fromkeys(e.method for e in config.methods):
        origin = locate_module(entry.partition(":")[0])
        if origin is None:
            continue  # not found here: the sealed process reports it as the method's own failure
        origin = origin.resolve()
        for what, folder in folders.items():
            if origin == folder or folder in origin.parents:
                raise ParameterError(
                    f"The method '{entry}' is imported from {origin}, inside {what} {folder}, which sealed "
                    f"methods cannot read (it holds results or simulated ground truth). Keep the method's "
                    f"module out of that folder: for example write the results to a sub-folder "
                    f"(--out results/).")


def _check_shared_params(config: LeaderboardConfig, shared: dict, limits: dict, deny: list) -> None:
    """Refuse, before any data is built, a shared hyperparameter (``--param``) that no method takes.

    Each method is started sealed (import and construction only) and reports its hyperparameters;
    a method that does not start is left out here (its failure becomes its row later). Before, a
    misspelt ``--param`` was found after the run, whose rows (run with the defaults, stored under
    the misspelt name) stayed in the store and the views.
    """
    if not shared:
        return
    from fuelhm_bench.methods.sandbox import SealedFailure, SealedMethod

    taken, started = set(), 0
    for entry in dict.fromkeys(config.methods):
        sealed = SealedMethod(entry.method, params=dict(entry.params), shared_params=shared, limits=limits, deny=deny)
        try:
            info = sealed.start()
        except SealedFailure:
            continue
        finally:
            sealed.close()
        started += 1
        taken |= set(info.get("params") or {})
    unknown = [k for k in shared if k not in taken]
    if started and unknown:
        raise ParameterError(f"--param {', '.join(unknown)}: no evaluated method has such a hyperparameter.")


def run_board(config: LeaderboardConfig, out, *, store_path=None, shared_params: dict | None = None,
              rerun: bool = False, jobs: int = 1, scheduler: str | None = None, method_seed: int = 0,
              cache_dir=None, flight_minutes=None, progress=None,
              log: Callable[[str], object] = lambda s: print(s, file=sys.stderr)) -> pd.DataFrame:
    """Evaluate every task of ``config`` missing from the store, then write the views; returns the board.

    Parameters
    ----------
    config : LeaderboardConfig
    out : path-like
        Output folder (views; the store by default).
    store_path : path-like, optional
        The SQLite store; None: ``<out>/results.sqlite``.
    shared_params : dict, optional
        Hyperparameters applied to every method that has them.
    rerun : bool, default=False
        Evaluate stored keys again (their rows are replaced).
    jobs : int, default=1
        1: in this process (data not yet cached simulated on every CPU, methods one at a time);
        > 1: on a local Dask cluster with that many worker processes.
    scheduler : str, optional
        Address of an existing Dask scheduler (``tcp://host:8786``); overrides ``jobs``.
    method_seed : int, default=0
        ``random_state`` passed to ``fit``.
    cache_dir : path-like, optional
        Cache of simulated products (must be shared by the workers of a remote cluster).
    progress : callable, optional
        ``progress(total=..., desc=...)`` context manager with ``update(n)`` (e.g. :func:`tqdm.tqdm`).
    log : callable
        Receives one line per finished evaluation.
    """
    from fuelhm_bench.benchmark.harness import earlier_outputs
    from fuelhm_bench.benchmark.store import ResultStore, default_store_path
    from fuelhm_bench.benchmark.views import write_views

    out = Path(out)
    # (with secret seeds, planned on the scenarios' own seeds first: every check before the store is opened)
    tasks = plan_tasks(dataclasses.replace(config, seeds=(None,)) if config.secret_seeds else config, shared_params)
    limits = {**dict(config.limits), "wall_s": config.timeout_s}
    store_path = Path(store_path or default_store_path(out))
    hidden = {"the output folder (--out)": out.resolve(),
              "the folder of the results store (--store)": store_path.resolve().parent}
    if cache_dir not in (None, False):
        hidden["the simulation cache (--cache-dir)"] = Path(cache_dir).resolve()
    for folder in earlier_outputs(Path.cwd()):  # hidden by run_in_env: a module inside one is refused now
        hidden.setdefault(f"an earlier fuelhm-bench output folder in the working directory ({folder.name})", folder)
    _check_modules_visible(config, hidden)
    _check_shared_params(config, shared_params or {}, limits, [str(p) for p in hidden.values()])
    store = ResultStore(store_path)
    try:
        if config.secret_seeds:  # drawn once, kept in the store (hidden from sealed methods), reused on resume
            config = dataclasses.replace(config, seeds=tuple(store.secret_seeds(config.secret_seeds)))
            tasks = plan_tasks(config, shared_params)
            log(f"{config.secret_seeds} secret seed(s), kept in {store.path}")
        stored = store.keys()
        todo = [t for t in tasks if rerun or t.key not in stored]
        if len(todo) < len(tasks):
            log(f"{len(tasks) - len(todo)} of {len(tasks)} evaluations already in {store.path}; "
                f"{len(todo)} to run" + ("" if not todo else "."))
        kwargs = {"limits": limits, "method_seed": method_seed, "cache_dir": cache_dir,
                  "flight_minutes": flight_minutes, "log_dir": str(out / "logs"),
                  "deny": [str(p) for p in hidden.values()]}

        def done(record: dict, tables: dict) -> None:
            store.put(record, tables)
            first = record["message"]
            score = record["kpis"].get("summary_score") if record["kpis"] else None
            log(f"{record['scenario']} seed {record['seed']}: {record['method']} {dict(record['params']) or ''}: "
                f"{record['status']}" + (f" (summary score {score:.3g})" if score is not None else "")
                + (f": {first}" if first else "")
                + f" [{record['seconds']:.1f} s]")

        if todo:
            if scheduler is not None or jobs > 1:
                from fuelhm_bench.benchmark.distributed import run_distributed

                from fuelhm_bench.benchmark.views import _method_report

                by_key = {t.key: t for t in todo}

                def done_and_report(record: dict, tables: dict) -> None:
                    # this process waits for the workers: it writes each entry's report now, not all in series
                    # at the end (write_views skips the reports that are up to date)
                    done(record, tables)
                    _method_report(store, out, by_key[record["key"]])

                run_distributed(todo, kwargs, done_and_report, jobs=jobs, scheduler=scheduler)
            else:
                from fuelhm_bench.methods.sandbox import prestart_zygote

                prestart_zygote()  # a clean interpreter importing its modules while the first data are built
                _run_local(todo, kwargs, done, progress)
        return write_views(store, out, tasks)
    finally:
        store.close()


def _run_local(todo: list[Task], kwargs: dict, done, progress) -> None:
    from fuelhm_bench.benchmark.harness import prepare_evaluation

    groups: dict[tuple, list[Task]] = {}
    for t in todo:
        groups.setdefault((t.scenario, t.seed, t.fidelity, t.scale), []).append(t)
    for (scenario, seed, fidelity, scale), group in groups.items():
        evaluation = _prepare(prepare_evaluation, scenario, seed, fidelity, scale, kwargs, progress)
        for task in group:
            if progress is not None:
                with progress(total=evaluation.n_flights, desc=f"{task.method} on {task.scenario_id}") as bar:
                    done(*evaluate_task(task, evaluation=evaluation, progress=bar.update, **kwargs))
            else:
                done(*evaluate_task(task, evaluation=evaluation, **kwargs))


def _prepare(prepare_evaluation, scenario, seed, fidelity, scale, kwargs, progress):
    from fuelhm_bench.datasets.parallel import default_workers

    # the data not yet cached are simulated on every CPU (byte-identical for any number of processes)
    common = {"fidelity": fidelity, "seed": seed, "scale": scale, "cache_dir": kwargs["cache_dir"],
              "flight_minutes": kwargs["flight_minutes"], "workers": default_workers()}
    if progress is None:
        return prepare_evaluation(scenario, **common)
    with progress(total=0, desc=f"data of {Path(str(scenario)).stem} (seed {seed})") as bar:
        def grow(n: int) -> None:  # the total is unknown: the cache may answer
            bar.total += n
            bar.update(n)

        return prepare_evaluation(scenario, progress=grow, **common)


def evaluation_config(methods: list[str], scenario: str, *, seed=None, scale: float = 1.0, timeout_s: float = 600.0,
                      fidelity=None, limits: dict | None = None, secret_seeds: int = 0) -> LeaderboardConfig:
    """The configuration of ``fuelhm-bench evaluate``: some methods on one scenario and seed.

    Raises
    ------
    ParameterError
        When a method's entry point is not of the form ``package.module:Class`` (before any data is built).
    """
    from fuelhm_bench.methods.loading import entry_point_problem

    for m in methods:
        if (problem := entry_point_problem(m)) is not None:
            raise ParameterError(f"--method {problem}")
    return LeaderboardConfig(tuple(LeaderboardEntry(m) for m in methods), (scenario,), (seed,), float(scale),
                             float(timeout_s), fidelity, tuple(sorted((limits or {}).items())), int(secret_seeds))


__all__ += ["build_data", "evaluation_config"]
