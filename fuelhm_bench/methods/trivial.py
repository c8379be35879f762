"""Trivial reference methods that anchor every results table (NAB practice).

* :class:`NullMethod` never alarms: it scores 0 on the normalised summary.
* :class:`RandomMethod` alarms at random with a fixed probability and blames a
  random mode: its expected normalised summary score is 0 as well, whatever the
  probability, which makes it a useful sanity check of the scorer.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from fuelhm_bench.methods.base import BaseMethod
from fuelhm_bench.methods.decision import Decision
from fuelhm_bench.methods.knowledge import Knowledge
from fuelhm_bench.methods.params import Interval, RandomState
from fuelhm_bench.taxonomy import MODE_IDS

__all__ = ["NullMethod", "RandomMethod"]


class NullMethod(BaseMethod):
    """Never alarms; score 0 for every flight.

    Examples
    --------
    >>> NullMethod()
    NullMethod()
    """

    def _fit(self, healthy_indicators: pd.DataFrame, *, knowledge: Knowledge | None,
             raw_flights: Any, rng: np.random.Generator) -> None:
        self.n_training_flights_ = len(healthy_indicators)

    def _decide(self, row: pd.Series) -> Decision:
        return Decision.no_alarm(0.0)


class RandomMethod(BaseMethod):
    """Alarms with probability ``alarm_probability``, independently per flight.

    The score is a uniform draw in [0, 1) and the alarm is ``score >= 1 -
    alarm_probability``; on an alarm, all the guilt goes to one mode drawn
    uniformly. Draws come from the per-unit generator ``unit_rng_``, so the
    decisions of a unit depend only on the seed and the unit id.

    Parameters
    ----------
    alarm_probability : float, default=0.05
        Probability of an alarm on any flight, in [0, 1].
    random_state : int, numpy.random.Generator or None, default=None
        Seed used when ``fit`` is not given one.

    Examples
    --------
    >>> RandomMethod(alarm_probability=0.1, random_state=0)
    RandomMethod(alarm_probability=0.1, random_state=0)
    """

    _parameter_constraints = {
        "alarm_probability": (Interval(float, 0.0, 1.0, closed="both"),),
        "random_state": (RandomState(),),
    }

    def __init__(self, *, alarm_probability: float = 0.05, random_state: Any = None) -> None:
        self.alarm_probability = alarm_probability
        self.random_state = random_state

    def _fit(self, healthy_indicators: pd.DataFrame, *, knowledge: Knowledge | None,
             raw_flights: Any, rng: np.random.Generator) -> None:
        self.n_training_flights_ = len(healthy_indicators)

    def _decide(self, row: pd.Series) -> Decision:
        score = float(self.unit_rng_.random())
        mode = int(self.unit_rng_.integers(len(MODE_IDS)))
        alarm = score >= 1.0 - float(self.alarm_probability)
        guilt = np.eye(len(MODE_IDS))[mode] if alarm else np.zeros(len(MODE_IDS))
        return Decision(score=score, alarm=alarm, guilt=guilt)
