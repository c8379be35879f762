"""Robustness measured: nominal-parameter drift swept one parameter at a time.

The paper defines robustness as the capacity of the monitoring system to stay efficient when
parameters drift from their nominal values. A single drift vector says little (it may happen to
help a method); this module sweeps each parameter *alone* over several magnitudes and reports,
for each, the change of the false-positive and of the false-negative rate
(:func:`fuelhm_bench.scoring.drift_sweep_table`) and the drift at which the method degrades by a
stated amount (:func:`fuelhm_bench.scoring.degradation_summary`).

Protocol: the scenario's training fleet and published knowledge are built once (with no drift:
the drift is of the scored units); the method is fitted and calibrated on them, then run on the
scenario's scored fleet without drift (the nominal run) and with each (parameter, magnitude)
drift applied to the scored fleet's nominal model (same seeds: same units, schedules and flights;
only the drifted parameter differs). Every run goes through
:func:`fuelhm_bench.benchmark.harness.run_in_env` (the sealed method process with its limits).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field

import pandas as pd

from fuelhm_bench.errors import FuelHMError, MethodError, ParameterError

__all__ = ["DriftSweep", "DriftSweepResult", "check_sweep", "run_drift_sweep"]

_CHANGES = ("relative", "absolute")


@dataclass(frozen=True)
class DriftSweep:
    """Which parameters to drift, alone, and by how much.

    Parameters
    ----------
    parameters : tuple of str
        Dotted model parameter paths (as in a scenario's ``drift``, e.g.
        ``"fluid.supply_rise_at_100pct_pa"``), at least one.
    magnitudes : tuple of float, default=(0.05, 0.1, 0.2)
        At least three distinct non-zero values: fractions for ``relative`` (new = nominal
        x (1 + m), m > -1), SI units for ``absolute`` (new = nominal + m). Each drift must also pass the
        scenario's drift rules (:func:`check_sweep`: within a factor 2 of the nominal value, and a
        parameter that adds to a degradation mode's within a quarter of that mode's full change).
    change : {"relative", "absolute"}, default="relative"
    tolerance : float, default=0.05
        Degradation threshold of the summary: a rise of the FPR or the FNR by more than this
        (absolute, 0.05 = 5 points), in (0, 1).
    """

    parameters: tuple = ("fluid.supply_rise_at_100pct_pa",)
    magnitudes: tuple = (0.05, 0.1, 0.2)
    change: str = "relative"
    tolerance: float = 0.05

    def __post_init__(self) -> None:
        params = tuple(self.parameters) if not isinstance(self.parameters, str) else None
        if not params or not all(isinstance(p, str) and p for p in params) or len(set(params)) != len(params):
            raise ParameterError(f"The 'parameters' parameter of DriftSweep must be a non-empty list of distinct "
                                 f"parameter paths. Got {self.parameters!r} instead.")
        try:
            mags = tuple(float(m) for m in self.magnitudes)
        except (TypeError, ValueError):
            mags = ()
        if len(set(mags)) < 3 or any(m == 0.0 or m != m for m in mags):
            raise ParameterError(f"The 'magnitudes' parameter of DriftSweep must be at least three distinct "
                                 f"non-zero numbers. Got {self.magnitudes!r} instead.")
        if self.change not in _CHANGES:
            raise ParameterError(f"The 'change' parameter of DriftSweep must be one of {list(_CHANGES)}. "
                                 f"Got {self.change!r} instead.")
        if self.change == "relative" and min(mags) <= -1.0:
            raise ParameterError(f"The 'magnitudes' parameter of DriftSweep must be > -1 for relative changes. "
                                 f"Got {self.magnitudes!r} instead.")
        if isinstance(self.tolerance, bool) or not isinstance(self.tolerance, (int, float)) \
                or not 0.0 < self.tolerance < 1.0:
            raise ParameterError(f"The 'tolerance' parameter of DriftSweep must be a float in (0, 1). "
                                 f"Got {self.tolerance!r} instead.")
        object.__setattr__(self, "parameters", params)
        object.__setattr__(self, "magnitudes", mags)

    def specs(self):
        """``[((parameter, magnitude), DriftSpec)]`` of every drifted run."""
        from fuelhm_bench.scenarios.schema import DriftSpec

        return [((p, m), DriftSpec(parameter=p, change=self.change, value=m))
                for p in self.parameters for m in self.magnitudes]


@dataclass(frozen=True)
class DriftSweepResult:
    """What :func:`run_drift_sweep` measured.

    Attributes
    ----------
    sweep : DriftSweep
    method : str
        ``repr`` of the method.
    table : pandas.DataFrame
        :func:`~fuelhm_bench.scoring.drift_sweep_table`: FPR, FNR and balanced accuracy of each
        drifted run and their changes from the nominal run.
    summary : pandas.DataFrame
        :func:`~fuelhm_bench.scoring.degradation_summary` at ``sweep.tolerance``.
    nominal : Run
        The run without drift.
    runs : dict
        ``{(parameter, magnitude): Run}``.
    """

    sweep: DriftSweep
    method: str
    table: pd.DataFrame
    summary: pd.DataFrame
    nominal: object
    runs: dict = field(repr=False)

    def to_markdown(self) -> str:
        """The sweep table and the summary sentences."""
        lines = [f"## Drift sweep: {self.method}", "",
                 "| parameter | drift | FPR | dFPR | FNR | dFNR | balanced accuracy |", "|---|---|---|---|---|---|---|"]
        for r in self.table.itertuples():
            lines.append(f"| {r.parameter} | {r.magnitude:g} | {r.fpr_drifted:.3f} | {r.delta_fpr:+.3f} | "
                         f"{r.fnr_drifted:.3f} | {r.delta_fnr:+.3f} | {r.balanced_accuracy_drifted:.3f} |")
        lines += ["", f"Nominal: FPR {self.table['fpr_nominal'].iloc[0]:.3f}, "
                      f"FNR {self.table['fnr_nominal'].iloc[0]:.3f}.", ""]
        lines += [f"* {s}" for s in self.summary["summary"]]
        return "\n".join(lines)


#: How :func:`check_sweep` names the sweep's fields by default (the command line passes its options).
API_NAMES = {"parameters": "DriftSweep.parameters", "magnitudes": "DriftSweep.magnitudes"}


def check_sweep(sweep: DriftSweep, scenario, *, names: dict | None = None):
    """The scenario without its own drift, once every swept drift passes the scenario's drift rules.

    Each ``(parameter, magnitude)`` is checked as a scenario ``drift`` entry would be (one definition:
    :meth:`fuelhm_bench.scenarios.Scenario` validation, :func:`fuelhm_bench.scenarios.schema.drift_range`),
    before anything is simulated.

    Parameters
    ----------
    sweep : DriftSweep
    scenario : str, Path or Scenario
    names : dict or None, default=None
        How messages name the sweep's ``parameters`` and ``magnitudes`` (default :data:`API_NAMES`;
        the command line gives ``{"parameters": "--parameters", "magnitudes": "--magnitudes"}``).

    Returns
    -------
    Scenario

    Raises
    ------
    ParameterError
        Naming the parameter or magnitude as the user gave it, what is allowed and why.
    """
    from fuelhm_bench.errors import ScenarioValidationError
    from fuelhm_bench.scenarios import load_scenario

    names = {**API_NAMES, **(names or {})}
    sc = load_scenario(scenario) if not hasattr(scenario, "test_fleet_config") else scenario
    sc = dataclasses.replace(sc, drift=())
    for (parameter, magnitude), spec in sweep.specs():
        try:
            dataclasses.replace(sc, drift=(spec,))
        except ScenarioValidationError as exc:
            problem = exc.problems[0]
            if problem.field.endswith(".parameter"):
                where = f"{names['parameters']} {parameter}"
            else:
                where = f"{names['magnitudes']} {magnitude:g} ({sweep.change}, on {parameter})"
            hint = f" {problem.hint}" if problem.hint else ""
            raise ParameterError(f"{where}: must be {problem.allowed}.{hint}") from None
        except FuelHMError as exc:
            raise ParameterError(f"{names['parameters']} {parameter}, {names['magnitudes']} {magnitude:g}: "
                                 f"{exc}") from None
    return sc


def run_drift_sweep(method, scenario, sweep: DriftSweep | None = None, *, scale: float = 1.0, doe_units: int = 6,
                    seed: int | None = None, random_state: int = 0, timeout_s: float = 600.0,
                    progress: Callable[[int], object] | None = None, cache_dir=None) -> DriftSweepResult:
    """Run one method through a drift sweep on a scenario (see the module docstring).

    Parameters
    ----------
    method : object
        A method of the common interface (:class:`fuelhm_bench.methods.Method`).
    scenario : str, Path or Scenario
        Its training fleet, published knowledge and scored fleet; the scenario's own ``drift``
        is ignored (each run carries one swept drift only).
    sweep : DriftSweep or None, default=None
        None: :class:`DriftSweep()` (supply pressure rise +5, +10, +20 %).
    scale : float, default=1.0
        Multiplies the number of scored units (quick looks).
    doe_units : int
        Units of the design of experiments of the published knowledge
        (:class:`~fuelhm_bench.datasets.cache.KnowledgeSize`).
    seed : int or None
        Overrides the scenario's master seed.
    random_state : int, default=0
        Passed to the method's ``fit``.
    timeout_s : float, default=600.0
        Wall-clock limit of each run.
    progress : callable, optional
        Called with numbers of flights simulated.
    cache_dir : path or None, default=None
        Simulation cache (None: the default cache directory).

    Returns
    -------
    DriftSweepResult

    Raises
    ------
    ParameterError
        A swept parameter path the model does not have, or a value it rejects.
    MethodError
        The method failed on one of the runs (the message says which).
    """
    from fuelhm_bench.benchmark.harness import prepare_evaluation, run_in_env
    from fuelhm_bench.datasets.cache import KnowledgeSize
    from fuelhm_bench.scoring import degradation_summary, drift_sweep_table

    sweep = DriftSweep() if sweep is None else sweep
    if not isinstance(sweep, DriftSweep):
        raise ParameterError(f"The 'sweep' parameter of run_drift_sweep must be a DriftSweep. Got {sweep!r} instead.")
    sc = check_sweep(sweep, scenario)  # fail before simulating anything
    specs = sweep.specs()
    common = {"fidelity": "physics", "seed": seed, "scale": scale, "robustness": False,
              "knowledge_size": KnowledgeSize(doe_units=doe_units), "progress": progress, "cache_dir": cache_dir}

    def run_on(variant, label):
        evaluation = prepare_evaluation(variant, **common)  # same training, knowledge and seeds for every variant
        outcome = run_in_env(method, evaluation, random_state=random_state, timeout_s=timeout_s)
        if not outcome.ok:
            raise MethodError(f"{outcome.method} failed on the {label} run of the drift sweep: {outcome.status}: "
                              f"{outcome.message.splitlines()[0] if outcome.message else ''}")
        return outcome.run(name=f"{outcome.method} ({label})")

    nominal = run_on(sc, "no drift")
    runs = {key: run_on(dataclasses.replace(sc, drift=(spec,)), f"{key[0]} {key[1]:+g}") for key, spec in specs}
    table = drift_sweep_table(nominal, runs)
    summary = degradation_summary(table, tolerance=sweep.tolerance)
    return DriftSweepResult(sweep, repr(method), table, summary, nominal, runs)
