"""Bad inputs give a DataFormatError / ParameterError with a clear message, never a traceback
from NumPy."""

from __future__ import annotations

import numpy as np
import pytest

from fuelhm_bench.errors import DataFormatError, FuelHMError, ParameterError
from fuelhm_bench.indicators import (
    ExtractionConfig,
    StreamingExtractor,
    extract_indicators,
    extract_table,
    velocity_gain_curve,
)


def good_arrays(n=200):
    t = np.arange(n) * 0.01
    i = np.sin(t * 3.0) * 3.0
    x = 30.0 + np.cumsum(6.0 * i) * 0.01
    return t, i, x


@pytest.mark.parametrize("engine", ["numba", "numpy"])
@pytest.mark.parametrize(
    ("mutate", "pattern"),
    [
        (lambda t, i, x: (t, i[:-1], x), r"flight 'F1'.*same length.*current_ma=199"),
        (lambda t, i, x: (t[:1], i[:1], x[:1]), r"flight 'F1': 1 sample\(s\).*at least 5"),
        (lambda t, i, x: (t[:4], i[:4], x[:4]), r"flight 'F1': 4 sample\(s\).*at least 5"),
        (lambda t, i, x: (np.r_[t[:50], t[49], t[51:]], i, x),
         r"flight 'F1'.*strictly increasing; sample 50 has t=0\.49 s after t=0\.49 s"),
        (lambda t, i, x: (t[::-1].copy(), i, x), r"flight 'F1'.*strictly increasing; sample 1"),
        (lambda t, i, x: (t, np.full_like(i, 0.7), x), r"flight 'F1'.*'current_ma' is constant"),
        (lambda t, i, x: (t, np.where(np.arange(len(i)) == 17, np.nan, i), x),
         r"flight 'F1'.*'current_ma' contains a non-finite value \(nan\) at sample 17"),
        (lambda t, i, x: (t, i, np.where(np.arange(len(x)) >= 100, np.inf, x)),
         r"flight 'F1'.*'position_mm'.*\(inf\) at sample 100 \(99 more"),
        (lambda t, i, x: (np.where(np.arange(len(t)) == 3, np.nan, t), i, x),
         r"flight 'F1'.*'time_s' contains a non-finite value"),
        (lambda t, i, x: (t, i.reshape(20, 10), x), r"flight 'F1'.*'current_ma'.*one-dimensional"),
        (lambda t, i, x: (t, i.astype(str), x), r"flight 'F1'.*'current_ma'.*real numbers"),
        (lambda t, i, x: (t, i, None), r"flight 'F1'.*'position_mm'.*real numbers"),
    ],
)
def test_batch_rejects_bad_arrays(mutate, pattern, engine):
    t, i, x = mutate(*good_arrays())
    with pytest.raises(DataFormatError, match=pattern):
        velocity_gain_curve(t, i, x, flight_id="F1", engine=engine)


def test_errors_are_catchable_as_one_class():
    t, i, x = good_arrays()
    with pytest.raises(FuelHMError):
        extract_indicators(t, i[:10], x)
    with pytest.raises(ValueError):  # DataFormatError is also a ValueError
        extract_indicators(t, i[:10], x)


def test_message_without_flight_id():
    t, i, x = good_arrays()
    with pytest.raises(DataFormatError, match=r"^flight: time_s, current_ma"):
        extract_indicators(t, i[:10], x)


def test_good_arrays_in_many_forms_are_accepted():
    t, i, x = good_arrays()
    a = velocity_gain_curve(list(t), list(i), list(x))
    b = velocity_gain_curve(t.astype(np.float32).astype(np.float64), i, x)
    c = velocity_gain_curve(t, i.astype(np.float32), x)  # converted to float64
    assert a.n_points == b.n_points == c.n_points > 0
    d = velocity_gain_curve(t[::-1][::-1], i[::2].repeat(2), x)  # non-contiguous views
    assert d.n_points > 0


def test_streaming_rejects_bad_chunks():
    t, i, x = good_arrays()
    ex = StreamingExtractor(flight_id=9)
    with pytest.raises(DataFormatError, match=r"flight 9.*same length"):
        ex.update(t, i[:-1], x)
    with pytest.raises(DataFormatError, match=r"flight 9.*'time_s' must be strictly increasing"):
        ex.update(np.r_[t[:5], t[3:]], np.r_[i[:5], i[3:]], np.r_[x[:5], x[3:]])
    with pytest.raises(DataFormatError, match=r"flight 9.*'current_ma'.*sample 4"):
        ex.update(t, np.where(np.arange(len(i)) == 4, np.nan, i), x)
    with pytest.raises(DataFormatError, match=r"flight 9.*one-dimensional"):
        ex.update(t.reshape(2, -1), i.reshape(2, -1), x.reshape(2, -1))
    assert ex.n_samples == 0


@pytest.mark.parametrize(
    ("field", "value", "allowed"),
    [
        ("bin_width_ma", 0.0, "a finite number > 0"),
        ("bin_width_ma", 0.07, "a divisor of the current range width"),
        ("bin_width_ma", float("nan"), "a finite number > 0"),
        ("current_range_ma", (5.0, -5.0), "a \\(low, high\\) pair .* with low < high"),
        ("current_range_ma", [-12.0, 12.0], "a \\(low, high\\) pair"),
        ("stroke_limits_mm", (0.0,), "None or a \\(low, high\\) pair"),
        ("diff_half_width", 0, "an integer in \\[1, 32\\]"),
        ("diff_half_width", 2.0, "an integer in \\[1, 32\\]"),
        ("diff_half_width", True, "an integer in \\[1, 32\\]"),
        ("max_frame_s", -1.0, "a finite number > 0"),
        ("end_stop_margin_mm", -0.1, "a finite number >= 0"),
        ("max_current_rate_ma_s", 0.0, "None or a finite number > 0"),
        ("idle_velocity_mm_s", 0.0, "a finite number > 0"),
        ("min_idle_points", 1, "an integer >= 2"),
        ("min_segment_points", "20", "an integer >= 2"),
        ("min_slope_change", 1.0, "a number in \\[0, 1\\)"),
        ("weight_cap", 0.5, "a finite number >= 1"),
        ("max_idle_ratio", -1.0, "a number >= 0"),
        ("max_breakpoint_interval_ma", 0.0, "a finite number > 0"),
        ("min_null_halfwidth_ma", -0.5, "a finite number >= 0"),
        ("coarse_grid_size", 100, "an integer in \\[16, 64\\]"),
    ],
)
def test_config_validation_message_template(field, value, allowed):
    pattern = (f"^The '{field}' parameter of ExtractionConfig must be {allowed}.*"
               f"Got .* instead\\.$")
    with pytest.raises(ParameterError, match=pattern):
        ExtractionConfig(**{field: value})


def test_config_is_frozen_and_records_itself():
    cfg = ExtractionConfig()
    with pytest.raises(AttributeError):
        cfg.bin_width_ma = 0.1
    assert cfg.to_dict()["bin_width_ma"] == 0.05
    assert ExtractionConfig(**cfg.to_dict()) == cfg
    assert cfg.n_bins == 480 and len(cfg.bin_edges_ma) == 481
    assert cfg.bin_centres_ma[0] == pytest.approx(-11.975)


def test_for_frame_rate():
    assert ExtractionConfig.for_frame_rate(100.0).diff_half_width == 2
    assert ExtractionConfig.for_frame_rate(10.0).diff_half_width == 1
    assert ExtractionConfig.for_frame_rate(400.0, bin_width_ma=0.1).diff_half_width == 8
    with pytest.raises(ParameterError, match="'rate_hz' parameter of ExtractionConfig.for_fr"):
        ExtractionConfig.for_frame_rate(0.0)
    with pytest.raises(ParameterError, match="'diff_half_width' parameter"):
        ExtractionConfig.for_frame_rate(100.0, diff_half_width=3)


def test_unknown_engine_and_on_error():
    t, i, x = good_arrays()
    with pytest.raises(ParameterError, match="'engine' parameter of velocity_gain_curve"):
        velocity_gain_curve(t, i, x, engine="cuda")
    with pytest.raises(ParameterError, match="'on_error' parameter of extract_table"):
        extract_table([], on_error="ignore")
    with pytest.raises(ParameterError, match="'engine' parameter of extract_table"):
        extract_table([], engine="fortran")
