"""Fault-detection KPIs: the paper's Table V, in both definitions, and results by band.

Counts follow the paper's condition assessment matrix (Fig. 9)::

                      estimated: no fault   estimated: fault
    actual: no fault        NFD                  FP
    actual: fault           FN                   FD

Rates (zero denominators give NaN and a note):

* ``fpr_standard  = FP / (FP + NFD)``  false alarms among healthy flights;
* ``fnr_standard  = FN / (FN + FD)``   missed detections among faulty flights;
* ``fpr_paper_def = FP / (FP + FD)``   the paper's Table III wording, "false
  positives among all the states where a fault is detected" (= 1 - precision);
* ``fnr_paper_def = FN / (FN + NFD)``  "false negatives among all the states
  where no fault is detected" (= false omission rate).

Only *detectable* faulty flights (intensity >= ``detectable_fraction`` of the
reference maximum) count as FN or FD; *incipient* ones are reported apart.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from fuelhm_bench.scoring.config import ScoringConfig
from fuelhm_bench.scoring.intervals import rates_with_intervals
from fuelhm_bench.scoring.run import HEALTHY, MULTIPLE
from fuelhm_bench.scoring.thresholds import HealthyScoreModel
from fuelhm_bench.taxonomy import MODE_IDS

__all__ = ["ALL_MODES", "METHOD_ALARM", "UNDEFINED_RATES", "detection_by_band", "detection_table", "modes_present",
           "operating_points"]

#: ``mode`` value of the rows pooling every flight.
ALL_MODES = "all"
#: ``operating_point`` of the method's own alarms.
METHOD_ALARM = "method_alarm"

_COUNTS = ["nfd", "fp", "fn", "fd", "n_healthy", "n_detectable", "n_detected", "n_not_detected",
           "n_incipient", "n_incipient_detected"]
_RATES = {
    "fpr_standard": ("fp", "n_healthy"),
    "fnr_standard": ("fn", "n_detectable"),
    "fpr_paper_def": ("fp", "n_detected"),
    "fnr_paper_def": ("fn", "n_not_detected"),
    "incipient_detection_rate": ("n_incipient_detected", "n_incipient"),
}
#: Why each rate is undefined (NaN) where it is: its denominator is 0.
UNDEFINED_RATES = {
    "fpr_standard": "no healthy flight",
    "fnr_standard": "no detectable faulty flight",
    "fpr_paper_def": "no detection: FP + FD = 0",
    "fnr_paper_def": "every flight detected: FN + NFD = 0",
}


def modes_present(flights: pd.DataFrame) -> list[str]:
    """Modes (in MODE_IDS order) that are the single active fault of at least one flight."""
    present = set(flights["true_mode"])
    return [m for m in MODE_IDS if m in present]


def operating_points(flights: pd.DataFrame, model: HealthyScoreModel,
                     config: ScoringConfig) -> list[tuple[str, float, float, np.ndarray]]:
    """``(name, a, threshold, detected)`` for every ``A`` and for the method's own alarm.

    A flight is detected at ``A`` when ``score > mu + A * sigma`` (strictly).
    """
    score = flights["score"].to_numpy(dtype=float)
    points = [(config.operating_point_name(a), a, model.threshold(a), score > model.threshold(a))
              for a in config.a_values]
    points.append((METHOD_ALARM, np.nan, np.nan, flights["alarm"].to_numpy(dtype=bool)))
    return points


def _unit_counts(flights: pd.DataFrame, points, modes: list[str]) -> pd.DataFrame:
    """Per-unit counts of every (operating point, mode), one row per unit in order of first appearance.

    Columns: ``operating_point``, ``mode``, ``unit_id``, ``nfd, fp, fn, fd, n_incipient,
    n_incipient_detected, n_healthy, n_detectable, n_detected, n_not_detected``. Counted with one
    ``bincount`` per column over all flights at once (a groupby per point and mode cost most of
    :func:`~fuelhm_bench.scoring.score_run`).
    """
    code, units = pd.factorize(flights["unit_id"], sort=False)
    n_units = len(units)
    true_mode = flights["true_mode"].to_numpy(dtype=object)
    healthy = true_mode == HEALTHY
    detectable_any = flights["detectable"].to_numpy(dtype=bool)
    incipient_any = flights["incipient"].to_numpy(dtype=bool)

    def per_unit(mask: np.ndarray) -> np.ndarray:
        return np.bincount(code[mask], minlength=n_units).astype(np.int64)

    members = {mode: ~healthy if mode == ALL_MODES else (true_mode == mode) & ~healthy for mode in modes}
    blocks = {c: [] for c in ("nfd", "fp", "fn", "fd", "n_incipient", "n_incipient_detected")}
    for _, _, _, detected in points:
        nfd, fp = per_unit(healthy & ~detected), per_unit(healthy & detected)
        for mode in modes:
            detectable = members[mode] & detectable_any
            incipient = members[mode] & incipient_any
            blocks["nfd"].append(nfd)
            blocks["fp"].append(fp)
            blocks["fn"].append(per_unit(detectable & ~detected))
            blocks["fd"].append(per_unit(detectable & detected))
            blocks["n_incipient"].append(per_unit(incipient))
            blocks["n_incipient_detected"].append(per_unit(incipient & detected))
    n_parts = len(points) * len(modes)
    c = pd.DataFrame({
        "operating_point": np.repeat(np.array([p[0] for p in points], dtype=object), len(modes) * n_units),
        "mode": np.tile(np.repeat(np.array(modes, dtype=object), n_units), len(points)),
        "unit_id": units.take(np.tile(np.arange(n_units), n_parts)),
        **{name: np.concatenate(parts) if parts else np.zeros(0, np.int64) for name, parts in blocks.items()},
    })
    c["n_healthy"] = c["fp"] + c["nfd"]
    c["n_detectable"] = c["fn"] + c["fd"]
    c["n_detected"] = c["fp"] + c["fd"]
    c["n_not_detected"] = c["fn"] + c["nfd"]
    return c


def _notes(table: pd.DataFrame) -> list[str]:
    notes = []
    for _, row in table.iterrows():
        parts = [f"{rate} undefined ({why})" for rate, why in UNDEFINED_RATES.items() if np.isnan(row[rate])]
        notes.append("; ".join(parts))
    return notes


def detection_table(flights: pd.DataFrame, model: HealthyScoreModel,
                    config: ScoringConfig | None = None) -> pd.DataFrame:
    """Table V: detection rates for every ``A`` (and the method's alarm) and every mode.

    For mode ``m`` the population is the healthy flights plus the flights
    where ``m`` is the only active fault; the ``"all"`` rows pool every flight
    (flights with several faults included).

    Parameters
    ----------
    flights : pandas.DataFrame
        Output of :func:`fuelhm_bench.scoring.flight_table`.
    model : HealthyScoreModel
        Gaussian fit of the healthy-training scores (thresholds).
    config : ScoringConfig or None, default=None

    Returns
    -------
    pandas.DataFrame
        One row per (operating point, mode): ``operating_point`` (``"thr(A=2)"``
        or ``"method_alarm"``), ``a``, ``threshold``, ``mode``, the counts
        ``nfd, fp, fn, fd, n_healthy, n_detectable, n_detected,
        n_not_detected, n_incipient, n_incipient_detected``, the rates
        ``fpr_standard, fnr_standard, fpr_paper_def, fnr_paper_def,
        incipient_detection_rate`` each with ``_ci_low``/``_ci_high`` (Wilson)
        and optionally ``_boot_low``/``_boot_high``, ``balanced_accuracy`` =
        ``1 - (fpr_standard + fnr_standard) / 2``, and ``note`` naming undefined
        rates.
    """
    config = ScoringConfig() if config is None else config
    counts = _unit_counts(flights, operating_points(flights, model, config), modes_present(flights) + [ALL_MODES])
    out = rates_with_intervals(counts, keys=["operating_point", "mode"], counts=_COUNTS,
                               rates=_RATES, confidence=config.confidence,
                               n_bootstrap=config.n_bootstrap, random_state=config.random_state)
    a_of = {config.operating_point_name(a): a for a in config.a_values}
    out.insert(1, "a", out["operating_point"].map(a_of).astype(float))
    out.insert(2, "threshold", [model.threshold(a_of[p]) if p in a_of else np.nan
                                for p in out["operating_point"]])
    out["balanced_accuracy"] = 1.0 - (out["fpr_standard"] + out["fnr_standard"]) / 2.0
    out["note"] = _notes(out)
    return out


def detection_by_band(flights: pd.DataFrame, model: HealthyScoreModel,
                      config: ScoringConfig | None = None) -> pd.DataFrame:
    """Detection rate per mode and intensity band, so incipient faults are visible.

    Parameters
    ----------
    flights : pandas.DataFrame
        Output of :func:`fuelhm_bench.scoring.flight_table`.
    model : HealthyScoreModel
    config : ScoringConfig or None, default=None

    Returns
    -------
    pandas.DataFrame
        One row per (operating point, mode, band) with ``n_flights``,
        ``n_detected``, ``detection_rate`` (+ intervals) and ``detectable``
        (whether the band lies wholly at or above ``detectable_fraction``). The
        ``"healthy"`` band rows give the false alarm rate; ``mode`` is
        ``"healthy"`` there. Multi-fault flights are excluded.
    """
    config = ScoringConfig() if config is None else config
    single = ~np.isin(flights["true_mode"].to_numpy(), [MULTIPLE])
    sub = flights[single]
    order = {b: i for i, b in enumerate((HEALTHY, *config.band_names))}
    mode_order = {m: i for i, m in enumerate((HEALTHY, *MODE_IDS))}
    parts = []
    for name, _, _, detected in operating_points(sub, model, config):
        c = pd.DataFrame({"operating_point": name, "mode": sub["true_mode"].to_numpy(),
                          "band": sub["band"].to_numpy(), "unit_id": sub["unit_id"].to_numpy(),
                          "n_flights": 1, "n_detected": detected.astype(np.int64)})
        c["_o"] = c["mode"].map(mode_order) * 100 + c["band"].map(order)
        c = c.sort_values("_o", kind="stable").drop(columns="_o")
        parts.append(c.groupby(["operating_point", "mode", "band", "unit_id"], sort=False)
                     .sum().reset_index())
    counts = pd.concat(parts, ignore_index=True)
    out = rates_with_intervals(counts, keys=["operating_point", "mode", "band"],
                               counts=["n_flights", "n_detected"],
                               rates={"detection_rate": ("n_detected", "n_flights")},
                               confidence=config.confidence, n_bootstrap=config.n_bootstrap,
                               random_state=config.random_state)
    lower_edge = dict(zip(config.band_names, (0.0, *config.band_edges)))
    out["detectable"] = [b != HEALTHY and lower_edge[b] >= config.detectable_fraction
                         for b in out["band"]]
    return out
