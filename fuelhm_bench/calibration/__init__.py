"""Recalibration of the model on measured healthy flights, and the model-discrepancy workflow.

* :func:`recalibrate` (``fuelhm-bench calibrate``, paper section IV.B / Fig. 7): fit the
  identifiable subset :data:`RECALIBRATION_PARAMETERS` to measured flights, unit by unit,
  by least squares on the replayed velocities (:mod:`~fuelhm_bench.calibration.replay`).
* :func:`find_discrepancy` (``fuelhm-bench discrepancy``): recalibrate on fit flights, map
  where the model and the measurement disagree, fit every candidate effect, decide by BIC
  and held-out gap, return the augmented model.

Modules: ``velocity`` (differentiator, local means), ``replay`` (measured flights through
the model), ``curve`` (velocity-gain curve and gap metric), ``fit`` (bounded joint least
squares), ``recalibrate``, ``candidates`` (effect library search space), ``regions``
(residual maps), ``discrepancy``, ``caveats`` (what weakens a verdict's evidence), ``report`` (figures, Markdown), ``synthetic`` (data with a
hidden effect), ``study`` (statistical evaluation). See ``docs/calibration.md`` and
``docs/discrepancy.md``.
"""

from fuelhm_bench.calibration.curve import CurveConfig, gap, gap_metric_text
from fuelhm_bench.calibration.discrepancy import (
    CandidateOutcome,
    DiscrepancyConfig,
    DiscrepancyResult,
    NoiseModel,
    decide,
    find_discrepancy,
    split_fit_holdout,
)
from fuelhm_bench.calibration.fit import FitParameter, Identifiability, JointFit, fit_joint
from fuelhm_bench.calibration.recalibrate import (
    EXCLUDED_PARAMETERS,
    RECALIBRATION_PARAMETERS,
    CalibrationConfig,
    CalibrationResult,
    ParameterEstimate,
    recalibrate,
)
from fuelhm_bench.calibration.replay import ReplayConfig, ReplaySet, prepare_replay, replay_batch, replay_velocity
from fuelhm_bench.calibration.synthetic import TEST_RANGES, hidden_effect_flights

__all__ = [
    "EXCLUDED_PARAMETERS",
    "RECALIBRATION_PARAMETERS",
    "TEST_RANGES",
    "CalibrationConfig",
    "CalibrationResult",
    "CandidateOutcome",
    "CurveConfig",
    "DiscrepancyConfig",
    "DiscrepancyResult",
    "FitParameter",
    "Identifiability",
    "JointFit",
    "NoiseModel",
    "ParameterEstimate",
    "ReplayConfig",
    "ReplaySet",
    "decide",
    "find_discrepancy",
    "fit_joint",
    "gap",
    "gap_metric_text",
    "hidden_effect_flights",
    "prepare_replay",
    "recalibrate",
    "replay_batch",
    "replay_velocity",
    "split_fit_holdout",
]
