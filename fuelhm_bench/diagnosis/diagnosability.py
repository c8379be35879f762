"""How well each degradation mode can be seen and told apart: the diagnosability report.

From a design of experiments (DOE) and a healthy fleet, for one set of indicators:

* **laws**: for every (mode, indicator), the paper's linear law through the origin
  ``dI = A s`` (:func:`~fuelhm_bench.diagnosis.itl.fit_through_origin`, eq. 2) and a
  *monotone law through the origin* ``dI = c s**p`` (:func:`fit_power_law`), with the centred
  R² of each. The power law covers what the line cannot: a saturating response (``p < 1``,
  down to a near step), an accelerating one (``p > 1``), and it equals the line at ``p = 1``.
  The paper's linear law is kept for the paper's study; the power law is the better form;
* **per mode**: the largest ``|Z|`` at the mode's maximum intensity ``s_max`` (the Z-score of
  the healthy mean moved by the law, eq. 9: ``c s_max**p / std``), for the better form and for
  the linear law, the indicator that carries it, and the largest ``|Z|`` *observed* (mean paired
  change at the DOE's largest intensity over the healthy standard deviation, no law involved);
* **signature similarity**: the 7x7 cosine similarity of the better-form signature vectors
  (``Z`` of every indicator at ``s_max``); a pair above ``cosine_limit`` cannot be told apart by
  the collinearity guilt of the paper's eq. 10.

A mode is reported *visible* when its better-form ``|Z|max`` reaches ``z_target``
(default 5) and *distinguishable* when no other mode's signature has a cosine above
``cosine_limit`` (default 0.9) with its own. These are properties of the physics and of the
indicator set, not tuning knobs: a mode below target is reported, never inflated.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.optimize import minimize_scalar

from fuelhm_bench.diagnosis._validation import check_features, indicator_matrix, param_error
from fuelhm_bench.diagnosis.itl import fit_through_origin, paired_deltas
from fuelhm_bench.taxonomy import MODE_IDS

__all__ = ["DiagnosabilityReport", "diagnosability_report", "fit_power_law"]

#: Exponents tried by :func:`fit_power_law` (log-spaced, 1 included exactly).
POWER_GRID: np.ndarray = np.unique(np.concatenate([np.geomspace(0.05, 8.0, 161), [1.0]]))


def _r2(d: np.ndarray, pred: np.ndarray) -> float:
    """Centred R² (``sklearn.metrics.r2_score``), the convention of ``fit_through_origin``."""
    ssr = float(((d - pred) ** 2).sum())
    sst = float(((d - d.mean()) ** 2).sum())
    if sst > 0:
        return 1.0 - ssr / sst
    return 1.0 if ssr == 0 else -math.inf


def fit_power_law(intensity: np.ndarray, delta: np.ndarray) -> dict[str, np.ndarray]:
    """Least-squares monotone laws through the origin ``dI = c * s**p``, one per column.

    For each exponent ``p`` of :data:`POWER_GRID` (0.05 to 8, 1 included) the best ``c`` has
    the closed form ``sum(s**p dI) / sum(s**2p)``; the exponent with the smallest residual sum
    of squares is kept (the first one on ties, so an exact line gives ``p = 1``) and refined by a
    bounded scalar minimisation between its grid neighbours (kept only if it lowers the residual;
    ``p`` stays within [0.05, 8]). The law is
    monotone in ``s`` and passes through the origin, as a degradation law must (no change
    without degradation); ``p < 1`` describes a response that saturates (a step-like change
    at small ``p``), ``p > 1`` one that accelerates. With intensities 0.25, 0.5, 0.75, 1 and no
    noise, ``dI = 1 - exp(-5 s)`` gets R² 0.91 (the line: -5.3) and ``dI = sqrt(s)`` 1.00 (the
    line: 0.39). A pure step (the same change at every intensity) has no spread to explain: no
    law, linear or not, gets a centred R² above that of a constant; its ``|Z|`` is still right.

    Parameters
    ----------
    intensity : ndarray of shape (n_rows,)
        Intensities, in (0, 1].
    delta : ndarray of shape (n_rows, n_laws)
        Indicator changes, NaN where unavailable.

    Returns
    -------
    dict of str to ndarray of shape (n_laws,)
        ``"c"`` (indicator unit), ``"p"`` (dimensionless), ``"r2"`` (centred, as
        :func:`~fuelhm_bench.diagnosis.itl.fit_through_origin`) and ``"n"``. NaN where fewer than
        two finite rows.

    Examples
    --------
    >>> import numpy as np
    >>> s = np.array([0.25, 0.5, 0.75, 1.0])
    >>> fit = fit_power_law(s, np.column_stack([2 * s, 3 * s**2, np.sqrt(s)]))
    >>> np.round(fit["c"], 3).tolist(), np.round(fit["p"], 2).tolist(), np.round(fit["r2"], 3).tolist()
    ([2.0, 3.0, 1.0], [1.0, 2.0, 0.5], [1.0, 1.0, 1.0])
    """
    s_all = np.asarray(intensity, dtype=np.float64)
    d_all = np.asarray(delta, dtype=np.float64)
    if s_all.ndim != 1 or d_all.ndim != 2 or d_all.shape[0] != s_all.shape[0]:
        raise param_error("delta", "fit_power_law", f"an array of shape ({s_all.shape[0]}, n_laws)", d_all.shape)
    if np.any(~(s_all > 0)):
        raise param_error("intensity", "fit_power_law", "an array of intensities in (0, 1]", s_all)
    n_laws = d_all.shape[1]
    out = {k: np.full(n_laws, np.nan) for k in ("c", "p", "r2")}
    out["n"] = np.zeros(n_laws, dtype=np.int64)
    for j in range(n_laws):
        ok = np.isfinite(d_all[:, j])
        n = int(ok.sum())
        out["n"][j] = n
        if n < 2:
            continue
        s, d = s_all[ok], d_all[ok, j]
        basis = s[None, :] ** POWER_GRID[:, None]               # (n_p, n)
        c = (basis @ d) / (basis ** 2).sum(axis=1)
        ssr = ((d[None, :] - c[:, None] * basis) ** 2).sum(axis=1)
        # Round to absorb floating-point noise between equivalent exponents (exact laws).
        k = int(np.argmin(np.round(ssr, 12)))
        best_p, best_ssr = float(POWER_GRID[k]), float(ssr[k])
        if 0 < k < len(POWER_GRID) - 1:  # refine between the grid neighbours
            def sse(q):
                b_ = s ** q
                return float(((d - (b_ @ d) / (b_ @ b_) * b_) ** 2).sum())

            res = minimize_scalar(sse, bounds=(POWER_GRID[k - 1], POWER_GRID[k + 1]), method="bounded",
                                  options={"xatol": 1e-7})
            if res.success and res.fun < best_ssr - 1e-12 * max(best_ssr, 1e-300):
                best_p, best_ssr = float(res.x), float(res.fun)
        b_ = s ** best_p
        c_best = float((b_ @ d) / (b_ @ b_))
        out["c"][j], out["p"][j] = c_best, best_p
        out["r2"][j] = _r2(d, c_best * b_)
    return out


@dataclass(frozen=True)
class DiagnosabilityReport:
    """The diagnosability of the modes for one indicator set (see the module docstring).

    Attributes
    ----------
    name : str
        Label of the indicator set (``"paper"``, ``"extended"``).
    features : tuple of str
        The indicators.
    modes : pandas.DataFrame
        One row per mode: ``mode``, ``max_intensity``, ``z_max`` (better form), ``z_max_indicator``,
        ``r2_linear_at_z_max``, ``r2_power_at_z_max`` and ``p_at_z_max`` (the laws of that indicator),
        ``z_max_linear`` (the paper's linear law), ``z_max_observed`` (no law), ``max_cosine``,
        ``closest_mode``, ``visible`` (``z_max >= z_target``), ``distinguishable``
        (``max_cosine <= cosine_limit``).
    laws : pandas.DataFrame
        One row per (mode, indicator): ``A``, ``r2_linear``, ``c``, ``p``, ``r2_power``, ``z_linear``,
        ``z_power`` (Z at the maximum intensity, each law), ``n``.
    signatures : pandas.DataFrame
        Better-form signature (Z at maximum intensity), modes x indicators.
    cosine : pandas.DataFrame
        Cosine similarity of the signatures, modes x modes.
    z_target, cosine_limit : float
        The thresholds behind ``visible`` and ``distinguishable``.
    """

    name: str
    features: tuple
    modes: pd.DataFrame
    laws: pd.DataFrame
    signatures: pd.DataFrame
    cosine: pd.DataFrame
    z_target: float
    cosine_limit: float

    @property
    def all_visible(self) -> bool:
        """Every mode reaches ``z_target``."""
        return bool(self.modes["visible"].all())

    @property
    def all_distinguishable(self) -> bool:
        """No pair of signatures above ``cosine_limit``."""
        return bool(self.modes["distinguishable"].all())

    def similar_pairs(self) -> list[tuple[str, str, float]]:
        """Pairs of modes whose signature cosine exceeds ``cosine_limit`` (each pair once)."""
        c = self.cosine
        out = []
        for i, a in enumerate(c.index):
            for b in c.index[i + 1:]:
                v = float(c.loc[a, b])
                if np.isfinite(v) and v > self.cosine_limit:
                    out.append((a, b, v))
        return out

    def to_markdown(self) -> str:
        """Human-readable report: the per-mode table, the cosine matrix and the weak laws."""
        lines = [f"## Diagnosability: {self.name} indicator set ({len(self.features)} indicators)", "",
                 f"Indicators: {', '.join(self.features)}. Target: |Z|max >= {self.z_target:g} at the maximum "
                 f"intensity, no signature pair with cosine > {self.cosine_limit:g}.", "",
                 "| mode | s_max | abs(Z)max (monotone law) | on | its R² (monotone, linear) | exponent p "
                 "| abs(Z)max (linear law) | abs(Z)max observed | max cosine | with | visible | distinguishable |",
                 "|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in self.modes.itertuples():
            lines.append(f"| {r.mode} | {r.max_intensity:g} | {r.z_max:.1f} | {r.z_max_indicator} | "
                         f"{r.r2_power_at_z_max:.2f}, {r.r2_linear_at_z_max:.2f} | {r.p_at_z_max:.2g} | "
                         f"{r.z_max_linear:.1f} | {r.z_max_observed:.1f} | {r.max_cosine:.2f} | {r.closest_mode} | "
                         f"{'yes' if r.visible else '**no**'} | {'yes' if r.distinguishable else '**no**'} |")
        lines += ["", "Cosine similarity of the signatures:", "",
                  "| | " + " | ".join(self.cosine.columns) + " |",
                  "|---" * (len(self.cosine.columns) + 1) + "|"]
        for mode, row in self.cosine.iterrows():
            lines.append(f"| {mode} | " + " | ".join(f"{v:.2f}" for v in row.to_numpy()) + " |")
        n = len(self.laws)
        lin = int((self.laws["r2_linear"] >= 0.8).sum())
        pw = int((self.laws["r2_power"] >= 0.8).sum())
        lines += ["", f"Laws with R² >= 0.8: {lin} of {n} linear, {pw} of {n} monotone power laws "
                  "(R² of every law in the JSON / CSV report)."]
        return "\n".join(lines)

    def to_dict(self) -> dict:
        """JSON-ready content (NaN as None)."""
        def clean(v):
            if isinstance(v, (float, np.floating)):
                return None if not np.isfinite(v) else float(v)
            if isinstance(v, (np.integer,)):
                return int(v)
            if isinstance(v, (np.bool_,)):
                return bool(v)
            return v

        def records(df):
            return [{k: clean(v) for k, v in row.items()} for row in df.to_dict(orient="records")]

        return {"name": self.name, "features": list(self.features), "z_target": self.z_target,
                "cosine_limit": self.cosine_limit, "all_visible": self.all_visible,
                "all_distinguishable": self.all_distinguishable,
                "similar_pairs": [[a, b, v] for a, b, v in self.similar_pairs()],
                "modes": records(self.modes), "laws": records(self.laws),
                "cosine": {m: {k: clean(v) for k, v in row.items()} for m, row in self.cosine.iterrows()}}

    def write(self, out_dir, stem: str | None = None) -> list[Path]:
        """Write ``<stem>.md``, ``<stem>.json`` and ``<stem>_laws.csv`` (stem: ``diagnosability_<name>``)."""
        out = Path(out_dir)
        stem = stem or f"diagnosability_{self.name}"
        paths = [out / f"{stem}.md", out / f"{stem}.json", out / f"{stem}_laws.csv"]
        paths[0].write_text(self.to_markdown() + "\n")
        paths[1].write_text(json.dumps(self.to_dict(), indent=1) + "\n")
        self.laws.to_csv(paths[2], index=False)
        return paths


def _cosine(sig: np.ndarray) -> np.ndarray:
    """Cosine similarity of the rows (NaN entries count as 0; a zero row gives NaN)."""
    v = np.nan_to_num(sig, nan=0.0)
    norm = np.linalg.norm(v, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        u = v / norm[:, None]
    return u @ u.T


def diagnosability_report(doe_table: pd.DataFrame, healthy_table: pd.DataFrame, *,
                          features: Iterable[str] | None = None, max_intensity: float | Mapping = 1.0,
                          name: str = "paper", z_target: float = 5.0,
                          cosine_limit: float = 0.9) -> DiagnosabilityReport:
    """Diagnosability of every mode of a DOE for one indicator set (see the module docstring).

    Parameters
    ----------
    doe_table : pandas.DataFrame
        Design of experiments (:func:`~fuelhm_bench.datasets.doe.run_doe`).
    healthy_table : pandas.DataFrame
        Healthy indicator table (its sample standard deviation, ddof=1, scales the Z-scores, as
        the healthy model of eq. 7).
    features : iterable of str or None, default=None
        Indicators (paper's ten or extended names); None: the paper's ten.
    max_intensity : float or mapping of str to float, default=1.0
        Maximum intensity per mode (the scenario's), in (0, 1].
    name : str, default="paper"
        Label of the indicator set.
    z_target : float, default=5.0
    cosine_limit : float, default=0.9

    Returns
    -------
    DiagnosabilityReport
    """
    features = check_features(features, "diagnosability_report")
    deltas = paired_deltas(doe_table, features=features)
    healthy = indicator_matrix(healthy_table, features, "healthy table")
    n_ok = np.isfinite(healthy).sum(axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        mean = np.nansum(healthy, axis=0) / np.maximum(n_ok, 1)
        std = np.sqrt(np.nansum((healthy - mean) ** 2, axis=0) / (n_ok - 1))
    std = np.where(np.isfinite(std) & (std > 0), std, np.nan)
    modes = [m for m in MODE_IDS if (deltas["mode"] == m).any()]
    law_rows, mode_rows, sig_rows = [], [], []
    for mode in modes:
        smax = float(max_intensity[mode] if isinstance(max_intensity, Mapping) else max_intensity)
        if not 0.0 < smax <= 1.0:
            raise param_error("max_intensity", "diagnosability_report", "in (0, 1] for every mode", max_intensity)
        rows = deltas[deltas["mode"] == mode]
        s = rows["intensity"].to_numpy(dtype=np.float64)
        d = rows[list(features)].to_numpy(dtype=np.float64)
        lin = fit_through_origin(s, d)
        pw = fit_power_law(s, d)
        z_lin = lin["A"] * smax / std
        z_pow = pw["c"] * smax ** pw["p"] / std
        top = s.max()
        at_top = d[s == top]
        n_top = np.isfinite(at_top).sum(axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            observed = np.where(n_top > 0, np.nansum(at_top, axis=0) / np.maximum(n_top, 1), np.nan) / std
        for j, f in enumerate(features):
            law_rows.append({"mode": mode, "indicator": f, "A": lin["A"][j], "r2_linear": lin["r2"][j],
                             "c": pw["c"][j], "p": pw["p"][j], "r2_power": pw["r2"][j],
                             "z_linear": z_lin[j], "z_power": z_pow[j], "n": int(pw["n"][j])})
        abs_pow = np.abs(z_pow)
        k = int(np.nanargmax(abs_pow)) if np.isfinite(abs_pow).any() else -1
        mode_rows.append({"mode": mode, "max_intensity": smax,
                          "z_max": float(abs_pow[k]) if k >= 0 else math.nan,
                          "z_max_indicator": features[k] if k >= 0 else "",
                          "r2_linear_at_z_max": float(lin["r2"][k]) if k >= 0 else math.nan,
                          "r2_power_at_z_max": float(pw["r2"][k]) if k >= 0 else math.nan,
                          "p_at_z_max": float(pw["p"][k]) if k >= 0 else math.nan,
                          "z_max_linear": float(np.nanmax(np.abs(z_lin))) if np.isfinite(z_lin).any() else math.nan,
                          "z_max_observed": (float(np.nanmax(np.abs(observed)))
                                             if np.isfinite(observed).any() else math.nan)})
        sig_rows.append(z_pow)
    sig = np.array(sig_rows, dtype=np.float64).reshape(len(modes), len(features))
    cos = _cosine(sig)
    cos_df = pd.DataFrame(cos, index=pd.Index(modes, name="mode"), columns=pd.Index(modes, name="mode"))
    for i, row in enumerate(mode_rows):
        other = np.where(np.arange(len(modes)) == i, -np.inf, np.nan_to_num(cos[i], nan=-np.inf))
        j = int(np.argmax(other)) if len(modes) > 1 else -1
        row["max_cosine"] = float(other[j]) if j >= 0 and np.isfinite(other[j]) else math.nan
        row["closest_mode"] = modes[j] if j >= 0 else ""
        row["visible"] = bool(np.isfinite(row["z_max"]) and row["z_max"] >= z_target)
        row["distinguishable"] = bool(not (row["max_cosine"] > cosine_limit))
    return DiagnosabilityReport(
        name=name, features=tuple(features), modes=pd.DataFrame(mode_rows), laws=pd.DataFrame(law_rows),
        signatures=pd.DataFrame(sig, index=pd.Index(modes, name="mode"), columns=pd.Index(features, name="indicator")),
        cosine=cos_df, z_target=float(z_target), cosine_limit=float(cosine_limit))
