"""Synthetic indicator tables with known statistics, for tests and examples.

These generators draw indicator values directly (no simulation): a Gaussian
healthy population and a design of experiments whose indicator changes follow
known laws. They let the diagnosis layer be checked against ground truth.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

import numpy as np
import pandas as pd

from fuelhm_bench.diagnosis._validation import HEALTHY, check_features, param_error
from fuelhm_bench.errors import UnknownNameError
from fuelhm_bench.taxonomy import INDICATOR_NAMES, MODE_IDS

#: Plausible healthy indicator means (units of ``INDICATOR_UNITS``) for a
#: rated current of 8 mA and a null-region velocity gain of about 6 mm/s/mA.
DEFAULT_MEAN: dict[str, float] = {
    "X1": -1.6, "Y1": -9.6, "X2": 1.6, "Y2": 9.6, "Inb": 0.0, "I0": 0.2,
    "Hys0": 1.5, "G_in": 12.0, "G_out": 12.0, "G_null": 6.0,
}

#: Plausible healthy flight-to-flight standard deviations (same units).
DEFAULT_STD: dict[str, float] = {
    "X1": 0.05, "Y1": 0.4, "X2": 0.05, "Y2": 0.4, "Inb": 0.04, "I0": 0.03,
    "Hys0": 0.2, "G_in": 0.3, "G_out": 0.3, "G_null": 0.2,
}


def _indicator_columns(values: np.ndarray, features: Sequence[str]) -> dict[str, np.ndarray]:
    cols: dict[str, np.ndarray] = {f: values[:, j] for j, f in enumerate(features)}
    cols.update({f"{f}_valid": np.isfinite(values[:, j]) for j, f in enumerate(features)})
    return cols


def make_healthy_table(
    n_flights: int,
    *,
    rng: np.random.Generator,
    mean: Mapping[str, float] | None = None,
    std: Mapping[str, float] | None = None,
    correlation: float = 0.3,
) -> pd.DataFrame:
    """Draw an indicator table of healthy flights from a known Gaussian.

    The ten indicators are multivariate normal with means ``mean``, standard
    deviations ``std`` and the correlation ``correlation ** |i - j|`` between
    the i-th and j-th indicators of ``INDICATOR_NAMES`` (positive definite for
    ``|correlation| < 1``).

    Parameters
    ----------
    n_flights : int
        Number of flights (rows), >= 1.
    rng : numpy.random.Generator
        Source of randomness (never the global RNG).
    mean, std : mapping of str to float, default=None
        Per-indicator mean and standard deviation in ``INDICATOR_UNITS``;
        missing keys take ``DEFAULT_MEAN`` / ``DEFAULT_STD``.
    correlation : float, default=0.3
        Correlation of neighbouring indicators, in (-1, 1).

    Returns
    -------
    pandas.DataFrame
        Columns ``flight_id``, the ten indicators, their ``<name>_valid``
        columns (all True), ``n_points`` and ``quality_reason`` (``"ok"``).

    Examples
    --------
    >>> import numpy as np
    >>> from fuelhm_bench.testing.diagnosis import make_healthy_table
    >>> make_healthy_table(3, rng=np.random.default_rng(0)).shape
    (3, 23)
    """
    if isinstance(n_flights, bool) or not isinstance(n_flights, (int, np.integer)) or n_flights < 1:
        raise param_error("n_flights", "make_healthy_table", "an int >= 1", n_flights)
    if not -1.0 < correlation < 1.0:
        raise param_error("correlation", "make_healthy_table", "a float in (-1, 1)", correlation)
    check_features(list(mean or {}) or None, "make_healthy_table", name="mean")
    check_features(list(std or {}) or None, "make_healthy_table", name="std")
    mu = np.array([{**DEFAULT_MEAN, **(mean or {})}[f] for f in INDICATOR_NAMES])
    sd = np.array([{**DEFAULT_STD, **(std or {})}[f] for f in INDICATOR_NAMES])
    lag = np.abs(np.subtract.outer(np.arange(len(mu)), np.arange(len(mu))))
    cov = correlation**lag * np.outer(sd, sd)
    values = rng.multivariate_normal(mu, cov, size=n_flights)
    return pd.DataFrame(
        {
            "flight_id": np.arange(n_flights, dtype=np.int64),
            **_indicator_columns(values, INDICATOR_NAMES),
            "n_points": np.full(n_flights, 1000, dtype=np.int64),
            "quality_reason": "ok",
        }
    )


def make_doe_table(
    coef: pd.DataFrame,
    *,
    rng: np.random.Generator,
    n_units: int = 4,
    intensities: Sequence[float] = (0.25, 0.5, 0.75, 1.0),
    n_healthy: int = 1,
    unit_std: float = 1.0,
    noise_std: float = 0.01,
    laws: Mapping[tuple[str, str], Callable[[np.ndarray], np.ndarray]] | None = None,
) -> pd.DataFrame:
    """Build a design-of-experiments table whose indicator changes are known.

    Each unit ``u`` has a healthy level ``DEFAULT_MEAN + offset_u`` (offsets
    i.i.d. normal with ``unit_std`` times ``DEFAULT_STD``). It is flown
    ``n_healthy`` times healthy and once at each intensity ``s`` of each mode
    ``m`` (rows of ``coef``), where indicator ``i`` reads
    ``healthy level + coef[m, i] * f(s) + noise`` with ``f(s) = s`` unless
    ``laws[(m, i)]`` gives another shape, and noise i.i.d. normal with
    ``noise_std`` times ``DEFAULT_STD``.

    Parameters
    ----------
    coef : pandas.DataFrame
        True ITL coefficients ``A``: index = modes (from ``MODE_IDS``),
        columns = indicators (from ``INDICATOR_NAMES``); indicators not given
        do not change. Units: indicator unit per unit intensity.
    rng : numpy.random.Generator
        Source of randomness.
    n_units : int, default=4
        Number of simulated units.
    intensities : sequence of float, default=(0.25, 0.5, 0.75, 1.0)
        Intensities flown for every mode, in [0, 1].
    n_healthy : int, default=1
        Healthy flights per unit.
    unit_std, noise_std : float, default=1.0 and 0.01
        Unit dispersion and flight noise, as multiples of ``DEFAULT_STD``.
    laws : mapping of (mode, indicator) to callable, default=None
        Non-linear shapes ``f`` (vectorised, ``f(0) = 0``) for some laws.

    Returns
    -------
    pandas.DataFrame
        Columns ``unit_id``, ``flight_id``, ``mode`` (``"healthy"`` or a mode),
        ``intensity``, the ten indicators and their ``<name>_valid`` columns.

    Examples
    --------
    >>> import numpy as np, pandas as pd
    >>> from fuelhm_bench.testing.diagnosis import make_doe_table
    >>> coef = pd.DataFrame({"X1": [0.3]}, index=["null_bias_drift"])
    >>> doe = make_doe_table(coef, rng=np.random.default_rng(0), n_units=2)
    >>> doe["mode"].value_counts().to_dict()
    {'null_bias_drift': 8, 'healthy': 2}
    """
    unknown = [m for m in coef.index if m not in MODE_IDS]
    if unknown:
        raise UnknownNameError(f"Unknown degradation mode(s) {unknown} in 'coef'; allowed: {list(MODE_IDS)}.")
    check_features(list(coef.columns), "make_doe_table", name="coef")
    for name, value in (("n_units", n_units), ("n_healthy", n_healthy)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
            raise param_error(name, "make_doe_table", "an int >= 1", value)
    s_levels = np.asarray(intensities, dtype=np.float64)
    if s_levels.ndim != 1 or s_levels.size == 0 or np.any(~((s_levels >= 0) & (s_levels <= 1))):
        raise param_error("intensities", "make_doe_table", "a non-empty sequence of floats in [0, 1]", intensities)
    a = coef.reindex(columns=list(INDICATOR_NAMES)).fillna(0.0).to_numpy(dtype=np.float64)
    mu = np.array([DEFAULT_MEAN[f] for f in INDICATOR_NAMES])
    sd = np.array([DEFAULT_STD[f] for f in INDICATOR_NAMES])
    laws = dict(laws or {})

    rows: list[tuple[int, str, float]] = []
    values = []
    for u in range(n_units):
        level = mu + unit_std * sd * rng.standard_normal(mu.size)
        for _ in range(n_healthy):
            rows.append((u, HEALTHY, 0.0))
            values.append(level + noise_std * sd * rng.standard_normal(mu.size))
        for m, mode in enumerate(coef.index):
            for s in s_levels:
                shape = np.array([laws.get((mode, f), lambda t: t)(s) for f in INDICATOR_NAMES])
                rows.append((u, mode, float(s)))
                values.append(level + a[m] * shape + noise_std * sd * rng.standard_normal(mu.size))
    unit_ids, modes, levels = zip(*rows)
    return pd.DataFrame(
        {
            "unit_id": np.asarray(unit_ids, dtype=np.int64),
            "flight_id": np.arange(len(rows), dtype=np.int64),
            "mode": list(modes),
            "intensity": np.asarray(levels, dtype=np.float64),
            **_indicator_columns(np.asarray(values), INDICATOR_NAMES),
        }
    )
