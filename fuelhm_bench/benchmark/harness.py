"""Evaluate any method of the common interface through the environment, safely, and score it.

The runner is the adapter between a :class:`fuelhm_bench.methods.BaseMethod`
(or any object with ``fit``, ``start_unit`` and ``decide``) and
``FuelHM/ActuationLoop-v3``: one episode per unit of the scenario's scored
fleet (``reset(options={"unit": k})``, maintenance off, so faults evolve as
scheduled as in the paper's KPIs), and for every flight

1. the observation is turned into an indicator row (:func:`observation_row`:
   ``flight_id``, ``unit_id``, ``flight_index``, the ten indicators with NaN
   for invalid ones, ``<name>_valid``) - the only thing the method sees;
2. ``method.decide(row)`` gives a :class:`~fuelhm_bench.methods.Decision`,
   checked (:func:`~fuelhm_bench.methods.decision_problem`) and recorded; a
   method that declares ``needs_raw`` also gets the flight's full-rate
   samples, ``decide(row, raw=RawFlight)``, from the environment's
   ``info["raw_flight"]`` (``reset(options={"raw_flight": True})``), and is
   fitted and calibrated on the raw training flights
   (:mod:`fuelhm_bench.benchmark.raw_flights`); at the surrogate fidelity, which
   has no flights, it is refused (status ``"refused"``);
3. the decision becomes the action (:func:`action_from_decision`) and the
   environment flies the next flight.

The ground truth comes back once per episode, in the terminal
``info["episode_truth"]``; it is turned into the labels table and never shown
to the method. The protocol of :mod:`fuelhm_bench.benchmark.loading` is kept: ``fit``
on the fit part of the healthy training flights with the published knowledge,
healthy calibration scores on held-out training units (thresholds
``mu + A sigma`` of Table V come from them only), then the causal decisions.

This module is the one harness of the benchmark: ``evaluate``,
``leaderboard`` and ``paper`` all run methods through :func:`run_in_env`.
The method runs sealed (:class:`~fuelhm_bench.methods.sandbox.SealedMethod`):
in its own process, with limits, seeing only the tables and rows it is sent;
the environment, the schedule and the labels stay in this process. Whatever
the method does, the result is one :class:`Outcome` with a ``status`` and a
one-line ``message``.

Examples
--------
>>> from fuelhm_bench.methods import NullMethod
>>> from fuelhm_bench.benchmark.harness import evaluate
>>> outcome = evaluate(NullMethod(), "paper_2012", fidelity="surrogate")  # doctest: +SKIP
>>> outcome.status, outcome.kpis()["fnr_standard_alarm"]                  # doctest: +SKIP
('ok', 1.0)
"""

from __future__ import annotations

import dataclasses
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from fuelhm_bench.datasets.checks import check_training_indicators, scenario_label
from fuelhm_bench.errors import DataFormatError, FuelHMError, ParameterError
from fuelhm_bench.taxonomy import EXTENDED_INDICATOR_NAMES, INDICATOR_NAMES, MODE_IDS, OBSERVATION_COLUMNS

__all__ = ["EnvEvaluation", "Outcome", "action_from_decision", "evaluate",
           "earlier_outputs", "observation_row", "prepare_evaluation", "run_in_env", "split_training"]

_ROW_INDEX = pd.Index(OBSERVATION_COLUMNS)
_ROW_LABELS = tuple(OBSERVATION_COLUMNS)  # one object: the sealed process receives the labels once


# --------------------------------------------------------------------------- the adapter
def observation_row(observation: dict, unit_id: Any, flight_index: int, flight_id: Any = None) -> pd.Series:
    """The indicator row a method sees for one observation of ``FuelHM/ActuationLoop-v3``.

    Parameters
    ----------
    observation : dict
        ``{"indicators": (10,) float32, "valid": (10,) 0/1, "extended": (11,) float32,
        "extended_valid": (11,) 0/1}`` (a ``"raw"`` entry, if any, is not passed on;
        without ``"extended"`` every extended indicator is reported invalid).
    unit_id : int or str
        The unit's identifier.
    flight_index : int
        0-based index of the flight in the unit's life.
    flight_id : int or str, optional
        Identifier of the flight; None: ``flight_index``.

    Returns
    -------
    pandas.Series
        ``flight_id``, ``unit_id``, ``flight_index``, the ten indicators
        (float, units of ``INDICATOR_UNITS``; NaN when invalid), ``<name>_valid`` (bool),
        the extended indicators (``EXTENDED_INDICATOR_NAMES``, units of
        ``EXTENDED_INDICATOR_UNITS``; NaN when invalid) and their ``<name>_valid``: the columns
        of an indicator table.
    """
    return pd.Series(_observation_values(observation, unit_id, flight_index, flight_id), index=_ROW_INDEX,
                     dtype=object)


def _observation_values(observation: dict, unit_id: Any, flight_index: int, flight_id: Any = None) -> list:
    """The values of :func:`observation_row`, in the order of ``OBSERVATION_COLUMNS`` (``_ROW_LABELS``):
    the harness sends them as they are, and the sealed process builds the Series the method sees."""
    values = np.asarray(observation["indicators"], dtype=np.float64)
    valid = np.asarray(observation["valid"]).astype(bool)
    if "extended" in observation:
        ext = np.asarray(observation["extended"], dtype=np.float64)
        ext_valid = np.asarray(observation["extended_valid"]).astype(bool)
    else:  # an observation without the extended indicators: all of them invalid (NaN, False)
        ext = np.full(len(EXTENDED_INDICATOR_NAMES), np.nan)
        ext_valid = np.zeros(len(EXTENDED_INDICATOR_NAMES), dtype=bool)
    data = [flight_index if flight_id is None else flight_id, unit_id, int(flight_index),
            *np.where(valid, values, np.nan).tolist(), *valid.tolist(),
            *np.where(ext_valid, ext, np.nan).tolist(), *ext_valid.tolist()]
    return data


def action_from_decision(decision) -> dict:
    """The action of ``FuelHM/ActuationLoop-v3`` for a :class:`~fuelhm_bench.methods.Decision`.

    Returns
    -------
    dict
        ``{"alarm": 0 or 1, "guilt": (7,) float32}``; the guilt is clipped to
        [0, 1] (a valid Decision may exceed 1 by its 1e-6 sum tolerance).
    """
    guilt = np.clip(np.asarray(decision.guilt, dtype=np.float32), 0.0, 1.0)
    return {"alarm": int(bool(decision.alarm)), "guilt": guilt}


def _labels(truth: dict, n_flights: int) -> pd.DataFrame:
    unit = truth["unit_id"]
    data = {"flight_id": unit * n_flights + truth["flight_index"], "unit_id": np.full(n_flights, unit),
            "flight_index": truth["flight_index"]}
    for j, m in enumerate(MODE_IDS):
        data[f"intensity_{m}"] = truth["intensity"][:, j]
    for j, m in enumerate(MODE_IDS):
        data[f"max_intensity_{m}"] = np.full(n_flights, truth["max_intensity"][j])
    for j, m in enumerate(MODE_IDS):
        data[f"onset_{m}"] = np.full(n_flights, truth["onset"][j], dtype=np.int64)
    data["unknown_fault"] = np.full(n_flights, truth.get("unknown_fault", ""), dtype=object)
    data["onset_unknown"] = np.full(n_flights, truth.get("unknown_onset", -1), dtype=np.int64)
    return pd.DataFrame(data)


# --------------------------------------------------------------------------- evaluation set-up
@dataclass(frozen=True, eq=False)
class EnvEvaluation:
    """Everything shared by the methods evaluated on one scenario (build it with :func:`prepare_evaluation`).

    Parameters
    ----------
    scenario : Scenario
        The scenario (seed override and scale applied).
    fidelity : {"physics", "surrogate"}
        Fidelity of the scored flights.
    units : tuple of int
        Scored units, one episode each.
    knowledge : KnowledgeResult
        The published knowledge (ITL, signatures; handed to ``fit`` as
        :class:`~fuelhm_bench.methods.Knowledge`).
    fit_indicators : pandas.DataFrame
        Healthy training flights the methods are fitted on.
    calibration_indicators : pandas.DataFrame
        Healthy training flights of held-out units, scored to set thresholds.
    env : ActuationLoopEnv
        The environment (``maintenance=False``).
    nominal : EnvEvaluation or None, default=None
        For a scenario with nominal-parameter drift: the same scored fleet
        without the drift (``drifted=False``), to measure robustness.
    cache_dir : path-like, False or None, default=None
        The disk cache the products were built in or read from (None: the
        default cache; False: memory only); sealed methods cannot read it.
    """

    scenario: Any
    fidelity: str
    units: tuple
    knowledge: Any
    fit_indicators: pd.DataFrame
    calibration_indicators: pd.DataFrame
    env: Any
    nominal: EnvEvaluation | None = None
    cache_dir: Any = None

    @property
    def n_flights(self) -> int:
        """Scored flights in total."""
        return len(self.units) * self.env.n_flights

    @property
    def method_knowledge(self):
        """The :class:`~fuelhm_bench.methods.Knowledge` handed to ``fit``."""
        return self.knowledge.as_method_knowledge()


def split_training(train: pd.DataFrame) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Fit / calibration parts of the healthy training table (the one home of this split).

    The last half of the units (``n_units // 2``, at least one) calibrate the thresholds; the rest fit
    the method. Units, not flights, are split: the healthy score of a new engine is dominated by its
    manufacturing dispersion, so the calibration scores must come from units the method has not seen,
    and ``mu`` and ``sigma`` of the threshold are only as good as the number of units behind them
    (about 100 for the rate at ``A = 2`` to be within 1.5 points of 2.3 %; see scenarios/README.md).

    Only the columns of an observation row are kept (no ``n_points`` / ``quality_reason``: the
    environment does not observe them), so a method sees the same columns in training and scoring.
    The extended indicators are kept when the table has them (tables of the paper's ten only, e.g.
    from an older cache or a user, are split as they are).

    Raises
    ------
    DataFormatError
        A column of the paper's observation row (ids, the ten indicators, their flags) is missing.
    """
    base = list(_ROW_INDEX[:3 + 2 * len(INDICATOR_NAMES)])
    missing = [c for c in base if c not in train.columns]
    if missing:
        raise DataFormatError(f"The healthy training table must have the columns {base}. "
                              f"Got a table without {missing} instead.")
    train = train[[c for c in _ROW_INDEX if c in train.columns]]
    units = list(dict.fromkeys(train["unit_id"]))
    n_cal = max(1, len(units) // 2) if len(units) > 1 else 0
    cal_mask = train["unit_id"].isin(set(units[len(units) - n_cal:]))
    fit_part = train[~cal_mask].reset_index(drop=True)
    cal_part = train[cal_mask].reset_index(drop=True) if n_cal else train.reset_index(drop=True)
    return fit_part, cal_part


def prepare_evaluation(scenario, *, fidelity: str | None = None, seed: int | None = None, scale: float = 1.0,
                       flight_minutes: float | None = None, robustness: bool = True, knowledge_size=None,
                       cache_dir=None, progress=None, workers: int = 1) -> EnvEvaluation:
    """Load a scenario, get its published knowledge and training flights (cached), make the environment.

    The data: the published knowledge from the benchmark's own simulations of the published
    model, the methods' healthy flights from the scenario's training fleet
    (split into fit and calibration units the same way, restricted to the
    columns of :func:`observation_row`) and, with the physics fidelity, the very
    same scored flights: simulated once (and cached) for all the methods, then
    served by the environment (:meth:`ActuationLoopEnv.load_replays
    <fuelhm_bench.envs.ActuationLoopEnv.load_replays>`).

    Parameters
    ----------
    scenario : str, Path or Scenario
        A shipped name, a YAML path or a loaded scenario.
    fidelity : {"physics", "surrogate"} or None, default=None
        None: the scenario's ``fidelity``.
    seed : int or None, default=None
        Overrides the scenario's master seed (both fleets re-derived from it).
    scale : float, default=1.0
        Multiplies the number of scored units (at least 1), > 0.
    flight_minutes : float or None, default=None
        Flight duration [min] of every simulated flight (knowledge, training,
        scored); None: the scenario's.
    robustness : bool, default=True
        For a scenario with drift, also prepare the same fleet without it
        (:attr:`EnvEvaluation.nominal`).
    knowledge_size : KnowledgeSize, dict or None, default=None
        Simulation sizes of the knowledge and the surrogate; None: the
        defaults (:class:`~fuelhm_bench.envs.KnowledgeSize`).
    cache_dir : str, path-like, False or None, default=None
        Cache of the simulated products (see :mod:`fuelhm_bench.datasets.cache`).
    progress : callable, optional
        Called with numbers of flights simulated while building them.
    workers : int, default=1
        Processes simulating the products not yet cached, in parallel; the data
        are byte-identical for any number (:mod:`fuelhm_bench.datasets.parallel`).

    Returns
    -------
    EnvEvaluation
    """
    from fuelhm_bench.envs.actuation_loop import ActuationLoopEnv
    from fuelhm_bench.datasets.cache import (KnowledgeSize, published_knowledge, resolve_scenario, scored_indicators,
                                         surrogate_knowledge, training_indicators)

    sc = resolve_scenario(scenario)
    if seed is not None:
        from fuelhm_bench.scenarios.schema import MAX_SEED

        if not isinstance(seed, (int, np.integer)) or isinstance(seed, bool) or not 0 <= seed <= MAX_SEED:
            raise ParameterError(f"The 'seed' parameter of prepare_evaluation must be an int in [0, {MAX_SEED}] or "
                                 f"None. Got {seed!r} instead.")
        sc = dataclasses.replace(sc, seeds=dataclasses.replace(sc.seeds, master=int(seed), training=None, test=None))
    if not (isinstance(scale, (int, float)) and not isinstance(scale, bool) and np.isfinite(scale) and scale > 0):
        raise ParameterError(f"The 'scale' parameter of prepare_evaluation must be a finite number > 0. "
                             f"Got {scale!r} instead.")
    size = KnowledgeSize.coerce(knowledge_size, "prepare_evaluation")
    fidelity = sc.fidelity if fidelity is None else fidelity
    from fuelhm_bench.datasets.parallel import check_workers

    workers = check_workers(workers, "prepare_evaluation")
    common = {"flight_minutes": flight_minutes, "cache_dir": cache_dir, "progress": progress, "workers": workers}
    from fuelhm_bench.flights.scale import scaled_unit_count  # every mode of the fleet stays represented
    n_units = scaled_unit_count(sc.test_fleet_config(), scale)
    label = scenario_label(scenario, sc)
    knowledge, training = _build_products(sc, fidelity, size, n_units, robustness and bool(sc.drift), common,
                                          label=label, flight_minutes=flight_minutes)
    fit_part, cal_part = split_training(training)
    scored = sc if n_units == sc.fleet.units else dataclasses.replace(
        sc, fleet=dataclasses.replace(sc.fleet, units=n_units))  # products above are keyed on the unscaled one

    def make(drifted: bool, nominal) -> EnvEvaluation:
        env_knowledge = None
        if fidelity == "surrogate":
            env_knowledge = surrogate_knowledge(sc, size=size, drifted=drifted, **common)
        env = ActuationLoopEnv(scenario=scored, fidelity=fidelity, maintenance=False, drifted=drifted,
                               flight_minutes=flight_minutes, knowledge=env_knowledge)
        if env.fidelity == "physics":  # flights do not depend on the actions: simulate them once for all methods
            env.load_replays(scored_indicators(sc, units=n_units, drifted=drifted, **common))
        env.reset(options={"unit": 0})  # builds the scored fleet once, up front
        return EnvEvaluation(scored, env.fidelity, tuple(range(n_units)), knowledge, fit_part, cal_part, env,
                             nominal, cache_dir)

    nominal = make(False, None) if robustness and sc.drift else None
    return make(True, nominal)


def _build_products(sc, fidelity, size, n_units: int, both: bool, common: dict, *, label: str,
                    flight_minutes: float | None):
    """The scenario's published knowledge and training table; every product :func:`prepare_evaluation` needs is
    built (or loaded) here, at once on ``common["workers"]`` processes
    (:func:`~fuelhm_bench.datasets.parallel.run_concurrently`), so that its later asks are memory hits.

    The training table comes first and is checked (:func:`check_training_indicators`): a scenario whose
    flights yield too few valid indicators is refused before the knowledge is simulated (with one
    worker) or before the knowledge's own failure is reported (its error comes first)."""
    import threading

    from fuelhm_bench.datasets.cache import (published_knowledge, scored_indicators, surrogate_doe, surrogate_healthy,
                                         training_indicators)
    from fuelhm_bench.datasets.parallel import run_concurrently

    progress = common["progress"]
    if progress is not None:  # called from several threads
        lock = threading.Lock()

        def locked(n: int) -> None:
            with lock:
                progress(n)

        common = {**common, "progress": locked}

    def training():
        table = training_indicators(sc, **common)
        check_training_indicators(table, label, fidelity=fidelity,
                                  knowledge_flights=size.healthy_units * size.healthy_flights,
                                  flight_minutes=flight_minutes)
        return table

    calls = [training, lambda: published_knowledge(sc, size=size, **common)]
    for drifted in ((True, False) if both else (True,)):
        if fidelity == "physics":
            calls.append(lambda d=drifted: scored_indicators(sc, units=n_units, drifted=d, **common))
        elif fidelity == "surrogate":
            calls.append(lambda d=drifted: surrogate_healthy(sc, size=size, drifted=d, **common))
            calls.append(lambda d=drifted: surrogate_doe(sc, size=size, drifted=d, **common))
    training_table, knowledge = run_concurrently(calls, workers=common["workers"])[:2]
    return knowledge, training_table


#: How deep and how many folders :func:`earlier_outputs` looks through.
EARLIER_OUTPUTS_DEPTH, EARLIER_OUTPUTS_MAX_FOLDERS = 3, 20000


def earlier_outputs(root: Path) -> list[Path]:
    """Folders under ``root`` that hold earlier fuelhm-bench output: hidden from sealed methods too.

    The working directory is readable by a sealed method (it is on its import path), and an earlier
    run's output there holds ground truth: a leaderboard's reports (fault onsets in ``delays.csv``),
    a results store, exported labels. A folder is such output when it holds the record
    fuelhm-bench writes into its output folders (:data:`~fuelhm_bench.io.outputs.MANIFEST`), a
    results store (``*.sqlite``, ``*.sqlite3``, ``*.db``) or exported labels
    (:data:`~fuelhm_bench.benchmark.exchange.EXPORT_MANIFEST`). Looks ``EARLIER_OUTPUTS_DEPTH``
    levels down, through at most ``EARLIER_OUTPUTS_MAX_FOLDERS`` folders, skipping hidden ones.
    """
    import os

    from fuelhm_bench.benchmark.exchange import EXPORT_MANIFEST
    from fuelhm_bench.filetypes import suffix_of
    from fuelhm_bench.io.outputs import MANIFEST

    root = Path(root).resolve()
    found, seen = [], 0
    for folder, dirs, files in os.walk(root):
        seen += 1
        depth = len(Path(folder).relative_to(root).parts)
        marks = MANIFEST in files or EXPORT_MANIFEST in files or any(
            suffix_of(f, "sqlite") and _is_results_store(Path(folder) / f) for f in files)
        if marks and depth > 0:
            found.append(Path(folder))
            dirs[:] = []  # everything below is hidden with it
            continue
        dirs[:] = [d for d in dirs if not d.startswith(".") and depth < EARLIER_OUTPUTS_DEPTH]
        if seen >= EARLIER_OUTPUTS_MAX_FOLDERS:
            break
    return found


def _is_results_store(path: Path) -> bool:
    """Whether ``path`` is an SQLite database with a ``results`` table (opened read-only)."""
    import sqlite3

    try:
        with path.open("rb") as f:
            if f.read(16) != b"SQLite format 3\x00":
                return False
        con = sqlite3.connect(f"file:{path}?mode=ro", uri=True)
        try:
            return con.execute("SELECT 1 FROM sqlite_master WHERE type = 'table' AND name = 'results'").fetchone() \
                is not None
        finally:
            con.close()
    except (OSError, sqlite3.Error):
        return False


# --------------------------------------------------------------------------- outcome
@dataclass(frozen=True, eq=False)
class Outcome:
    """What happened when a method was run through the harness (the one outcome type).

    Attributes
    ----------
    method : str
        The method's name (entry point, or class name of an instance).
    status : {"ok", "error", "crash", "timeout", "cpu_limit", "memory", "invalid", "refused"}
        ``"error"``: the method raised (or the environment failed, said in the
        message); ``"refused"``: the method cannot run at this fidelity (a
        method with ``needs_raw`` at the surrogate fidelity, which has no
        flights); ``"crash"``: its process died (``os._exit``, a signal);
        ``"timeout"``, ``"cpu_limit"``, ``"memory"``: it hit a limit;
        ``"invalid"``: it broke the Decision contract or returned unusable output.
    message : str
        Empty when ok; otherwise one line saying what went wrong and where.
    decisions : DataFrame or None
        ``unit_id, flight_index, score, alarm, guilt_<mode>`` per scored flight.
    labels : DataFrame or None
        Ground truth of the same flights.
    healthy_scores : ndarray or None
        The method's scores on the healthy calibration flights.
    episodes : DataFrame or None
        Per unit: ``unit_id``, ``flights``, ``return_kusd`` (sum of the
        environment's rewards, without maintenance: faults are not repaired by
        alarms; the cost under the maintenance protocol is ``cost_kusd``),
        ``alarms``, ``false_alarms``, ``undetected_flights``, ``failures``.
    seconds : float
        Wall time of the whole run [s].
    scenario, fidelity : str
        Scenario id and fidelity of the scored flights.
    fit_seconds, decide_seconds : float
        Wall time of ``fit`` (measured in the sealed process) and of the
        calibration scores plus every decision (seen from the harness) [s].
    params : dict
        The method's hyperparameters as reported by it (JSON values).
    sandbox : str
        The isolation applied (see :mod:`fuelhm_bench.methods.sandbox`).
    costs : CostSpec or None
        The scenario's cost model (``cost_kusd``; None: the default CostSpec).
    """

    method: str
    status: str
    message: str = ""
    decisions: pd.DataFrame | None = None
    labels: pd.DataFrame | None = None
    healthy_scores: np.ndarray | None = None
    episodes: pd.DataFrame | None = None
    seconds: float = 0.0
    scenario: str = ""
    fidelity: str = ""
    fit_seconds: float = float("nan")
    decide_seconds: float = float("nan")
    params: dict = dataclasses.field(default_factory=dict)
    sandbox: str = ""
    costs: Any = None

    @property
    def ok(self) -> bool:
        """True when the method ran and its output is valid."""
        return self.status == "ok"

    @property
    def cost_kusd(self) -> float:
        """Total cost of the method's decisions over the scored fleet [kUSD] (NaN unless ok).

        Replayed under the scenario's maintenance protocol
        (:func:`fuelhm_bench.scoring.maintenance_cost`): an alarm triggers an
        inspection, the diagnosis decides what is replaced, a failure costs
        what the cost model says.
        """
        if not self.ok:
            return float("nan")
        from fuelhm_bench.scenarios import CostSpec
        from fuelhm_bench.scoring import total_cost

        return total_cost(self.run(), self.costs if self.costs is not None else CostSpec())

    def run(self, name: str | None = None):
        """The :class:`fuelhm_bench.scoring.Run` of this outcome.

        Raises
        ------
        FuelHMError
            When the outcome is not ok.
        """
        from fuelhm_bench.scoring import Run

        if not self.ok:
            first = self.message.splitlines()[0] if self.message else ""
            raise FuelHMError(f"Cannot score {self.method}: {self.status}: {first}")
        return Run(labels=self.labels, decisions=self.decisions, healthy_scores=self.healthy_scores,
                   name=self.method if name is None else name)

    def score(self, config=None):
        """Scorecard (:func:`fuelhm_bench.scoring.score_run`) of this outcome."""
        from fuelhm_bench.scoring import score_run

        return score_run(self.run(), config)

    def kpis(self, config=None) -> pd.Series:
        """Headline KPIs (:func:`fuelhm_bench.scoring.headline_kpis`) plus ``cost_kusd``."""
        from fuelhm_bench.scoring import headline_kpis

        kpis = headline_kpis(self.score(config))
        kpis["cost_kusd"] = self.cost_kusd
        return kpis


# --------------------------------------------------------------------------- the sealed run
class _EnvFailure(Exception):
    """The environment (not the method) failed."""


def _env_call(fn, *args, **kwargs):
    try:
        return fn(*args, **kwargs)
    except BaseException as exc:  # noqa: BLE001 - re-raised with its origin
        raise _EnvFailure(f"{type(exc).__name__}: {exc}") from exc


def _training_raw(evaluation: EnvEvaluation, table: pd.DataFrame):
    """The raw flights of the rows of a training table, in the table's unit order (one at a time)."""
    from fuelhm_bench.benchmark.raw_flights import training_raw_flights

    return training_raw_flights(evaluation.scenario, list(dict.fromkeys(table["unit_id"].tolist())),
                                flight_minutes=evaluation.env.flight_minutes)


def _raw_calibration_scores(sealed, evaluation: EnvEvaluation) -> np.ndarray:
    """Healthy calibration scores of a raw method: unit by unit, each row with its flight's samples."""
    table = evaluation.calibration_indicators
    order = table.assign(_u=pd.factorize(table["unit_id"])[0]).sort_values(["_u", "flight_index"], kind="stable")
    flights = _training_raw(evaluation, table)
    scores, unit = [], None
    for i in range(len(order)):
        row = order.iloc[i].drop("_u")
        flight = next(flights)
        if (flight.unit_id, flight.flight_index) != (row["unit_id"], int(row["flight_index"])):
            raise _EnvFailure(f"the raw training flight of unit {flight.unit_id}, flight {flight.flight_index} "
                              f"does not match the table row (unit {row['unit_id']}, flight {row['flight_index']})")
        if row["unit_id"] != unit:
            unit = row["unit_id"]
            sealed.start_unit(unit)
        scores.append(sealed.decide(row, raw=flight, where=f"calibration scores (unit {unit}, flight "
                                                          f"{row['flight_index']})").score)
    return np.asarray(scores, dtype=np.float64)


def _episodes(sealed, evaluation: EnvEvaluation, progress, raw: bool = False
              ) -> tuple[pd.DataFrame, pd.DataFrame, pd.DataFrame]:
    from fuelhm_bench.benchmark.raw_flights import raw_flight_from_info
    from fuelhm_bench.methods.tables import DECISION_COLUMNS

    env = evaluation.env
    n = env.n_flights
    unit_col, flight_col, scores, alarms, guilts = [], [], [], [], []
    labels, episodes = [], []
    for k in evaluation.units:
        obs, info = _env_call(env.reset, options={"unit": k, "raw_flight": True} if raw else {"unit": k})
        sealed.start_unit(k)
        total, terminated = 0.0, False
        for f in range(n):
            values = _observation_values(obs, k, f, k * n + f)
            flight = None
            if raw:
                flight = _env_call(raw_flight_from_info, info["raw_flight"], k, f)
                info = None  # the flight is now held once, by ``flight``
            decision = sealed.decide_values(_ROW_LABELS, values, raw=flight, where=f"decide (unit {k}, flight {f})")
            flight = None
            unit_col.append(k)
            flight_col.append(f)
            scores.append(decision.score)
            alarms.append(decision.alarm)
            guilts.append(decision.guilt)
            obs, reward, terminated, _, info = _env_call(env.step, action_from_decision(decision))
            total += reward
        if not terminated or "episode_truth" not in info:
            raise _EnvFailure(f"the episode of unit {k} did not terminate after its {n} flights")
        truth = info.pop("episode_truth")
        labels.append(_labels(truth, n))
        alarm_k = np.array(alarms[-n:], dtype=bool)
        episodes.append({"unit_id": k, "flights": n, "return_kusd": total, "alarms": int(alarm_k.sum()),
                         "false_alarms": int((alarm_k & ~truth["detectable"]).sum()),
                         "undetected_flights": int((~alarm_k & truth["detectable"]).sum()),
                         "failures": int(truth["failure"].sum())})
        if progress is not None:
            progress(n)
    guilt = np.array(guilts, dtype=np.float64).reshape(len(scores), len(MODE_IDS))
    data = {"unit_id": np.array(unit_col, dtype=np.int64), "flight_index": np.array(flight_col, dtype=np.int64),
            "score": np.array(scores, dtype=np.float64), "alarm": np.array(alarms, dtype=bool)}
    data.update({f"guilt_{m}": guilt[:, j] for j, m in enumerate(MODE_IDS)})
    decisions = pd.DataFrame(data, columns=list(DECISION_COLUMNS))
    return decisions, pd.concat(labels, ignore_index=True), pd.DataFrame(episodes)


def run_in_env(method, evaluation: EnvEvaluation, *, random_state: int = 0, timeout_s: float | None = None,
               limits=None, params: dict | None = None, shared_params: dict | None = None, knowledge=None,
               log_path=None, deny=(), progress=None) -> Outcome:
    """Fit ``method`` sealed and run it on every scored unit; never raises for the method's faults.

    Parameters
    ----------
    method : str or BaseMethod
        ``"module:Class"`` (imported only in the sealed process) or an unfitted
        instance (any object with ``fit``, ``start_unit`` and ``decide``).
    evaluation : EnvEvaluation
        From :func:`prepare_evaluation`.
    random_state : int, default=0
        Passed to ``fit``.
    timeout_s : float, optional
        Wall-clock limit [s], > 0 (overrides ``limits.wall_s``).
    limits : Limits or dict, optional
        Resource limits (:class:`~fuelhm_bench.methods.sandbox.Limits`).
    params, shared_params : dict, optional
        Hyperparameters of ``module:Class``; hyperparameters applied when the method has them.
    knowledge : Knowledge, optional
        Handed to ``fit`` instead of the evaluation's published knowledge.
    log_path : path-like, optional
        The method's stdout/stderr (size-bounded); None: dropped.
    deny : sequence of path-like, default=()
        Paths the method must not read (added to the simulation cache).
    progress : callable, optional
        Called with the number of flights done after each unit.

    Returns
    -------
    Outcome
    """
    from fuelhm_bench.datasets.cache import default_cache_dir
    from fuelhm_bench.methods.sandbox import Limits, SealedFailure, SealedMethod

    limits = Limits.coerce(limits, "limits")
    if timeout_s is not None:
        if not (isinstance(timeout_s, (int, float)) and not isinstance(timeout_s, bool) and timeout_s > 0):
            raise ParameterError(f"The 'timeout_s' parameter of run_in_env must be a number > 0. Got {timeout_s!r} "
                                 f"instead.")
        limits = dataclasses.replace(limits, wall_s=float(timeout_s))
    name = method if isinstance(method, str) else type(method).__name__
    meta = {"scenario": evaluation.scenario.id, "fidelity": evaluation.fidelity,
            "costs": evaluation.scenario.costs}
    hidden = [default_cache_dir(), *([evaluation.cache_dir] if evaluation.cache_dir not in (None, False) else []),
              *earlier_outputs(Path.cwd()), *deny]
    sealed = SealedMethod(method, params=params, shared_params=shared_params, limits=limits, log_path=log_path,
                          deny=hidden)
    t0 = time.perf_counter()
    fit_s = decide_s = float("nan")
    try:
        info = sealed.start()
        raw = sealed.needs_raw
        if raw and evaluation.fidelity != "physics":
            return Outcome(name, "refused", f"{name} needs the raw flights (needs_raw = True), which the "
                                            f"{evaluation.fidelity} fidelity does not have (it draws indicators, "
                                            f"not flights): run it at fidelity 'physics'.",
                           seconds=time.perf_counter() - t0, params=info.get("params", {}),
                           sandbox=sealed.sandbox, **meta)
        t_fit = time.perf_counter()  # measured here: the method's own report of its fit time can be forged
        sealed.fit(evaluation.fit_indicators, knowledge=evaluation.method_knowledge if knowledge is None else knowledge,
                   random_state=random_state,
                   raw_flights=_training_raw(evaluation, evaluation.fit_indicators) if raw else None)
        t1 = time.perf_counter()
        fit_s = t1 - t_fit
        healthy = (_raw_calibration_scores(sealed, evaluation) if raw
                   else sealed.scores(evaluation.calibration_indicators))
        decisions, labels, episodes = _episodes(sealed, evaluation, progress, raw=raw)
        decide_s = time.perf_counter() - t1
    except SealedFailure as exc:
        return Outcome(name, exc.status, exc.message, seconds=time.perf_counter() - t0, fit_seconds=fit_s,
                       params=sealed.info.get("params", {}), sandbox=sealed.sandbox, **meta)
    except _EnvFailure as exc:
        return Outcome(name, "error", f"The environment failed (not the method): {exc}",
                       seconds=time.perf_counter() - t0, **meta)
    finally:
        sealed.close()
    seconds = time.perf_counter() - t0
    extra = {"fit_seconds": fit_s, "decide_seconds": decide_s, "params": info.get("params", {}),
             "sandbox": sealed.sandbox}
    problem = _check_outputs(name, decisions, labels, healthy, evaluation)
    if problem:
        return Outcome(name, "invalid", problem, seconds=seconds, **meta, **extra)
    return Outcome(name, "ok", "", decisions, labels, healthy, episodes, seconds, **meta, **extra)


def _check_outputs(name: str, decisions, labels, healthy, evaluation: EnvEvaluation) -> str:
    from fuelhm_bench.scoring import Run

    healthy = np.asarray(healthy, dtype=float)
    if healthy.size < 2 or not np.all(np.isfinite(healthy)):
        return f"{name} returned non-finite scores on healthy calibration flights (or fewer than 2)."
    if len(decisions) != evaluation.n_flights:
        return f"{name} returned {len(decisions)} decisions for {evaluation.n_flights} scored flights."
    try:
        Run(labels=labels, decisions=decisions, healthy_scores=healthy, name=name)
    except DataFormatError as exc:
        return f"{name}: its output cannot be scored: {str(exc).splitlines()[0]}"
    return ""


# --------------------------------------------------------------------------- one call
def evaluate(method, scenario, *, fidelity: str | None = None, seed: int | None = None, scale: float = 1.0,
             flight_minutes: float | None = None, random_state: int = 0, timeout_s: float = 600.0,
             limits=None, knowledge_size=None, cache_dir=None, progress=None) -> Outcome:
    """Evaluate one method on one scenario through the environment (:func:`prepare_evaluation` + :func:`run_in_env`).

    Parameters
    ----------
    method : str or BaseMethod
        ``"module:Class"`` or an unfitted instance (not modified: the sealed process fits its own copy).
    scenario : str, Path or Scenario
        A shipped name, a YAML path or a loaded scenario.
    fidelity, seed, scale, flight_minutes, knowledge_size, cache_dir
        See :func:`prepare_evaluation`.
    random_state : int, default=0
        Passed to ``fit``.
    timeout_s : float, default=600.0
        Wall-time limit of the method [s].
    limits : Limits or dict, optional
        Other resource limits (CPU time, memory, log size).
    progress : callable, optional
        ``progress(total=..., desc=...)`` returning a context manager with ``update(n)`` and a
        mutable ``total`` (such as :func:`tqdm.tqdm`); the command line hands its progress bar down.

    Returns
    -------
    Outcome
        Call ``.kpis()`` or ``.score()`` on it.

    Raises
    ------
    ParameterError
        For a method with ``needs_raw`` at the surrogate fidelity (no flights to give it).
    """
    from fuelhm_bench.methods.base import method_needs_raw

    if not isinstance(method, str) and method_needs_raw(method):  # refuse before building anything
        from fuelhm_bench.datasets.cache import resolve_scenario

        if (fidelity or resolve_scenario(scenario).fidelity) != "physics":
            raise ParameterError(f"{type(method).__name__} needs the raw flights (needs_raw = True), which the "
                                 f"surrogate fidelity does not have (it draws indicators, not flights): "
                                 f"evaluate it with fidelity='physics'.")
    if progress is not None:
        with progress(total=0, desc="published knowledge") as bar:
            def grow(k: int) -> None:
                bar.total += k
                bar.update(k)

            evaluation = prepare_evaluation(scenario, fidelity=fidelity, seed=seed, scale=scale,
                                            flight_minutes=flight_minutes, knowledge_size=knowledge_size,
                                            cache_dir=cache_dir, progress=grow)
        with progress(total=evaluation.n_flights, desc=f"{method if isinstance(method, str) else type(method).__name__}"
                                                       f" on {evaluation.scenario.id}") as bar:
            return _refusal_raised(run_in_env(method, evaluation, random_state=random_state, timeout_s=timeout_s,
                                              limits=limits, progress=bar.update))
    evaluation = prepare_evaluation(scenario, fidelity=fidelity, seed=seed, scale=scale,
                                    flight_minutes=flight_minutes, knowledge_size=knowledge_size,
                                    cache_dir=cache_dir)
    return _refusal_raised(run_in_env(method, evaluation, random_state=random_state, timeout_s=timeout_s,
                                      limits=limits))


def _refusal_raised(outcome: Outcome) -> Outcome:
    if outcome.status == "refused":
        raise ParameterError(outcome.message)
    return outcome
