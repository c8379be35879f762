"""Indicator transformation laws (ITL): linear response of indicators to degradations.

Paper section V, eqs. 2-5. From a design of experiments (DOE) where every
simulated unit is flown healthy and at several intensities of each mode, the
change of indicator ``i`` under mode ``deg`` is regressed on the intensity
through the origin, ``dI = A * intensity`` (eq. 2); a law then predicts
degraded indicators from healthy ones, ``I_deg = I_healthy + A * intensity``
(eq. 4).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterable
from pathlib import Path

import numpy as np
import pandas as pd

from fuelhm_bench.diagnosis._validation import (
    HEALTHY,
    check_dataframe,
    check_features,
    check_output_path,
    indicator_matrix,
    param_error,
    require_columns,
)
from fuelhm_bench.errors import DataFormatError, UnknownNameError
from fuelhm_bench.taxonomy import ALL_INDICATOR_NAMES, INDICATOR_NAMES, INDICATOR_UNITS, MODE_IDS

#: Columns of :attr:`ITL.table`, in order.
ITL_COLUMNS: tuple[str, ...] = ("mode", "indicator", "A", "r2", "residual_std", "n")

_DOE = "DOE table"


def paired_deltas(doe_table: pd.DataFrame, *, features: Iterable[str] | None = None) -> pd.DataFrame:
    """Indicator changes of every degraded DOE flight relative to its own unit (eq. 3).

    ``dI = I(unit, mode, intensity) - I(unit, healthy)`` where the healthy
    reference of a unit is the mean of its healthy flights (NaN values
    skipped). Pairing by ``unit_id`` cancels the unit-to-unit dispersion.

    Parameters
    ----------
    doe_table : pandas.DataFrame
        Columns ``mode`` (a mode of ``MODE_IDS`` or ``"healthy"``),
        ``intensity`` (in [0, 1], 0 for healthy rows), ``unit_id`` and the
        indicator columns (missing values as NaN or ``<name>_valid`` False).
    features : iterable of str or None, default=None
        Indicators to use; ``None`` means all ten.

    Returns
    -------
    pandas.DataFrame
        One row per degraded flight (index of ``doe_table`` kept): ``unit_id``,
        ``mode``, ``intensity`` and one column of ``dI`` per indicator, in the
        indicator's unit (NaN when either value is missing).

    Raises
    ------
    DataFormatError
        Missing column, unknown mode, intensity outside [0, 1] (or non-zero on
        a healthy row), no degraded flight, or a unit with degraded flights
        but no healthy flight.
    """
    features = check_features(features, "paired_deltas")
    doe = check_dataframe(doe_table, _DOE)
    require_columns(doe, ("mode", "intensity", "unit_id"), _DOE)
    x = indicator_matrix(doe, features, _DOE)

    mode = doe["mode"].astype(object).to_numpy()
    unknown = sorted({str(m) for m in mode if m != HEALTHY and m not in MODE_IDS})
    if unknown:
        raise DataFormatError(
            f"Column 'mode' of the {_DOE} has unknown value(s) {unknown}; "
            f"allowed: {[HEALTHY, *MODE_IDS]}."
        )
    try:
        intensity = pd.to_numeric(doe["intensity"], errors="raise").to_numpy(dtype=np.float64, na_value=np.nan)
    except (TypeError, ValueError) as exc:
        raise DataFormatError(f"Column 'intensity' of the {_DOE} must be numeric ({exc}).") from None
    bad = ~((intensity >= 0.0) & (intensity <= 1.0))
    if bad.any():
        raise DataFormatError(
            f"Column 'intensity' of the {_DOE} must be in [0, 1]. "
            f"Got {float(intensity[bad][0])!r} (row {doe.index[bad][0]!r}) instead."
        )
    healthy = mode == HEALTHY
    if np.any(intensity[healthy] != 0.0):
        row = doe.index[healthy & (intensity != 0.0)][0]
        raise DataFormatError(f"Healthy rows of the {_DOE} must have intensity 0 (row {row!r}).")
    if healthy.all():
        raise DataFormatError(f"The {_DOE} has no degraded flight (every 'mode' is {HEALTHY!r}).")
    unit = doe["unit_id"]
    if unit.isna().any():
        raise DataFormatError(f"Column 'unit_id' of the {_DOE} has missing values.")

    reference = pd.DataFrame(x[healthy], columns=list(features)).groupby(unit.to_numpy()[healthy]).mean()
    degraded_units = unit[~healthy]
    orphans = sorted(set(degraded_units) - set(reference.index), key=str)
    if orphans:
        raise DataFormatError(
            f"Every unit of the {_DOE} needs at least one healthy flight to pair with; "
            f"units {orphans[:10]}{' ...' if len(orphans) > 10 else ''} have none."
        )
    delta = x[~healthy] - reference.loc[degraded_units.to_numpy()].to_numpy()
    out = pd.DataFrame(delta, index=doe.index[~healthy], columns=list(features))
    out.insert(0, "intensity", intensity[~healthy])
    out.insert(0, "mode", mode[~healthy])
    out.insert(0, "unit_id", degraded_units.to_numpy())
    return out


def fit_through_origin(intensity: np.ndarray, delta: np.ndarray) -> dict[str, np.ndarray]:
    """Least-squares lines through the origin, one per column of ``delta``.

    For each column, over the rows where ``delta`` is finite:
    ``A = sum(s dI) / sum(s^2)``; residuals ``e = dI - A s``;
    ``residual_std = sqrt(sum(e^2) / (n - 1))`` (one fitted parameter);
    ``r2 = 1 - sum(e^2) / sum((dI - mean(dI))^2)``, the *centred*
    coefficient of determination (what ``sklearn.metrics.r2_score(dI, A s)``
    returns). Unlike the uncentred ``1 - sum(e^2)/sum(dI^2)``, usually quoted
    for regressions through the origin, it compares the law with the best
    constant, so curvature and offsets show: with intensities 0.25, 0.5, 0.75,
    1 and no noise, ``dI = s^2`` gives r2 = 0.84 (uncentred 0.94) and
    ``dI = 1 - exp(-5 s)`` gives r2 = -5.3 (uncentred 0.90). It can be
    negative (the line through the origin is worse than a constant).
    Conventions: ``n < 2`` gives NaN r2 and residual_std; ``sum(s^2) = 0``
    gives NaN A; zero spread of ``dI`` gives r2 = 1 if the law is exact, else
    ``-inf``.

    Parameters
    ----------
    intensity : ndarray of shape (n_rows,)
        Degradation intensities (dimensionless, in [0, 1]).
    delta : ndarray of shape (n_rows, n_laws)
        Indicator changes, NaN where unavailable.

    Returns
    -------
    dict of str to ndarray of shape (n_laws,)
        ``"A"``, ``"r2"``, ``"residual_std"`` (float64) and ``"n"`` (int64).

    Examples
    --------
    >>> import numpy as np
    >>> from fuelhm_bench.diagnosis.itl import fit_through_origin
    >>> s = np.array([0.25, 0.5, 0.75, 1.0])
    >>> fit = fit_through_origin(s, np.column_stack([2 * s, s**2]))
    >>> np.round(fit["A"], 3).tolist(), np.round(fit["r2"], 2).tolist()
    ([2.0, 0.833], [1.0, 0.84])
    """
    s = np.asarray(intensity, dtype=np.float64)
    d = np.asarray(delta, dtype=np.float64)
    if s.ndim != 1 or d.ndim != 2 or d.shape[0] != s.shape[0]:
        raise DataFormatError(
            "fit_through_origin needs intensity of shape (n_rows,) and delta of shape (n_rows, n_laws). "
            f"Got {s.shape} and {d.shape} instead."
        )
    s = s[:, None]
    ok = np.isfinite(d)
    d0 = np.where(ok, d, 0.0)
    s0 = np.where(ok, s, 0.0)
    n = ok.sum(axis=0)
    sxx = (s0**2).sum(axis=0)
    a = np.where(sxx > 0, (s0 * d0).sum(axis=0) / np.where(sxx > 0, sxx, 1.0), np.nan)
    resid = np.where(ok, d0 - a * s0, 0.0)
    ssr = (resid**2).sum(axis=0)
    mean = d0.sum(axis=0) / np.maximum(n, 1)
    sst = (np.where(ok, d0 - mean, 0.0) ** 2).sum(axis=0)
    r2 = np.where(sst > 0, 1.0 - ssr / np.where(sst > 0, sst, 1.0), np.where(ssr == 0, 1.0, -np.inf))
    r2 = np.where((n >= 2) & np.isfinite(a), r2, np.nan)
    residual_std = np.where((n >= 2) & np.isfinite(a), np.sqrt(ssr / np.maximum(n - 1, 1)), np.nan)
    return {"A": a, "r2": r2, "residual_std": residual_std, "n": n.astype(np.int64)}


@dataclasses.dataclass(frozen=True, eq=False)
class ITL:
    """A set of indicator transformation laws ``dI = A * intensity`` (paper eqs. 2-5).

    Build one with :func:`fit_itl` (from a DOE table) or :meth:`from_csv`.

    Parameters
    ----------
    table : pandas.DataFrame
        One row per law, columns exactly ``ITL_COLUMNS``: ``mode``
        (``MODE_IDS``), ``indicator`` (``INDICATOR_NAMES``), ``A`` (indicator
        unit per unit intensity, see ``INDICATOR_UNITS``), ``r2`` (centred
        coefficient of determination, see :func:`fit_through_origin`),
        ``residual_std`` (indicator unit) and ``n`` (number of DOE flights
        used). It is stored as a copy sorted in the order of ``MODE_IDS``
        then ``INDICATOR_NAMES``.

    Attributes
    ----------
    modes : tuple of str
        Modes that have laws, in ``MODE_IDS`` order.
    indicators : tuple of str
        Indicators that have laws, in ``INDICATOR_NAMES`` order.

    Examples
    --------
    >>> import numpy as np, pandas as pd
    >>> from fuelhm_bench.diagnosis import fit_itl
    >>> from fuelhm_bench.testing.diagnosis import make_doe_table
    >>> coef = pd.DataFrame({"X1": [0.4], "X2": [0.4]}, index=["null_bias_drift"])
    >>> itl = fit_itl(make_doe_table(coef, rng=np.random.default_rng(0)))
    >>> round(float(itl.matrix().loc["null_bias_drift", "X1"]), 2)
    0.4
    >>> healthy = np.array([-1.6, -9.6, 1.6, 9.6, 0.0, 0.2, 1.5, 12.0, 12.0, 6.0])
    >>> np.round(itl.apply(healthy, "null_bias_drift", 0.5)[[0, 2]], 1).tolist()
    [-1.4, 1.8]
    """

    table: pd.DataFrame

    def __post_init__(self) -> None:
        table = check_dataframe(self.table, "ITL table")
        require_columns(table, ITL_COLUMNS, "ITL table")
        extra = [c for c in table.columns if c not in ITL_COLUMNS]
        if extra:
            raise DataFormatError(f"The ITL table has unexpected column(s) {extra}; allowed: {list(ITL_COLUMNS)}.")
        for column, allowed in (("mode", MODE_IDS), ("indicator", ALL_INDICATOR_NAMES)):
            unknown = sorted({str(v) for v in table[column] if v not in allowed})
            if unknown:
                raise DataFormatError(f"Column {column!r} of the ITL table has unknown value(s) {unknown}; allowed: {list(allowed)}.")
        if table.duplicated(["mode", "indicator"]).any():
            first = table.loc[table.duplicated(["mode", "indicator"]), ["mode", "indicator"]].iloc[0].tolist()
            raise DataFormatError(f"The ITL table has more than one law for (mode, indicator) = {tuple(first)}.")
        out = pd.DataFrame({"mode": table["mode"].astype(str), "indicator": table["indicator"].astype(str)})
        for column in ("A", "r2", "residual_std", "n"):
            try:
                out[column] = pd.to_numeric(table[column], errors="raise").astype(np.float64)
            except (TypeError, ValueError) as exc:
                raise DataFormatError(f"Column {column!r} of the ITL table must be numeric ({exc}).") from None
        if not np.all(np.isfinite(out["n"]) & (out["n"] >= 0) & (out["n"] % 1 == 0)):
            raise DataFormatError("Column 'n' of the ITL table must hold non-negative integers.")
        out["n"] = out["n"].astype(np.int64)
        order = np.lexsort((out["indicator"].map(ALL_INDICATOR_NAMES.index), out["mode"].map(MODE_IDS.index)))
        object.__setattr__(self, "table", out.iloc[order].reset_index(drop=True))

    @property
    def modes(self) -> tuple[str, ...]:
        present = set(self.table["mode"])
        return tuple(m for m in MODE_IDS if m in present)

    @property
    def indicators(self) -> tuple[str, ...]:
        present = set(self.table["indicator"])
        return tuple(f for f in ALL_INDICATOR_NAMES if f in present)

    def matrix(self, value: str = "A") -> pd.DataFrame:
        """One column of the law table as a modes x indicators matrix.

        Parameters
        ----------
        value : {"A", "r2", "residual_std", "n"}, default="A"
            Which quantity.

        Returns
        -------
        pandas.DataFrame
            Index ``modes`` (named ``mode``), columns ``indicators`` (named
            ``indicator``); NaN for a (mode, indicator) without a law.
        """
        if value not in ITL_COLUMNS[2:]:
            raise param_error("value", "ITL.matrix", f"one of {list(ITL_COLUMNS[2:])}", value)
        wide = self.table.pivot(index="mode", columns="indicator", values=value)
        return wide.reindex(index=list(self.modes), columns=list(self.indicators))

    def apply(self, healthy_values, mode: str, intensity):
        """Estimated degraded indicators ``I_deg = I_healthy + A * intensity`` (eq. 4).

        Parameters
        ----------
        healthy_values : pandas.DataFrame, pandas.Series or array-like
            Healthy indicator values: a DataFrame or Series holding every
            indicator of :attr:`indicators` (other columns are passed through),
            or an array of shape (n_indicators,) or (n_rows, n_indicators)
            with the columns of :attr:`indicators` in order. Units of
            ``INDICATOR_UNITS``.
        mode : str
            Degradation mode, one of :attr:`modes`.
        intensity : float or array-like of shape (n_rows,)
            Intensity in [0, 1] (the range the laws were fitted on), one per
            row of ``healthy_values``; with a 1-D array of healthy values, an
            array of intensities gives one row per intensity.

        Returns
        -------
        Same type as ``healthy_values``
            A copy with the indicators moved by their laws (NaN where the law
            has no coefficient); same shape, except a 1-D array with an array
            of intensities gives shape (n_intensities, n_indicators).

        Raises
        ------
        UnknownNameError
            ``mode`` has no law.
        ParameterError
            ``intensity`` is not finite, outside [0, 1], or has the wrong shape.
        DataFormatError
            ``healthy_values`` lacks an indicator or has the wrong shape.
        """
        if mode not in self.modes:
            raise UnknownNameError(f"The ITL has no law for mode {mode!r}; it has laws for {list(self.modes)}.")
        coef = self.matrix().loc[mode].to_numpy(dtype=np.float64)
        s = np.asarray(intensity, dtype=np.float64)
        if s.ndim > 1 or not np.all((s >= 0.0) & (s <= 1.0)):
            raise param_error("intensity", "ITL.apply", "a float or 1-D array of floats in [0, 1]", intensity)
        names = list(self.indicators)
        if isinstance(healthy_values, (pd.DataFrame, pd.Series)):
            is_frame = isinstance(healthy_values, pd.DataFrame)
            labels = healthy_values.columns if is_frame else healthy_values.index
            missing = [f for f in names if f not in labels]
            if missing:
                raise DataFormatError(f"The healthy values passed to ITL.apply lack indicator(s) {missing}.")
            out = healthy_values.copy()
            values = (out[names] if is_frame else out[names].to_frame().T).to_numpy(dtype=np.float64)
            moved = _move(values, coef, s)
            if is_frame:
                out[names] = moved
            else:
                out[names] = moved[0]
            return out
        values = np.array(healthy_values, dtype=np.float64)
        if values.ndim not in (1, 2) or values.shape[-1] != len(names):
            raise DataFormatError(
                f"The healthy values passed to ITL.apply must have shape ({len(names)},) or "
                f"(n_rows, {len(names)}) with columns {names}. Got shape {values.shape} instead."
            )
        return _move(values, coef, s)

    def to_csv(self, path) -> Path:
        """Write :attr:`table` to a CSV file (columns ``ITL_COLUMNS``); returns the path."""
        path = Path(path)
        check_output_path(path)
        self.table.to_csv(path, index=False)
        return path

    @classmethod
    def from_csv(cls, path) -> "ITL":
        """Read laws written by :meth:`to_csv`.

        Raises
        ------
        DataFormatError
            The file does not exist or is not a valid ITL table (naming the
            missing or malformed column).
        """
        path = Path(path)
        if not path.is_file():
            raise DataFormatError(f"ITL file {str(path)!r} does not exist.")
        return cls(pd.read_csv(path))


def _move(values: np.ndarray, coef: np.ndarray, s: np.ndarray) -> np.ndarray:
    """``values + coef * s``: one intensity per row, or one healthy vector at many intensities."""
    if s.ndim == 0:
        return values + coef * s
    if values.ndim == 2 and s.shape[0] != values.shape[0]:
        raise param_error("intensity", "ITL.apply", f"a float or an array of shape ({values.shape[0]},)", s)
    return values + coef * s[:, None]


def fit_itl(doe_table: pd.DataFrame, *, features: Iterable[str] | None = None) -> ITL:
    """Fit the indicator transformation laws of every mode of a DOE table.

    For each mode present and each indicator, regresses the paired changes
    ``dI`` (:func:`paired_deltas`) on the intensity through the origin
    (:func:`fit_through_origin`). Only degraded rows enter the regressions;
    healthy rows serve as the per-unit references.

    Parameters
    ----------
    doe_table : pandas.DataFrame
        Design of experiments, see :func:`paired_deltas`.
    features : iterable of str or None, default=None
        Indicators; ``None`` means all ten (then 70 laws for 7 modes).

    Returns
    -------
    ITL
    """
    deltas = paired_deltas(doe_table, features=features)
    features = [c for c in deltas.columns if c not in ("unit_id", "mode", "intensity")]
    parts = []
    for mode in MODE_IDS:
        rows = deltas[deltas["mode"] == mode]
        if rows.empty:
            continue
        fit = fit_through_origin(rows["intensity"].to_numpy(), rows[features].to_numpy(dtype=np.float64))
        parts.append(pd.DataFrame({"mode": mode, "indicator": features, **fit}))
    return ITL(pd.concat(parts, ignore_index=True))


def plot_itl(itl: ITL, doe_table: pd.DataFrame, out_path) -> Path:
    """Grid of the laws: paired ``dI`` against intensity with the fitted line.

    One row of panels per mode of ``itl``, one column per indicator; each panel
    shows the DOE points, the line ``A * intensity`` and ``r2`` in its title,
    so a non-linear law is visible at a glance. Rendered with the Agg backend
    (no pyplot state).

    Parameters
    ----------
    itl : ITL
        The laws.
    doe_table : pandas.DataFrame
        The DOE they were fitted on (see :func:`paired_deltas`).
    out_path : str or path-like
        Image file to write (format from the suffix, e.g. ``.png``); its
        directory must exist.

    Returns
    -------
    pathlib.Path
        ``out_path``.
    """
    out_path = Path(out_path)
    check_output_path(out_path)
    modes, names = itl.modes, itl.indicators
    deltas = paired_deltas(doe_table, features=names)
    slope, r2 = itl.matrix("A"), itl.matrix("r2")
    width, height = 1.9 * len(names) + 1.2, 1.5 * len(modes) + 1.3
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # plotting only: not on a method's import path
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height))
    FigureCanvasAgg(fig)
    # Fixed margins (in inches) instead of a layout engine: much faster for 70 panels.
    fig.subplots_adjust(left=1.2 / width, right=1 - 0.15 / width, bottom=0.55 / height, top=1 - 1.0 / height,
                        wspace=0.45, hspace=0.55)
    axes = fig.subplots(len(modes), len(names), squeeze=False, sharex=True)
    line_s = np.array([0.0, 1.0])
    for r, mode in enumerate(modes):
        rows = deltas[deltas["mode"] == mode]
        for c, name in enumerate(names):
            ax = axes[r, c]
            ax.scatter(rows["intensity"], rows[name], s=6, alpha=0.6, color="tab:blue", linewidths=0)
            ax.plot(line_s, slope.loc[mode, name] * line_s, color="tab:red", lw=1)
            ax.axhline(0.0, color="0.7", lw=0.5)
            ax.set_title(f"r2 = {r2.loc[mode, name]:.2f}", fontsize=7, pad=2)
            ax.locator_params(nbins=3)
            ax.tick_params(labelsize=6)
            if r == 0:
                ax.annotate(f"{name} [{INDICATOR_UNITS[name]}]", (0.5, 1.3), xycoords="axes fraction",
                            ha="center", fontsize=8, fontweight="bold")
            if c == 0:
                ax.set_ylabel(f"{mode}\ndI", fontsize=7)
            if r == len(modes) - 1:
                ax.set_xlabel("intensity", fontsize=7)
    fig.suptitle("Indicator transformation laws dI = A * intensity (points: paired DOE flights)",
                 fontsize=10, y=1 - 0.15 / height, va="top")
    fig.savefig(out_path, dpi=110)
    return out_path
