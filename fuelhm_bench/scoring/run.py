"""A scored run (labels + decisions + healthy-training scores) and its per-flight table."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd

from fuelhm_bench.errors import DataFormatError, show_value
from fuelhm_bench.methods.decision import GUILT_SUM_TOLERANCE
from fuelhm_bench.methods.tables import DECISION_COLUMNS, GUILT_COLUMNS
from fuelhm_bench.scoring.config import ScoringConfig
from fuelhm_bench.taxonomy import MODE_IDS, UNKNOWN_MODE

__all__ = ["HEALTHY", "INTENSITY_COLUMNS", "LABEL_COLUMNS", "MULTIPLE", "NO_ALARM", "Run", "TIE", "UNKNOWN",
           "UNKNOWN_ONSET_COLUMN", "flight_table"]

INTENSITY_COLUMNS: tuple[str, ...] = tuple(f"intensity_{m}" for m in MODE_IDS)
MAX_INTENSITY_COLUMNS: tuple[str, ...] = tuple(f"max_intensity_{m}" for m in MODE_IDS)
ONSET_COLUMNS: tuple[str, ...] = tuple(f"onset_{m}" for m in MODE_IDS)
FRACTION_COLUMNS: tuple[str, ...] = tuple(f"fraction_{m}" for m in MODE_IDS)

#: Required columns of a labels table.
LABEL_COLUMNS: tuple[str, ...] = ("unit_id", "flight_index", *INTENSITY_COLUMNS,
                                  *MAX_INTENSITY_COLUMNS, *ONSET_COLUMNS)

#: ``true_mode`` of a flight without any active degradation.
HEALTHY = "healthy"
#: ``true_mode`` of a flight with several active degradations.
MULTIPLE = "multiple"
#: ``true_mode`` of a flight whose only fault is outside the seven modes (optional label columns
#: ``unknown_fault``, the effect id, and ``onset_unknown``, its onset flight or -1).
UNKNOWN = UNKNOWN_MODE
#: Optional label column: onset flight of the unit's fault outside the seven modes (-1: none).
UNKNOWN_ONSET_COLUMN = "onset_unknown"
#: ``predicted`` of a flight without alarm.
NO_ALARM = "no_alarm"
#: ``predicted`` of an alarmed flight whose largest guilt is shared by several modes.
TIE = "tie"

_KEYS = ["unit_id", "flight_index"]


@dataclass(frozen=True, eq=False)
class Run:
    """What the scorer needs from one evaluation of one method.

    Parameters
    ----------
    labels : pandas.DataFrame
        Ground truth, one row per evaluated flight: ``unit_id``,
        ``flight_index``, ``intensity_<mode>``, ``max_intensity_<mode>``,
        ``onset_<mode>`` (see docs/scoring.md). Never shown to the method.
    decisions : pandas.DataFrame
        The method's decisions for the same flights: ``unit_id``,
        ``flight_index``, ``score``, ``alarm``, ``guilt_<mode>`` (as returned by
        :func:`fuelhm_bench.methods.run_table`).
    healthy_scores : array-like of float
        The method's global scores on its *healthy training* flights (computed
        after ``fit``). Thresholds ``mu + A * sigma`` come from these only.
    name : str, default="run"
        Name used in reports.

    Raises
    ------
    DataFormatError
        When a table misses a column, holds invalid values, or the two tables do
        not cover the same (unit_id, flight_index) keys.
    """

    labels: pd.DataFrame
    decisions: pd.DataFrame
    healthy_scores: np.ndarray
    name: str = "run"

    def __post_init__(self) -> None:
        _check_labels(self.labels)
        _check_decisions(self.decisions)
        _check_same_keys(self.labels, self.decisions)
        scores = np.array(self.healthy_scores, dtype=np.float64, copy=True).ravel()
        if scores.size < 2 or not np.all(np.isfinite(scores)):
            raise DataFormatError(f"The 'healthy_scores' parameter of Run must hold at least 2 "
                                  f"finite scores. Got {scores.size} scores "
                                  f"({int((~np.isfinite(scores)).sum())} non-finite) instead.")
        scores.setflags(write=False)
        object.__setattr__(self, "healthy_scores", scores)


def _missing(table: pd.DataFrame, required: tuple[str, ...], what: str) -> None:
    if not isinstance(table, pd.DataFrame):
        raise DataFormatError(f"The '{what}' parameter of Run must be a pandas DataFrame. "
                              f"Got {type(table).__name__} instead.")
    missing = [c for c in required if c not in table.columns]
    if missing:
        raise DataFormatError(f"The '{what}' parameter of Run must have the columns "
                              f"{list(required)}. Missing {missing}.")
    if len(table) == 0:
        raise DataFormatError(f"The '{what}' parameter of Run must have at least one row. "
                              f"Got an empty table instead.")
    dup = table.duplicated(_KEYS)
    if dup.any():
        row = table.loc[dup, _KEYS].iloc[0]
        raise DataFormatError(f"The '{what}' parameter of Run must have one row per (unit_id, "
                              f"flight_index). Got flight {row['flight_index']} of unit "
                              f"{show_value(row['unit_id'])} twice instead.")


def _first_bad(table: pd.DataFrame, mask: np.ndarray) -> str:
    row = table.loc[mask, _KEYS].iloc[0]
    return f"flight {row['flight_index']} of unit {show_value(row['unit_id'])}"


def _check_labels(labels: pd.DataFrame) -> None:
    _missing(labels, LABEL_COLUMNS, "labels")
    inten = labels[list(INTENSITY_COLUMNS)].to_numpy(dtype=float)
    bad = ~np.isfinite(inten) | (inten < 0)
    if bad.any():
        raise DataFormatError(f"The 'labels' parameter of Run must have finite intensities >= 0. "
                              f"Got an invalid intensity at {_first_bad(labels, bad.any(axis=1))} "
                              f"instead.")
    onset = labels[list(ONSET_COLUMNS)].to_numpy(dtype=float)
    for j, mode in enumerate(MODE_IDS):
        per_unit = pd.Series(onset[:, j]).groupby(labels["unit_id"].to_numpy()).nunique()
        if (per_unit > 1).any():
            raise DataFormatError(f"The 'labels' parameter of Run must have one onset_{mode} per "
                                  f"unit. Got several for unit {per_unit.index[per_unit > 1][0]!r} "
                                  f"instead.")
        active_without_onset = (inten[:, j] > 0) & (onset[:, j] < 0)
        if active_without_onset.any():
            raise DataFormatError(f"The 'labels' parameter of Run must give onset_{mode} >= 0 when "
                                  f"intensity_{mode} > 0. Got onset -1 at "
                                  f"{_first_bad(labels, active_without_onset)} instead.")


def _check_decisions(decisions: pd.DataFrame) -> None:
    _missing(decisions, DECISION_COLUMNS, "decisions")
    if not pd.api.types.is_bool_dtype(decisions["alarm"]):
        raise DataFormatError(f"The 'decisions' parameter of Run must have a bool 'alarm' column. "
                              f"Got dtype {decisions['alarm'].dtype} instead.")
    score = decisions["score"].to_numpy(dtype=float)
    if not np.all(np.isfinite(score)):
        raise DataFormatError(f"The 'decisions' parameter of Run must have finite scores. Got a "
                              f"non-finite score at {_first_bad(decisions, ~np.isfinite(score))} "
                              f"instead.")
    guilt = decisions[list(GUILT_COLUMNS)].to_numpy(dtype=float)
    bad = (~np.isfinite(guilt) | (guilt < 0)).any(axis=1)
    alarm = decisions["alarm"].to_numpy(dtype=bool)
    bad |= alarm & (np.abs(guilt.sum(axis=1) - 1.0) > GUILT_SUM_TOLERANCE)
    if bad.any():
        raise DataFormatError(f"The 'decisions' parameter of Run must have guilt >= 0 summing to 1 "
                              f"on alarms. Got an invalid guilt at {_first_bad(decisions, bad)} "
                              f"instead.")


def _check_same_keys(labels: pd.DataFrame, decisions: pd.DataFrame) -> None:
    try:
        both = labels[_KEYS].merge(decisions[_KEYS], on=_KEYS, how="outer", indicator=True)
    except ValueError as exc:
        raise DataFormatError(f"The 'decisions' and 'labels' parameters of Run must use the same "
                              f"key types. Got unit_id {labels['unit_id'].dtype} and "
                              f"{decisions['unit_id'].dtype} instead ({exc}).") from exc
    for side, other in (("left_only", "decisions"), ("right_only", "labels")):
        extra = both[both["_merge"] == side]
        if len(extra):
            row = extra.iloc[0]
            raise DataFormatError(f"The 'decisions' and 'labels' parameters of Run must cover the "
                                  f"same flights. Got {len(extra)} flight(s) missing from "
                                  f"{other}, e.g. flight {row['flight_index']} of unit "
                                  f"{show_value(row['unit_id'])}.")


def _reference_max(labels: pd.DataFrame, config: ScoringConfig) -> np.ndarray:
    n = len(labels)
    if config.reference_max is None:
        return labels[list(MAX_INTENSITY_COLUMNS)].to_numpy(dtype=float)
    return np.array([[config.reference_max.get(m, np.nan) for m in MODE_IDS]] * n).reshape(
        n, len(MODE_IDS))


def flight_table(run: Run, config: ScoringConfig | None = None) -> pd.DataFrame:
    """One row per evaluated flight with its truth category and the method's decision.

    Parameters
    ----------
    run : Run
        The run to score.
    config : ScoringConfig or None, default=None
        Scoring configuration (None = defaults).

    Returns
    -------
    pandas.DataFrame
        Sorted by unit then flight index, columns:

        ``unit_id, flight_index``
            Keys.
        ``true_mode``
            ``"healthy"`` (all intensities 0), the mode id of the single active
            degradation, ``"unknown"`` (the only fault is outside the seven
            modes: labels with ``onset_unknown`` >= 0, from that flight on;
            fraction 1) or ``"multiple"``.
        ``fraction``
            Intensity / reference maximal intensity of the active mode (the
            largest fraction for ``"multiple"``, 0 for healthy flights).
        ``band``
            ``"healthy"`` or the name of the intensity band of ``fraction``.
        ``detectable``, ``incipient``
            Faulty with ``fraction >= detectable_fraction``, resp. below it.
        ``score, alarm, guilt_<mode>``
            The decision.
        ``predicted``
            ``"no_alarm"``, the mode with the unique largest guilt, or ``"tie"``.
        ``fraction_<mode>, onset_<mode>``
            Per-mode fraction of the reference maximal intensity and onset.

    Raises
    ------
    DataFormatError
        When a degraded flight's reference maximal intensity is not > 0.
    """
    config = ScoringConfig() if config is None else config
    labels = run.labels.sort_values(_KEYS, kind="stable")
    extra = [UNKNOWN_ONSET_COLUMN] if UNKNOWN_ONSET_COLUMN in labels.columns else []
    merged = labels[[*LABEL_COLUMNS, *extra]].merge(run.decisions[list(DECISION_COLUMNS)], on=_KEYS,
                                            how="left", validate="one_to_one")
    inten = merged[list(INTENSITY_COLUMNS)].to_numpy(dtype=float)
    ref = _reference_max(merged, config)
    active = inten > 0
    bad = active & ~(np.isfinite(ref) & (ref > 0))
    if bad.any():
        i, j = np.argwhere(bad)[0]
        source = ("labels' max_intensity" if config.reference_max is None
                  else "ScoringConfig.reference_max")
        raise DataFormatError(f"The reference maximal intensity of mode {MODE_IDS[j]!r} must be "
                              f"> 0 for degraded flights. Got {ref[i, j]!r} from {source} at "
                              f"flight {merged['flight_index'].iloc[i]} of unit "
                              f"{merged['unit_id'].iloc[i]!r} instead.")
    with np.errstate(divide="ignore", invalid="ignore"):
        frac = np.where(active, inten / np.where(active, ref, 1.0), 0.0)
    n_active = active.sum(axis=1)
    fraction = frac.max(axis=1)
    mode_names = np.array(MODE_IDS, dtype=object)
    true_mode = np.where(n_active == 0, HEALTHY,
                         np.where(n_active == 1, mode_names[frac.argmax(axis=1)], MULTIPLE))
    if extra:  # a fault outside the seven modes: at full "intensity" from its onset (a step)
        onset_u = merged[UNKNOWN_ONSET_COLUMN].to_numpy(dtype=float)
        unknown = (onset_u >= 0) & (merged["flight_index"].to_numpy() >= onset_u)
        true_mode = np.where(unknown, np.where(n_active == 0, UNKNOWN, MULTIPLE), true_mode)
        fraction = np.where(unknown, 1.0, fraction)
        n_active = n_active + unknown
    band_idx = np.searchsorted(np.array(config.band_edges), fraction, side="left")
    band = np.where(n_active == 0, HEALTHY, np.array(config.band_names, dtype=object)[band_idx])
    faulty = n_active > 0
    detectable = faulty & (fraction >= config.detectable_fraction)
    guilt = merged[list(GUILT_COLUMNS)].to_numpy(dtype=float)
    alarm = merged["alarm"].to_numpy(dtype=bool)
    top = guilt.max(axis=1, keepdims=True)
    unique_top = (guilt == top).sum(axis=1) == 1
    predicted = np.where(~alarm, NO_ALARM,
                         np.where(unique_top, mode_names[guilt.argmax(axis=1)], TIE))
    out: dict[str, Any] = {
        "unit_id": merged["unit_id"].to_numpy(),
        "flight_index": merged["flight_index"].to_numpy(dtype=np.int64),
        "true_mode": true_mode.astype(str),
        "fraction": fraction,
        "band": band.astype(str),
        "detectable": detectable,
        "incipient": faulty & ~detectable,
        "score": merged["score"].to_numpy(dtype=float),
        "alarm": alarm,
        "predicted": predicted.astype(str),
    }
    out.update({c: guilt[:, j] for j, c in enumerate(GUILT_COLUMNS)})
    out.update({c: frac[:, j] for j, c in enumerate(FRACTION_COLUMNS)})
    out.update({c: merged[c].to_numpy(dtype=np.int64) for c in ONSET_COLUMNS})
    return pd.DataFrame(out)
