"""The benchmark's vocabulary: degradation modes, indicators, optional effects.

These names are part of the public interface (file columns, YAML keys, CLI
arguments, method outputs); they never change within a major version.
"""

from __future__ import annotations

#: The seven degradation modes of the paper's Table III, in the paper's order.
MODE_IDS: tuple[str, ...] = (
    "filter_contamination",
    "null_bias_drift",
    "backlash",
    "spool_friction",
    "radial_clearance",
    "internal_leakage",
    "diaphragm_clogging",
)

#: The ten indicators of the paper's Table I, in the paper's order.
INDICATOR_NAMES: tuple[str, ...] = (
    "X1", "Y1", "X2", "Y2", "Inb", "I0", "Hys0", "G_in", "G_out", "G_null",
)

#: Units of the indicators at the data boundary (currents in mA, velocities in
#: mm/s; a gain in mm/s per mA equals the same number in m/s per A).
INDICATOR_UNITS: dict[str, str] = {
    "X1": "mA", "Y1": "mm/s", "X2": "mA", "Y2": "mm/s", "Inb": "mA", "I0": "mA",
    "Hys0": "mA", "G_in": "mm/s/mA", "G_out": "mm/s/mA", "G_null": "mm/s/mA",
}

#: Model-free indicators beyond the paper (docs/indicators.md, "Extended indicators"), computed
#: by the same extractors from the same binned velocity-gain curve. Not used by the paper's
#: method unless asked for; exposed as extra columns with ``<name>_valid`` flags.
EXTENDED_INDICATOR_NAMES: tuple[str, ...] = (
    "V_in1", "V_out1", "V_in3", "V_out3", "V_in7", "V_out7", "Vsd_null", "Idle_frac",
    "Hys_lo", "Hys_hi", "I0_slope",
)

#: Units of the extended indicators (velocities in mm/s; ``Idle_frac`` is a fraction).
EXTENDED_INDICATOR_UNITS: dict[str, str] = {
    "V_in1": "mm/s", "V_out1": "mm/s", "V_in3": "mm/s", "V_out3": "mm/s", "V_in7": "mm/s",
    "V_out7": "mm/s", "Vsd_null": "mm/s", "Idle_frac": "1",
    "Hys_lo": "mA", "Hys_hi": "mA", "I0_slope": "mA/%",
}

#: The paper's ten followed by the extended indicators: every name a table may carry.
ALL_INDICATOR_NAMES: tuple[str, ...] = INDICATOR_NAMES + EXTENDED_INDICATOR_NAMES

#: The columns of what a method sees of a flight, in order: an observation row in ``decide`` and
#: every row of the tables given to ``fit`` (docs/methods.md section 2); the checks' data have them too.
OBSERVATION_COLUMNS: tuple[str, ...] = (
    "flight_id", "unit_id", "flight_index", *INDICATOR_NAMES, *(f"{n}_valid" for n in INDICATOR_NAMES),
    *EXTENDED_INDICATOR_NAMES, *(f"{n}_valid" for n in EXTENDED_INDICATOR_NAMES))

#: True mode of a fault outside the seven modes (a scenario's ``unknown_faults``): detection counts
#: it, and a method diagnoses it right only by naming no single mode (docs/scoring.md).
UNKNOWN_MODE: str = "unknown"

#: Optional physical effects a nominal model omits (docs/physics.md §7 Optional effects).
EFFECT_IDS: tuple[str, ...] = (
    "spool_overlap",
    "spool_flow_force",
    "rod_friction",
    "lvdt_lag",
    "load_stiffness",
    "current_driver_lag",
    "torque_motor_hysteresis",
    "viscosity_temperature",
)
