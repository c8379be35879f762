"""Gymnasium environments of fuelhm-bench, registered lazily (as ``gymnasium/envs/__init__.py`` does).

Importing this package registers every id of :data:`ENV_IDS` with
Gymnasium's registry; the environment module itself (physics, indicators) is
only imported by ``gymnasium.make``::

    import gymnasium as gym
    import fuelhm_bench.envs  # registers FuelHM/ActuationLoop-v0

    env = gym.make("FuelHM/ActuationLoop-v0", scenario="all_modes", fidelity="surrogate")

``gym.make("fuelhm_bench.envs:FuelHM/ActuationLoop-v0")`` imports the package
itself. Versions follow Gymnasium's rule: any change that alters observations
or rewards for the same arguments bumps ``-vN``; asking for a retired
version names the current one.

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
SurrogateModel
    The surrogate fidelity (:mod:`fuelhm_bench.envs.surrogate`).
"""

from __future__ import annotations

from gymnasium.envs.registration import register, registry

__all__ = ["ENV_IDS", "ActuationLoopEnv", "KnowledgeSize", "SurrogateModel", "clear_memory_cache",
           "default_cache_dir", "published_knowledge", "register_envs", "scored_indicators",
           "surrogate_knowledge", "training_indicators"]

#: Registered environment ids -> entry points (``"module:Class"``, imported on ``make``).
ENV_IDS: dict[str, str] = {
    "FuelHM/ActuationLoop-v0": "fuelhm_bench.envs.actuation_loop:ActuationLoopEnv",
}

_LAZY = {
    "ActuationLoopEnv": "fuelhm_bench.envs.actuation_loop",
    "KnowledgeSize": "fuelhm_bench.datasets.cache",
    "published_knowledge": "fuelhm_bench.datasets.cache",
    "default_cache_dir": "fuelhm_bench.datasets.cache",
    "clear_memory_cache": "fuelhm_bench.datasets.cache",
    "surrogate_knowledge": "fuelhm_bench.datasets.cache",
    "training_indicators": "fuelhm_bench.datasets.cache",
    "scored_indicators": "fuelhm_bench.datasets.cache",
    "SurrogateModel": "fuelhm_bench.envs.surrogate",
}


def register_envs() -> None:
    """Register every id of :data:`ENV_IDS` (idempotent; already registered ids are left alone)."""
    for env_id, entry_point in ENV_IDS.items():
        if env_id not in registry:
            # The episode length is the scenario's flights_per_unit: the environment
            # terminates itself, so no TimeLimit (max_episode_steps) is registered.
            register(id=env_id, entry_point=entry_point, nondeterministic=False)


def __getattr__(name: str):
    """Import the heavy modules only when one of their names is used (PEP 562)."""
    if name in _LAZY:
        import importlib

        return getattr(importlib.import_module(_LAZY[name]), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


register_envs()
