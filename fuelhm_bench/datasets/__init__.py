"""Simulated data products of the benchmark, below the environment and the harness.

Modules
-------
fleets
    :func:`fleet_indicators`: simulate a fleet and extract its indicator and label tables.
doe
    The design of experiments of the ITL (one flight per mode and intensity).
knowledge
    The published knowledge (healthy model, ITL, signature matrix) built from simulations of the
    published model.
cache
    Every product of a scenario (published knowledge, training, scored fleet, surrogate inputs)
    built once and cached in memory and on disk.

Data flow: physics -> flights -> indicators -> **datasets** -> envs -> benchmark.
"""

from __future__ import annotations

from fuelhm_bench.datasets.fleets import fleet_indicators

__all__ = ["fleet_indicators"]
