"""Evaluate any method of the common interface on a data set, safely, and score it.

A plugged-in method is untrusted code: it may raise, hang or return invalid
output. :func:`run_method` runs it in a forked child process with a wall-clock
limit; whatever happens, it returns a :class:`MethodOutcome` whose ``status`` is
``"ok"``, ``"error"`` (the method raised; message and traceback kept),
``"invalid"`` (it returned something that breaks the Decision contract) or
``"timeout"``. The caller's process and the other methods' results are never
affected.

Protocol (also in docs/methods.md):

1. ``fit`` on the *fit* part of the healthy training flights (with the published
   :class:`~fuelhm_bench.methods.Knowledge`);
2. the fitted method scores the *calibration* part of the healthy training
   flights (held-out units): these scores, never the scored labels, set the
   thresholds ``mu + A sigma`` of Table V;
3. the method decides, flight by flight and unit by unit, on the test flights
   (:func:`fuelhm_bench.methods.run_table`, causal).
"""

from __future__ import annotations

import dataclasses
import importlib
import multiprocessing
import time
import traceback
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from fuelhm_bench.errors import FuelHMError, MethodError, ParameterError


@dataclass(frozen=True)
class EvaluationData:
    """Everything a run needs (indicator tables are what methods see; labels only the scorer).

    Parameters
    ----------
    fit_indicators : DataFrame
        Healthy training flights the method is fitted on.
    calibration_indicators : DataFrame
        Healthy training flights of other units, scored by the fitted method to set thresholds.
    test_indicators : DataFrame
        Flights the method decides on (``unit_id``, ``flight_index``, indicators).
    test_labels : DataFrame
        Ground truth of the test flights.
    knowledge : Knowledge or None
        Published knowledge handed to ``fit``.
    name : str
        Data-set name for reports.
    nominal : EvaluationData or None
        For a scenario with nominal-parameter drift: the same test fleet (same seeds) without
        the drift, to measure robustness (:func:`fuelhm_bench.scoring.robustness`).
    """

    fit_indicators: pd.DataFrame
    calibration_indicators: pd.DataFrame
    test_indicators: pd.DataFrame
    test_labels: pd.DataFrame
    knowledge: object = None
    name: str = "dataset"
    nominal: EvaluationData | None = None


@dataclass(frozen=True)
class MethodOutcome:
    """What happened when a method was run.

    Attributes
    ----------
    method : str
        ``repr`` of the method (class and hyperparameters).
    status : {"ok", "error", "invalid", "timeout"}
    message : str
        Empty when ok; otherwise what went wrong (with the traceback for errors).
    decisions : DataFrame or None
        Decisions on the test flights.
    healthy_scores : ndarray or None
        Scores of the calibration flights.
    seconds : float
        Wall time.
    """

    method: str
    status: str
    message: str = ""
    decisions: pd.DataFrame | None = None
    healthy_scores: np.ndarray | None = None
    seconds: float = 0.0
    extra: dict = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        """True when the method ran and its output is valid."""
        return self.status == "ok"


def load_method(spec: str, params: dict | None = None):
    """Instantiate ``module:Class`` with keyword hyperparameters.

    Raises
    ------
    MethodError
        Naming what could not be found or built.
    """
    from fuelhm_bench.methods import BaseMethod

    module_name, sep, cls_name = spec.partition(":")
    if not sep or not module_name or not cls_name:
        raise MethodError(f"--method must look like 'package.module:Class'. Got '{spec}' instead.")
    import os
    import sys

    if os.getcwd() not in sys.path:  # a submission in the current directory, as 'python -m' would find it
        sys.path.insert(0, os.getcwd())
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise MethodError(f"Cannot import the method module '{module_name}': {exc}.") from None
    cls = getattr(module, cls_name, None)
    if cls is None:
        public = sorted(n for n, v in vars(module).items()
                        if isinstance(v, type) and issubclass(v, BaseMethod) and v is not BaseMethod)
        raise MethodError(f"Module '{module_name}' has no class '{cls_name}'. Methods it defines: "
                          f"{', '.join(public) or 'none'}.")
    if not (isinstance(cls, type) and issubclass(cls, BaseMethod)):
        raise MethodError(f"'{spec}' is not a subclass of fuelhm_bench.methods.BaseMethod.")
    try:
        return cls(**(params or {}))
    except TypeError as exc:
        names = sorted(cls().get_params()) if _constructible(cls) else []
        raise MethodError(f"Cannot build {cls_name} with {params}: {exc}. Its hyperparameters: "
                          f"{', '.join(names) or 'none'}.") from None


def _constructible(cls) -> bool:
    try:
        cls()
        return True
    except Exception:  # noqa: BLE001 - only used to list parameters in an error message
        return False


def parse_params(items: list[str]) -> dict:
    """Parse ``k=v`` strings; values are read as YAML scalars (numbers, booleans, strings)."""
    import yaml

    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise ParameterError(f"--param must look like NAME=VALUE. Got '{item}' instead.")
        out[key.strip()] = yaml.safe_load(value) if value.strip() else ""
    return out


def _run_in_child(method, data: EvaluationData, random_state, conn) -> None:
    from fuelhm_bench.methods import run_table

    try:
        t0 = time.perf_counter()
        method.fit(data.fit_indicators, knowledge=data.knowledge, random_state=random_state)
        healthy = run_table(method, data.calibration_indicators)["score"].to_numpy(dtype=float)
        decisions = run_table(method, data.test_indicators)
        conn.send(("ok", "", decisions, healthy, time.perf_counter() - t0))
    except MethodError as exc:
        conn.send(("invalid", str(exc), None, None, 0.0))
    except BaseException as exc:  # noqa: BLE001 - the method is untrusted code
        conn.send(("error", f"{type(exc).__name__}: {exc}\n{traceback.format_exc(limit=8)}", None, None, 0.0))
    finally:
        conn.close()


def run_method(method, data: EvaluationData, *, random_state: int = 0, timeout_s: float = 600.0) -> MethodOutcome:
    """Fit and run ``method`` in a child process with a time limit; never raises for the method's faults."""
    name = repr(method)
    ctx = multiprocessing.get_context("fork")
    parent, child = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_run_in_child, args=(method, data, random_state, child), daemon=True)
    t0 = time.perf_counter()
    proc.start()
    child.close()
    if not parent.poll(timeout_s):
        proc.terminate()
        proc.join(5)
        if proc.is_alive():
            proc.kill()
        return MethodOutcome(name, "timeout", f"{name} did not finish within {timeout_s:g} s; it was stopped.",
                             seconds=time.perf_counter() - t0)
    try:
        status, message, decisions, healthy, _ = parent.recv()
    except EOFError:
        proc.join(5)
        return MethodOutcome(name, "error", f"{name} crashed the worker process (exit code {proc.exitcode}).",
                             seconds=time.perf_counter() - t0)
    proc.join(5)
    outcome = MethodOutcome(name, status, message, decisions, healthy, time.perf_counter() - t0)
    if outcome.ok:
        problem = _check_outputs(outcome, data)
        if problem:
            return MethodOutcome(name, "invalid", problem, seconds=outcome.seconds)
    return outcome


def _check_outputs(outcome: MethodOutcome, data: EvaluationData) -> str:
    if outcome.healthy_scores is None or not np.all(np.isfinite(outcome.healthy_scores)):
        return f"{outcome.method} returned non-finite scores on healthy calibration flights."
    if len(outcome.decisions) != len(data.test_indicators):
        return (f"{outcome.method} returned {len(outcome.decisions)} decisions for "
                f"{len(data.test_indicators)} test flights.")
    return ""


def score_outcome(outcome: MethodOutcome, data: EvaluationData, config=None):
    """Scorecard of a successful outcome (:func:`fuelhm_bench.scoring.score_run`)."""
    from fuelhm_bench.scoring import Run, score_run

    if not outcome.ok:
        raise FuelHMError(f"Cannot score {outcome.method}: {outcome.status}: {outcome.message.splitlines()[0]}")
    run = Run(labels=data.test_labels, decisions=outcome.decisions, healthy_scores=outcome.healthy_scores,
              name=outcome.method)
    return score_run(run, config)


def scenario_data(scenario, *, seed: int | None = None, doe_units: int = 6, scale: float = 1.0,
                  progress=None, drifted: bool = True) -> tuple[EvaluationData, object]:
    """Simulate a scenario's training and test fleets and build the published knowledge.

    Parameters
    ----------
    scenario : str, Path or Scenario
        A shipped name or a YAML file.
    seed : int, optional
        Overrides the scenario's master seed.
    doe_units : int, default=6
        Units of the ITL design of experiments.
    scale : float, default=1.0
        Multiplies the number of test units (quick looks).
    progress : callable, optional
        Called with numbers of flights done.
    drifted : bool, default=True
        Whether the test fleet carries the scenario's nominal-parameter drift. When it does
        (and the scenario has drift), ``data.nominal`` holds the same fleet without the drift.

    Returns
    -------
    data : EvaluationData
    knowledge : KnowledgeResult
    """
    from fuelhm_bench.datasets import fleet_indicators
    from fuelhm_bench.knowledge import KnowledgeBuild, build_knowledge
    from fuelhm_bench.scenarios import load_scenario

    sc = load_scenario(scenario) if not hasattr(scenario, "test_fleet_config") else scenario
    if seed is not None:  # a new master seed: both fleets re-derived from it
        sc = dataclasses.replace(sc, seeds=dataclasses.replace(sc.seeds, master=int(seed), training=None, test=None))
    train_cfg = sc.training_fleet_config()
    test_cfg = sc.test_fleet_config()
    if not drifted:
        test_cfg = dataclasses.replace(test_cfg, nominal=sc.truth_model())
    if scale != 1.0:
        from fuelhm_bench.flights.scale import scaled_unit_count  # every mode stays represented
        test_cfg = dataclasses.replace(test_cfg, n_units=scaled_unit_count(test_cfg, scale))
    # The published knowledge (healthy spread for the signatures, ITL) comes from the benchmark's own
    # simulations of the published model, whatever the amount of data the methods are given.
    build = KnowledgeBuild.from_scenario(sc, doe_units=doe_units, seed=train_cfg.seed)
    knowledge = build_knowledge(build, progress=progress)
    train, _ = fleet_indicators(train_cfg, progress=progress)
    test_ind, test_lab = fleet_indicators(test_cfg, progress=progress)
    units = list(dict.fromkeys(train["unit_id"]))
    n_cal = max(1, int(round(0.25 * len(units)))) if len(units) > 1 else 0
    cal_units = set(units[len(units) - n_cal:])
    cal_mask = train["unit_id"].isin(cal_units)
    fit_part = train[~cal_mask].reset_index(drop=True)
    cal_part = train[cal_mask].reset_index(drop=True) if n_cal else train.reset_index(drop=True)
    nominal = None
    if drifted and sc.drift:
        nom_cfg = dataclasses.replace(test_cfg, nominal=sc.truth_model())
        nom_ind, nom_lab = fleet_indicators(nom_cfg, progress=progress)
        nominal = EvaluationData(fit_part, cal_part, nom_ind, nom_lab, knowledge.as_method_knowledge(),
                                 name=f"{sc.name} (no drift)")
    data = EvaluationData(fit_part, cal_part, test_ind, test_lab, knowledge.as_method_knowledge(), name=sc.name,
                          nominal=nominal)
    return data, knowledge
