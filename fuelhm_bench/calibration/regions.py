"""Residual maps over operating regions: where model and measurement disagree.

Every scored sample of a replay gets a level on each of these factors:

==============  ==============================================================================
factor          levels
==============  ==============================================================================
current band    ``near idle`` (``|i - I0| < idle_halfwidth_ma``, ``I0`` the unit's median idle
                current), ``null region`` (``|i - Inb| < transition_start * I_r``), ``transition``
                (up to ``transition_end * I_r``), ``outer`` (up to ``I_r``), ``saturation``
                (``|i - Inb| >= I_r``: spool at full stroke); ``Inb``, ``I_r`` from the unit's model
direction       current ``rising``, ``falling``, ``steady`` over the differentiator window
velocity        ``still`` (< ``moving_velocity``), ``extending slow/fast``, ``retracting slow/fast``
                (``fast`` from ``fast_velocity_mm_s``)
position        ``low``, ``mid``, ``high`` third of the stroke
N2              ``< 70 %``, ``70-90 %``, ``>= 90 %`` (supply pressure ~ N2^2)
flight phase    the file's ``phase`` names (when present)
==============  ==============================================================================

For each level the map holds the sample count, the mean and RMS residual, the *local gap*
(the gap metric of :mod:`~fuelhm_bench.calibration.curve` restricted to the level's samples:
how far the model's curve is from the measured one in that region) and the *misfit score*:
the mean over the level's curve cells of ``z_c^2``, with ``z_c`` the cell's mean residual
divided by its standard error (``s_c sqrt(tau / n_c)``, ``tau`` the residuals' correlation
time). A score near 1 is noise; the disagreement *concentrates* in the levels with the
largest score (levels holding less than ``min_share`` of the samples are not named). The
score, unlike the local gap, discounts sparse noisy cells (e.g. a few samples at the current
limit) and weighs consistent offsets over many samples.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fuelhm_bench.calibration import velocity as vel
from fuelhm_bench.calibration.curve import CurveConfig

FACTORS: tuple[str, ...] = ("current band", "direction", "velocity", "position", "N2", "flight phase")


@dataclass(frozen=True)
class RegionLevel:
    """Residual statistics of one level of one factor.

    Attributes
    ----------
    factor, level : str
        Names.
    count : int
        Scored samples.
    mean_mm_s, rms_mm_s : float
        Mean and RMS residual (measured - model) [mm/s].
    local_gap_mm_s : float
        Gap metric restricted to the level's samples [mm/s] (NaN if no cell is populated).
    score : float
        Misfit score: mean ``z^2`` over the level's cells [-] (NaN if no cell is populated).
    """

    factor: str
    level: str
    count: int
    mean_mm_s: float
    rms_mm_s: float
    local_gap_mm_s: float
    score: float


@dataclass(frozen=True)
class RegionMap:
    """Residual statistics over every factor level, and the overall gap.

    Attributes
    ----------
    levels : tuple of RegionLevel
    gap_mm_s : float
        Gap metric over all samples [mm/s].
    score : float
        Misfit score over all samples [-].
    count : int
        Scored samples.
    """

    levels: tuple
    gap_mm_s: float
    score: float
    count: int

    def level(self, factor: str, level: str) -> RegionLevel | None:
        """The statistics of one level (None if absent)."""
        for lv in self.levels:
            if lv.factor == factor and lv.level == level:
                return lv
        return None

    def ranked(self, *, min_share: float = 0.05, by: str = "local_gap") -> list[RegionLevel]:
        """Levels among those with at least ``min_share`` of the samples, most disagreeing first.

        ``by="local_gap"`` (default) ranks the levels whose misfit score is significant (above
        the overall score's noise level, 3) by their local gap -- *where the gap is* -- then the
        others by score; ``by="score"`` ranks by misfit score only.
        """
        ok = [lv for lv in self.levels if lv.count >= min_share * max(self.count, 1) and np.isfinite(lv.score)]
        if by == "score":
            return sorted(ok, key=lambda lv: -lv.score)
        sig = [lv for lv in ok if lv.score > 3.0 and np.isfinite(lv.local_gap_mm_s)]
        rest = [lv for lv in ok if lv not in sig]
        return sorted(sig, key=lambda lv: -lv.local_gap_mm_s) + sorted(rest, key=lambda lv: -lv.score)

    def concentration(self, *, min_share: float = 0.05, n_top: int = 2) -> str:
        """Name of the region(s) where the disagreement concentrates.

        The ``n_top`` levels (one per factor at most) first in :meth:`ranked` (largest local gap
        among the significant levels), e.g.
        ``"current band: null region (score 41 vs 12 overall, local gap 0.52 mm/s)"``.
        """
        seen, names = set(), []
        for lv in self.ranked(min_share=min_share):
            if lv.factor in seen:
                continue
            seen.add(lv.factor)
            names.append(f"{lv.factor}: {lv.level} (score {lv.score:.3g} vs {self.score:.3g} overall, "
                         f"local gap {lv.local_gap_mm_s:.2f} mm/s)")
            if len(names) == n_top:
                break
        return "; ".join(names) if names else "nowhere in particular"


def sample_levels(rs, unit_models: dict, unit_of_flight, *, idle_halfwidth_ma: float = 0.25,
                  fast_velocity_mm_s: float = 20.0) -> dict[str, np.ndarray]:
    """Level name of every scored sample for each factor.

    Parameters
    ----------
    rs : ReplaySet
        The samples.
    unit_models : dict
        Model per unit key (null bias, rated current, transitions, stroke).
    unit_of_flight : callable
        Maps a flight index of ``rs`` to its unit key.
    idle_halfwidth_ma : float, default=0.25
        Half-width of the *near idle* band [mA].
    fast_velocity_mm_s : float, default=20.0
        Speed from which a motion is *fast* [mm/s].

    Returns
    -------
    dict
        Factor name -> object array of level names (one per scored sample).
    """
    s = rs.scored
    i = rs.i_ma[s]
    v = rs.v_meas_mm_s[s]
    flight = rs.flight[s]
    moving = rs.moving[s]
    n = i.shape[0]
    band = np.empty(n, dtype=object)
    pos_level = np.empty(n, dtype=object)
    for fi in np.unique(flight):
        sel = flight == fi
        model = unit_models[unit_of_flight(int(fi))]
        sv = model.servovalve
        inb = 1e3 * (sv.total_null_bias_a - model.driver.offset_a) / model.driver.gain
        ir = 1e3 * sv.rated_current_a / model.driver.gain
        idle_i = i[sel & ~moving]
        i0 = float(np.median(idle_i)) if idle_i.size else inb
        d = np.abs(i[sel] - inb)
        b = np.where(d >= ir, "saturation", np.where(d >= sv.transition_end * ir, "outer", np.where(
            d >= sv.transition_start * ir, "transition", "null region")))
        b = np.where(np.abs(i[sel] - i0) < idle_halfwidth_ma, "near idle", b)
        band[sel] = b
        third = 1e3 * model.cylinder.stroke_m / 3.0
        x = rs.position_mm[s][sel]
        pos_level[sel] = np.where(x < third, "low", np.where(x < 2 * third, "mid", "high"))
    direction = np.array(["falling", "steady", "rising"], dtype=object)[rs.direction[s].astype(int) + 1]
    mv = rs.config.moving_velocity_mm_s
    speed = np.where(np.abs(v) < mv, "still", np.where(
        v > 0, np.where(v >= fast_velocity_mm_s, "extending fast", "extending slow"),
        np.where(v <= -fast_velocity_mm_s, "retracting fast", "retracting slow")))
    n2 = 100.0 * rs.n2_frac[s]
    n2_level = np.where(n2 < 70.0, "N2 < 70 %", np.where(n2 < 90.0, "N2 70-90 %", "N2 >= 90 %"))
    out = {"current band": band, "direction": direction, "velocity": speed.astype(object),
           "position": pos_level, "N2": n2_level.astype(object)}
    if rs.phase is not None:
        out["flight phase"] = np.asarray(rs.phase[s], dtype=object).astype(str).astype(object)
    return out


def _cell_stats(i, r, groups, curve: CurveConfig, tau: float) -> tuple[float, float]:
    """(gap, mean z^2) over the populated cells of some samples."""
    m, c = vel.binned_mean(i, r, curve.edges, groups, 3)
    m2, _ = vel.binned_mean(i, r * r, curve.edges, groups, 3)
    good = c >= curve.min_count
    if not good.any():
        return float("nan"), float("nan")
    var = np.clip(m2[good] - m[good] ** 2, 1e-12, None) * c[good] / np.maximum(c[good] - 1, 1)
    z2 = m[good] ** 2 / (var * max(tau, 1.0) / c[good])
    return float(np.sqrt(np.mean(m[good] ** 2))), float(np.mean(z2))


def region_map(rs, v_model: np.ndarray, levels: dict[str, np.ndarray], curve: CurveConfig = CurveConfig(),
               tau: float = 1.0) -> RegionMap:
    """Residual statistics per factor level (see the module docstring).

    Parameters
    ----------
    rs : ReplaySet
        Samples.
    v_model : numpy.ndarray (N,)
        Replayed model velocity [mm/s].
    levels : dict
        From :func:`sample_levels`.
    curve : CurveConfig
        Cells of the gap metric.
    tau : float, default=1.0
        Correlation time of the residuals [samples] (standard errors of the cell means).
    """
    s = rs.scored
    r = rs.v_meas_mm_s[s] - v_model[s]
    i = rs.i_ma[s]
    groups = rs.direction[s].astype(np.int64) + 1
    gap_all, score_all = _cell_stats(i, r, groups, curve, tau)
    out = []
    for factor, names in levels.items():
        for name in sorted(set(names.tolist())):
            sel = names == name
            if not sel.any():
                continue
            lg, sc = _cell_stats(i[sel], r[sel], groups[sel], curve, tau)
            out.append(RegionLevel(factor, str(name), int(sel.sum()), float(np.mean(r[sel])),
                                   float(np.sqrt(np.mean(r[sel] ** 2))), lg, sc))
    return RegionMap(tuple(out), gap_all, score_all, int(r.shape[0]))
