"""Validation tools that are not part of the benchmark's production paths.

:mod:`~fuelhm_bench.validation.altsim` is a second, structurally different simulator of the
actuation loop (its own equations, no code shared with :mod:`fuelhm_bench.physics`), used to
make "measured" flights for testing and calibrating the model-discrepancy workflow on data
that the model under test did not produce. Only tests, benchmarks and the discrepancy study
import this package.
"""
