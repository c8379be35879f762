"""Indicator extraction from flight records: velocity-gain curve -> ten indicators.

Each flight records only the servovalve control current (mA) and the LVDT cylinder position
(mm). This package differentiates the position, masks unusable samples (end stops, current
saturation, gaps), smooths the velocity-gain curve by local means over fixed current bins
(paper Fig. 4), fits its slope changes and returns the ten indicators of the paper's Table I
(X1, Y1, X2, Y2, Inb, I0, Hys0, G_in, G_out, G_null) with a validity flag each.

Two extractors share every definition and the final curve -> indicator step:

* batch, over a recorded flight: :func:`extract_indicators`, :func:`velocity_gain_curve`,
  :func:`extract_table` (one row per flight);
* streaming, on board, fixed memory (< 64 KiB): :class:`StreamingExtractor`.

Exact definitions: ``docs/indicators.md`` and the docstrings of :mod:`.velocity`,
:mod:`.fit` and :mod:`.indicators`. Plots: :mod:`fuelhm_bench.indicators.plot` (imported
separately, it needs matplotlib). Synthetic test flights with known indicators:
:mod:`fuelhm_bench.testing.indicators`.
"""

from fuelhm_bench.indicators.batch import (
    extract_indicators,
    extract_table,
    velocity_gain_curve,
    velocity_points,
)
from fuelhm_bench.indicators.config import STREAMING_STATE_BUDGET_BYTES, ExtractionConfig
from fuelhm_bench.indicators.curve import COUNTER_NAMES, VelocityGainCurve
from fuelhm_bench.indicators.fit import CurveFit, fit_curve
from fuelhm_bench.indicators.indicators import idle_statistics, indicators_from_curve
from fuelhm_bench.indicators.result import IndicatorResult, table_columns
from fuelhm_bench.indicators.streaming import StreamingExtractor
from fuelhm_bench.indicators.velocity import differentiate_position

__all__ = [
    "COUNTER_NAMES",
    "STREAMING_STATE_BUDGET_BYTES",
    "CurveFit",
    "ExtractionConfig",
    "IndicatorResult",
    "StreamingExtractor",
    "VelocityGainCurve",
    "differentiate_position",
    "extract_indicators",
    "extract_table",
    "fit_curve",
    "idle_statistics",
    "indicators_from_curve",
    "table_columns",
    "velocity_gain_curve",
    "velocity_points",
]
