"""``FuelHM/ActuationLoop-v3``: the health monitoring of one actuation loop, flight by flight."""

from __future__ import annotations

import dataclasses
import math
import os
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.error import ResetNeeded

from fuelhm_bench.envs._validation import did_you_mean, reject_unknown
from fuelhm_bench.datasets.cache import KnowledgeSize, resolve_scenario, surrogate_knowledge
from fuelhm_bench.envs.surrogate import SurrogateModel
from fuelhm_bench.errors import DataFormatError, ParameterError
from fuelhm_bench.flights.fleet import build_units, mission_rng, noise_rng, rng_for, unit_rng
from fuelhm_bench.flights.schedule import UnitSchedule, draw_unit_schedule, draw_unknown_fault
from fuelhm_bench.taxonomy import EXTENDED_INDICATOR_NAMES, INDICATOR_NAMES, MODE_IDS

__all__ = ["ActuationLoopEnv", "EXTENDED_INDICATOR_BOUNDS", "FIDELITIES", "INDICATOR_BOUNDS", "RAW_BOUNDS"]

#: Simulation fidelities of the environment.
FIDELITIES: tuple[str, ...] = ("physics", "surrogate")

#: Bounds of the ``"indicators"`` observation, per indicator, in ``INDICATOR_UNITS``
#: (currents in mA inside the extraction's +/-12 mA current bins; velocities in mm/s;
#: gains in mm/s/mA). Values outside (never seen in the shipped scenarios) are clipped.
INDICATOR_BOUNDS: dict[str, tuple[float, float]] = {
    "X1": (-12.0, 12.0), "Y1": (-1000.0, 1000.0), "X2": (-12.0, 12.0), "Y2": (-1000.0, 1000.0),
    "Inb": (-12.0, 12.0), "I0": (-12.0, 12.0), "Hys0": (0.0, 12.0),
    "G_in": (-1000.0, 1000.0), "G_out": (-1000.0, 1000.0), "G_null": (-1000.0, 1000.0),
}

#: Bounds of the ``"extended"`` observation, per extended indicator, in ``EXTENDED_INDICATOR_UNITS``
#: (velocities in mm/s, ``Idle_frac`` a fraction, ``Hys_lo``/``Hys_hi`` in mA, ``I0_slope`` in
#: mA per % N2: at most 24 mA over the 5 % minimum band separation). Values outside are clipped.
EXTENDED_INDICATOR_BOUNDS: dict[str, tuple[float, float]] = {
    "V_in1": (-1000.0, 1000.0), "V_out1": (-1000.0, 1000.0), "V_in3": (-1000.0, 1000.0),
    "V_out3": (-1000.0, 1000.0), "V_in7": (-1000.0, 1000.0), "V_out7": (-1000.0, 1000.0),
    "Vsd_null": (0.0, 1000.0), "Idle_frac": (0.0, 1.0), "Hys_lo": (0.0, 12.0), "Hys_hi": (0.0, 12.0),
    "I0_slope": (-5.0, 5.0),
}

#: Bounds of the ``"raw"`` observation rows: control current [mA] and LVDT position [mm].
RAW_BOUNDS: dict[str, tuple[float, float]] = {"current_mA": (-50.0, 50.0), "position_mm": (-20.0, 80.0)}

_STREAM_SURROGATE = 20  # fleet streams are 0-2, DOE streams 10-12
_N_MODES = len(MODE_IDS)
#: Bit of the unit's fault outside the seven modes in the per-flight bitmasks (after the modes' bits).
_UNKNOWN_BIT = 1 << _N_MODES
_ALL = (1 << (_N_MODES + 1)) - 1
_BITS = np.array([1 << j for j in range(_N_MODES)], dtype=np.int64)
_LOW = np.array([INDICATOR_BOUNDS[n][0] for n in INDICATOR_NAMES], dtype=np.float32)
_HIGH = np.array([INDICATOR_BOUNDS[n][1] for n in INDICATOR_NAMES], dtype=np.float32)
_XLOW = np.array([EXTENDED_INDICATOR_BOUNDS[n][0] for n in EXTENDED_INDICATOR_NAMES], dtype=np.float32)
_XHIGH = np.array([EXTENDED_INDICATOR_BOUNDS[n][1] for n in EXTENDED_INDICATOR_NAMES], dtype=np.float32)
_N_EXT = len(EXTENDED_INDICATOR_NAMES)
_N_IND = len(INDICATOR_NAMES)
_NO_ONSET = np.full(_N_MODES, -1, dtype=np.int64)
_OBS_KEYS = ("indicators", "valid", "extended", "extended_valid")
# the ten, then the extended; float64 (exact) so that clipping float64 draws casts nothing
_OBS_LOW = np.concatenate([_LOW, _XLOW]).astype(np.float64)
_OBS_HIGH = np.concatenate([_HIGH, _XHIGH]).astype(np.float64)


def _ufunc_clip():
    """The ufunc ``numpy.clip`` ends in (numpy >= 2), else ``numpy.clip``: the same values without its Python layers."""
    return getattr(getattr(getattr(np, "_core", None), "umath", None), "clip", np.clip)


_clip = _ufunc_clip()
_ARGUMENTS = ("scenario", "fidelity", "maintenance", "drifted", "flight_minutes", "raw", "raw_samples",
              "knowledge", "knowledge_size", "cache_dir", "render_mode")
_OPTIONS = ("unit", "evaluation", "raw_flight")

#: Signals of the full-rate flight in ``info["raw_flight"]`` (reset option ``raw_flight``): name -> unit.
RAW_FLIGHT_SIGNALS: dict[str, str] = {"time_s": "s", "current_mA": "mA", "position_mm": "mm",
                                      "demand_mm": "mm", "n2_pct": "%"}


def _observation_arrays(rows) -> dict[str, np.ndarray]:
    """Observation arrays of indicator rows (a table or a dict of columns): values 0 where invalid, clipped.

    Returns
    -------
    dict
        ``"indicators"`` (n, 10) and ``"extended"`` (n, 11) float32, ``"valid"`` and
        ``"extended_valid"`` int8.
    """
    out = {}
    for key, flag, names, low, high in (("indicators", "valid", INDICATOR_NAMES, _LOW, _HIGH),
                                        ("extended", "extended_valid", EXTENDED_INDICATOR_NAMES, _XLOW, _XHIGH)):
        valid = np.column_stack([np.asarray(rows[f"{n}_valid"], dtype=bool) for n in names])
        values = np.column_stack([np.asarray(rows[n], dtype=np.float64) for n in names])
        valid &= np.isfinite(values)
        out[key] = np.clip(np.where(valid, values, 0.0), low, high).astype(np.float32)
        out[flag] = valid.astype(np.int8)
    return out


def _bitmask(flags: np.ndarray, extra: np.ndarray | None = None) -> list[int]:
    """Row-wise bitmask (bit j = column j) of a boolean matrix, or-ed with ``extra`` (int64 per row), as Python ints."""
    bits = flags.astype(np.int64) @ _BITS
    if extra is not None:
        bits |= extra
    return bits.tolist()


class ActuationLoopEnv(gym.Env):
    """Health monitoring of a fuel-system actuation loop: one episode is one unit's life, one step one flight.

    ## Description

    A unit (servovalve + cylinder + LVDT in the FADEC's position loop) of a
    scenario's scored fleet flies ``fleet.flights_per_unit`` flights while its
    degradations (paper Table III) start and grow according to the scenario's
    schedule. After each flight the on-board computer extracts the ten
    indicators of the paper's Table I from the velocity-gain curve; the agent
    sees them and decides whether to remove the unit for maintenance (alarm)
    and which mode it blames (guilt). Rewards are the scenario's costs
    (``costs`` section, kUSD). With ``fidelity="physics"`` every flight is
    simulated (numba integrator, the scenario's truth model with its hidden
    effects and drift) and the indicators are extracted from the recorded
    current and position, exactly as :func:`fuelhm_bench.datasets.fleet_indicators`
    does; with ``fidelity="surrogate"`` they are drawn from a law learnt on
    physics flights of the scored fleet's model (a Gaussian unit effect,
    resampled flight-to-flight residuals with their invalid indicators, and the
    per-unit, per-intensity responses of a design of experiments, and for each of
    the scenario's faults outside the seven modes its full-strength response from
    design-of-experiments flights with that fault, added from the fault's onset:
    :class:`~fuelhm_bench.envs.surrogate.SurrogateModel`; inputs from
    :func:`~fuelhm_bench.datasets.cache.surrogate_knowledge`, cached), thousands of
    times faster.

    ## Action Space

    ``Dict({"alarm": Discrete(2), "guilt": Box(0, 1, (7,), float32)})``

    | key     | space               | meaning                                                        |
    |---------|---------------------|----------------------------------------------------------------|
    | alarm   | Discrete(2)         | 1: remove the unit for maintenance after this flight; 0: keep it flying |
    | guilt   | Box(0, 1, (7,))     | guilt of each mode of ``MODE_IDS`` (filter_contamination, null_bias_drift, backlash, spool_friction, radial_clearance, internal_leakage, diaphragm_clogging) |

    The alarm is the only decision that changes the world (reward and, with
    ``maintenance=True``, the unit), so it is a discrete choice an agent can
    learn directly; guilt mirrors :class:`fuelhm_bench.methods.Decision`
    (a probability per mode, the paper's collinearity guilt) so that a method
    of the common interface maps onto an action without loss. A Box cannot
    say "sums to 1": the environment only requires each entry in [0, 1]; the
    runner (:mod:`fuelhm_bench.benchmark.harness`) records the guilt for the diagnosis
    KPIs. Guilt does not enter the reward (v0 and v1). An action outside the space
    raises :class:`~fuelhm_bench.errors.ParameterError` naming the space.

    ## Observation Space

    ``Dict({"indicators": Box(low, high, (10,), float32), "valid": MultiBinary(10),
    "extended": Box(low, high, (11,), float32), "extended_valid": MultiBinary(11)})``,
    plus ``"raw": Box((2, raw_samples), float32)`` when ``raw=True``.

    | index | indicator | unit    | low   | high | meaning (paper Table I)                          |
    |-------|-----------|---------|-------|------|--------------------------------------------------|
    | 0     | X1        | mA      | -12   | 12   | current of the inlet slope change                |
    | 1     | Y1        | mm/s    | -1000 | 1000 | velocity at X1                                   |
    | 2     | X2        | mA      | -12   | 12   | current of the outlet slope change               |
    | 3     | Y2        | mm/s    | -1000 | 1000 | velocity at X2                                   |
    | 4     | Inb       | mA      | -12   | 12   | (X1 + X2) / 2                                    |
    | 5     | I0        | mA      | -12   | 12   | mean control current at rest (v = 0)             |
    | 6     | Hys0      | mA      | 0     | 12   | spread of the control current at rest            |
    | 7     | G_in      | mm/s/mA | -1000 | 1000 | gain of the inlet segment                        |
    | 8     | G_out     | mm/s/mA | -1000 | 1000 | gain of the outlet segment                       |
    | 9     | G_null    | mm/s/mA | -1000 | 1000 | gain of the null segment                         |

    ``"extended"`` holds the model-free indicators beyond the paper
    (:data:`~fuelhm_bench.taxonomy.EXTENDED_INDICATOR_NAMES`, docs/indicators.md), extracted from
    the same flight by the same on-board extractor, with their flags in ``"extended_valid"``:

    | index | indicator | unit | low   | high | meaning                                              |
    |-------|-----------|------|-------|------|------------------------------------------------------|
    | 0     | V_in1     | mm/s | -1000 | 1000 | mean velocity of the moving samples at I0 - 1 mA     |
    | 1     | V_out1    | mm/s | -1000 | 1000 | the same at I0 + 1 mA                                |
    | 2     | V_in3     | mm/s | -1000 | 1000 | the same at I0 - 3 mA                                |
    | 3     | V_out3    | mm/s | -1000 | 1000 | the same at I0 + 3 mA                                |
    | 4     | V_in7     | mm/s | -1000 | 1000 | the same at I0 - 7 mA                                |
    | 5     | V_out7    | mm/s | -1000 | 1000 | the same at I0 + 7 mA                                |
    | 6     | Vsd_null  | mm/s | 0     | 1000 | velocity scatter within I0 +- 1 mA                   |
    | 7     | Idle_frac | 1    | 0     | 1    | share of the used samples at rest                    |
    | 8     | Hys_lo    | mA   | 0     | 12   | Hys0 of the rests at low supply pressure (N2 < 70 %) |
    | 9     | Hys_hi    | mA   | 0     | 12   | Hys0 of the rests at high supply pressure (N2 >= 80 %) |
    | 10    | I0_slope  | mA/% | -5    | 5    | change of the idle current per % of N2 between the two bands |

    ``valid[i]`` (``extended_valid[i]``) is 1 when indicator ``i`` was extracted, 0 when the
    flight's data did not support it; an invalid indicator is reported as 0 in
    ``"indicators"`` (``"extended"``), never NaN. Values are clipped to the bounds (shipped
    scenarios stay well inside). The arrays of an observation are the agent's to keep or modify: the
    environment never reads them again (at surrogate fidelity they are views of the episode's table
    rows, the last flight's copies). With ``fidelity="surrogate"`` the extended indicators are
    drawn by the surrogate like the ten (it must have learnt them: a surrogate without them is
    refused with :class:`~fuelhm_bench.errors.DataFormatError`). ``"raw"`` (physics only) is the recorded
    flight resampled by linear interpolation to ``raw_samples`` equally spaced
    instants from the first to the last sample: row 0 the control current [mA]
    in [-50, 50], row 1 the LVDT position [mm] in [-20, 80]. The ground truth
    (intensities, onsets) is never part of the observation.

    ## Raw flights

    ``reset(options={"raw_flight": True})`` (physics only) adds to the ``info``
    of ``reset`` and of every non-final ``step`` the full-rate samples of the
    flight in the observation: ``info["raw_flight"]``, a dict of 1-D float64
    arrays of equal length (:data:`RAW_FLIGHT_SIGNALS`: ``time_s`` [s],
    ``current_mA`` [mA], ``position_mm`` [mm, LVDT], ``demand_mm`` [mm],
    ``n2_pct`` [%]), every recorded sample (150,000 for a 25-minute flight),
    no cap and no resampling. It travels in ``info`` rather than in the
    observation because its length varies from flight to flight and a
    ``Box`` must have a fixed shape (``check_env`` accepts any ``info``; the
    ``raw=True`` argument keeps a fixed-size resampled view in the observation
    for agents that need one). With replayed units (:meth:`load_replays`) the
    indicators are the replayed ones and the samples are the same flight flown
    again from its seeds. One flight is held at a time.

    ## Rewards

    The reward of step ``t`` is minus the cost, in kUSD, of the decision on
    flight ``t`` (the flight shown in the observation), from the scenario's
    ``costs``. A fault is *detectable* on a flight when one of its modes has an
    intensity >= ``detectable_fraction`` x that mode's ``max_intensity``; it
    causes an *in-flight failure* on the flight where it reaches
    ``failure_fraction`` x ``max_intensity``. A fault outside the seven modes
    (the scenario's ``unknown_faults``) acts at full strength from its onset:
    it is detectable on every flight from then on and, having no failure law,
    never causes an in-flight failure.

    | decision on flight t                  | reward                                                        |
    |---------------------------------------|---------------------------------------------------------------|
    | alarm, detectable fault present       | ``-repair_kusd`` (correct maintenance)                        |
    | alarm, no detectable fault            | ``-false_alarm_kusd`` (removal, no fault found)               |
    | no alarm, detectable fault present    | ``-undetected_flight_kusd`` (flight flown with an undetected fault) |
    | no alarm, no detectable fault         | 0                                                             |
    | a fault reached failure on flight t   | additionally ``-failure_kusd`` (delay / cancellation)         |

    The episode return is minus the total cost of the unit's life. A failure
    on flight ``t`` could only have been prevented by an alarm on an earlier
    flight (credit assignment spans at least one step).

    ## Maintenance

    ``maintenance=True`` (default, for control): a correct maintenance (alarm
    with a detectable fault present) or an in-flight failure repairs the unit
    after the flight: every mode active on that flight, and a fault outside the
    seven modes present on it, is removed and does not recur in the episode
    (modes scheduled to start later still do). A false
    alarm changes nothing. ``maintenance=False`` (for the paper's KPIs, and
    what :mod:`fuelhm_bench.benchmark.harness` uses): alarms are only scored, faults
    evolve as scheduled whatever the agent does, and each mode's failure is
    charged once, on the first flight where it reaches ``failure_fraction``.

    ## Starting State

    ``reset()`` starts a new unit drawn from the scenario's scored-fleet
    distributions (manufacturing dispersion, which modes occur, their onsets, and
    a fault outside the seven modes for a unit that drew no mode, as in the fleet)
    with the environment's own generator ``self.np_random``;
    ``reset(options={"unit": k})`` replays unit ``k`` of the scenario's scored
    fleet instead (0 <= k < ``fleet.units``), fixed by the scenario's test seed
    whatever the environment's seed: with the physics fidelity its indicators
    are those of :func:`fuelhm_bench.datasets.fleet_indicators` on
    ``Scenario.test_fleet_config()`` (:meth:`load_replays` serves such flights
    from a precomputed table, so that many agents are evaluated on flights
    simulated once). The first observation is the first
    flight's; ``info`` holds ``"flight_index"`` (0) and ``"unit"`` (``k``, or -1
    for a drawn unit).

    ## Episode End

    The episode terminates (``terminated=True``) after the decision on the
    last flight: the unit retires and no cost follows (``truncated`` is always
    False). The observation returned then repeats the last flight's (no new
    flight is flown). The ground truth of the whole episode is returned once,
    in that step's ``info["episode_truth"]``: ``unit_id``, ``flight_index``
    (n,), ``intensity`` (n, 7, flown, after repairs), ``max_intensity`` (7,),
    ``onset`` (7,; -1 for absent modes), ``detectable``, ``failure``,
    ``repaired`` (n,), ``cost_kusd`` (n,), ``unknown_fault`` (the effect id of
    the unit's fault outside the seven modes, "" without one; ``detectable``
    includes it, ``intensity`` does not) and ``unknown_onset`` (-1 without). With
    ``reset(options={"evaluation": True})`` every ``info`` also carries
    ``"truth"`` for the flight in the observation (``intensity``,
    ``max_intensity``, ``onset``, ``detectable``, ``failure``) and every step's
    ``info["cost_kusd"]`` the breakdown of its reward; the runner strips them
    before anything reaches a method.

    ## Arguments

    ```python
    import gymnasium as gym
    import fuelhm_bench.envs
    env = gym.make("FuelHM/ActuationLoop-v3", scenario="all_modes", fidelity="surrogate")
    ```

    | argument        | default        | meaning                                                                     |
    |-----------------|----------------|-----------------------------------------------------------------------------|
    | scenario        | "paper_2012"   | shipped scenario name (``"all_modes"``, ``"all_modes-v1"``), YAML path or Scenario |
    | fidelity        | None           | "physics" or "surrogate"; None: the scenario's ``fidelity``                 |
    | maintenance     | True           | alarms repair the unit (see Maintenance)                                    |
    | drifted         | True           | the scored fleet carries the scenario's nominal-parameter drift (False: the same fleet without it) |
    | flight_minutes  | None           | flight duration [min] overriding the scenario's (>= start + 1 min); short flights make tests fast |
    | raw             | False          | add the resampled raw flight to the observation (physics only)              |
    | raw_samples     | 256            | samples per raw row, in [2, 100000]                                         |
    | knowledge       | None           | a precomputed :class:`~fuelhm_bench.datasets.knowledge.KnowledgeResult` the surrogate draws from (its ``healthy_model``, ``healthy_table``, ``itl``); None: :func:`~fuelhm_bench.datasets.cache.surrogate_knowledge` |
    | knowledge_size  | None           | :class:`~fuelhm_bench.envs.KnowledgeSize` (or a dict of its fields) of that build; ``KnowledgeSize.small()`` for tests |
    | cache_dir       | None           | cache of the simulated products; None: ``$FUELHM_BENCH_CACHE`` or ``~/.cache/fuelhm-bench``; False: memory only |
    | render_mode     | None           | no rendering is implemented                                                  |

    A misspelt argument or option raises
    :class:`~fuelhm_bench.errors.ParameterError` with a did-you-mean; an
    unknown scenario :class:`~fuelhm_bench.errors.UnknownNameError`.

    ## Version History

    * v3: a fault outside the seven modes enters the rewards (detectable from its onset,
      repaired by a correct maintenance, never an in-flight failure) and drawn units get the
      scenario's ``unknown_faults`` like the scored fleet's units (v2 rewarded those flights as
      healthy); at surrogate fidelity a repaired unit keeps its manufacturing draws. Later in v3
      (no change for arguments accepted before): the surrogate fidelity draws scenarios with
      ``unknown_faults``, which it refused until then. Retired v2:
      ``gym.make("FuelHM/ActuationLoop-v2")`` raises ``DeprecatedEnv`` naming v3.
    * v2: the observation gains ``"extended"`` and ``"extended_valid"``: the eleven extended
      indicators (velocities at fixed currents, null scatter, rest fraction, and the issue-11
      supply-pressure indicators ``Hys_lo``, ``Hys_hi``, ``I0_slope``, which need N2 per sample).
      The paper's ten and the rewards are unchanged. Retired v1: ``gym.make("FuelHM/ActuationLoop-v1")``
      raises ``DeprecatedEnv`` naming v2.
    * v1: physics v2 (issue 11): no per-frame N2 dither in the operating excitation, the seven
      degradation laws act on the physical element that degrades, every shipped scenario at
      version 2 (all_modes with >= 15 faulty units per mode). Observations and rewards differ
      from v0 for the same arguments. The observation still holds the paper's ten indicators;
      the extended indicators are columns of the indicator tables (training, DOE), not yet of
      the observation. The surrogate fidelity is re-learnt from physics flights (resampled
      residuals, invalid indicators, DOE responses per unit and intensity; issue 12).
    * v0: initial version (surrogate with unit/flight variance split; guilt not rewarded). Retired:
      ``gym.make("FuelHM/ActuationLoop-v0")`` raises ``DeprecatedEnv`` naming v1.

    Attributes
    ----------
    scenario : Scenario
        The loaded scenario.
    fidelity : str
        The fidelity in use.
    n_flights : int
        Flights per episode (the scenario's ``fleet.flights_per_unit``).
    surrogate : SurrogateModel or None
        The surrogate (surrogate fidelity only).
    """

    metadata = {"render_modes": [], "render_fps": 1}

    def __init__(self, *, scenario="paper_2012", fidelity: str | None = None, maintenance: bool = True,
                 drifted: bool = True, flight_minutes: float | None = None, raw: bool = False,
                 raw_samples: int = 256, knowledge=None, knowledge_size=None,
                 cache_dir: str | os.PathLike | bool | None = None, render_mode: str | None = None,
                 **unknown: Any) -> None:
        owner = type(self).__name__
        reject_unknown(unknown, _ARGUMENTS, what="argument", owner=owner)
        self.scenario = resolve_scenario(scenario)
        sc = self.scenario
        if fidelity is None:
            fidelity = sc.fidelity
        if fidelity not in FIDELITIES:
            raise ParameterError(f"The 'fidelity' parameter of {owner} must be one of {', '.join(FIDELITIES)} or None "
                                 f"(the scenario's default). Got {fidelity!r} instead."
                                 f"{did_you_mean(fidelity, FIDELITIES)}")
        self.fidelity = fidelity
        for name, value in (("maintenance", maintenance), ("drifted", drifted), ("raw", raw)):
            if not isinstance(value, (bool, np.bool_)):
                raise ParameterError(f"The '{name}' parameter of {owner} must be a bool. Got {value!r} instead.")
        self.maintenance = bool(maintenance)
        self.drifted = bool(drifted)
        self.raw = bool(raw)
        if not (isinstance(raw_samples, (int, np.integer)) and not isinstance(raw_samples, bool)
                and 2 <= raw_samples <= 100_000):
            raise ParameterError(f"The 'raw_samples' parameter of {owner} must be an int in [2, 100000]. "
                                 f"Got {raw_samples!r} instead.")
        self.raw_samples = int(raw_samples)
        if self.raw and fidelity != "physics":
            raise ParameterError(f"The 'raw' parameter of {owner} may only be True with fidelity='physics' (the "
                                 f"surrogate draws indicators, not flights). Got raw=True with fidelity={fidelity!r}.")
        shortest = (sc.mission.start_duration_s + 60.0) / 60.0
        number = isinstance(flight_minutes, (int, float, np.integer, np.floating))
        number = number and not isinstance(flight_minutes, bool)
        if flight_minutes is not None and not (number and math.isfinite(flight_minutes) and flight_minutes >= shortest):
            raise ParameterError(f"The 'flight_minutes' parameter of {owner} must be None or a number >= "
                                 f"{shortest:g} (engine start {sc.mission.start_duration_s:g} s + 60 s). "
                                 f"Got {flight_minutes!r} instead.")
        self.flight_minutes = None if flight_minutes is None else float(flight_minutes)
        if render_mode is not None:
            raise ParameterError(f"The 'render_mode' parameter of {owner} must be None (no rendering is "
                                 f"implemented). Got {render_mode!r} instead.")
        self.render_mode = None
        size = KnowledgeSize.coerce(knowledge_size, owner)
        if knowledge is not None and not all(hasattr(knowledge, a) for a in ("healthy_model", "healthy_table", "itl")):
            raise ParameterError(f"The 'knowledge' parameter of {owner} must be a KnowledgeResult or None. "
                                 f"Got {type(knowledge).__name__} instead.")

        config = sc.test_fleet_config()
        if not self.drifted:
            config = dataclasses.replace(config, nominal=sc.truth_model())
        if self.flight_minutes is not None:
            config = dataclasses.replace(config, mission=dataclasses.replace(
                config.mission, duration_s=60.0 * self.flight_minutes))
        self._config = config
        self.n_flights = config.n_flights
        self._fleet = None  # the scored fleet's units, built on the first replay
        costs = sc.costs
        self._c_false, self._c_repair = float(costs.false_alarm_kusd), float(costs.repair_kusd)
        self._c_undetected, self._c_failure = float(costs.undetected_flight_kusd), float(costs.failure_kusd)
        self.surrogate = None
        self._fault_columns = None
        if fidelity == "surrogate":
            if knowledge is None:
                # (the scenario as given, so that a refusal names its file)
                knowledge = surrogate_knowledge(scenario, flight_minutes=self.flight_minutes, size=size,
                                                drifted=self.drifted, cache_dir=cache_dir)
            self.surrogate = SurrogateModel.from_knowledge(knowledge)
            missing = [n for n in INDICATOR_NAMES if n not in self.surrogate.names]
            if missing or tuple(self.surrogate.modes) != tuple(MODE_IDS):
                raise DataFormatError(f"The surrogate of {owner} must draw the indicators {list(INDICATOR_NAMES)} "
                                      f"for the modes {list(MODE_IDS)}. Got indicators {list(self.surrogate.names)}"
                                      f" and modes {list(self.surrogate.modes)} instead.")
            self._columns = np.array([self.surrogate.names.index(n) for n in INDICATOR_NAMES])
            lacking = [n for n in EXTENDED_INDICATOR_NAMES if n not in self.surrogate.names]
            if lacking:
                raise DataFormatError(f"The surrogate of {owner} must also draw the extended indicators "
                                      f"{list(EXTENDED_INDICATOR_NAMES)} (the observation's 'extended'); it lacks "
                                      f"{lacking}. Build its knowledge from indicator tables with those columns "
                                      f"(fuelhm_bench.datasets.cache.surrogate_knowledge does).")
            self._ext_columns = np.array([self.surrogate.names.index(n) for n in EXTENDED_INDICATOR_NAMES])
            self._obs_columns = np.concatenate([self._columns, self._ext_columns])
            if np.array_equal(self._obs_columns, np.arange(len(self.surrogate.names))):
                self._obs_columns = None
            if config.unknown_faults:  # each fault outside the seven modes: its learnt full-strength response
                from fuelhm_bench.datasets.doe import fault_case

                learnt = {f: j for j, f in enumerate(self.surrogate.faults) if self.surrogate.fault_learnt[j]}
                labels = [fault_case(u) for u in config.unknown_faults]
                missing = [label for label in labels if label not in learnt]
                if missing:
                    raise ParameterError(
                        f"{owner}: scenario {sc.id} has the fault(s) outside the seven modes {missing}, whose "
                        f"response the surrogate was not learnt for (its design of experiments did not fly them; "
                        f"it learnt {list(learnt)}). Build its knowledge with "
                        f"fuelhm_bench.datasets.cache.surrogate_knowledge (which flies every unknown fault of the "
                        f"scenario) or use fidelity='physics'.")
                self._fault_columns = np.array([learnt[label] for label in labels], dtype=np.intp)

        obs = {"indicators": spaces.Box(_LOW, _HIGH, (len(INDICATOR_NAMES),), np.float32),
               "valid": spaces.MultiBinary(len(INDICATOR_NAMES)),
               "extended": spaces.Box(_XLOW, _XHIGH, (_N_EXT,), np.float32),
               "extended_valid": spaces.MultiBinary(_N_EXT)}
        if self.raw:
            low = np.repeat(np.array([[RAW_BOUNDS["current_mA"][0]], [RAW_BOUNDS["position_mm"][0]]],
                                     dtype=np.float32), self.raw_samples, axis=1)
            high = np.repeat(np.array([[RAW_BOUNDS["current_mA"][1]], [RAW_BOUNDS["position_mm"][1]]],
                                      dtype=np.float32), self.raw_samples, axis=1)
            obs["raw"] = spaces.Box(low, high, (2, self.raw_samples), np.float32)
        self.observation_space = spaces.Dict(obs)
        self.action_space = spaces.Dict({"alarm": spaces.Discrete(2),
                                         "guilt": spaces.Box(0.0, 1.0, (_N_MODES,), np.float32)})
        self._t = -1  # no episode yet
        self._flights = np.arange(self.n_flights)
        self._last_flight = self.n_flights - 1
        self._flights.setflags(write=False)
        self._raw_flight = False
        self._replays: dict[int, dict[str, np.ndarray]] = {}

    def load_replays(self, table) -> None:
        """Serve replayed units from precomputed physics indicators instead of simulating them again.

        Without maintenance a replayed unit's flights do not depend on the
        actions, so its observations can be simulated once
        (:func:`fuelhm_bench.datasets.cache.scored_indicators`) and shared by every
        agent or method evaluated; rewards and truth are computed as usual.

        Parameters
        ----------
        table : pandas.DataFrame
            Indicator table of the scored fleet as :func:`fuelhm_bench.datasets.fleet_indicators`
            returns it for ``test_fleet_config()`` (``unit_id``, ``flight_index``, the
            ten and the extended indicators, ``<name>_valid``), every flight of each unit it holds.

        Raises
        ------
        ParameterError
            Not the physics fidelity, maintenance on, raw observations on, a missing
            indicator column, or a unit's flights incomplete.
        """
        if self.fidelity != "physics" or self.maintenance or self.raw:  # (the raw_flight option is fine)
            raise ParameterError(f"{type(self).__name__}.load_replays needs fidelity='physics', maintenance=False "
                                 f"and raw=False (replayed flights must not depend on the actions). Got "
                                 f"fidelity={self.fidelity!r}, maintenance={self.maintenance}, raw={self.raw}.")
        needed = [c for n in (*INDICATOR_NAMES, *EXTENDED_INDICATOR_NAMES) for c in (n, f"{n}_valid")]
        missing = [c for c in needed if c not in table.columns]
        if missing:
            raise ParameterError(f"The 'table' parameter of {type(self).__name__}.load_replays must hold the "
                                 f"columns of every observed indicator and its flag. Got no {missing} instead.")
        # One pass over the whole table, sorted by unit then flight, cut into units (a pass per unit
        # reads every column once per unit: the larger part of an evaluation's set-up on big fleets).
        ordered = table[table["unit_id"].notna()].sort_values(["unit_id", "flight_index"], kind="stable")
        arrays = _observation_arrays(ordered)
        units = ordered["unit_id"].to_numpy()
        flights = ordered["flight_index"].to_numpy()
        bounds = [*np.flatnonzero(np.r_[True, units[1:] != units[:-1]]), len(units)]
        replays = {}
        for a, b in zip(bounds[:-1], bounds[1:]):
            unit = units[a].item() if isinstance(units[a], np.generic) else units[a]
            if flights[a:b].tolist() != list(range(self.n_flights)):
                raise ParameterError(f"The 'table' parameter of {type(self).__name__}.load_replays must hold "
                                     f"flights 0..{self.n_flights - 1} of each unit. Got "
                                     f"{flights[a:b].tolist()} for unit {unit!r} instead.")
            replays[int(unit)] = {k: v[a:b] for k, v in arrays.items()}
        self._replays = replays

    # ------------------------------------------------------------------ episode set-up
    def _scored_fleet(self):
        if self._fleet is None:
            self._fleet = build_units(self._config)
        return self._fleet

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Start a unit's life and return the first flight's observation and info.

        Parameters
        ----------
        seed : int or None, default=None
            Seeds ``self.np_random`` (the only source of randomness of drawn units).
        options : dict or None, default=None
            ``"unit"``: int, replay that unit of the scored fleet;
            ``"evaluation"``: bool, add the ground truth to every ``info``;
            ``"raw_flight"``: bool, add the full-rate samples of the observed
            flight to ``info["raw_flight"]`` for the whole episode (physics only;
            see Raw flights).

        Returns
        -------
        observation : dict
        info : dict
        """
        super().reset(seed=seed)
        options = {} if options is None else options
        if not isinstance(options, dict):
            raise ParameterError(f"The 'options' parameter of {type(self).__name__}.reset must be a dict or None. "
                                 f"Got {type(options).__name__} instead.")
        reject_unknown(options, _OPTIONS, what="option", owner=f"{type(self).__name__}.reset")
        evaluation = options.get("evaluation", False)
        if not isinstance(evaluation, (bool, np.bool_)):
            raise ParameterError(f"The 'evaluation' option of {type(self).__name__}.reset must be a bool. "
                                 f"Got {evaluation!r} instead.")
        self._evaluation = bool(evaluation)
        raw_flight = options.get("raw_flight", False)
        if not isinstance(raw_flight, (bool, np.bool_)):
            raise ParameterError(f"The 'raw_flight' option of {type(self).__name__}.reset must be a bool. "
                                 f"Got {raw_flight!r} instead.")
        if raw_flight and self.fidelity != "physics":
            raise ParameterError(f"The 'raw_flight' option of {type(self).__name__}.reset needs fidelity='physics' "
                                 f"(the surrogate draws indicators, not flights). Got fidelity={self.fidelity!r}.")
        self._raw_flight = bool(raw_flight)
        unit = options.get("unit")
        config = self._config
        n = self.n_flights
        if unit is None:
            schedule = draw_unit_schedule(config.schedules, self.np_random, simultaneous=config.simultaneous)
            if config.unknown_faults and not schedule.schedules:  # as a scored-fleet unit (flights.fleet)
                fault, fault_onset = draw_unknown_fault(config.unknown_faults, self.np_random)
                schedule = UnitSchedule(unknown=fault, unknown_onset=fault_onset)
            key = int(self.np_random.integers(0, 2**63 - 1))
            self._unit_id, self._seed, self._slot, self._model = -1, key, 0, None
        else:
            if not (isinstance(unit, (int, np.integer)) and not isinstance(unit, bool) and 0 <= unit < config.n_units):
                raise ParameterError(f"The 'unit' option of {type(self).__name__}.reset must be an int in "
                                     f"[0, {config.n_units - 1}] (a unit of the scored fleet of {self.scenario.id}). "
                                     f"Got {unit!r} instead.")
            fleet_unit = self._scored_fleet()[int(unit)]
            schedule = fleet_unit.schedule
            self._unit_id, self._seed, self._slot, self._model = int(unit), config.seed, int(unit), fleet_unit.model
        # Truth: scheduled intensities, thresholds, per-flight bitmasks.
        intensity = np.zeros((n, _N_MODES))
        max_intensity = np.zeros(_N_MODES)
        onset = _NO_ONSET.copy()
        flights = self._flights
        for s, o in zip(schedule.schedules, schedule.onsets):
            j = MODE_IDS.index(s.mode)
            intensity[:, j] = s.intensity(flights, o)
            max_intensity[j], onset[j] = s.max_intensity, o
        costs = self.scenario.costs
        present = intensity > 0.0
        self._schedule = schedule
        self._intensity, self._max, self._onset = intensity, max_intensity, onset
        # A fault outside the seven modes acts at full strength from its onset: present and detectable
        # from then on; it has no failure law, so it never fails in flight.
        unknown = (np.where(flights >= schedule.unknown_onset, _UNKNOWN_BIT, 0).astype(np.int64)
                   if schedule.unknown is not None else None)
        if schedule.schedules:
            self._present_bits = _bitmask(present, unknown)
            self._det_bits = _bitmask(present & (intensity >= costs.detectable_fraction * max_intensity), unknown)
            self._fail_bits = _bitmask(present & (intensity >= costs.failure_fraction * max_intensity))
        else:  # no mode: the unknown fault's bits only
            self._present_bits = [0] * n if unknown is None else unknown.tolist()
            self._det_bits = list(self._present_bits)
            self._fail_bits = [0] * n
        self._active, self._failed = _ALL, 0
        self._active_log, self._fail_log, self._repair_log, self._cost_log = [], [], [], []
        if self.fidelity == "surrogate":
            rng = rng_for(self._seed, _STREAM_SURROGATE, self._slot)
            # the unit the physics would fly: its manufacturing coordinates drive its draws
            coordinates = self.surrogate.unit_coordinates(
                self._model if self._model is not None else unit_rng(self._seed, self._slot), config.nominal,
                config.dispersion)
            self._parts = self.surrogate.draw_parts(rng, n, coordinates)
            self._faults = None
            if self._fault_columns is not None:  # presence of the unit's unknown fault, from its onset on
                self._faults = np.zeros((n, len(self.surrogate.faults)), dtype=bool)
                if schedule.unknown is not None:
                    column = self._fault_columns[config.unknown_faults.index(schedule.unknown)]
                    self._faults[schedule.unknown_onset:, column] = True
            self._fill_surrogate(0, intensity, self._faults)
        elif self._model is None:
            from fuelhm_bench.physics.model import manufacture

            self._model = manufacture(config.nominal, unit_rng(self._seed, self._slot), config.dispersion)
        self._t = 0
        obs = self._observe(0)
        info = {"flight_index": 0, "unit": self._unit_id}
        if self._raw_flight:
            info["raw_flight"] = self._raw_payload
        if self._evaluation:
            info["truth"] = self._flight_truth(0)
        return obs, info

    # ------------------------------------------------------------------ flights
    def _observe(self, t: int) -> dict:
        """Fly flight ``t`` (physics) or read it (surrogate); log the unit's state during it."""
        self._active_log.append(self._active)
        if self.surrogate is not None:
            return self._surrogate_observation(t)
        replay = self._replays.get(self._unit_id) if self._unit_id >= 0 else None
        if replay is not None:
            self._last = {k: v[t] for k, v in replay.items()}
            if self._raw_flight:  # the replayed indicators, the same flight's samples flown again
                self._raw_payload = self._raw_of(*self._simulate(t))
        else:
            self._last = self._fly(t)
        return {k: v.copy() for k, v in self._last.items()}

    def _simulate(self, t: int):
        """Simulate flight ``t`` of the current unit: ``(SimOutput, FlightInputs)``."""
        from fuelhm_bench.physics.simulate import simulate

        active = self._active
        intens = {s.mode: (float(self._intensity[t, MODE_IDS.index(s.mode)])
                           if active >> MODE_IDS.index(s.mode) & 1 else 0.0)
                  for s in self._schedule.schedules}
        model = self._model.degraded(intens)
        if active & _UNKNOWN_BIT:  # a fault outside the seven modes, until a maintenance removes it
            for effect in self._schedule.effects(t):
                model = model.with_effect(effect)
        inputs = self._config.mission.sample(mission_rng(self._seed, self._slot, t))
        noise = noise_rng(self._seed, self._slot, t)
        where = f"unit {self._unit_id}, flight {t}" if self._unit_id >= 0 else f"drawn unit, flight {t}"
        return simulate([model], [inputs], [noise], labels=[where])[0], inputs

    @staticmethod
    def _raw_of(out, inputs) -> dict:
        """The full-rate payload of ``info["raw_flight"]`` (:data:`RAW_FLIGHT_SIGNALS`, float64, no cap)."""
        n = out.time_s.size
        extras = inputs.extras
        return {"time_s": np.asarray(out.time_s, dtype=np.float64),
                "current_mA": out.current_a * 1e3, "position_mm": out.measured_position_m * 1e3,
                "demand_mm": np.asarray(extras.get("demand_mm", np.full(n, np.nan)), dtype=np.float64),
                "n2_pct": np.asarray(extras.get("n2_pct", np.full(n, np.nan)), dtype=np.float64)}

    def _fly(self, t: int) -> dict:
        from fuelhm_bench.indicators import extract_indicators
        from fuelhm_bench.indicators.result import IndicatorResult

        out, inputs = self._simulate(t)
        if self._raw_flight:
            self._raw_payload = self._raw_of(out, inputs)
        current_ma = out.current_a * 1e3
        position_mm = out.measured_position_m * 1e3
        try:
            result = extract_indicators(out.time_s, current_ma, position_mm, flight_id=t,
                                        n2_pct=100.0 * inputs.n2_frac)
        except DataFormatError as exc:
            result = IndicatorResult.invalid((str(exc),))
        row = {**result.values, **{f"{n}_valid": v for n, v in result.valid.items()},
               **result.extended_values, **{f"{n}_valid": v for n, v in result.extended_valid.items()}}
        obs = {k: v[0] for k, v in _observation_arrays({k: [v] for k, v in row.items()}).items()}
        if self.raw:
            grid = np.linspace(out.time_s[0], out.time_s[-1], self.raw_samples)
            raw = np.stack([np.interp(grid, out.time_s, current_ma), np.interp(grid, out.time_s, position_mm)])
            low, high = self.observation_space["raw"].low, self.observation_space["raw"].high
            obs["raw"] = np.clip(raw, low, high).astype(np.float32)
        return obs

    def _fill_surrogate(self, start: int, intensity: np.ndarray, faults: np.ndarray | None = None) -> None:
        """Surrogate observations of flights ``start ..`` for these intensities and unknown faults present
        (the unit's draws are kept)."""
        parts = self._parts
        if start:
            parts = self.surrogate.tail(parts, start)
        values, valid = self.surrogate.degrade(parts, intensity, faults)
        # the ten and the extended indicators in one pass (values 0 where invalid, clipped to the bounds)
        columns = self._obs_columns
        if columns is not None:  # (None: the surrogate's columns are the observation's, in order)
            values, valid = values[:, columns], valid[:, columns]
        if math.isfinite(values.sum()):  # every value finite (a NaN or inf would make the sum so): degrade's
            ok = valid                   # values are already 0 where invalid
        else:
            ok = valid & np.isfinite(values)
            values = np.where(ok, values, 0.0)
        table = _clip(values, _OBS_LOW, _OBS_HIGH)
        n = _N_IND
        tables = (table[:, :n].astype(np.float32), ok[:, :n].astype(np.int8),
                  table[:, n:].astype(np.float32), ok[:, n:].astype(np.int8))
        if start:
            for mine, new in zip(self._obs_tables, tables):
                mine[start:] = new
        else:
            self._obs_tables = tables

    @property
    def _tables(self) -> dict:
        """The episode's surrogate observations, per key."""
        return dict(zip(_OBS_KEYS, self._obs_tables))

    def _surrogate_observation(self, t: int) -> dict:
        """Flight ``t``'s observation: views of its rows (the env never reads a row again once it is observed: a
        repair rewrites later flights only, a reset makes new tables), copies for the last flight (which the
        terminal step shows again)."""
        a, b, c, d = self._obs_tables
        if t == self._last_flight:
            return {"indicators": a[t].copy(), "valid": b[t].copy(), "extended": c[t].copy(),
                    "extended_valid": d[t].copy()}
        return {"indicators": a[t], "valid": b[t], "extended": c[t], "extended_valid": d[t]}

    def _mask(self, bits: int) -> np.ndarray:
        return ((bits & _BITS) != 0).astype(np.float64)

    def _flight_truth(self, t: int) -> dict:
        active = self._active
        return {"intensity": self._intensity[t] * self._mask(active), "max_intensity": self._max.copy(),
                "onset": self._onset.copy(), "detectable": bool(self._det_bits[t] & active),
                "failure": bool(self._fail_bits[t] & active & ~self._failed)}

    # ------------------------------------------------------------------ step
    def _action_error(self, problem: str) -> ParameterError:
        return ParameterError(f"The action passed to {type(self).__name__}.step must be in the action space "
                              f"{self.action_space} (alarm: 0 or 1; guilt: 7 numbers in [0, 1], one per mode of "
                              f"MODE_IDS). Got {problem} instead.")

    def _alarm_of(self, action) -> bool:
        """Check ``action`` against the action space (fast path) and return the alarm."""
        try:
            alarm, guilt = action["alarm"], action["guilt"]
        except (TypeError, KeyError, IndexError):
            raise self._action_error(f"{type(action).__name__} {action!r:.100}") from None
        if len(action) != 2:
            extra = [k for k in action if k not in ("alarm", "guilt")]
            raise self._action_error(f"the extra key(s) {extra}")
        if isinstance(alarm, (int, np.integer, np.bool_)):
            value = int(alarm)
        elif isinstance(alarm, np.ndarray) and alarm.shape == () and alarm.dtype.kind in "biu":
            value = int(alarm)
        else:
            raise self._action_error(f"alarm={alarm!r} ({type(alarm).__name__})")
        if value != 0 and value != 1:
            raise self._action_error(f"alarm={value!r}")
        g = guilt if type(guilt) is np.ndarray else np.asarray(guilt)
        if g.shape != (_N_MODES,) or g.dtype.kind not in "biuf":
            raise self._action_error(f"guilt of shape {g.shape} and dtype {g.dtype}")
        values = g.tolist()  # on 7 numbers, builtins beat reductions; a NaN fails the sum's self-equality
        total = sum(values)
        if not (0.0 <= min(values) and max(values) <= 1.0 and total == total):
            raise self._action_error(f"guilt={values} (entries outside [0, 1] or NaN)")
        return value == 1

    def step(self, action):
        """Decide on the current flight, fly the next one.

        Parameters
        ----------
        action : dict
            ``{"alarm": 0 or 1, "guilt": array of 7 floats in [0, 1]}``.

        Returns
        -------
        observation : dict
            The next flight's (the last flight's again at the end).
        reward : float
            Minus the cost of the decision [kUSD] (see Rewards).
        terminated : bool
            True after the decision on the last flight.
        truncated : bool
            Always False.
        info : dict
            ``"flight_index"`` of the observation; ``"episode_truth"`` at the end;
            ``"truth"`` and ``"cost_kusd"`` with the evaluation option.

        Raises
        ------
        ParameterError
            The action is outside the action space.
        gymnasium.error.ResetNeeded
            No episode is running (call ``reset``).
        """
        t = self._t
        if t < 0:
            raise ResetNeeded(f"{type(self).__name__}.step was called without a running episode; call reset() "
                              f"first (an episode ends after the decision on its last flight).")
        alarm = self._alarm_of(action)
        active = self._active
        detectable = self._det_bits[t] & active
        failure = self._fail_bits[t] & active & ~self._failed
        if alarm:
            cost = self._c_repair if detectable else self._c_false
        else:
            cost = self._c_undetected if detectable else 0.0
        if failure:
            cost += self._c_failure
        repaired = 0
        if self.maintenance:
            if (alarm and detectable) or failure:
                repaired = self._present_bits[t] & active
                if repaired:
                    self._repair(t, repaired)
        elif failure:
            self._failed |= failure
        self._fail_log.append(failure)
        self._repair_log.append(repaired)
        self._cost_log.append(cost)
        t += 1
        reward = -cost if cost else 0.0
        if t == self.n_flights:
            self._t = -1
            if self.surrogate is not None:  # (shown a second time: new copies, whatever the agent did to the first)
                obs = self._surrogate_observation(t - 1)
            else:
                obs = {k: v.copy() for k, v in self._last.items()}
            info = {"flight_index": t - 1, "episode_truth": self._episode_truth()}
            terminated = True
        else:
            self._t = t
            if self.surrogate is not None:  # (_observe, inlined: the surrogate's hot path)
                self._active_log.append(self._active)
                obs = self._surrogate_observation(t)
            else:
                obs = self._observe(t)
            info = {"flight_index": t}
            if self._raw_flight:
                info["raw_flight"] = self._raw_payload
            terminated = False
        if self._evaluation:
            info["cost_kusd"] = self._breakdown(alarm, detectable, failure)
            if not terminated:
                info["truth"] = self._flight_truth(t)
        return obs, reward, terminated, False, info

    def _breakdown(self, alarm: bool, detectable: int, failure: int) -> dict:
        return {"repair": self._c_repair if alarm and detectable else 0.0,
                "false_alarm": self._c_false if alarm and not detectable else 0.0,
                "undetected_flight": self._c_undetected if not alarm and detectable else 0.0,
                "failure": self._c_failure if failure else 0.0}

    def _repair(self, t: int, repaired: int) -> None:
        """Remove the repaired modes from flight ``t + 1`` on (surrogate: recompute the remaining table)."""
        self._active &= ~repaired
        if self.surrogate is not None and t + 1 < self.n_flights:
            faults = self._faults
            if faults is not None:
                faults = faults[t + 1:] & bool(self._active & _UNKNOWN_BIT)
            self._fill_surrogate(t + 1, self._intensity[t + 1:] * self._mask(self._active), faults)

    def episode_truth(self) -> dict:
        """Ground truth of the flights of the current episode decided so far.

        What ``info["episode_truth"]`` holds at the end of an episode, for the
        first ``k`` flights when called after ``k`` steps (e.g. after a
        ``TimeLimit`` truncation, see :class:`fuelhm_bench.envs.wrappers.KeepEpisodeTruth`).

        Raises
        ------
        ResetNeeded
            Before the first ``reset``.
        """
        if not hasattr(self, "_cost_log"):
            from gymnasium.error import ResetNeeded

            raise ResetNeeded("Call reset before episode_truth.")
        return self._episode_truth()

    def _episode_truth(self) -> dict:
        n = len(self._cost_log)
        active = np.array(self._active_log[:n], dtype=np.int64)
        if any(self._repair_log):
            flown = self._intensity[:n] * ((active[:, None] & _BITS) != 0)
        else:  # every mode active on every flight: x * 1.0 is x, bit for bit
            flown = self._intensity[:n].copy()
        return {
            "unit_id": self._unit_id,
            "flight_index": np.arange(n, dtype=np.int64),
            "intensity": flown,
            "max_intensity": self._max.copy(),
            "onset": self._onset.copy(),
            "detectable": (np.array(self._det_bits[:n], dtype=np.int64) & active) != 0,
            "failure": np.array(self._fail_log, dtype=np.int64) != 0 if n else np.array([]),
            "repaired": np.array(self._repair_log, dtype=np.int64) != 0 if n else np.array([]),
            "cost_kusd": np.array(self._cost_log, dtype=np.float64),
            "unknown_fault": "" if self._schedule.unknown is None else self._schedule.unknown.effect,
            "unknown_onset": int(self._schedule.unknown_onset),
        }

    def render(self) -> None:
        """No rendering is implemented (``render_modes`` is empty)."""
        return None

    def __repr__(self) -> str:
        return (f"<{type(self).__name__} scenario={self.scenario.id} fidelity={self.fidelity} "
                f"maintenance={self.maintenance}>")
