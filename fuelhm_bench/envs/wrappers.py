"""Wrappers that make ``FuelHM/ActuationLoop-v3`` fit off-the-shelf RL libraries.

* :class:`AlarmOnlyAction`: a ``Discrete(2)`` action (0 = no alarm, 1 = alarm)
  instead of the ``Dict`` action most agents (e.g. stable-baselines3 PPO)
  refuse; the guilt sent with an alarm is fixed (uniform by default).
* :class:`NormalizedObservation`: a flat ``Box`` observation of 20 numbers:
  the ten indicators as healthy Z-scores (clipped, 0 where invalid) followed
  by the ten validity flags. Raw indicators span up to +/-1000 in their units.
* :class:`KeepEpisodeTruth`: when a ``TimeLimit`` truncates an episode
  (``gym.make(..., max_episode_steps=N)`` below the unit's life), the last
  ``info`` still carries ``"episode_truth"`` for the flights flown. ``gym.make``
  applies it to every registered id, outside the ``TimeLimit``.

Example::

    import gymnasium as gym
    import fuelhm_bench.envs
    from fuelhm_bench.envs.wrappers import AlarmOnlyAction, NormalizedObservation

    env = NormalizedObservation(AlarmOnlyAction(gym.make("FuelHM/ActuationLoop-v3",
                                                         fidelity="surrogate")))
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from fuelhm_bench.errors import ParameterError
from fuelhm_bench.taxonomy import INDICATOR_NAMES, MODE_IDS

__all__ = ["AlarmOnlyAction", "KeepEpisodeTruth", "NormalizedObservation", "healthy_statistics"]

_P = len(INDICATOR_NAMES)


class AlarmOnlyAction(gym.ActionWrapper, gym.utils.RecordConstructorArgs):
    """Alarm-only discrete action: ``0`` = no alarm, ``1`` = alarm.

    Parameters
    ----------
    env : gymnasium.Env
        A ``FuelHM/ActuationLoop`` environment (possibly wrapped).
    guilt : array-like of shape (7,) or None, default=None
        Guilt sent with every alarm (``MODE_IDS`` order, in [0, 1], summing to
        1); None: uniform ``1/7``. No guilt is sent without an alarm.
    """

    def __init__(self, env: gym.Env, guilt: Any = None) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, guilt=guilt)
        gym.ActionWrapper.__init__(self, env)
        g = np.full(len(MODE_IDS), 1.0 / len(MODE_IDS)) if guilt is None else np.asarray(
            guilt, dtype=np.float64)
        if g.shape != (len(MODE_IDS),) or not np.all(np.isfinite(g)) or np.any(g < 0) \
                or np.any(g > 1) or abs(g.sum() - 1.0) > 1e-6:
            raise ParameterError(f"The 'guilt' parameter of AlarmOnlyAction must be None or 7 "
                                 f"numbers in [0, 1] summing to 1. Got {guilt!r} instead.")
        self._guilt = g.astype(np.float32)
        self._none = np.zeros(len(MODE_IDS), dtype=np.float32)
        self.action_space = spaces.Discrete(2)

    def action(self, action: Any) -> dict:
        """The environment's ``Dict`` action for a discrete one."""
        a = int(np.asarray(action).reshape(()))
        if a not in (0, 1):
            raise ParameterError(f"The action of AlarmOnlyAction must be 0 or 1. Got {action!r} "
                                 f"instead.")
        return {"alarm": a, "guilt": self._guilt.copy() if a else self._none.copy()}


def healthy_statistics(env: gym.Env) -> tuple[np.ndarray, np.ndarray]:
    """Healthy mean and standard deviation of the ten indicators for an environment.

    The surrogate fidelity carries them (its healthy model); the physics
    fidelity takes them from the scenario's healthy training flights (the
    cached ones every method is fitted on).

    Returns
    -------
    mean, std : numpy.ndarray of shape (10,)
        Indicator units (``INDICATOR_UNITS``); ``std`` > 0.
    """
    base = env.unwrapped
    surrogate = getattr(base, "surrogate", None)
    if surrogate is not None:
        # unit-to-unit variance (its Gaussian unit effect) + flight-to-flight variance (its resampled residuals)
        idx = [list(surrogate.names).index(n) for n in INDICATOR_NAMES]
        between = np.diag(np.asarray(surrogate.unit_cov, float))[idx]
        res = np.where(np.asarray(surrogate.residual_valid, bool), np.asarray(surrogate.residuals, float), np.nan)[:, idx]
        n_valid = np.isfinite(res).sum(axis=0)
        within = np.where(n_valid > 1, np.nansum(res ** 2, axis=0) / np.maximum(n_valid - 1, 1), 0.0)
        mean, std = np.asarray(surrogate.mean, float)[idx], np.sqrt(between + within)
    else:
        from fuelhm_bench.datasets.cache import training_indicators

        table = training_indicators(base.scenario, flight_minutes=base.flight_minutes)
        x = table[list(INDICATOR_NAMES)].to_numpy(dtype=float)
        for j, name in enumerate(INDICATOR_NAMES):
            if f"{name}_valid" in table.columns:
                x[~table[f"{name}_valid"].to_numpy(dtype=bool), j] = np.nan
        mean, std = np.nanmean(x, axis=0), np.nanstd(x, axis=0, ddof=1)
    std = np.where(np.isfinite(std) & (std > 0), std, 1.0)
    return np.where(np.isfinite(mean), mean, 0.0), std


class NormalizedObservation(gym.ObservationWrapper, gym.utils.RecordConstructorArgs):
    """Flat, normalised observation: 10 clipped healthy Z-scores, then 10 validity flags.

    Parameters
    ----------
    env : gymnasium.Env
        A ``FuelHM/ActuationLoop`` environment (possibly wrapped), without
        ``raw=True`` (the raw samples are dropped otherwise).
    mean, std : array-like of shape (10,) or None, default=None
        Healthy statistics (indicator units); None: :func:`healthy_statistics`.
    clip : float, default=10.0
        Z-scores are clipped to ``[-clip, clip]``.

    Notes
    -----
    Observation space: ``Box(-clip, clip, (20,), float32)`` with entries 10..19
    in {0, 1}. An invalid indicator has Z-score 0 (its healthy mean).
    """

    def __init__(self, env: gym.Env, *, mean: Any = None, std: Any = None,
                 clip: float = 10.0) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, mean=mean, std=std, clip=clip)
        gym.ObservationWrapper.__init__(self, env)
        if isinstance(clip, bool) or not isinstance(clip, (int, float)) or not clip > 0 \
                or not np.isfinite(clip):
            raise ParameterError(f"The 'clip' parameter of NormalizedObservation must be a "
                                 f"finite number > 0. Got {clip!r} instead.")
        if (mean is None) != (std is None):
            raise ParameterError("The 'mean' and 'std' parameters of NormalizedObservation must "
                                 "be given together or both be None.")
        if mean is None:
            mean, std = healthy_statistics(env)
        mean, std = np.asarray(mean, dtype=np.float64), np.asarray(std, dtype=np.float64)
        if mean.shape != (_P,) or std.shape != (_P,) or not np.all(np.isfinite(mean)) \
                or not np.all(np.isfinite(std) & (std > 0)):
            raise ParameterError(f"The 'mean' and 'std' parameters of NormalizedObservation must "
                                 f"be {_P} finite numbers (std > 0). Got shapes {mean.shape} and "
                                 f"{std.shape} instead.")
        self.mean, self.std, self.clip = mean, std, float(clip)
        self.observation_space = spaces.Box(-self.clip, self.clip, (2 * _P,), np.float32)

    def observation(self, observation: dict) -> np.ndarray:
        """The flat normalised observation."""
        valid = np.asarray(observation["valid"]).astype(bool)
        z = (np.asarray(observation["indicators"], dtype=np.float64) - self.mean) / self.std
        z = np.clip(np.where(valid & np.isfinite(z), z, 0.0), -self.clip, self.clip)
        return np.concatenate([z, valid.astype(np.float64)]).astype(np.float32)


class KeepEpisodeTruth(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """Add ``info["episode_truth"]`` (flights flown so far) when an episode is truncated.

    The environment returns the episode's ground truth when the unit retires
    (``terminated``); a ``TimeLimit`` that stops earlier would lose it. This
    wrapper, placed outside the ``TimeLimit``, asks the environment for the
    truth of the flights flown (``ActuationLoopEnv.episode_truth``).
    """

    def __init__(self, env: gym.Env) -> None:
        gym.utils.RecordConstructorArgs.__init__(self)
        gym.Wrapper.__init__(self, env)

    def step(self, action: Any):
        obs, reward, terminated, truncated, info = self.env.step(action)
        if truncated and "episode_truth" not in info:
            info = dict(info)
            info["episode_truth"] = self.env.unwrapped.episode_truth()
        return obs, reward, terminated, truncated, info
