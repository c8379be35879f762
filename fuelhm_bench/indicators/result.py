"""The output of an extraction: ten indicator values, their validity and the reasons."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from fuelhm_bench.errors import ParameterError
from fuelhm_bench.indicators.fit import CurveFit
from fuelhm_bench.taxonomy import EXTENDED_INDICATOR_NAMES, INDICATOR_NAMES, INDICATOR_UNITS


def table_columns(with_unit_id: bool = True, *, extended: bool = True) -> list[str]:
    """Column names of the indicator table (the contract of :func:`extract_table`).

    Parameters
    ----------
    with_unit_id : bool, default=True
        Whether the ``unit_id`` column is present.
    extended : bool, default=True
        Whether the extended indicators (:data:`~fuelhm_bench.taxonomy.EXTENDED_INDICATOR_NAMES`)
        and their ``<name>_valid`` flags are present.

    Returns
    -------
    list of str
        ``flight_id``, [``unit_id``], the ten indicators, ``<name>_valid`` for the ten,
        [the extended indicators, ``<name>_valid`` for them], ``n_points``, ``quality_reason``.
    """
    cols = ["flight_id"] + (["unit_id"] if with_unit_id else [])
    cols += list(INDICATOR_NAMES)
    cols += [f"{name}_valid" for name in INDICATOR_NAMES]
    if extended:
        cols += list(EXTENDED_INDICATOR_NAMES)
        cols += [f"{name}_valid" for name in EXTENDED_INDICATOR_NAMES]
    return cols + ["n_points", "quality_reason"]


@dataclass(frozen=True)
class IndicatorResult:
    """Indicators of one flight (paper Table I), with a validity flag for each.

    Parameters
    ----------
    values : dict of str to float
        Indicator values keyed by :data:`~fuelhm_bench.taxonomy.INDICATOR_NAMES`, in the units
        of :data:`~fuelhm_bench.taxonomy.INDICATOR_UNITS` (mA, mm/s, mm/s/mA). NaN when the
        indicator is not valid.
    valid : dict of str to bool
        Whether each indicator is supported by the flight's data.
    reasons : tuple of str
        One human-readable reason per failed check, e.g.
        ``"G_out: 3 points in the outlet segment (above X2), need >= 20"``; empty when all ten
        indicators are valid.
    n_points : int
        Number of samples that entered the velocity-gain curve.
    fit : CurveFit or None, default=None
        The piecewise-linear fit the curve indicators come from (for plots and diagnostics).
    n_idle : int, default=0
        Number of idle samples ``I0`` and ``Hys0`` were computed from.
    extended_values : dict of str to float or None, default=None
        The extended indicators (:mod:`fuelhm_bench.indicators.extended`) keyed by
        :data:`~fuelhm_bench.taxonomy.EXTENDED_INDICATOR_NAMES`; None: all invalid.
    extended_valid : dict of str to bool or None, default=None
        Their validity flags.
    extended_reasons : tuple of str, default=()
        Why extended indicators are invalid (kept out of ``reasons`` / ``quality_reason``, which
        describe the paper's ten).

    Examples
    --------
    >>> r = IndicatorResult.invalid(("no data",))
    >>> r.to_row()["X1_valid"], r.to_row()["quality_reason"]
    (False, 'no data')
    """

    values: dict[str, float]
    valid: dict[str, bool]
    reasons: tuple[str, ...]
    n_points: int
    fit: CurveFit | None = field(default=None, compare=False)
    n_idle: int = 0
    extended_values: dict | None = None
    extended_valid: dict | None = None
    extended_reasons: tuple = ()

    def __post_init__(self) -> None:
        if set(self.values) != set(INDICATOR_NAMES) or set(self.valid) != set(INDICATOR_NAMES):
            raise ParameterError(
                f"The 'values' and 'valid' parameters of IndicatorResult must have one entry "
                f"per indicator name {INDICATOR_NAMES}. Got {sorted(self.values)} and "
                f"{sorted(self.valid)} instead."
            )
        values = {name: float(self.values[name]) for name in INDICATOR_NAMES}
        valid = {name: bool(self.valid[name]) for name in INDICATOR_NAMES}
        for name in INDICATOR_NAMES:
            if not valid[name]:
                values[name] = math.nan
            elif not math.isfinite(values[name]):
                raise ParameterError(
                    f"The 'values' parameter of IndicatorResult must hold a finite value for "
                    f"each valid indicator. Got {name}={values[name]!r} flagged valid instead."
                )
        object.__setattr__(self, "values", values)
        object.__setattr__(self, "valid", valid)
        object.__setattr__(self, "reasons", tuple(str(r) for r in self.reasons))
        object.__setattr__(self, "n_points", int(self.n_points))
        object.__setattr__(self, "n_idle", int(self.n_idle))
        ev = self.extended_values or {}
        ef = self.extended_valid or {}
        unknown = sorted(set(ev) - set(EXTENDED_INDICATOR_NAMES)) + sorted(set(ef) - set(EXTENDED_INDICATOR_NAMES))
        if unknown:
            raise ParameterError(
                f"The 'extended_values' and 'extended_valid' parameters of IndicatorResult must be keyed by "
                f"{EXTENDED_INDICATOR_NAMES}. Got unknown key(s) {unknown} instead."
            )
        ext_valid = {name: bool(ef.get(name, False)) for name in EXTENDED_INDICATOR_NAMES}
        ext_values = {name: float(ev.get(name, math.nan)) if ext_valid[name] else math.nan
                      for name in EXTENDED_INDICATOR_NAMES}
        bad = [n for n in EXTENDED_INDICATOR_NAMES if ext_valid[n] and not math.isfinite(ext_values[n])]
        if bad:
            raise ParameterError(
                f"The 'extended_values' parameter of IndicatorResult must hold a finite value for each valid "
                f"indicator. Got {bad[0]}={ext_values[bad[0]]!r} flagged valid instead."
            )
        object.__setattr__(self, "extended_values", ext_values)
        object.__setattr__(self, "extended_valid", ext_valid)
        object.__setattr__(self, "extended_reasons", tuple(str(r) for r in self.extended_reasons))

    @classmethod
    def invalid(cls, reasons: tuple[str, ...], n_points: int = 0) -> IndicatorResult:
        """A result with every indicator invalid (NaN) for the given reasons."""
        return cls(values={name: math.nan for name in INDICATOR_NAMES},
                   valid={name: False for name in INDICATOR_NAMES},
                   reasons=tuple(reasons), n_points=n_points)

    @property
    def all_valid(self) -> bool:
        """True when all ten indicators are valid."""
        return all(self.valid.values())

    @property
    def quality_reason(self) -> str:
        """The reasons joined with ``"; "`` (empty string when all indicators are valid)."""
        return "; ".join(self.reasons)

    @staticmethod
    def units() -> dict[str, str]:
        """Units of the indicators (:data:`~fuelhm_bench.taxonomy.INDICATOR_UNITS`)."""
        return dict(INDICATOR_UNITS)

    def to_row(self) -> dict[str, object]:
        """Flat dict with the table columns (without ``flight_id`` / ``unit_id``).

        Returns
        -------
        dict
            The ten indicators (float, NaN when invalid), ``<name>_valid`` (bool), the extended
            indicators and their ``<name>_valid``, ``n_points`` (int) and ``quality_reason`` (str,
            ``""`` when all ten are valid).
        """
        row: dict[str, object] = {name: self.values[name] for name in INDICATOR_NAMES}
        row.update({f"{name}_valid": self.valid[name] for name in INDICATOR_NAMES})
        row.update({name: self.extended_values[name] for name in EXTENDED_INDICATOR_NAMES})
        row.update({f"{name}_valid": self.extended_valid[name] for name in EXTENDED_INDICATOR_NAMES})
        row["n_points"] = self.n_points
        row["quality_reason"] = self.quality_reason
        return row
