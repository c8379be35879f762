"""fuelhm-bench: a health-monitoring benchmark for a turbofan fuel-system actuation loop."""

from fuelhm_bench import _numba_cache  # noqa: F401 - first: numba caches go outside the package

from fuelhm_bench.taxonomy import EFFECT_IDS, INDICATOR_NAMES, INDICATOR_UNITS, MODE_IDS

__version__ = "0.2.0"  # the one source of the version (pyproject.toml reads it)

__all__ = ["EFFECT_IDS", "INDICATOR_NAMES", "INDICATOR_UNITS", "MODE_IDS", "__version__"]

from fuelhm_bench import envs  # noqa: E402,F401 - registers FuelHM/ActuationLoop-v3 with gymnasium
