"""Healthy false-alarm rate of the paper's threshold ``mu + A sigma`` on the shipped scenarios.

The scorer's standard threshold (Table V) is ``mu + A sigma`` of a method's
scores on the *calibration* units of the healthy training fleet
(:func:`fuelhm_bench.benchmark.harness.split_training`). For a Gaussian
healthy score, ``A = 2`` gives a false-alarm rate of 2.3 % (one-sided).
:func:`healthy_false_alarm_rate` runs the paper's method
(``fuelhm_baselines.paper_mahalanobis:PaperMahalanobis``) through the harness,
exactly as ``evaluate`` and ``paper`` do, and reports the share of the scored
fleet's healthy flights (every flight of a healthy unit, and the flights of a
faulty unit before its first onset) whose score exceeds that threshold, with a
unit-bootstrap percentile interval (flights of one unit share its
manufacturing dispersion, so units, not flights, are the independent draws).

For a scenario with nominal-parameter drift the rate is reported twice: on
the drifted scored fleet (what the robustness KPIs measure: a drifted healthy
unit may look abnormal) and on the same fleet without the drift (what the
calibration controls).

Run it from the command line (about one minute of CPU per scenario with a
cold cache)::

    python -m fuelhm_bench.benchmark.false_alarms                 # every shipped scenario
    python -m fuelhm_bench.benchmark.false_alarms paper_2012 --a 2
"""

from __future__ import annotations

import argparse
import sys
from dataclasses import dataclass

from fuelhm_bench.errors import FuelHMError

__all__ = ["PAPER_METHOD", "FalseAlarmRate", "healthy_false_alarm_rate", "main"]

#: Size of the published knowledge simulated for the measurement: the paper method's score does not
#: depend on it (only its diagnosis does), so the smallest design of experiments that builds it is used.
KNOWLEDGE_SIZE = {"doe_units": 2}

#: The method whose threshold is checked: the paper's Mahalanobis detector.
PAPER_METHOD = "fuelhm_baselines.paper_mahalanobis:PaperMahalanobis"


@dataclass(frozen=True)
class FalseAlarmRate:
    """Healthy false-alarm rate at ``mu + A sigma`` of the calibration scores.

    Attributes
    ----------
    scenario : str
        Scenario id.
    drifted : bool
        Whether the scored fleet carried the scenario's nominal-parameter drift.
    a : float
        ``A`` of the threshold.
    rate, ci_low, ci_high : float
        Share of healthy scored flights above the threshold, and its 95 %
        unit-bootstrap percentile interval (2000 resamples, seed 0).
    healthy_flights, healthy_units : int
        Healthy flights scored, and the units they belong to.
    calibration_flights, calibration_units : int
        Size of the calibration split behind ``mu`` and ``sigma``.
    """

    scenario: str
    drifted: bool
    a: float
    rate: float
    ci_low: float
    ci_high: float
    healthy_flights: int
    healthy_units: int
    calibration_flights: int
    calibration_units: int


def healthy_false_alarm_rate(scenario, *, a: float = 2.0, knowledge_size=None, cache_dir=None,
                             timeout_s: float = 3000.0) -> list[FalseAlarmRate]:
    """Run the paper's method on a scenario and measure its healthy false-alarm rate at ``mu + a sigma``.

    Parameters
    ----------
    scenario : str, Path or Scenario
        A shipped name, a YAML path or a loaded scenario.
    a : float, default=2.0
        ``A`` of the threshold (>= 0).
    knowledge_size : KnowledgeSize, dict or None, default=None
        Size of the published knowledge (it does not enter the paper method's score).
    cache_dir : str, path-like, False or None, default=None
        Simulation cache (:mod:`fuelhm_bench.datasets.cache`).
    timeout_s : float, default=3000.0
        Wall-time limit of the sealed method [s].

    Returns
    -------
    list of FalseAlarmRate
        One entry; two (drifted, then without the drift) for a scenario with drift.

    Raises
    ------
    FuelHMError
        When the method does not run (its status and message).
    """
    from fuelhm_bench.benchmark.harness import prepare_evaluation, run_in_env
    from fuelhm_bench.scoring import scorecard_intervals
    from fuelhm_bench.scoring.config import ScoringConfig

    evaluation = prepare_evaluation(scenario, fidelity="physics", robustness=True, knowledge_size=knowledge_size,
                                    cache_dir=cache_dir)
    cal = evaluation.calibration_indicators
    out = []
    for ev in (evaluation, evaluation.nominal):
        if ev is None:
            continue
        outcome = run_in_env(PAPER_METHOD, ev, params={"a": float(a)}, random_state=0, timeout_s=timeout_s)
        if not outcome.ok:
            raise FuelHMError(f"{ev.scenario.id}: the paper method did not run ({outcome.status}): {outcome.message}")
        card = outcome.score(ScoringConfig(headline_a=float(a)))
        row = scorecard_intervals(card).set_index("kpi").loc["fpr_standard_thr"]
        healthy = card.flights[card.flights["true_mode"] == "healthy"]
        out.append(FalseAlarmRate(ev.scenario.id, ev is evaluation and bool(ev.scenario.drift), float(a),
                                  float(row["value"]), float(row["ci_low"]), float(row["ci_high"]),
                                  int(len(healthy)), int(healthy["unit_id"].nunique()),
                                  int(len(cal)), int(cal["unit_id"].nunique())))
    return out


def main(argv=None) -> int:
    """Command line: print the healthy false-alarm rate of the paper's threshold per scenario."""
    from scipy.stats import norm

    from fuelhm_bench.scenarios import list_scenarios

    p = argparse.ArgumentParser(prog="python -m fuelhm_bench.benchmark.false_alarms",
                                description="Healthy false-alarm rate of the paper's threshold mu + A sigma "
                                            "(calibration units of the training fleet) on shipped scenarios.")
    p.add_argument("scenarios", nargs="*", help="scenario names or YAML files (default: every shipped one)")
    p.add_argument("--a", type=float, default=2.0, help="A of the threshold (default 2)")
    args = p.parse_args(argv)
    if not (args.a >= 0):
        p.error(f"--a must be a number >= 0. Got {args.a!r} instead.")
    names = args.scenarios or list_scenarios()
    print(f"Gaussian tail at A = {args.a:g}: {100 * norm.sf(args.a):.2f} %")
    print(f"{'scenario':28s} {'drift':6s} {'FAR %':>6s} {'95 % CI (units)':>16s} {'healthy flights/units':>22s} "
          f"{'calibration flights/units':>26s}")
    try:
        for name in names:
            for r in healthy_false_alarm_rate(name, a=args.a, knowledge_size=KNOWLEDGE_SIZE):
                drift = "yes" if r.drifted else "no"
                print(f"{r.scenario:28s} {drift:6s} {100 * r.rate:6.2f} {100 * r.ci_low:7.2f} - {100 * r.ci_high:5.2f} "
                      f"{r.healthy_flights:>15d} / {r.healthy_units:<4d} {r.calibration_flights:>19d} / "
                      f"{r.calibration_units:<4d}", flush=True)
    except FuelHMError as exc:
        print(f"false_alarms: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
