"""Degradation schedules: when a fault starts in a unit's life and how it grows.

A :class:`ModeSchedule` says, for one degradation mode, with what probability a
unit develops it, how its onset flight is drawn, how the intensity grows from the
onset (step, linear ramp, exponential) and its maximum intensity. A
:class:`UnitSchedule` is the realisation for one unit: the onset flight of each
mode that occurs, from which :meth:`UnitSchedule.intensities` gives the
intensities at any flight.

Growth laws, with ``k = flight - onset`` (``k < 0``: intensity 0):

* ``step``: ``f = f_max``;
* ``linear``: ``f = f_max * min(1, (k + 1) / ramp_flights)``;
* ``exponential``: ``f = f_max * min(1, exp((k + 1 - ramp_flights) / tau))`` with
  ``tau = ramp_flights / 5`` — an incipient fault that accelerates and reaches
  ``f_max`` after ``ramp_flights`` flights (starting from ``f_max * e^-5``).

**Faults outside the library.** An :class:`UnknownFault` is a physical effect of
:mod:`fuelhm_bench.physics.effects` (not one of the seven modes) that a unit
acquires at an onset flight and keeps (step: the effect with its parameters is
switched on from the onset). A unit that drew no degradation mode develops at
most one of them (:func:`draw_unknown_fault`); its labels name the effect, and
the scorer counts its flights as faulty with the true mode ``"unknown"``
(docs/scoring.md).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from fuelhm_bench.errors import range_error
from fuelhm_bench.physics._validation import check_fields
from fuelhm_bench.physics.degradations import validate_intensities
from fuelhm_bench.taxonomy import MODE_IDS, UNKNOWN_MODE

GROWTH_LAWS = ("step", "linear", "exponential")

#: ``true_mode`` of a flight whose only fault is outside the seven modes (an :class:`UnknownFault`).
UNKNOWN = UNKNOWN_MODE


@dataclass(frozen=True)
class ModeSchedule:
    """Schedule of one degradation mode over a unit's flights.

    Parameters
    ----------
    mode : str
        One of :data:`~fuelhm_bench.taxonomy.MODE_IDS`.
    probability : float, default=1.0
        Probability that a unit develops this mode, in [0, 1].
    onset_min, onset_max : int, default=0, 0
        Onset flight index drawn uniformly in ``[onset_min, onset_max]`` (0-based).
    growth : {"step", "linear", "exponential"}, default="linear"
        Growth law from the onset.
    ramp_flights : int, default=20
        Flights from onset to maximum intensity (linear and exponential).
    max_intensity : float, default=1.0
        Maximum intensity, in (0, 1].
    """

    mode: str
    probability: float = 1.0
    onset_min: int = 0
    onset_max: int = 0
    growth: str = "linear"
    ramp_flights: int = 20
    max_intensity: float = 1.0

    def __post_init__(self) -> None:
        validate_intensities({self.mode: 0.0}, where="ModeSchedule.mode")
        check_fields(self, {"probability": (0.0, 1.0, True), "max_intensity": (0.0, 1.0, False)})
        for name in ("onset_min", "onset_max", "ramp_flights"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < (1 if name == "ramp_flights" else 0):
                raise range_error(f"ModeSchedule.{name}", "an integer >= " + ("1" if name == "ramp_flights" else "0"), v)
        if self.onset_max < self.onset_min:
            raise range_error("ModeSchedule.onset_max", f">= onset_min ({self.onset_min})", self.onset_max)
        if self.growth not in GROWTH_LAWS:
            raise range_error("ModeSchedule.growth", f"one of {', '.join(GROWTH_LAWS)}", self.growth)

    def intensity(self, flight: np.ndarray | int, onset: int) -> np.ndarray:
        """Intensity at flight index(es) ``flight`` for a given ``onset`` flight."""
        k = np.asarray(flight, dtype=float) - onset
        f_max = self.max_intensity
        if self.growth == "step":
            f = np.full_like(k, f_max)
        elif self.growth == "linear":
            f = f_max * np.minimum(1.0, (k + 1.0) / self.ramp_flights)
        else:
            tau = self.ramp_flights / 5.0
            f = f_max * np.minimum(1.0, np.exp(np.minimum((k + 1.0 - self.ramp_flights) / tau, 0.0)))
        return np.where(k < 0, 0.0, f)


@dataclass(frozen=True)
class UnknownFault:
    """A fault outside the seven modes: an optional physical effect switched on at an onset flight.

    Parameters
    ----------
    effect : str
        One of :data:`~fuelhm_bench.taxonomy.EFFECT_IDS` (docs/physics.md §7).
    probability : float, default=1.0
        Probability that a unit without any degradation mode develops it, in [0, 1].
    onset_min, onset_max : int, default=0, 0
        Onset flight drawn uniformly in ``[onset_min, onset_max]`` (0-based).
    parameters : tuple of (str, float), default=()
        Parameter overrides of the effect (SI units as in their names); the
        others take the effect's defaults.
    """

    effect: str
    probability: float = 1.0
    onset_min: int = 0
    onset_max: int = 0
    parameters: tuple = ()

    def __post_init__(self) -> None:
        check_fields(self, {"probability": (0.0, 1.0, True)})
        for name in ("onset_min", "onset_max"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 0:
                raise range_error(f"UnknownFault.{name}", "an integer >= 0", v)
        if self.onset_max < self.onset_min:
            raise range_error("UnknownFault.onset_max", f">= onset_min ({self.onset_min})", self.onset_max)
        self.build()  # an unknown effect id or a parameter out of range fails here, naming it

    def build(self):
        """The effect instance (:func:`fuelhm_bench.physics.effects.make_effect`)."""
        from fuelhm_bench.physics.effects import make_effect

        return make_effect(self.effect, **dict(self.parameters))


def draw_unknown_fault(faults: Sequence[UnknownFault], rng: np.random.Generator) -> tuple[UnknownFault | None, int]:
    """Draw at most one fault outside the library for a unit: ``(fault, onset)`` or ``(None, -1)``.

    Fault ``k`` is chosen with probability ``faults[k].probability`` (the
    probabilities sum to at most 1; the remainder keeps the unit healthy).
    Nothing is drawn from ``rng`` when ``faults`` is empty.
    """
    if not faults:
        return None, -1
    p = np.array([f.probability for f in faults], dtype=float)
    if p.sum() > 1.0 + 1e-9:
        raise range_error("unknown fault probabilities", "summing to <= 1", round(float(p.sum()), 6))
    idx = int(np.searchsorted(np.cumsum(p), rng.random(), side="right"))
    if idx >= len(faults):
        return None, -1
    fault = faults[idx]
    return fault, int(rng.integers(fault.onset_min, fault.onset_max + 1))


@dataclass(frozen=True)
class UnitSchedule:
    """The realised degradation history of one unit.

    Parameters
    ----------
    schedules : tuple of ModeSchedule
        The mode schedules that occur in this unit.
    onsets : tuple of int
        Onset flight of each, aligned with ``schedules``.
    unknown : UnknownFault or None, default=None
        The fault outside the seven modes this unit develops, if any.
    unknown_onset : int, default=-1
        Its onset flight (-1 without one).
    """

    schedules: tuple = ()
    onsets: tuple = ()
    unknown: UnknownFault | None = None
    unknown_onset: int = -1

    def effects(self, flight: int) -> tuple:
        """Effects of the unknown fault active at a flight index (empty before its onset or without one)."""
        if self.unknown is None or flight < self.unknown_onset:
            return ()
        return (self.unknown.build(),)

    def intensities(self, flight: int) -> dict[str, float]:
        """``{mode: intensity}`` at a flight index (modes absent from the unit omitted)."""
        return {s.mode: float(s.intensity(flight, o)) for s, o in zip(self.schedules, self.onsets)}

    def onset_of(self, mode: str) -> int:
        """Onset flight of ``mode``, or -1 if it does not occur."""
        for s, o in zip(self.schedules, self.onsets):
            if s.mode == mode:
                return o
        return -1

    def max_intensity_of(self, mode: str) -> float:
        """Maximum intensity of ``mode`` in this unit (0 if it does not occur)."""
        for s in self.schedules:
            if s.mode == mode:
                return s.max_intensity
        return 0.0


def draw_unit_schedule(schedules: Sequence[ModeSchedule], rng: np.random.Generator, *,
                       simultaneous: bool = True) -> UnitSchedule:
    """Draw which modes occur in a unit and their onsets.

    Parameters
    ----------
    schedules : sequence of ModeSchedule
        Candidate modes.
    rng : numpy.random.Generator
        Source of randomness.
    simultaneous : bool, default=True
        If False at most one mode occurs per unit: one is chosen with the
        schedules' probabilities (which must then sum to at most 1; the remainder
        is the probability that the unit stays healthy).

    Returns
    -------
    UnitSchedule
    """
    if simultaneous:
        chosen = [s for s in schedules if rng.random() < s.probability]
    else:
        p = np.array([s.probability for s in schedules], dtype=float)
        total = p.sum()
        if total > 1.0 + 1e-9:
            raise range_error("degradation probabilities (simultaneous faults not allowed)", "summing to <= 1",
                              round(float(total), 6))
        u = rng.random()
        idx = int(np.searchsorted(np.cumsum(p), u, side="right"))
        chosen = [schedules[idx]] if idx < len(schedules) else []
    onsets = tuple(int(rng.integers(s.onset_min, s.onset_max + 1)) for s in chosen)
    return UnitSchedule(tuple(chosen), onsets)


def label_columns() -> list[str]:
    """Ground-truth columns written to the labels table, besides the keys."""
    cols = []
    for m in MODE_IDS:
        cols += [f"intensity_{m}", f"max_intensity_{m}", f"onset_{m}"]
    return cols


