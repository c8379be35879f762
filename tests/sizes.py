"""The small sizes the tests run at, in one place.

Every test that simulates flights, builds knowledge or runs a workflow end to end takes its sizes
from here (in the spirit of scikit-learn's table of test instances), so that the cost of the
default run is set in one file and a change of size is one edit. Long statistical runs use their
own, larger sizes and are marked ``slow``.

Cost notes (2-core machine): a simulated 2-minute flight costs a few tens of ms once the numba
kernels are compiled; a DOE unit of the published knowledge is 7 modes x its intensities flights.
"""

from __future__ import annotations

import dataclasses

#: Flight length of the environment and runner tests [min]: the shortest mission (60 s engine
#: start with its test sweep + 60 s).
FLIGHT_MINUTES = 2.0

#: Scored fleet of a tiny scenario: units x flights per unit.
TINY_UNITS, TINY_FLIGHTS = 3, 8
#: Healthy training fleet of a tiny scenario: units x flights per unit.
TINY_TRAINING_UNITS, TINY_TRAINING_FLIGHTS = 4, 6  # half the units fit: 2 x 6 >= the 11 flights of a 10-indicator model
#: Degradation timing of a tiny scenario's modes (flight indices): onset window and ramp length.
TINY_ONSET_MIN, TINY_ONSET_MAX, TINY_RAMP_FLIGHTS = 1, 3, 3
#: Latest onset of the modes in tiny scenario *files* (flight index).
TINY_FILE_ONSET_MAX = 2
#: Flight length of tiny scenario *files* run through ``scenario_data`` / the CLI [min]: longer
#: than FLIGHT_MINUTES so that the in-flight part of the mission also feeds the indicators.
TINY_FILE_MINUTES = 5.0

#: DOE units of the published knowledge in tests (``scenario_data(doe_units=...)``).
DOE_UNITS = 1

#: Hidden-effect data of one discrepancy case: units, flights per unit, flight length [min].
DISCREPANCY_UNITS, DISCREPANCY_FLIGHTS, DISCREPANCY_MINUTES = 2, 2, 4.0
#: Fit frames of the recalibration and held-out frames of one discrepancy case.
DISCREPANCY_FIT_FRAMES, DISCREPANCY_HELDOUT_FRAMES = 16000, 60000
#: Hidden-effect data of the (slow) discrepancy study: units, flights per unit, flight length [min].
STUDY_UNITS, STUDY_FLIGHTS, STUDY_MINUTES = 2, 3, 4.0


def knowledge_size():
    """The knowledge build of the environment and runner tests (``KnowledgeSize.small()``)."""
    from fuelhm_bench.envs import KnowledgeSize

    return KnowledgeSize.small()


def discrepancy_config(**changes):
    """The discrepancy configuration of the end-to-end tests (frames capped, 2 jobs)."""
    from fuelhm_bench.calibration.discrepancy import DiscrepancyConfig
    from fuelhm_bench.calibration.recalibrate import CalibrationConfig

    fields = dict(calibration=CalibrationConfig(fit_max_frames=DISCREPANCY_FIT_FRAMES),
                  heldout_max_frames=DISCREPANCY_HELDOUT_FRAMES, n_jobs=2)
    fields.update(changes)
    return DiscrepancyConfig(**fields)


def tiny_scenario(base: str = "paper_2012", name: str = "tiny", **changes):
    """A shipped scenario shrunk to the tiny sizes, as a ``Scenario`` (flights of FLIGHT_MINUTES).

    Scenarios whose modes are exclusive get no healthy units and equal mode probabilities, so that
    every mode occurs in so few units. ``changes`` replace further fields.
    """
    from fuelhm_bench.scenarios import load_scenario

    sc = load_scenario(base)
    degradations = tuple(dataclasses.replace(d, onset_min=TINY_ONSET_MIN, onset_max=TINY_ONSET_MAX,
                                             ramp_flights=TINY_RAMP_FLIGHTS) for d in sc.degradations)
    fields = dict(name=name, fleet=dataclasses.replace(sc.fleet, units=TINY_UNITS, flights_per_unit=TINY_FLIGHTS),
                  mission=dataclasses.replace(sc.mission, duration_min=FLIGHT_MINUTES),
                  training=dataclasses.replace(sc.training, units=TINY_TRAINING_UNITS,
                                               flights_per_unit=TINY_TRAINING_FLIGHTS),
                  degradations=degradations,
                  unknown_faults=tuple(dataclasses.replace(u, onset_min=TINY_ONSET_MIN, onset_max=TINY_ONSET_MAX)
                                       for u in sc.unknown_faults))
    if not sc.simultaneous:  # every unit has a mode, so none could develop a fault outside the seven
        n = len(degradations)
        fields.update(healthy_probability=0.0, unknown_faults=(),
                      degradations=tuple(dataclasses.replace(d, probability=1.0 / n) for d in degradations))
    fields.update(changes)
    return dataclasses.replace(sc, **fields)


def tiny_scenario_data(data: dict) -> dict:
    """Shrink a scenario file's parsed YAML to the tiny sizes in place (flights of TINY_FILE_MINUTES)."""
    data["fleet"]["units"] = TINY_UNITS
    data["fleet"]["flights_per_unit"] = TINY_FLIGHTS
    data["mission"]["duration_min"] = TINY_FILE_MINUTES
    data["training"]["units"] = TINY_TRAINING_UNITS
    data["training"]["flights_per_unit"] = TINY_TRAINING_FLIGHTS
    for d in data["degradations"]:
        d["onset_min"], d["onset_max"], d["ramp_flights"] = TINY_ONSET_MIN, TINY_FILE_ONSET_MAX, TINY_RAMP_FLIGHTS
    for u in data.get("unknown_faults") or ():
        u["onset_min"], u["onset_max"] = TINY_ONSET_MIN, TINY_FILE_ONSET_MAX
    if data.get("simultaneous") is False:
        data["healthy_probability"] = 0.0
        data["unknown_faults"] = []  # every unit has a mode, so none could develop a fault outside the seven
        for d in data["degradations"]:
            d["probability"] = 1.0 / len(data["degradations"])
    return data
