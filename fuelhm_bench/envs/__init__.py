"""Gymnasium environments of fuelhm-bench, registered lazily (as ``gymnasium/envs/__init__.py`` does).

Importing this package registers every id of :data:`ENV_IDS` with
Gymnasium's registry; the environment module itself (physics, indicators) is
only imported by ``gymnasium.make``::

    import gymnasium as gym
    import fuelhm_bench.envs  # registers FuelHM/ActuationLoop-v3

    env = gym.make("FuelHM/ActuationLoop-v3", scenario="all_modes", fidelity="surrogate")

``gym.make("fuelhm_bench.envs:FuelHM/ActuationLoop-v3")`` imports the package
itself. Versions follow Gymnasium's rule: any change that alters observations
or rewards for the same arguments bumps ``-vN``; asking for a retired
version names the current one (``FuelHM/ActuationLoop-v2`` -> "deprecated. Please use
`FuelHM/ActuationLoop-v3` instead", Gymnasium's :class:`~gymnasium.error.DeprecatedEnv`).

Version history
---------------
v3
    A fault outside the seven modes (a scenario's ``unknown_faults``) enters the rewards and
    is removed by a correct maintenance; units drawn by ``reset()`` get the scenario's
    ``unknown_faults``; a repaired unit keeps its manufacturing draws at surrogate fidelity.
    v2 is retired.
v2
    The observation gains the extended indicators (``"extended"``, ``"extended_valid"``),
    among them the supply-pressure indicators ``Hys_lo``, ``Hys_hi`` and ``I0_slope`` (issue 11).
    The paper's ten and the rewards are unchanged. Retired.
v1
    Physics v2 (issue 11): operating excitation without per-frame N2 dither, degradation
    laws as mechanisms, re-sized scenarios (every shipped scenario at version 2). Scores of
    v0 are not comparable. Retired.
v0
    Initial version (retired).

Public names
------------
ENV_IDS
    The registered ids.
ActuationLoopEnv
    The environment class (see its docstring, a manual).
KnowledgeSize, published_knowledge, training_indicators, scored_indicators, surrogate_knowledge,
default_cache_dir, clear_memory_cache
    Cached simulated products: published knowledge, training flights, scored flights, the
    surrogate's inputs (:mod:`fuelhm_bench.datasets.cache`).
SurrogateModel, fit_surrogate, surrogate_doe
    The surrogate fidelity, learnt from physics indicator tables (:mod:`fuelhm_bench.envs.surrogate`),
    and the design of experiments it is learnt on.
"""

from __future__ import annotations

from gymnasium.envs.registration import WrapperSpec, register, registry

__all__ = ["ENV_IDS", "MAX_EPISODE_STEPS", "ActuationLoopEnv", "KnowledgeSize", "SurrogateModel", "clear_memory_cache",
           "default_cache_dir", "published_knowledge", "register_envs", "scored_indicators",
           "fit_surrogate", "surrogate_doe", "surrogate_healthy", "surrogate_knowledge", "training_indicators"]

#: ``spec.max_episode_steps`` of every id: flights in a unit's life beyond which a ``TimeLimit``
#: truncates (above every shipped scenario's ``flights_per_unit``, at most 60).
MAX_EPISODE_STEPS: int = 1000

#: Registered environment ids -> entry points (``"module:Class"``, imported on ``make``).
ENV_IDS: dict[str, str] = {
    "FuelHM/ActuationLoop-v3": "fuelhm_bench.envs.actuation_loop:ActuationLoopEnv",
}

_LAZY = {
    "ActuationLoopEnv": "fuelhm_bench.envs.actuation_loop",
    "KnowledgeSize": "fuelhm_bench.datasets.cache",
    "published_knowledge": "fuelhm_bench.datasets.cache",
    "default_cache_dir": "fuelhm_bench.datasets.cache",
    "clear_memory_cache": "fuelhm_bench.datasets.cache",
    "surrogate_knowledge": "fuelhm_bench.datasets.cache",
    "surrogate_doe": "fuelhm_bench.datasets.cache",
    "surrogate_healthy": "fuelhm_bench.datasets.cache",
    "fit_surrogate": "fuelhm_bench.envs.surrogate",
    "training_indicators": "fuelhm_bench.datasets.cache",
    "scored_indicators": "fuelhm_bench.datasets.cache",
    "SurrogateModel": "fuelhm_bench.envs.surrogate",
}


def register_envs() -> None:
    """Register every id of :data:`ENV_IDS` (idempotent; already registered ids are left alone)."""
    for env_id, entry_point in ENV_IDS.items():
        if env_id not in registry:
            # The episode length is the scenario's flights_per_unit (the environment terminates
            # itself); MAX_EPISODE_STEPS bounds it for RL libraries, and KeepEpisodeTruth (outside
            # the TimeLimit) keeps info["episode_truth"] when a shorter limit truncates.
            register(id=env_id, entry_point=entry_point, nondeterministic=False,
                     max_episode_steps=MAX_EPISODE_STEPS,
                     additional_wrappers=(WrapperSpec("KeepEpisodeTruth",
                                                      "fuelhm_bench.envs.wrappers:KeepEpisodeTruth",
                                                      {}),))


def __getattr__(name: str):
    """Import the heavy modules only when one of their names is used (PEP 562)."""
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


register_envs()
