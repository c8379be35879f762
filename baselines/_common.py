"""Helpers shared by the reference methods (written against the public API only).

Everything here is ordinary submission code: it uses ``fuelhm_bench.methods``,
``fuelhm_bench.diagnosis`` and ``fuelhm_bench.taxonomy`` public names plus
numpy/pandas, exactly as an outside researcher would.

Conventions shared by the baselines
-----------------------------------
* **Missing indicators.** An indicator is missing when its value is NaN or its
  ``<name>_valid`` column exists and is not True (the rule of
  ``fuelhm_bench.diagnosis.HealthyModel``).
* **Cross-fitted training scores.** A threshold set on the scores of the very
  flights a model was fitted on is biased low (a flight is always closer to a
  model that has seen it). The baselines therefore score every healthy
  training flight with a model fitted *without* it (leave-one-out or k-fold
  cross-fitting, :func:`cross_fit_folds`) and set their thresholds on those
  out-of-fold scores. ``cv=None`` restores the in-sample recipe.
* **Training sequences.** Per-unit smoothing needs the training flights in
  flight order: they are grouped by ``unit_id`` and sorted by
  ``flight_index`` when those columns exist (:func:`training_sequences`).
* **Standardisation needs few flights.** A method that uses the healthy model
  only to turn indicators into Z-scores needs each indicator's mean and
  standard deviation, not their correlation: :func:`standardisation` fits it
  from as few as :data:`STANDARDISATION_MIN_FLIGHTS` flights (the full
  Mahalanobis model needs ``n_features + 1``). This is what lets such methods
  learn from a scarce healthy set (scenario ``low_data``: 12 fit flights,
  cross-fitted in folds of 9-10).
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from fuelhm_bench.diagnosis import ITL, ITL_COLUMNS, HealthyModel, collinearity_guilt
from fuelhm_bench.methods import Knowledge, normalize_guilt
from fuelhm_bench.methods.params import Constraint
from fuelhm_bench.taxonomy import INDICATOR_NAMES, MODE_IDS

__all__ = [
    "INDICATORS", "STANDARDISATION_MIN_FLIGHTS", "ModeSubset", "collinearity_guilt_7",
    "cross_fit_folds", "indicator_values", "itl_coefficients", "reference_signatures", "row_values",
    "sklearn_seed", "standardisation", "training_sequences", "window_mean",
]

#: The ten indicators, in the paper's order (column order of every array here).
INDICATORS: list[str] = list(INDICATOR_NAMES)

#: Fewest healthy flights (overall and per indicator) :func:`standardisation` fits from: a mean and a
#: sample standard deviation (ddof=1) need 2; 3 keeps one degree of freedom beyond that.
STANDARDISATION_MIN_FLIGHTS = 3


class ModeSubset(Constraint):
    """A tuple of distinct degradation-mode ids from ``MODE_IDS`` (possibly empty)."""

    def is_satisfied_by(self, value: Any) -> bool:
        return (isinstance(value, tuple) and all(isinstance(m, str) and m in MODE_IDS
                                                 for m in value)
                and len(set(value)) == len(value))

    def describe(self) -> str:
        return f"a tuple of distinct mode ids from {list(MODE_IDS)}"

    def __repr__(self) -> str:
        return "ModeSubset()"


# --------------------------------------------------------------------------- inputs
def indicator_values(table: pd.DataFrame) -> np.ndarray:
    """Indicator matrix of a table, NaN where an indicator is missing.

    Parameters
    ----------
    table : pandas.DataFrame
        Indicator table (the ten indicator columns, optionally ``<name>_valid``).
        Not modified.

    Returns
    -------
    numpy.ndarray of shape (n_flights, 10)
        float64, columns in ``INDICATOR_NAMES`` order, in the indicators' units.
    """
    out = np.empty((len(table), len(INDICATORS)))
    for j, name in enumerate(INDICATORS):
        col = pd.to_numeric(table[name], errors="coerce").to_numpy(dtype=np.float64,
                                                                   na_value=np.nan)
        valid_col = f"{name}_valid"
        if valid_col in table.columns:
            ok = np.array([_is_valid(v) for v in table[valid_col].to_numpy(dtype=object)],
                          dtype=bool)
            col = np.where(ok, col, np.nan)
        out[:, j] = col
    return out


def _is_valid(flag: Any) -> bool:
    """A ``<name>_valid`` flag: missing (None, NA, NaN) counts as not valid."""
    if flag is None or flag is pd.NA or (isinstance(flag, float) and np.isnan(flag)):
        return False
    return bool(flag)


def row_values(row: pd.Series) -> np.ndarray:
    """Indicator vector of one observation row as a (1, 10) array (:func:`indicator_values`)."""
    out = np.empty((1, len(INDICATORS)))
    for j, name in enumerate(INDICATORS):
        value = row[name]
        try:
            v = float(value)
        except (TypeError, ValueError):
            v = np.nan
        valid_col = f"{name}_valid"
        if valid_col in row.index and not _is_valid(row[valid_col]):
            v = np.nan
        out[0, j] = v
    return out


def training_sequences(table: pd.DataFrame) -> list[np.ndarray]:
    """Row positions of the training flights, one array per unit, in flight order.

    Parameters
    ----------
    table : pandas.DataFrame
        Healthy training table. Grouped by ``unit_id`` when the column exists
        (otherwise one sequence); sorted by ``flight_index`` when the column
        exists (otherwise table order).

    Returns
    -------
    list of numpy.ndarray of int
        Positions (``iloc``) into ``table``.
    """
    n = len(table)
    order = np.arange(n)
    if "flight_index" in table.columns:
        key = pd.to_numeric(table["flight_index"], errors="coerce").to_numpy(dtype=float,
                                                                            na_value=np.nan)
        order = np.argsort(np.where(np.isfinite(key), key, np.inf), kind="stable")
    if "unit_id" not in table.columns:
        return [order]
    units = table["unit_id"].to_numpy(dtype=object)[order]
    codes, _ = pd.factorize(pd.Series(units, dtype=object), use_na_sentinel=False)
    return [order[codes == c] for c in range(int(codes.max()) + 1)] if n else []


def window_mean(stack: np.ndarray) -> np.ndarray:
    """NaN-aware mean over the rows of ``stack`` (NaN where a column has no finite value).

    Parameters
    ----------
    stack : numpy.ndarray of shape (k, p)

    Returns
    -------
    numpy.ndarray of shape (p,)
    """
    finite = np.isfinite(stack)
    count = finite.sum(axis=0)
    total = np.where(finite, stack, 0.0).sum(axis=0)
    return np.divide(total, count, out=np.full(stack.shape[1], np.nan), where=count > 0)


def cross_fit_folds(n: int, cv: Any, rng: np.random.Generator,
                    owner: str, groups: np.ndarray | None = None,
                    min_train: int = 1) -> list[tuple[np.ndarray, np.ndarray]]:
    """Train/held-out splits of ``n`` training flights for out-of-fold scores.

    Parameters
    ----------
    n : int
        Number of training flights.
    cv : {"units", "loo"}, int >= 2 or None
        ``"units"``: leave one unit out (one split per distinct ``groups`` value, so
        held-out flights come from a unit the model never saw, like a new engine;
        falls back to ``"loo"`` when ``groups`` is None, has fewer than 3 units, or
        leaving a unit out would leave fewer than ``min_train`` training flights);
        ``"loo"``: leave one flight out (``n`` splits, no randomness); int ``k``:
        ``k`` folds of a random permutation drawn from ``rng``; None: a single
        in-sample "split" (train = held-out = all flights).
    rng : numpy.random.Generator
        Used only for ``k`` folds.
    owner : str
        Class name for error messages.
    groups : ndarray of shape (n,), optional
        Unit of each flight (for ``"units"``).
    min_train : int, default=1
        Fewest training flights a ``"units"`` fold may have.

    Returns
    -------
    list of (train_positions, heldout_positions)
        The held-out positions partition ``range(n)`` (except for None).

    Raises
    ------
    ValueError
        When there are fewer flights than folds.
    """
    everything = np.arange(n)
    if cv is None:
        return [(everything, everything)]
    if cv == "units":
        if groups is not None and len(np.unique(groups)) >= 3:
            uniq = list(dict.fromkeys(groups.tolist()))
            folds = [(everything[groups != g], everything[groups == g]) for g in uniq]
            if min(len(train) for train, _ in folds) >= min_train:
                return folds
        cv = "loo"
    k = n if cv == "loo" else int(cv)
    if n < max(k, 2):
        raise ValueError(f"The 'cv' parameter of {owner} must not exceed the number of healthy "
                         f"training flights ({n}). Got {cv!r} instead.")
    if cv == "loo":
        return [(np.delete(everything, i), everything[i:i + 1]) for i in range(n)]
    parts = np.array_split(rng.permutation(n), k)
    return [(np.sort(np.concatenate([p for j, p in enumerate(parts) if j != f])), np.sort(held))
            for f, held in enumerate(parts)]


def standardisation(x: np.ndarray) -> HealthyModel:
    """A healthy model used for its per-indicator mean and standard deviation only (Z-scores).

    Parameters
    ----------
    x : numpy.ndarray of shape (n_flights, 10)
        Healthy indicator matrix (NaN where missing), ``n_flights >=``
        :data:`STANDARDISATION_MIN_FLIGHTS` with each indicator available that
        often.

    Returns
    -------
    fuelhm_bench.diagnosis.HealthyModel
        Fitted with ``min_flights=STANDARDISATION_MIN_FLIGHTS``: ``mean_``,
        ``std_`` and ``zscores`` are those of the usual model; its correlation
        (Ledoit-Wolf shrunk) is not meant to be used for Mahalanobis distances
        when there are fewer than ``n_features + 1`` flights.

    Raises
    ------
    fuelhm_bench.errors.DataFormatError
        Fewer flights than :data:`STANDARDISATION_MIN_FLIGHTS` (overall or for
        one indicator).

    Examples
    --------
    >>> rng = np.random.default_rng(0)
    >>> model = standardisation(rng.normal(size=(5, 10)))
    >>> model.zscores(np.zeros((1, 10))).shape
    (1, 10)
    """
    return HealthyModel(min_flights=STANDARDISATION_MIN_FLIGHTS).fit(x)


def sklearn_seed(rng: np.random.Generator) -> int:
    """An integer seed for a scikit-learn estimator, drawn from ``rng``."""
    return int(rng.integers(0, 2**31 - 1))


# --------------------------------------------------------------------------- knowledge
def itl_coefficients(knowledge: Knowledge | None) -> pd.DataFrame | None:
    """ITL slopes ``A`` (paper eq. 2) as a modes x indicators table, or None.

    Parameters
    ----------
    knowledge : Knowledge or None

    Returns
    -------
    pandas.DataFrame or None
        Index: the modes that have laws (``MODE_IDS`` order); columns: the
        ten indicators; indicator units per unit intensity; NaN where a law is
        missing. None when ``knowledge`` or its ITL is None.
    """
    if knowledge is None or knowledge.itl is None or len(knowledge.itl) == 0:
        return None
    laws = ITL(knowledge.itl.loc[:, list(ITL_COLUMNS)])
    return laws.matrix("A").reindex(columns=INDICATORS)


def reference_signatures(knowledge: Knowledge | None, source: str,
                         healthy_std: np.ndarray) -> pd.DataFrame | None:
    """Reference Z-score signatures of the modes (paper eq. 9), or None.

    Parameters
    ----------
    knowledge : Knowledge or None
    source : {"signatures", "itl"}
        ``"signatures"``: the published ``knowledge.signatures``;
        ``"itl"``: recomputed as ``A * max_intensity / healthy_std`` from the
        published ITL and maximal intensities with the method's own healthy
        standard deviations (modes lacking either are left out).
    healthy_std : numpy.ndarray of shape (10,)
        Healthy standard deviations of the indicators (indicator units).

    Returns
    -------
    pandas.DataFrame or None
        Rows: the modes with at least one finite, non-zero entry, in
        ``MODE_IDS`` order; columns: the ten indicators (dimensionless). None
        when no mode qualifies.
    """
    if knowledge is None:
        return None
    if source == "signatures":
        sig = pd.DataFrame(knowledge.signature_matrix(), index=list(MODE_IDS), columns=INDICATORS)
    else:
        coef = itl_coefficients(knowledge)
        if coef is None or not knowledge.max_intensity:
            return None
        modes = [m for m in coef.index if m in knowledge.max_intensity]
        scale = np.array([knowledge.max_intensity[m] for m in modes], dtype=float)
        sig = pd.DataFrame(coef.loc[modes].to_numpy(float) * scale[:, None] / healthy_std[None, :],
                           index=modes, columns=INDICATORS)
    values = sig.to_numpy(float)
    keep = (np.isfinite(values) & (values != 0)).any(axis=1)
    return sig.loc[keep] if keep.any() else None


def collinearity_guilt_7(z: np.ndarray, references: pd.DataFrame | None,
                         symmetric_modes: tuple[str, ...]) -> np.ndarray:
    """Guilt over the seven modes by collinearity with the reference signatures.

    Parameters
    ----------
    z : numpy.ndarray of shape (10,)
        Current Z-score signature (paper eq. 8); NaN entries are ignored.
    references : pandas.DataFrame or None
        Reference signatures (:func:`reference_signatures`).
    symmetric_modes : tuple of str
        Modes whose direction is not signed (scored with ``|cos|``).

    Returns
    -------
    numpy.ndarray of shape (7,)
        Probabilities summing to 1 in ``MODE_IDS`` order; modes without a
        reference get 0. Uniform over all modes when ``references`` is None,
        uniform over the referenced modes when no mode is positively collinear
        (the convention of ``collinearity_guilt``).
    """
    if references is None:
        return normalize_guilt(np.zeros(len(MODE_IDS)))
    symmetric = [m for m in symmetric_modes if m in references.index]
    prob = collinearity_guilt(z, references, symmetric=symmetric)
    out = np.zeros(len(MODE_IDS))
    out[[MODE_IDS.index(m) for m in references.index]] = prob
    return normalize_guilt(out)
