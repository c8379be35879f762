"""Statistical evaluation of the discrepancy workflow on data with a known hidden effect.

:func:`run_study` generates, for every effect id (and ``"none"``) and every seed, a small
fleet with that effect hidden at a magnitude drawn in
:data:`~fuelhm_bench.calibration.synthetic.TEST_RANGES` (or at fixed fractions of it), runs
:func:`~fuelhm_bench.calibration.discrepancy.find_discrepancy` from the nominal model, and
records what was named, the held-out gaps and the fitted magnitude. :func:`summarize`
turns the cases into rates: identification accuracy per hidden effect, false discoveries
(an effect named on data without one), wrong names, the held-out gap reduction and the
error on the main parameter.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np
import pandas as pd

from fuelhm_bench.calibration.discrepancy import DiscrepancyConfig, find_discrepancy
from fuelhm_bench.calibration.synthetic import TEST_RANGES, hidden_effect_flights
from fuelhm_bench.io import split_flights
from fuelhm_bench.taxonomy import EFFECT_IDS


@dataclass(frozen=True)
class StudyCase:
    """One run of the workflow on data with a known hidden effect.

    Attributes
    ----------
    hidden : str
        Hidden effect id or ``"none"``.
    seed : int
        Seed of the data and of the workflow.
    magnitude : float
        Hidden value of the effect's main parameter [SI] (NaN for ``none``).
    named : str
        What the workflow named.
    fitted : float
        Fitted value of the hidden effect's main parameter when it was named [SI] (else NaN).
    gap_before, gap_recalibrated, gap_after : float
        Held-out gaps [mm/s].
    seconds : float
        Wall time of the workflow [s].
    runner_up : str
        Best-ranked (lowest BIC) candidate other than the hidden effect and ``none``.
    runner_up_delta_bic : float
        Its BIC gain over recalibration alone.
    max_wrong_reduction : float
        Largest held-out gap reduction (relative to recalibration alone) of a candidate other
        than the hidden effect: the margin of the decision rule's second condition.
    """

    hidden: str
    seed: int
    magnitude: float
    named: str
    fitted: float
    gap_before: float
    gap_recalibrated: float
    gap_after: float
    seconds: float
    runner_up: str = ""
    runner_up_delta_bic: float = float("nan")
    max_wrong_reduction: float = float("nan")

    @property
    def correct(self) -> bool:
        """Whether the named effect is the hidden one (``none`` for ``none``)."""
        return self.named == self.hidden

    @property
    def gap_reduction(self) -> float:
        """``1 - gap_after / gap_before`` [-]."""
        return 1.0 - self.gap_after / self.gap_before if self.gap_before > 0 else float("nan")


def run_study(effects: Sequence[str] = EFFECT_IDS + ("none",), seeds: Sequence[int] = range(5), *,
              fractions: Sequence[float] | None = None, n_units: int = 2, n_flights: int = 3, minutes: float = 4.0,
              frame_s: float = 0.01, noise_std_m: float = 3e-6, config: DiscrepancyConfig | None = None,
              progress: Callable[[StudyCase], None] | None = None) -> list[StudyCase]:
    """Run the workflow on simulated data for every (effect, seed) pair.

    Parameters
    ----------
    effects : sequence of str
        Effect ids to hide (``"none"``: no effect).
    seeds : sequence of int
        Seeds (data and workflow).
    fractions : sequence of float, optional
        If given, the magnitude is set at each of these fractions of the test range (on a log
        scale: 0 = its low end, 1 = its high end) instead of drawn at random; one case per
        (effect, seed, fraction).
    n_units, n_flights, minutes, frame_s, noise_std_m :
        Data set size and acquisition (see :func:`hidden_effect_flights`).
    config : DiscrepancyConfig, optional
        Workflow settings (its seed is replaced by each case's seed).
    progress : callable, optional
        Called with each finished case.

    Returns
    -------
    list of StudyCase
    """
    import dataclasses

    config = config or DiscrepancyConfig()
    cases = []
    for effect in effects:
        for seed in seeds:
            for frac in (fractions if (fractions is not None and effect != "none") else [None]):
                params = None
                if frac is not None:
                    name, lo, hi = TEST_RANGES[effect]
                    params = {name: float(math.exp(math.log(lo) + frac * (math.log(hi) - math.log(lo))))}
                frame, truth = hidden_effect_flights(effect, parameters=params, n_units=n_units, n_flights=n_flights,
                                                     minutes=minutes, frame_s=frame_s, noise_std_m=noise_std_m,
                                                     seed=seed)
                flights, _ = split_flights(frame)
                t0 = time.perf_counter()
                result = find_discrepancy(flights, config=dataclasses.replace(config, seed=int(seed)))
                main = TEST_RANGES[effect][0] if effect != "none" else None
                magnitude = float(truth.parameters[main]) if main else float("nan")
                fitted = float(result.parameters.get(main, float("nan"))) if main and result.effect == effect \
                    else float("nan")
                others = [c for c in result.ranking if c.effect not in ("none", effect)]
                runner = others[0] if others else None
                case = StudyCase(effect, int(seed), magnitude, result.effect, fitted, result.gap_before,
                                 result.gap_recalibrated, result.gap_after, time.perf_counter() - t0,
                                 runner.effect if runner else "", runner.delta_bic if runner else float("nan"),
                                 max((c.gap_reduction for c in others), default=float("nan")))
                cases.append(case)
                if progress is not None:
                    progress(case)
    return cases


def summarize(cases: Sequence[StudyCase]) -> pd.DataFrame:
    """Rates per hidden effect.

    Returns
    -------
    pandas.DataFrame
        One row per hidden effect: ``cases``, ``accuracy`` (named the hidden effect, or
        ``none`` for ``none``), ``false_discovery`` (for ``none``: an effect was named),
        ``wrong_effect`` (another effect named), ``missed`` (``none`` named), median and minimum
        held-out gap reduction, median |relative error| of the main parameter when named, the
        largest held-out gap reduction of a wrong candidate (the margin of the decision rule's
        second condition), median wall time [s].
    """
    rows = []
    for hidden in dict.fromkeys(c.hidden for c in cases):
        sub = [c for c in cases if c.hidden == hidden]
        rel = [abs(c.fitted - c.magnitude) / abs(c.magnitude) for c in sub
               if c.correct and np.isfinite(c.fitted) and np.isfinite(c.magnitude) and c.magnitude != 0]
        red = [c.gap_reduction for c in sub]
        rows.append({
            "hidden": hidden,
            "cases": len(sub),
            "accuracy": float(np.mean([c.correct for c in sub])),
            "false_discovery": float(np.mean([c.named != "none" for c in sub])) if hidden == "none" else float("nan"),
            "wrong_effect": float(np.mean([c.named not in ("none", hidden) for c in sub])),
            "missed": float(np.mean([c.named == "none" for c in sub])) if hidden != "none" else float("nan"),
            "median_gap_reduction": float(np.median(red)),
            "min_gap_reduction": float(np.min(red)),
            "median_parameter_error": float(np.median(rel)) if rel else float("nan"),
            "max_wrong_reduction": float(np.nanmax([c.max_wrong_reduction for c in sub]))
            if any(np.isfinite(c.max_wrong_reduction) for c in sub) else float("nan"),
            "median_seconds": float(np.median([c.seconds for c in sub])),
        })
    return pd.DataFrame(rows)


def cases_frame(cases: Sequence[StudyCase]) -> pd.DataFrame:
    """One row per case (for CSV export)."""
    return pd.DataFrame([{**c.__dict__, "correct": c.correct, "gap_reduction": c.gap_reduction} for c in cases])
