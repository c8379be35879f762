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

For each level the map holds the sample count, the mean and RMS residual, and the *local
gap*: the gap metric (:mod:`~fuelhm_bench.calibration.curve`) restricted to the level's
samples, i.e. how far the model's curve is from the measured one in that region. The
disagreement *concentrates* where the local gap is largest relative to the gap over all
samples (levels holding less than ``min_share`` of the samples are not named).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fuelhm_bench.calibration import velocity as vel
from fuelhm_bench.calibration.curve import CurveConfig, cell_residuals

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
    """

    factor: str
    level: str
    count: int
    mean_mm_s: float
    rms_mm_s: float
    local_gap_mm_s: float


@dataclass(frozen=True)
class RegionMap:
    """Residual statistics over every factor level, and the overall gap.

    Attributes
    ----------
    levels : tuple of RegionLevel
    gap_mm_s : float
        Gap metric over all samples [mm/s].
    count : int
        Scored samples.
    """

    levels: tuple
    gap_mm_s: float
    count: int

    def level(self, factor: str, level: str) -> RegionLevel | None:
        """The statistics of one level (None if absent)."""
        for lv in self.levels:
            if lv.factor == factor and lv.level == level:
                return lv
        return None

    def ranked(self, *, min_share: float = 0.05) -> list[RegionLevel]:
        """Levels by decreasing local gap, among those with at least ``min_share`` of the samples."""
        ok = [lv for lv in self.levels if lv.count >= min_share * max(self.count, 1) and np.isfinite(lv.local_gap_mm_s)]
        return sorted(ok, key=lambda lv: -lv.local_gap_mm_s)

    def concentration(self, *, min_share: float = 0.05, n_top: int = 2) -> str:
        """Name of the region(s) where the disagreement concentrates, e.g. ``"current band: null region (x2.1)"``.

        One level per factor at most, the ``n_top`` levels with the largest local gap relative to
        the overall gap.
        """
        seen, names = set(), []
        for lv in self.ranked(min_share=min_share):
            if lv.factor in seen:
                continue
            seen.add(lv.factor)
            ratio = lv.local_gap_mm_s / self.gap_mm_s if self.gap_mm_s > 0 else float("nan")
            names.append(f"{lv.factor}: {lv.level} (local gap {lv.local_gap_mm_s:.2f} mm/s, x{ratio:.1f})")
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


def region_map(rs, v_model: np.ndarray, levels: dict[str, np.ndarray], curve: CurveConfig = CurveConfig()
               ) -> RegionMap:
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
    """
    s = rs.scored
    r = rs.v_meas_mm_s[s] - v_model[s]
    mean_all, count_all = cell_residuals(rs, v_model, curve)
    ok = count_all >= curve.min_count
    gap_all = float(np.sqrt(np.mean(mean_all[ok] ** 2))) if ok.any() else float("nan")
    i = rs.i_ma[s]
    groups = rs.direction[s].astype(np.int64) + 1
    out = []
    for factor, names in levels.items():
        for name in sorted(set(names.tolist())):
            sel = names == name
            if not sel.any():
                continue
            m, c = vel.binned_mean(i[sel], r[sel], curve.edges, groups[sel], 3)
            good = c >= curve.min_count
            lg = float(np.sqrt(np.mean(m[good] ** 2))) if good.any() else float("nan")
            out.append(RegionLevel(factor, str(name), int(sel.sum()), float(np.mean(r[sel])),
                                   float(np.sqrt(np.mean(r[sel] ** 2))), lg))
    return RegionMap(tuple(out), gap_all, int(r.shape[0]))
