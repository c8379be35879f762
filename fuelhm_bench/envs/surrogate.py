"""The surrogate fidelity: healthy Gaussian draws shifted by the indicator transformation laws.

Paper (Lamoureux, Massé & Mechbal 2012) eq. 4 predicts the indicators of a
degraded flight from healthy ones, ``I_deg = I_healthy + A * intensity``. The
surrogate turns it into a simulator:

1. **Healthy indicators** of a unit's flights are drawn from the published
   healthy Gaussian model ``N(mean_, cov_)``
   (:class:`~fuelhm_bench.diagnosis.HealthyModel`), split into a *unit* part
   drawn once per unit (manufacturing dispersion) and a *flight* part drawn
   per flight (operating conditions, noise)::

       I_healthy[unit, flight] = mean_ + L_unit u[unit] + L_flight e[unit, flight]
       u, e ~ N(0, identity),   L_unit L_unit^T + L_flight L_flight^T = cov_ (exactly)

   The split is estimated on the healthy table the model was fitted on, in
   the coordinates whitened by ``cov_`` (one-way random-effects estimator:
   ``B = (MS_between - MS_within) / n0``, eigenvalues clipped to [0, 1]), so
   each indicator keeps the published mean and standard deviation while
   consecutive flights of a unit are correlated as in the physics (most of
   the healthy spread of the indicators is unit-to-unit). With fewer than two
   units or too few flights the whole covariance is per flight.
2. **Degradation**: ``I = I_healthy + intensity @ A`` with ``A`` the ITL
   slopes (indicator unit per unit intensity, 0 where a law is missing) and
   ``intensity`` the 7 mode intensities of the flight (several modes add up).
3. **Structure**: ``Inb = (X1 + X2) / 2`` is restored after both steps (it
   holds exactly on board, paper Table I); every indicator is valid.

What the surrogate does not reproduce: invalid indicators, the curvature of
the laws (they are linear by construction), nominal-parameter drift of the
scored fleet, and interactions between simultaneous modes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from fuelhm_bench.errors import DataFormatError
from fuelhm_bench.taxonomy import INDICATOR_NAMES, MODE_IDS

__all__ = ["SurrogateModel"]

_X1, _X2, _INB = (INDICATOR_NAMES.index(n) for n in ("X1", "X2", "Inb"))


def _sqrt_psd(matrix: np.ndarray) -> np.ndarray:
    """Symmetric square root of a symmetric positive semi-definite matrix."""
    w, v = np.linalg.eigh(0.5 * (matrix + matrix.T))
    return (v * np.sqrt(np.clip(w, 0.0, None))) @ v.T


def _between_share(z: np.ndarray, units: np.ndarray) -> np.ndarray:
    """Between-unit covariance of whitened rows ``z`` (eigenvalues in [0, 1]); zeros when not estimable."""
    p = z.shape[1]
    labels, counts = np.unique(units, return_counts=True)
    k, n = len(labels), len(z)
    if k < 2 or n - k < 1:
        return np.zeros((p, p))
    grand = z.mean(axis=0)
    means = np.stack([z[units == u].mean(axis=0) for u in labels])
    resid = z - means[np.searchsorted(labels, units)]
    ms_within = resid.T @ resid / (n - k)
    dev = means - grand
    ms_between = (dev * counts[:, None]).T @ dev / (k - 1)
    n0 = (n - (counts ** 2).sum() / n) / (k - 1)
    b = (ms_between - ms_within) / n0
    w, v = np.linalg.eigh(0.5 * (b + b.T))
    return (v * np.clip(w, 0.0, 1.0)) @ v.T


@dataclass(frozen=True, eq=False)
class SurrogateModel:
    """Healthy Gaussian draws plus linear ITL shifts (see the module docstring).

    Build one with :meth:`from_knowledge`.

    Parameters
    ----------
    mean : ndarray of shape (10,)
        Healthy mean of the indicators, ``INDICATOR_NAMES`` order, units of
        ``INDICATOR_UNITS`` (mA, mm/s, mm/s/mA).
    unit_factor : ndarray of shape (10, 10)
        ``L_unit`` (same units as ``mean`` per unit normal draw).
    flight_factor : ndarray of shape (10, 10)
        ``L_flight``.
    shift : ndarray of shape (7, 10)
        ITL slopes ``A`` (``MODE_IDS`` x ``INDICATOR_NAMES``, indicator unit per
        unit intensity), 0 where no law exists.

    Attributes
    ----------
    unit_share : ndarray of shape (10,)
        Fraction of each indicator's healthy variance that is unit-to-unit.
    """

    mean: np.ndarray
    unit_factor: np.ndarray
    flight_factor: np.ndarray
    shift: np.ndarray

    def __post_init__(self) -> None:
        p, m = len(INDICATOR_NAMES), len(MODE_IDS)
        for name, shape in (("mean", (p,)), ("unit_factor", (p, p)), ("flight_factor", (p, p)), ("shift", (m, p))):
            arr = np.array(getattr(self, name), dtype=np.float64, copy=True)
            if arr.shape != shape or not np.all(np.isfinite(arr)):
                raise DataFormatError(f"The '{name}' parameter of SurrogateModel must be a finite array of shape "
                                      f"{shape}. Got shape {arr.shape} instead.")
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    @classmethod
    def from_knowledge(cls, knowledge) -> SurrogateModel:
        """The surrogate of a :class:`~fuelhm_bench.datasets.knowledge.KnowledgeResult`.

        Parameters
        ----------
        knowledge : KnowledgeResult
            Its ``healthy_model`` (all ten indicators), ``healthy_table`` (with
            ``unit_id``) and ``itl`` are used.

        Returns
        -------
        SurrogateModel

        Raises
        ------
        DataFormatError
            The healthy model does not cover the ten indicators in order.
        """
        hm = knowledge.healthy_model
        if tuple(hm.features_) != tuple(INDICATOR_NAMES):
            raise DataFormatError(f"The surrogate needs a healthy model of the ten indicators {list(INDICATOR_NAMES)}."
                                  f" Got features {list(hm.features_)} instead.")
        cov = np.asarray(hm.cov_, dtype=np.float64)
        root = _sqrt_psd(cov)
        w, v = np.linalg.eigh(0.5 * (cov + cov.T))
        inv_root = (v / np.sqrt(np.clip(w, 1e-300, None))) @ v.T
        table = knowledge.healthy_table
        x = table[list(INDICATOR_NAMES)].to_numpy(dtype=np.float64)
        valid = np.ones(len(table), dtype=bool)
        for j, name in enumerate(INDICATOR_NAMES):
            col = f"{name}_valid"
            if col in table.columns:
                valid &= table[col].to_numpy(dtype=bool)
        complete = valid & np.isfinite(x).all(axis=1)
        units = table["unit_id"].to_numpy() if "unit_id" in table.columns else np.zeros(len(table))
        z = (x[complete] - hm.mean_) @ inv_root
        between = _between_share(z, np.asarray(units)[complete])
        within = np.eye(len(INDICATOR_NAMES)) - between
        unit_factor = root @ _sqrt_psd(between)
        flight_factor = root @ _sqrt_psd(within)
        a = knowledge.itl.matrix("A").reindex(index=list(MODE_IDS), columns=list(INDICATOR_NAMES))
        shift = a.to_numpy(dtype=np.float64)
        return cls(np.asarray(hm.mean_, dtype=np.float64), unit_factor, flight_factor,
                   np.where(np.isfinite(shift), shift, 0.0))

    @property
    def unit_share(self) -> np.ndarray:
        b = (self.unit_factor ** 2).sum(axis=1)
        total = b + (self.flight_factor ** 2).sum(axis=1)
        return b / np.where(total > 0, total, 1.0)

    def healthy(self, rng: np.random.Generator, n_flights: int) -> np.ndarray:
        """Healthy indicators of the flights of one new unit.

        Parameters
        ----------
        rng : numpy.random.Generator
            Source of the draws (one call of ``standard_normal``).
        n_flights : int
            Number of flights.

        Returns
        -------
        ndarray of shape (n_flights, 10)
            float64, ``INDICATOR_NAMES`` order and units.
        """
        draws = rng.standard_normal((n_flights + 1, len(INDICATOR_NAMES)))
        return self.mean + draws[0] @ self.unit_factor.T + draws[1:] @ self.flight_factor.T

    def indicators(self, healthy: np.ndarray, intensities: np.ndarray) -> np.ndarray:
        """Degraded indicators ``healthy + intensities @ shift`` with ``Inb = (X1 + X2) / 2``.

        Parameters
        ----------
        healthy : ndarray of shape (n, 10)
            Healthy indicators (:meth:`healthy`).
        intensities : ndarray of shape (n, 7)
            Mode intensities of each flight (``MODE_IDS`` order, fraction of the
            Table III maximum).

        Returns
        -------
        ndarray of shape (n, 10)
        """
        out = healthy + intensities @ self.shift
        out[:, _INB] = 0.5 * (out[:, _X1] + out[:, _X2])
        return out

    def describe(self) -> pd.DataFrame:
        """Mean, standard deviation and unit share of each healthy indicator (one row per indicator)."""
        std = np.sqrt((self.unit_factor ** 2).sum(axis=1) + (self.flight_factor ** 2).sum(axis=1))
        return pd.DataFrame({"mean": self.mean, "std": std, "unit_share": self.unit_share},
                            index=pd.Index(INDICATOR_NAMES, name="indicator"))
