"""Checks of the raw flight arrays, with messages that name the flight and the problem.

Every malformed input the extractors can receive is turned into a
:class:`~fuelhm_bench.errors.DataFormatError` here, before any NumPy arithmetic runs on it, so a
user never sees a NumPy traceback for bad data.
"""

from __future__ import annotations

import numpy as np

from fuelhm_bench.errors import DataFormatError

ARRAY_NAMES: tuple[str, str, str] = ("time_s", "current_ma", "position_mm")


def flight_label(flight_id: object) -> str:
    """Return ``"flight <id>"`` (or ``"flight"`` when the id is unknown) for messages."""
    return "flight" if flight_id is None else f"flight {flight_id!r}"


def as_1d_float(value: object, name: str, flight_id: object) -> np.ndarray:
    """Convert one input to a contiguous 1-D float64 array.

    Parameters
    ----------
    value : array_like
        The input (a scalar is taken as one sample).
    name : str
        Array name for messages (``"time_s"``, ``"current_ma"`` or ``"position_mm"``).
    flight_id : object
        Flight identifier for messages (may be None).

    Returns
    -------
    numpy.ndarray
        1-D float64, C-contiguous (no copy when the input already is).

    Raises
    ------
    DataFormatError
        If the input is not numeric or has more than one dimension.
    """
    try:
        arr = np.asarray(value)
        if arr.dtype.kind not in "biuf":
            raise TypeError(f"dtype {arr.dtype}")
        arr = np.ascontiguousarray(arr, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise DataFormatError(
            f"{flight_label(flight_id)}: '{name}' must be an array of real numbers; "
            f"got {type(value).__name__} ({exc})."
        ) from None
    if arr.ndim == 0:
        arr = arr.reshape(1)
    if arr.ndim != 1:
        raise DataFormatError(
            f"{flight_label(flight_id)}: '{name}' must be one-dimensional; got shape {arr.shape}."
        )
    return arr


def check_lengths(arrays: tuple[np.ndarray, ...], flight_id: object) -> None:
    """Raise :class:`DataFormatError` unless the three arrays have the same length."""
    lengths = {name: len(a) for name, a in zip(ARRAY_NAMES, arrays)}
    if len(set(lengths.values())) != 1:
        detail = ", ".join(f"{k}={v}" for k, v in lengths.items())
        raise DataFormatError(
            f"{flight_label(flight_id)}: time_s, current_ma and position_mm must have the same "
            f"length; got {detail}."
        )


def nonfinite_message(name: str, index: int, value: float, n_bad: int | None,
                      flight_id: object) -> str:
    """Message for a NaN / infinite value in array ``name`` at ``index``."""
    more = "" if not n_bad or n_bad <= 1 else f" ({n_bad - 1} more non-finite value(s))"
    return (
        f"{flight_label(flight_id)}: '{name}' contains a non-finite value ({value!r}) at "
        f"sample {index}{more}; remove or interpolate such samples before extraction."
    )


def time_order_message(index: int, previous: float, current: float, flight_id: object) -> str:
    """Message for a time stamp that does not strictly increase at ``index``."""
    return (
        f"{flight_label(flight_id)}: 'time_s' must be strictly increasing; sample {index} has "
        f"t={current!r} s after t={previous!r} s (repeated or out-of-order time stamp)."
    )


def too_short_message(n_samples: int, window: int, flight_id: object) -> str:
    """Message for a flight shorter than one differentiator window."""
    return (
        f"{flight_label(flight_id)}: {n_samples} sample(s); indicator extraction needs at least "
        f"{window} (one differentiator window of 2*diff_half_width+1 samples)."
    )


def constant_current_message(value: float, n_samples: int, flight_id: object) -> str:
    """Message for a flight whose control current never changes."""
    return (
        f"{flight_label(flight_id)}: 'current_ma' is constant ({value!r} mA) over all "
        f"{n_samples} samples; a velocity-gain curve needs a varying control current."
    )


def validate_n2(n2_pct: object, n_samples: int, flight_id: object) -> np.ndarray | None:
    """Convert and check the optional engine HP speed N2 of a flight (or chunk).

    Parameters
    ----------
    n2_pct : array_like or None
        N2 in percent, one value per sample; None when the flight does not record it. NaN marks
        a missing sample (it joins no supply-pressure band); infinite values are refused.
    n_samples : int
        Number of samples of the other arrays.
    flight_id : object
        Flight identifier for messages.

    Returns
    -------
    numpy.ndarray or None
        Contiguous float64 N2 (%), or None.

    Raises
    ------
    DataFormatError
        Non-numeric or multi-dimensional input, a length other than ``n_samples``, or an
        infinite value.
    """
    if n2_pct is None:
        return None
    n2 = as_1d_float(n2_pct, "n2_pct", flight_id)
    if len(n2) != n_samples:
        raise DataFormatError(
            f"{flight_label(flight_id)}: 'n2_pct' must have one value per sample ({n_samples}); "
            f"got {len(n2)}."
        )
    bad = np.isinf(n2)
    if bad.any():
        idx = int(np.argmax(bad))
        raise DataFormatError(
            f"{flight_label(flight_id)}: 'n2_pct' contains an infinite value ({float(n2[idx])!r}) at "
            f"sample {idx}; use NaN for a missing N2 sample."
        )
    return n2


def validate_flight(time_s: object, current_ma: object, position_mm: object, *,
                    window: int, flight_id: object = None
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Convert and check the three arrays of a whole recorded flight.

    Parameters
    ----------
    time_s, current_ma, position_mm : array_like
        Time stamps (s), control current (mA), LVDT position (mm), one value per sample.
    window : int
        Differentiator window length (samples); shorter flights are rejected.
    flight_id : object, optional
        Flight identifier used in messages.

    Returns
    -------
    tuple of numpy.ndarray
        ``(t, i, x)`` as contiguous float64 arrays.

    Raises
    ------
    DataFormatError
        Non-numeric or multi-dimensional input, mismatched lengths, fewer than ``window``
        samples, NaN or infinite values, time not strictly increasing, or constant current.
    """
    arrays = tuple(
        as_1d_float(v, name, flight_id)
        for v, name in zip((time_s, current_ma, position_mm), ARRAY_NAMES)
    )
    check_lengths(arrays, flight_id)
    n = len(arrays[0])
    if n < window:
        raise DataFormatError(too_short_message(n, window, flight_id))
    from fuelhm_bench.indicators.kernel import check_chunk  # numba: imported when first needed

    t, i, x = arrays
    # One compiled pass (no temporaries) finds whether anything is wrong; only then do the
    # NumPy checks below run, to name the first problem of each kind in the message.
    if check_chunk(t, i, x, 0.0, False)[0] != 0:
        _raise_first_problem(arrays, flight_id)
    if i.min() == i.max():
        raise DataFormatError(constant_current_message(float(i[0]), n, flight_id))
    return t, i, x


def _raise_first_problem(arrays: tuple[np.ndarray, ...], flight_id: object) -> None:
    """Raise the :class:`DataFormatError` of a flight's first non-finite value or time step that does not
    increase (non-finite values first, array by array)."""
    for arr, name in zip(arrays, ARRAY_NAMES):
        bad = ~np.isfinite(arr)
        if bad.any():
            idx = int(np.argmax(bad))
            raise DataFormatError(
                nonfinite_message(name, idx, float(arr[idx]), int(bad.sum()), flight_id)
            )
    t = arrays[0]
    steps = np.diff(t)
    if not (steps > 0).all():
        idx = int(np.argmax(~(steps > 0))) + 1
        raise DataFormatError(time_order_message(idx, float(t[idx - 1]), float(t[idx]), flight_id))
    raise AssertionError("unreachable: the compiled check found a problem the NumPy checks do not")
