"""Trivial anchors of every results table: never alarm, and alarm at random (NAB practice).

``fuelhm_baselines.trivial:NullMethod`` is :class:`fuelhm_bench.methods.NullMethod`
itself (it has no randomness). ``fuelhm_baselines.trivial:RandomMethod`` is a thin
subclass of :class:`fuelhm_bench.methods.RandomMethod` whose only difference is
the default seed, ``random_state=0``, so that the leaderboard row is
reproducible from its entry point and hyperparameters alone (a seed passed to
``fit`` still takes precedence).
"""

from __future__ import annotations

from typing import Any

from fuelhm_bench.methods import NullMethod
from fuelhm_bench.methods import RandomMethod as _PackageRandomMethod

__all__ = ["NullMethod", "RandomMethod"]


class RandomMethod(_PackageRandomMethod):
    """Alarms with probability ``alarm_probability`` per flight, blames a random mode; seeded.

    Same behaviour as :class:`fuelhm_bench.methods.RandomMethod` (score uniform
    in [0, 1), alarm when ``score >= 1 - alarm_probability``, all the guilt on
    one uniformly drawn mode, draws from the per-unit generator), with
    ``random_state=0`` by default. Its expected normalised summary score is 0.

    Parameters
    ----------
    alarm_probability : float, default=0.05
        Probability of an alarm on any flight, in [0, 1].
    random_state : int, numpy.random.Generator or None, default=0
        Seed used when ``fit`` is not given one.

    Examples
    --------
    >>> RandomMethod()
    RandomMethod(alarm_probability=0.05, random_state=0)
    """

    def __init__(self, *, alarm_probability: float = 0.05, random_state: Any = 0) -> None:
        self.alarm_probability = alarm_probability
        self.random_state = random_state
