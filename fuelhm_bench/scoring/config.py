"""Scoring configuration: operating points, intensity bands, confidence intervals."""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field
from typing import Any, Mapping

from fuelhm_bench.errors import ParameterError, parameter_error
from fuelhm_bench.taxonomy import MODE_IDS

__all__ = ["ScoringConfig"]


def _err(name: str, allowed: str, given: Any) -> ParameterError:
    return parameter_error(name, "ScoringConfig", allowed, given)


def _is_real(x: Any) -> bool:
    return (isinstance(x, numbers.Real) and not isinstance(x, bool)
            and math.isfinite(float(x)))


@dataclass(frozen=True)
class ScoringConfig:
    """How a run is scored. All fields have the documented defaults (docs/scoring.md).

    Parameters
    ----------
    a_values : tuple of float, default=(0, 1, 2, 3, 5)
        Values of ``A`` in ``Thr = mu + A * sigma`` (paper eq. 10) for Table V.
    headline_a : float, default=2.0
        ``A`` of the headline threshold KPIs (the paper's first choice).
    detectable_fraction : float, default=0.25
        A faulty flight whose intensity is at least this fraction of the
        reference maximal intensity is *detectable*: it counts as a false
        negative when not detected. Below it the flight is *incipient*: neither
        a false negative nor a true positive (reported separately). In [0, 1].
    band_edges : tuple of float, default=(0.125, 0.375, 0.75)
        Upper edges (fractions of the reference maximal intensity) of the
        intensity bands; bands are ``(0, e0], (e0, e1], (e1, e2], (e2, inf)``.
    band_names : tuple of str, default=("<12.5%", "25%", "50%", "100%")
        Names of the bands (one more than ``band_edges``). The last three are
        the 25 %, 50 % and 100 % rows of the paper's Table VI.
    reference_max : mapping of str to float or None, default=None
        Maximal intensity per mode that fractions refer to. None uses the
        labels' ``max_intensity_<mode>`` (the maximum of the unit's schedule).
        Pass e.g. ``Knowledge.max_intensity`` or ``{m: 1.0 for m in MODE_IDS}``
        to refer to a fleet-wide maximum instead.
    confidence : float, default=0.95
        Confidence level of every interval, in (0, 1).
    n_bootstrap : int, default=0
        Number of bootstrap resamples over units (clustered intervals, columns
        ``<rate>_boot_low/high``); 0 disables them.
    random_state : int, default=0
        Seed of the bootstrap.
    summary_detection_weight : float, default=0.5
        Share of the normalised summary score earned by detection alone; the
        rest requires a correct classification (see :func:`summary_score`). In
        [0, 1].

    Examples
    --------
    >>> ScoringConfig(a_values=(2.0,), n_bootstrap=200).band_names
    ('<12.5%', '25%', '50%', '100%')
    """

    a_values: tuple[float, ...] = (0.0, 1.0, 2.0, 3.0, 5.0)
    headline_a: float = 2.0
    detectable_fraction: float = 0.25
    band_edges: tuple[float, ...] = (0.125, 0.375, 0.75)
    band_names: tuple[str, ...] = ("<12.5%", "25%", "50%", "100%")
    reference_max: Mapping[str, float] | None = field(default=None, hash=False)
    confidence: float = 0.95
    n_bootstrap: int = 0
    random_state: int = 0
    summary_detection_weight: float = 0.5

    def __post_init__(self) -> None:
        try:
            a_values = tuple(float(a) for a in self.a_values if _is_real(a))
        except TypeError:
            raise _err("a_values", "a non-empty sequence of finite floats", self.a_values) from None
        if not a_values or len(a_values) != len(tuple(self.a_values)):
            raise _err("a_values", "a non-empty sequence of finite floats", self.a_values)
        if len(set(a_values)) != len(a_values):
            raise _err("a_values", "a sequence of distinct floats", self.a_values)
        object.__setattr__(self, "a_values", a_values)
        if not _is_real(self.headline_a):
            raise _err("headline_a", "a finite float", self.headline_a)
        if not (_is_real(self.detectable_fraction) and 0 <= self.detectable_fraction <= 1):
            raise _err("detectable_fraction", "a float in [0, 1]", self.detectable_fraction)
        edges = tuple(self.band_edges)
        if (not edges or not all(_is_real(e) and e > 0 for e in edges)
                or any(b <= a for a, b in zip(edges, edges[1:]))):
            raise _err("band_edges", "a non-empty increasing sequence of floats > 0",
                       self.band_edges)
        object.__setattr__(self, "band_edges", tuple(float(e) for e in edges))
        names = tuple(self.band_names)
        if len(names) != len(edges) + 1 or len(set(names)) != len(names) or "healthy" in names:
            raise _err("band_names", f"{len(edges) + 1} distinct names other than 'healthy'",
                       self.band_names)
        object.__setattr__(self, "band_names", tuple(str(n) for n in names))
        if self.reference_max is not None:
            if not isinstance(self.reference_max, Mapping):
                raise _err("reference_max", "a mapping mode -> float > 0 or None",
                           self.reference_max)
            ref = {}
            for mode, value in self.reference_max.items():
                if mode not in MODE_IDS or not (_is_real(value) and value > 0):
                    raise _err("reference_max", "a mapping from mode ids to floats > 0",
                               self.reference_max)
                ref[mode] = float(value)
            object.__setattr__(self, "reference_max", ref)
        if not (_is_real(self.confidence) and 0 < self.confidence < 1):
            raise _err("confidence", "a float in (0, 1)", self.confidence)
        if not (isinstance(self.n_bootstrap, numbers.Integral) and self.n_bootstrap >= 0
                and not isinstance(self.n_bootstrap, bool)):
            raise _err("n_bootstrap", "an int >= 0", self.n_bootstrap)
        if not (isinstance(self.random_state, numbers.Integral) and self.random_state >= 0
                and not isinstance(self.random_state, bool)):
            raise _err("random_state", "an int >= 0", self.random_state)
        if not (_is_real(self.summary_detection_weight)
                and 0 <= self.summary_detection_weight <= 1):
            raise _err("summary_detection_weight", "a float in [0, 1]",
                       self.summary_detection_weight)

    def operating_point_name(self, a: float) -> str:
        """Label of the threshold operating point ``A = a``, e.g. ``"thr(A=2)"``."""
        return f"thr(A={a:g})"
