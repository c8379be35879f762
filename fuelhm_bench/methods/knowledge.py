"""Published knowledge a method may use: ITL, signatures, maximal intensities.

The benchmark publishes, for every scenario, what the paper's method needs
besides healthy flights (Lamoureux et al. 2012, sections V and VI.B.3):

* the 70 indicator transformation laws (ITL, paper eq. 2): one linear law
  ``delta_indicator = A * intensity`` per (mode, indicator);
* the matrix of signatures (paper eq. 9 and Table IV): the Z-score of every
  indicator at the maximal intensity of every mode;
* the maximal intensity of every mode (the intensity the signatures refer to).

Ground-truth labels are never part of it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping

import numpy as np
import pandas as pd

from fuelhm_bench.errors import DataFormatError
from fuelhm_bench.taxonomy import INDICATOR_NAMES, MODE_IDS

__all__ = ["ITL_COLUMNS", "Knowledge"]

#: Columns of the ITL table, one row per (mode, indicator) law.
ITL_COLUMNS: tuple[str, ...] = ("mode", "indicator", "A", "r2", "residual_std", "n")


@dataclass(frozen=True, eq=False)
class Knowledge:
    """Published knowledge handed to :meth:`BaseMethod.fit`.

    Every field may be None when a scenario does not publish it. The tables are
    copied on construction, so later edits of the caller's objects do not leak
    into a fitted method.

    Parameters
    ----------
    itl : pandas.DataFrame or None, default=None
        Indicator transformation laws, columns ``mode, indicator, A, r2,
        residual_std, n`` (one row per law, 70 for the full benchmark). ``A`` is
        the slope of the law in indicator units per unit of intensity (indicator
        units: see :data:`fuelhm_bench.taxonomy.INDICATOR_UNITS`; intensity is
        dimensionless), ``residual_std`` is in indicator units.
    signatures : pandas.DataFrame or None, default=None
        Z-score signatures at maximal intensity: index = mode ids (a subset of
        :data:`~fuelhm_bench.taxonomy.MODE_IDS`), columns = the ten
        :data:`~fuelhm_bench.taxonomy.INDICATOR_NAMES`. Dimensionless.
    max_intensity : mapping of str to float or None, default=None
        Maximal intensity per mode (dimensionless, > 0), the intensity at which
        ``signatures`` are given.

    Raises
    ------
    DataFormatError
        When a table lacks a column or names an unknown mode/indicator.

    Examples
    --------
    >>> import pandas as pd
    >>> from fuelhm_bench.methods import Knowledge
    >>> k = Knowledge(max_intensity={"null_bias_drift": 1.0})
    >>> k.signature_matrix().shape
    (7, 10)
    """

    itl: pd.DataFrame | None = None
    signatures: pd.DataFrame | None = None
    max_intensity: Mapping[str, float] | None = None

    def __post_init__(self) -> None:
        if self.itl is not None:
            object.__setattr__(self, "itl", _check_itl(self.itl))
        if self.signatures is not None:
            object.__setattr__(self, "signatures", _check_signatures(self.signatures))
        if self.max_intensity is not None:
            object.__setattr__(self, "max_intensity", _check_max_intensity(self.max_intensity))

    def signature_matrix(self) -> np.ndarray:
        """Signatures as a (7, 10) float array in MODE_IDS x INDICATOR_NAMES order.

        Returns
        -------
        numpy.ndarray of shape (7, 10)
            NaN rows for modes without a published signature (all NaN when
            ``signatures`` is None).
        """
        out = np.full((len(MODE_IDS), len(INDICATOR_NAMES)), np.nan)
        if self.signatures is not None:
            sig = self.signatures.reindex(index=list(MODE_IDS), columns=list(INDICATOR_NAMES))
            out[:] = sig.to_numpy(dtype=float)
        return out


def _check_itl(itl: object) -> pd.DataFrame:
    if not isinstance(itl, pd.DataFrame):
        raise DataFormatError(f"The 'itl' parameter of Knowledge must be a pandas DataFrame. "
                              f"Got {type(itl).__name__} instead.")
    missing = [c for c in ITL_COLUMNS if c not in itl.columns]
    if missing:
        raise DataFormatError(f"The 'itl' parameter of Knowledge must have the columns "
                              f"{list(ITL_COLUMNS)}. Missing {missing}.")
    bad_modes = sorted(set(itl["mode"]) - set(MODE_IDS))
    bad_ind = sorted(set(itl["indicator"]) - set(INDICATOR_NAMES))
    if bad_modes or bad_ind:
        raise DataFormatError(f"The 'itl' parameter of Knowledge must name known modes and "
                              f"indicators. Got unknown modes {bad_modes} and indicators "
                              f"{bad_ind} instead.")
    return itl.copy(deep=True)


def _check_signatures(sig: object) -> pd.DataFrame:
    if not isinstance(sig, pd.DataFrame):
        raise DataFormatError(f"The 'signatures' parameter of Knowledge must be a pandas "
                              f"DataFrame. Got {type(sig).__name__} instead.")
    bad_modes = sorted(map(str, set(sig.index) - set(MODE_IDS)))
    if bad_modes:
        raise DataFormatError(f"The 'signatures' parameter of Knowledge must be indexed by mode "
                              f"ids {list(MODE_IDS)}. Got unknown index values {bad_modes} "
                              f"instead.")
    if sorted(map(str, sig.columns)) != sorted(INDICATOR_NAMES):
        raise DataFormatError(f"The 'signatures' parameter of Knowledge must have exactly the "
                              f"columns {list(INDICATOR_NAMES)}. Got {list(sig.columns)} instead.")
    return sig.copy(deep=True)


def _check_max_intensity(mi: object) -> dict[str, float]:
    if not isinstance(mi, Mapping):
        raise DataFormatError(f"The 'max_intensity' parameter of Knowledge must be a mapping "
                              f"mode -> float. Got {type(mi).__name__} instead.")
    out: dict[str, float] = {}
    for mode, value in mi.items():
        if mode not in MODE_IDS:
            raise DataFormatError(f"The 'max_intensity' parameter of Knowledge must be keyed by "
                                  f"mode ids {list(MODE_IDS)}. Got {mode!r} instead.")
        v = float(value)
        if not (math.isfinite(v) and v > 0):
            raise DataFormatError(f"The 'max_intensity[{mode!r}]' parameter of Knowledge must be "
                                  f"a finite float > 0. Got {value!r} instead.")
        out[mode] = v
    return out
