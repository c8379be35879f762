"""A raw-signal baseline: servo-loop features of the full-rate flight.

Written against the public raw-flight input (``fuelhm_bench.methods.raw.RawFlight``:
time, current, position, demand, N2 at full rate), as an outside researcher
would. Per flight it computes seven features of the closed loop:

1. ``track_bias_mm``: mean tracking error ``position - demand`` [mm];
2. ``track_rms_mm``: RMS of the tracking error [mm];
3. ``saturation_fraction``: fraction of samples with ``|current|`` at >= 98 %
   of the flight's largest ``|current|`` (the loop asking for more than the
   valve gives);
4. ``gain_mm_s_per_mA``: least-squares slope of the rod velocity on the
   current over the unsaturated samples (a whole-flight velocity gain);
5. ``gain_residual_mm_s``: RMS residual of that fit [mm/s] (how badly a
   linear valve law explains the flight: backlash, friction, leakage bend it);
6. ``position_roughness_mm``: standard deviation of the second difference of
   the position [mm] (sensor noise and stick-slip);
7. ``hold_current_mA``: median current while the rod holds still (speed below
   5 % of the flight's 95th-percentile speed): the current that balances the
   valve's null bias and leaks at rest.

Healthy statistics come from the healthy training flights of the *fit* units;
the score is the root mean square of the seven Z-scores; the alarm
threshold is the ``quantile`` quantile of the scores of held-out training units
(never of scored flights). Guilt is uniform on an alarm (detection only).

On ``paper_2012`` at physics fidelity, scale 0.3 (9 scored units of 30
flights), seed 0, it scores 24.6 (summary score; paper-Mahalanobis 55.5,
null 0): 71 % of the fault events detected, flight false-alarm rate 7 %,
flight miss rate 50 %. Without the hold-current feature it scored 11.7 (miss
rate 73 %). The 11.7 was measured sealed (``run_in_env``) and in process on the
same flights (``observation_row`` and ``info["raw_flight"]`` of the environment),
to the same digits; the 24.6 in process.
"""

from __future__ import annotations

from typing import Any, ClassVar, Iterable

import numpy as np
import pandas as pd

from fuelhm_bench.methods import BaseMethod, Decision
from fuelhm_bench.methods.params import Interval, RandomState
from fuelhm_bench.methods.raw import RawFlight
from fuelhm_bench.taxonomy import MODE_IDS

__all__ = ["FEATURES", "RawTrackingMethod", "raw_features"]

#: Feature names, in the order of :func:`raw_features`.
FEATURES: tuple[str, ...] = ("track_bias_mm", "track_rms_mm", "saturation_fraction",
                             "gain_mm_s_per_mA", "gain_residual_mm_s", "position_roughness_mm",
                             "hold_current_mA")


def raw_features(flight: RawFlight) -> np.ndarray:
    """The seven loop features of one flight (see the module docstring).

    Parameters
    ----------
    flight : RawFlight

    Returns
    -------
    numpy.ndarray of shape (7,)
        :data:`FEATURES` order; NaN where a feature is undefined (e.g. no
        unsaturated sample with current variation).

    Examples
    --------
    >>> import numpy as np
    >>> from fuelhm_bench.methods.raw import RawFlight
    >>> t = np.arange(0, 10, 0.01)
    >>> i = np.sin(t)                      # mA
    >>> x = 2.0 * (1 - np.cos(t))          # mm: velocity = 2 mm/s/mA * current
    >>> f = raw_features(RawFlight(0, 0, t, i, x, x - 0.1, np.full_like(t, 80.0)))
    >>> np.round(f[[0, 1, 3]], 3).tolist()
    [0.1, 0.1, 2.0]
    """
    t, i, x, d = flight.time_s, flight.current_mA, flight.position_mm, flight.demand_mm
    err = x - d
    out = np.full(len(FEATURES), np.nan)
    out[0] = err.mean()
    out[1] = np.sqrt(np.mean(err ** 2))
    peak = np.max(np.abs(i))
    saturated = np.abs(i) >= 0.98 * peak if peak > 0 else np.zeros(i.size, dtype=bool)
    out[2] = saturated.mean()
    v = np.gradient(x, t)
    ok = ~saturated
    if ok.sum() >= 3 and np.ptp(i[ok]) > 0:
        design = np.column_stack([i[ok], np.ones(int(ok.sum()))])
        coef, *_ = np.linalg.lstsq(design, v[ok], rcond=None)
        out[3] = coef[0]
        out[4] = np.sqrt(np.mean((v[ok] - design @ coef) ** 2))
    if x.size >= 3:
        out[5] = np.std(np.diff(x, n=2))
    speed = np.abs(v)
    still = speed < 0.05 * np.percentile(speed, 95) if np.any(speed > 0) else np.ones(v.size, dtype=bool)
    if still.sum() >= 10:
        out[6] = np.median(i[still])
    return out


class RawTrackingMethod(BaseMethod):
    """Loop features of the raw flight, healthy Z-scores, threshold on held-out units.

    Parameters
    ----------
    quantile : float in (0.5, 1), default=0.99
        Quantile of the held-out training scores used as threshold.
    calibration_fraction : float in (0, 1), default=0.25
        Fraction of the healthy training units held out to set the threshold
        (the last flights of the single unit when there is only one).
    random_state : int, numpy.random.Generator or None, default=None
        Seed of the choice of held-out units.

    Attributes
    ----------
    mean_, std_ : numpy.ndarray of shape (6,)
        Healthy feature statistics (fit units).
    threshold_ : float
    calibration_scores_ : numpy.ndarray
    """

    needs_raw: ClassVar[bool] = True
    _parameter_constraints: ClassVar[dict[str, tuple]] = {
        "quantile": (Interval(float, 0.5, 1.0, closed="neither"),),
        "calibration_fraction": (Interval(float, 0.0, 1.0, closed="neither"),),
        "random_state": (RandomState(),),
    }

    def __init__(self, *, quantile: float = 0.99, calibration_fraction: float = 0.25,
                 random_state: Any = None) -> None:
        self.quantile = quantile
        self.calibration_fraction = calibration_fraction
        self.random_state = random_state

    def _fit(self, healthy_indicators: pd.DataFrame, *, knowledge: Any,
             raw_flights: Iterable[RawFlight], rng: np.random.Generator) -> None:
        units, indices, feats = [], [], []
        for flight in raw_flights:  # one flight in memory at a time
            units.append(flight.unit_id)
            indices.append(flight.flight_index)
            feats.append(raw_features(flight))
        if len(feats) < 4:
            raise ValueError(f"RawTrackingMethod needs at least 4 raw healthy training flights. Got "
                             f"{len(feats)} instead.")
        x = np.array(feats)
        codes = pd.factorize(pd.Series(units, dtype=object))[0]
        n_units = int(codes.max()) + 1
        if n_units >= 2:
            n_cal = min(n_units - 1, max(1, int(round(self.calibration_fraction * n_units))))
            cal = np.isin(codes, rng.permutation(n_units)[:n_cal])
        else:
            order = np.argsort(indices, kind="stable")
            cal = np.zeros(len(x), dtype=bool)
            cal[order[len(x) - max(2, int(self.calibration_fraction * len(x))):]] = True
        fit = x[~cal]
        self.mean_ = np.nanmean(fit, axis=0)
        std = np.nanstd(fit, axis=0, ddof=1)
        self.std_ = np.where(np.isfinite(std) & (std > 0), std, 1.0)
        self.mean_ = np.where(np.isfinite(self.mean_), self.mean_, 0.0)
        self.calibration_scores_ = self._scores(x[cal])
        self.threshold_ = float(np.quantile(self.calibration_scores_, self.quantile))

    def _scores(self, x: np.ndarray) -> np.ndarray:
        z = (x - self.mean_) / self.std_
        z = np.where(np.isfinite(z), z, 0.0)
        return np.sqrt(np.mean(z ** 2, axis=1))

    def _decide(self, row: pd.Series, raw: RawFlight) -> Decision:
        score = float(self._scores(raw_features(raw)[None, :])[0])
        if score <= self.threshold_:
            return Decision.no_alarm(score)
        return Decision(score=score, alarm=True, guilt=np.full(len(MODE_IDS), 1.0 / len(MODE_IDS)))
