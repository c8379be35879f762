"""Reproduction of the paper's study (section VI, Tables IV-VI) on ``scenarios/paper_2012.yaml``.

Steps: healthy training fleet -> healthy model; design of experiments -> ITL ->
signature matrix (Table IV); test fleet with the two degradations -> the paper's
method (``fuelhm_baselines.paper_mahalanobis:PaperMahalanobis``: Mahalanobis score,
threshold mu + A sigma, collinearity diagnosis against the two reference
signatures) -> scorer -> Tables V and VI; figures equivalent to Figs. 4, 5, 8 and
10; a Markdown report that puts every table beside the published values.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import pandas as pd

from fuelhm_bench.taxonomy import INDICATOR_NAMES

#: Published values (Lamoureux, Masse & Mechbal 2012).
PAPER_TABLE_IV = pd.DataFrame(
    [[24, 0, 26, 0, 28, 24, 0, 0, 0, 0], [0, 4, 0, 11, 0, 1, 0, 0, 0, 0]],
    index=pd.Index(["null_bias_drift", "internal_leakage"], name="mode"), columns=list(INDICATOR_NAMES),
    dtype=float)
PAPER_TABLE_V = pd.DataFrame(
    {"A": [0, 1, 2, 3, 5],
     "drift_fpr_pct": [0, 0, 0, 0, 0], "drift_fnr_pct": [0, 0, 0, 0, 0],
     "leak_fpr_pct": [50, 16, 3, 0.3, 0], "leak_fnr_pct": [0, 0, 0, 2, 6]})
PAPER_TABLE_VI = pd.DataFrame(
    {"effective": ["null_bias_drift"] * 3 + ["internal_leakage"] * 3,
     "band": ["25%", "50%", "100%"] * 2,
     "guilt_drift": [0.94, 0.94, 0.94, 0.37, 0.13, 0.11],
     "guilt_leak": [0.06, 0.06, 0.06, 0.63, 0.87, 0.89]})
PAPER_MODES = ("null_bias_drift", "internal_leakage")


@dataclass(frozen=True)
class PaperResult:
    """Everything the study produced."""

    table_iv: pd.DataFrame
    table_v: pd.DataFrame
    table_vi: pd.DataFrame
    scorecard: object
    run: object
    knowledge: object
    timings: dict
    sizes: dict
    mission: object = None


def run_paper(scenario="paper_2012", *, doe_units: int = 8, a_values=(0, 1, 2, 3, 5), scale: float = 1.0,
              progress: Callable[[int], object] | None = None, on_stage: Callable[[str], object] | None = None,
              cache_dir=None, timeout_s: float = 600.0, workers: int | None = None) -> PaperResult:
    """Run the study through the benchmark's harness.

    The data are those of every evaluation (:func:`~fuelhm_bench.benchmark.harness.prepare_evaluation`,
    physics fidelity, cached); the paper's method
    (``fuelhm_baselines.paper_mahalanobis:PaperMahalanobis``, ``a=2``) runs sealed
    (:func:`~fuelhm_bench.benchmark.harness.run_in_env`) with the signatures of the
    two modes of the study. The design of experiments flies those two modes only
    (the laws of a mode do not depend on the other modes of the design).
    ``scale`` < 1 shrinks the scored fleet (quick checks).
    ``workers`` processes simulate what is not cached (None: every CPU this
    process may use); the results are byte-identical for any number.
    """
    from fuelhm_bench.benchmark.harness import prepare_evaluation, run_in_env
    from fuelhm_bench.datasets.cache import KnowledgeSize, resolve_scenario
    from fuelhm_bench.datasets.parallel import check_workers
    from fuelhm_bench.errors import MethodError
    from fuelhm_bench.methods import Knowledge
    from fuelhm_bench.scoring import ScoringConfig, score_run

    stage = on_stage or (lambda s: None)
    sc = resolve_scenario(scenario)
    workers = check_workers(workers, "run_paper")
    _overlap_the_tail(workers)
    timings = {}
    t0 = time.perf_counter()
    stage("data: published knowledge (design of experiments, ITL, signatures), training and scored flights")
    evaluation = prepare_evaluation(sc, fidelity="physics", scale=scale, robustness=False,
                                    knowledge_size=KnowledgeSize(doe_units=doe_units, doe_modes=PAPER_MODES), cache_dir=cache_dir,
                                    progress=progress, workers=workers)
    knowledge = evaluation.knowledge
    timings["data_s"] = time.perf_counter() - t0

    t2 = time.perf_counter()
    stage("paper method (sealed): fit, thresholds, decisions")
    sig = knowledge.signatures.loc[list(PAPER_MODES)]
    method_knowledge = Knowledge(itl=knowledge.itl.table, signatures=sig, max_intensity=dict(knowledge.max_intensity))
    outcome = run_in_env("fuelhm_baselines.paper_mahalanobis:PaperMahalanobis", evaluation, params={"a": 2.0},
                         knowledge=method_knowledge, timeout_s=timeout_s)
    if not outcome.ok:
        raise MethodError(f"The paper method failed: {outcome.status}: {outcome.message}")
    config = ScoringConfig(a_values=tuple(float(a) for a in a_values))
    run = outcome.run("paper_mahalanobis")
    card = score_run(run, config)
    timings["method_and_scoring_s"] = time.perf_counter() - t2
    timings["total_s"] = time.perf_counter() - t0

    table_iv = _table_iv(knowledge.signatures)
    table_v = _table_v(card, config)
    table_vi = _table_vi(card)
    mission = sc.test_fleet_config().mission
    sizes = {"training_flights": len(evaluation.fit_indicators) + len(evaluation.calibration_indicators),
             "fit_flights": len(evaluation.fit_indicators),
             "calibration_flights": len(evaluation.calibration_indicators), "doe_flights": len(knowledge.doe_table),
             "test_flights": evaluation.n_flights, "test_units": len(evaluation.units),
             "flight_minutes": mission.duration_s / 60.0}
    return PaperResult(table_iv, table_v, table_vi, card, run, knowledge, timings, sizes, mission)


#: Modules the study needs after its data (scoring, its figures): imported while the data are built.
_TAIL_MODULES = ("fuelhm_bench.scoring.scorecard", "fuelhm_bench.scoring.figures", "fuelhm_bench.scoring.export",
                 "fuelhm_bench.benchmark.harness", "fuelhm_bench.methods.sandbox")


def _overlap_the_tail(workers: int) -> None:
    """Start, now, what the study needs once its data are built, so that it is ready by then.

    The data are simulated by the worker processes while this process mostly waits;
    what follows them ran in series: the sealed method's zygote (a fresh interpreter
    importing its modules, :func:`~fuelhm_bench.methods.sandbox.prestart_zygote`) and
    this process's imports of the scorer and its figures (SciPy, Matplotlib), a few
    seconds of wall time together. Both now start here: the zygote as a process of its
    own, the imports on a background thread. The worker pool is forked first, so
    that no worker is forked while that thread holds an import lock. Only speed changes.
    """
    import threading

    from fuelhm_bench.datasets.parallel import ensure_pool
    from fuelhm_bench.methods.sandbox import prestart_zygote

    ensure_pool(workers)
    prestart_zygote()

    def preload() -> None:
        import importlib

        for name in _TAIL_MODULES:
            try:
                importlib.import_module(name)
            except Exception:  # noqa: BLE001 - the study imports them again and reports a failure itself
                return

    threading.Thread(target=preload, name="fuelhm-paper-preload", daemon=True).start()


def _table_iv(signatures: pd.DataFrame) -> pd.DataFrame:
    rows = []
    for mode in PAPER_MODES:
        rows.append(pd.Series(signatures.loc[mode, list(INDICATOR_NAMES)].to_numpy(dtype=float),
                              index=list(INDICATOR_NAMES), name=(mode, "this project")))
        rows.append(pd.Series(PAPER_TABLE_IV.loc[mode].to_numpy(), index=list(INDICATOR_NAMES), name=(mode, "paper")))
    out = pd.DataFrame(rows)
    out.index = pd.MultiIndex.from_tuples(out.index, names=["mode", "source"])
    return out


def _table_v(card, config) -> pd.DataFrame:
    det = card.detection
    rows = []
    for a in config.a_values:
        op = config.operating_point_name(a)
        row = {"A": a}
        for mode, short in (("null_bias_drift", "drift"), ("internal_leakage", "leak")):
            sel = det[(det["operating_point"] == op) & (det["mode"] == mode)]
            r = sel.iloc[0] if len(sel) else None
            for col, name in (("fpr_paper_def", "fpr"), ("fnr_paper_def", "fnr")):
                row[f"{short}_{name}_pct"] = 100.0 * float(r[col]) if r is not None else np.nan
            row[f"{short}_fpr_standard_pct"] = 100.0 * float(r["fpr_standard"]) if r is not None else np.nan
            row[f"{short}_fnr_standard_pct"] = 100.0 * float(r["fnr_standard"]) if r is not None else np.nan
        paper = PAPER_TABLE_V[PAPER_TABLE_V["A"] == a]
        for col in ("drift_fpr_pct", "drift_fnr_pct", "leak_fpr_pct", "leak_fnr_pct"):
            row[f"paper_{col}"] = float(paper[col].iloc[0]) if len(paper) else np.nan
        rows.append(row)
    return pd.DataFrame(rows)


def _table_vi(card) -> pd.DataFrame:
    diag = card.diagnosis
    rows = []
    for mode in PAPER_MODES:
        for band in ("25%", "50%", "100%"):
            sel = diag[(diag["true_mode"] == mode) & (diag["band"] == band)]
            r = sel.iloc[0] if len(sel) else None
            paper = PAPER_TABLE_VI[(PAPER_TABLE_VI["effective"] == mode) & (PAPER_TABLE_VI["band"] == band)].iloc[0]
            rows.append({
                "effective": mode, "band": band,
                "n_alarmed": int(r["n_alarmed"]) if r is not None else 0,
                "guilt_drift": float(r["guilt_null_bias_drift"]) if r is not None else np.nan,
                "guilt_leak": float(r["guilt_internal_leakage"]) if r is not None else np.nan,
                "paper_guilt_drift": paper["guilt_drift"], "paper_guilt_leak": paper["guilt_leak"],
            })
    return pd.DataFrame(rows)
