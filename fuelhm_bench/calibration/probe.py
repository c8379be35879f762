"""Sparse probe of what the effect library lacks: residuals regressed on physical terms.

When the discrepancy workflow's verdict is ``unexplained``, the velocity residuals that
remain (measured - model, on the fit flights) are regressed on a library of physically
meaningful terms evaluated at the same samples, and the few terms that explain most of them
are reported with their coefficients and the part of the *held-out* gap they close.

Terms (each at the scored samples; the model velocity is the final model's replayed one):

==============================  =======================================================
term                            reads as
==============================  =======================================================
``current rate``                d i/dt [mA/s]: a lag or a rate-dependent effect
``current``                     i [mA]: a gain or offset error along the curve
``current^3``                   i^3 [mA^3]: a curvature of the gain
``flow x supply``               v_model N2^2 [mm/s]: flow- and pressure-dependent
``model velocity``              v_model [mm/s]: a gain error
``sign of velocity``            sgn v_model: a force opposing the motion
``position``                    x [mm]: a position-dependent load
``N2``                          N2 [%]: supply pressure / load level
``fuel temperature``            T [degC] (when the file has ``fuel_temp_degC``)
``velocity x temperature``      v_model (T - 40 degC) [mm/s degC]: viscosity
``time in flight``              t [h]: a drift
``offset``                      1: a constant velocity offset
==============================  =======================================================

Solver: orthogonal matching pursuit (scikit-learn ``OrthogonalMatchingPursuit``) on
standardised terms, with 1, 2, ... ``max_terms`` terms; the number kept is the smallest
after which one more term closes less than ``min_step`` of the held-out gap. OMP was chosen
over the Lasso because the question is "which few terms", not a shrunk continuous path:
OMP returns exactly ``k`` terms with unbiased least-squares coefficients, without a
penalty to tune; PySINDy would add a dependency whose strength (learning a dynamical system
from state derivatives) is not needed here, the target being already a velocity residual.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from sklearn.linear_model import OrthogonalMatchingPursuit

from fuelhm_bench.calibration.curve import CurveConfig, gap

TERM_UNITS = {"current rate": "mm/s per mA/s", "current": "mm/s per mA", "current^3": "mm/s per mA^3",
              "flow x supply": "-", "model velocity": "-", "sign of velocity": "mm/s", "position": "mm/s per mm",
              "N2": "mm/s per %", "fuel temperature": "mm/s per degC", "velocity x temperature": "1/degC",
              "time in flight": "mm/s per h", "offset": "mm/s"}


@dataclass(frozen=True)
class ProbeResult:
    """Outcome of :func:`sparse_probe`.

    Attributes
    ----------
    terms : tuple of str
        Selected terms, in the order chosen.
    coefficients : tuple of float
        Their coefficients in physical units (:data:`TERM_UNITS`).
    gap_before, gap_after : float
        Held-out gap of the final model, and with the terms added to it [mm/s].
    steps : tuple of (term, held-out gap)
        The held-out gap after each term.
    """

    terms: tuple
    coefficients: tuple
    gap_before: float
    gap_after: float
    steps: tuple

    @property
    def gap_closed(self) -> float:
        """Share of the held-out gap the terms close [-]."""
        return 1.0 - self.gap_after / self.gap_before if self.gap_before > 0 else 0.0

    def as_json(self) -> dict:
        """JSON-ready summary."""
        return {"terms": [{"term": t, "coefficient": c, "unit": TERM_UNITS.get(t, "")}
                          for t, c in zip(self.terms, self.coefficients)],
                "gap_before": self.gap_before, "gap_after": self.gap_after, "gap_closed": self.gap_closed,
                "steps": [{"term": t, "gap": g} for t, g in self.steps]}


def probe_terms(rs, v_model: np.ndarray) -> tuple[list[str], np.ndarray]:
    """The term library at the scored samples of ``rs`` (names, matrix (n_scored, n_terms))."""
    s = rs.scored
    cur_ma = 1e3 * rs.current_a
    rate = np.zeros_like(cur_ma)
    for a, n in zip(rs.starts, rs.lengths):
        if n > 1:
            rate[a:a + n] = np.gradient(cur_ma[a:a + n], rs.frame_s)
    v = np.nan_to_num(v_model[s])
    i = rs.i_ma[s]
    n2 = 100.0 * rs.n2_frac[s]
    cols = {"current rate": rate[s], "current": i, "current^3": i ** 3, "flow x supply": v * (n2 / 100.0) ** 2,
            "model velocity": v, "sign of velocity": np.sign(np.where(np.abs(v) < 0.5, 0.0, v)),
            "position": rs.position_mm[s], "N2": n2}
    if rs.fuel_temp_degc is not None:
        temp = rs.fuel_temp_degc[s]
        cols["fuel temperature"] = temp
        cols["velocity x temperature"] = v * (temp - 40.0)
    if rs.time_s is not None:
        cols["time in flight"] = rs.time_s[s] / 3600.0
    names = list(cols)
    return names, np.column_stack([cols[k] for k in names])


def sparse_probe(fit_rs, v_fit: np.ndarray, held_rs, v_held: np.ndarray, *, curve: CurveConfig = CurveConfig(),
                 max_terms: int = 3, min_step: float = 0.05) -> ProbeResult:
    """Regress the remaining residuals on the term library (module docstring).

    Parameters
    ----------
    fit_rs, held_rs : ReplaySet
        Fit and held-out samples.
    v_fit, v_held : numpy.ndarray
        The final model's replayed velocity on them [mm/s].
    curve : CurveConfig
        Cells of the gap metric.
    max_terms : int, default=3
        Most terms reported.
    min_step : float, default=0.05
        Smallest share of the held-out gap one more term must close to be kept.
    """
    names, x_fit = probe_terms(fit_rs, v_fit)
    names_h, x_held = probe_terms(held_rs, v_held)
    common = [n for n in names if n in names_h]
    x_fit = x_fit[:, [names.index(n) for n in common]]
    x_held = x_held[:, [names_h.index(n) for n in common]]
    y = (fit_rs.v_meas_mm_s - v_fit)[fit_rs.scored]
    ok = np.isfinite(y) & np.all(np.isfinite(x_fit), axis=1)
    x_fit, y = x_fit[ok], y[ok]
    mu, sd = x_fit.mean(axis=0), x_fit.std(axis=0)
    sd[sd == 0] = 1.0
    const = np.array([n == "offset" for n in common])
    z_fit = (x_fit - mu) / sd
    g0 = gap(held_rs, v_held, curve)
    best = (g0, (), (), ())
    steps = []
    prev_gap = g0
    for k in range(1, min(max_terms, len(common)) + 1):
        omp = OrthogonalMatchingPursuit(n_nonzero_coefs=k, fit_intercept=True).fit(z_fit, y)
        coef = omp.coef_ / sd
        intercept = omp.intercept_ - float(np.sum(omp.coef_ * mu / sd))
        pred = np.full(held_rs.n_frames, np.nan)
        pred[held_rs.scored] = np.nan_to_num(x_held @ coef) + intercept
        g = gap(held_rs, v_held + np.nan_to_num(pred), curve)
        chosen = [j for j in np.flatnonzero(omp.coef_) if not const[j]]
        # order by contribution (|standardised coefficient|)
        chosen.sort(key=lambda j: -abs(omp.coef_[j]))
        new = [common[j] for j in chosen if common[j] not in best[1]]
        steps.append((", ".join(new) if new else "(none)", g))
        if prev_gap - g < min_step * g0:
            break
        best = (g, tuple(common[j] for j in chosen), tuple(float(coef[j]) for j in chosen), ())
        prev_gap = g
    return ProbeResult(terms=best[1], coefficients=best[2], gap_before=g0, gap_after=best[0], steps=tuple(steps))


__all__ = ["ProbeResult", "TERM_UNITS", "probe_terms", "sparse_probe"]
