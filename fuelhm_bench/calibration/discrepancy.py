"""The model-discrepancy workflow: which effect is the model missing, and how much does it explain.

Given measured healthy flights and a model (nominal by default):

1. **Split** the flights into *fit* and *held-out* flights (:func:`split_fit_holdout`: about
   ``holdout_fraction`` of the flights, by flight, seeded, stratified so that every unit
   with two flights or more keeps one for fitting).
2. **Recalibrate** the model on the fit flights, per unit
   (:data:`~fuelhm_bench.calibration.recalibrate.RECALIBRATION_PARAMETERS`): what is left is
   not manufacturing dispersion.
3. **Find where they disagree**: replay every flight through the model
   (:mod:`~fuelhm_bench.calibration.replay`: measured current imposed, measured N2, rod
   position forced to the measured one at each frame, model LVDT applied, differentiated
   like the measurement) and map the velocity residuals over operating regions
   (:mod:`~fuelhm_bench.calibration.regions`); the region with the largest local gap is
   named.
4. **Name the missing effect**: for every candidate of the effect library
   (:mod:`~fuelhm_bench.calibration.candidates`), fit its parameters (fleet-wide, bounded by
   the documented ranges, multi-start over a grid) jointly with the per-unit recalibration
   parameters, by bounded least squares on the fit flights.
5. **Decide** (:func:`decide`): candidates are ranked by BIC on the fit flights under the
   noise model of :class:`NoiseModel`; the best-ranked candidate is accepted if it *earns its
   parameters*: its BIC is lower than the recalibrated model's by more than
   ``bic_threshold`` (10: "very strong" evidence) **and** it shrinks the gap on the held-out
   flights, which took no part in any fit, by at least ``min_gap_reduction`` (30 %) relative
   to recalibration alone. Otherwise the answer is ``none``. The held-out condition is the
   one that matters in practice: the fit-flight likelihood of a wrong candidate still rises
   when its parameters can soak up some unit-specific misfit (BIC differences of hundreds on
   healthy data), but that gain does not carry over to other flights.
6. **Add it**: the augmented model (fleet mean of the unit values, plus the effect) is
   returned for :func:`~fuelhm_bench.physics.model.save_model`; gaps before (input model),
   after recalibration and after augmentation are all measured on the held-out flights.
"""

from __future__ import annotations

import dataclasses
import math
import multiprocessing
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from fuelhm_bench.calibration import replay as rp
from fuelhm_bench.calibration.candidates import EffectCandidate, get_candidates
from fuelhm_bench.calibration.curve import CurveConfig, gap, gap_metric_text, gap_noise_floor
from fuelhm_bench.calibration.fit import JointFit, apply_values, fit_joint
from fuelhm_bench.calibration.recalibrate import (
    NO_UNIT,
    RECALIBRATION_PARAMETERS,
    CalibrationConfig,
    check_excitation,
    fleet_values,
    merge_sets,
    model_for_data,
    prepare_units,
    unit_key,
)
from fuelhm_bench.calibration.regions import region_map, sample_levels
from fuelhm_bench.errors import DataFormatError, range_error
from fuelhm_bench.physics.effects import effect_parameters
from fuelhm_bench.taxonomy import EFFECT_IDS

#: Misfit score (mean z^2 of the curve cells, :mod:`~fuelhm_bench.calibration.regions`) of the
#: recalibrated model on the held-out flights above which a disagreement is reported as significant.
SIGNIFICANT_SCORE = 3.0

#: Candidate fits use Broyden updates of the recalibration columns of the Jacobian
#: (:func:`~fuelhm_bench.calibration.fit.fit_joint`).
BROYDEN = True

#: Units of the effect parameters (for reports and JSON).
PARAMETER_UNITS: dict[str, str] = {
    "overlap_m": "m", "stiffness_ratio": "-", "coulomb_n": "N", "static_ratio": "-",
    "stribeck_velocity_m_s": "m/s", "viscous_n_s_m": "N s/m", "time_constant_s": "s",
    "stiffness_n_m": "N/m", "reference_m": "m", "width_a": "A",
}


@dataclass(frozen=True)
class DiscrepancyConfig:
    """Settings of the discrepancy workflow.

    Parameters
    ----------
    calibration : CalibrationConfig
        Replay, curve and recalibration settings (``fit_max_frames`` caps the fit flights'
        replayed frames, ``max_iterations`` the recalibration).
    holdout_fraction : float, default=0.3
        Share of the flights held out, in (0, 0.9].
    heldout_max_frames : int or None, default=200000
        Cap on the replayed frames of the held-out flights (segments drawn at random, seeded;
        None: all).
    candidates : tuple of str, default=all effect ids
        Candidate effects.
    bic_threshold : float, default=10.0
        BIC improvement over the recalibrated model a candidate needs [-].
    min_gap_reduction : float, default=0.3
        Relative held-out gap reduction over the recalibrated model a candidate needs, in [0, 1).
    candidate_iterations : int, default=12
        Trust-region iterations of each candidate fit.
    n_jobs : int, default=1
        Worker processes for the candidate fits.
    seed : int, default=0
        Seed of the split and of the segment draws.
    """

    calibration: CalibrationConfig = field(default_factory=lambda: CalibrationConfig(fit_max_frames=40000))
    holdout_fraction: float = 0.3
    heldout_max_frames: int | None = 200000
    candidates: tuple = EFFECT_IDS
    bic_threshold: float = 10.0
    min_gap_reduction: float = 0.3
    candidate_iterations: int = 12
    n_jobs: int = 1
    seed: int = 0

    def __post_init__(self) -> None:
        if not (isinstance(self.holdout_fraction, (int, float)) and 0.0 < self.holdout_fraction <= 0.9):
            raise range_error("DiscrepancyConfig.holdout_fraction", "in (0, 0.9]", self.holdout_fraction)
        if not isinstance(self.candidates, tuple) or not self.candidates:
            raise range_error("DiscrepancyConfig.candidates", "a non-empty tuple of effect ids", self.candidates)
        if not (isinstance(self.min_gap_reduction, (int, float)) and 0.0 <= self.min_gap_reduction < 1.0):
            raise range_error("DiscrepancyConfig.min_gap_reduction", "in [0, 1)", self.min_gap_reduction)
        if not (isinstance(self.bic_threshold, (int, float)) and math.isfinite(self.bic_threshold)):
            raise range_error("DiscrepancyConfig.bic_threshold", "a finite number", self.bic_threshold)
        for name in ("candidate_iterations", "n_jobs"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise range_error(f"DiscrepancyConfig.{name}", "an integer >= 1", v)
        if self.heldout_max_frames is not None and (not isinstance(self.heldout_max_frames, int) or isinstance(
                self.heldout_max_frames, bool) or self.heldout_max_frames < 2000):
            raise range_error("DiscrepancyConfig.heldout_max_frames", "None or an integer >= 2000",
                              self.heldout_max_frames)
        if not isinstance(self.seed, int) or isinstance(self.seed, bool) or self.seed < 0:
            raise range_error("DiscrepancyConfig.seed", "an integer >= 0", self.seed)

    @property
    def decision_rule(self) -> str:
        """The decision rule in words."""
        return (f"accept the candidate with the lowest BIC on the fit flights if its BIC is lower than the "
                f"recalibrated model's by more than {self.bic_threshold:g} AND it reduces the held-out gap by at "
                f"least {100 * self.min_gap_reduction:g} % relative to recalibration alone; otherwise 'none'")


@dataclass(frozen=True)
class NoiseModel:
    """Noise model of the velocity residuals behind the BIC.

    Residuals are Gaussian, zero-mean, with one variance (profiled: ``sigma^2 = RSS / n``),
    and serially correlated: the differentiator window and the spool/LVDT memory correlate
    neighbouring samples. The correlation is accounted for by an effective number of
    independent residuals ``n_eff = n / tau``, with ``tau = 1 + 2 sum_{l=1}^{L} rho_l`` the
    integrated autocorrelation time of the recalibrated model's residuals on the fit flights
    (within segments, ``L = 4 h`` lags, ``tau >= 1``). Then, for ``k`` fitted values,
    ``BIC = n_eff ln(RSS / n) + k ln(n_eff)`` (up to a constant common to all candidates).

    Attributes
    ----------
    n : int
        Residuals.
    tau : float
        Integrated autocorrelation time [samples].
    sigma_mm_s : float
        Residual standard deviation of the recalibrated model [mm/s].
    """

    n: int
    tau: float
    sigma_mm_s: float

    @property
    def n_eff(self) -> float:
        """Effective number of independent residuals."""
        return self.n / self.tau

    def bic(self, rss: float, k: int) -> float:
        """BIC of a fit with residual sum of squares ``rss`` [(mm/s)^2] and ``k`` fitted values."""
        return self.n_eff * math.log(max(rss, 1e-300) / self.n) + k * math.log(self.n_eff)


def correlation_time(sets: Sequence[rp.ReplaySet], velocities: Sequence[np.ndarray]) -> float:
    """Integrated autocorrelation time of the residuals ``v_meas - v`` [samples], ``>= 1``.

    ``tau = 1 + 2 sum_{l=1}^{L} rho_l`` with the autocorrelations ``rho_l`` pooled over the
    segments of the sets (scored samples only, ``L = 4 h`` lags).
    """
    lags = 4 * max(rs.config.half_width for rs in sets)
    num = np.zeros(lags + 1)
    den = 0.0
    for rs, v in zip(sets, velocities):
        r = np.where(rs.scored, rs.v_meas_mm_s - v, np.nan)
        for s, n in zip(rs.starts, rs.lengths):
            seg = r[s:s + n]
            seg = seg[np.isfinite(seg)]
            if seg.size <= lags + 1:
                continue
            den += float(seg @ seg)
            for lag in range(1, lags + 1):
                num[lag] += float(seg[:-lag] @ seg[lag:])
    if den <= 0.0:
        return 1.0
    return max(1.0, 1.0 + 2.0 * float(np.sum(num[1:] / den)))


def noise_model(fit: JointFit, sets: dict) -> NoiseModel:
    """Estimate :class:`NoiseModel` from a fit's residuals (see its docstring)."""
    vs = rp.replay_batch([fit.unit_models[k] for k in sets], [sets[k] for k in sets])
    return NoiseModel(max(fit.n_residuals, 1), correlation_time(list(sets.values()), vs), fit.rms)


@dataclass(frozen=True)
class CandidateOutcome:
    """Result of one candidate effect (or of ``none``: recalibration alone).

    Attributes
    ----------
    effect : str
        Effect id or ``"none"``.
    parameters : dict
        Fitted effect parameters [SI] (with the held ones).
    bic : float
        BIC on the fit flights [-].
    delta_bic : float
        BIC of the recalibrated model minus this BIC (> 0: better) [-].
    rss : float
        Residual sum of squares on the fit flights [(mm/s)^2].
    gap_after : float
        Held-out gap with this candidate [mm/s].
    gap_reduction : float
        ``1 - gap_after / gap_recalibrated`` on the held-out flights [-].
    eligible : bool
        Whether it passes both conditions of the decision rule.
    passes : int
        Model replays spent on it.
    seconds : float
        Wall time [s].
    unit_values : dict
        Recalibration values per unit fitted jointly with the effect [SI].
    """

    effect: str
    parameters: dict
    bic: float
    delta_bic: float
    rss: float
    gap_after: float
    gap_reduction: float
    eligible: bool
    passes: int
    seconds: float
    unit_values: dict

    def as_json(self) -> dict:
        """JSON-ready summary."""
        return {
            "effect": self.effect,
            "parameters": {k: {"value": v, "unit": PARAMETER_UNITS.get(k, "")} for k, v in self.parameters.items()},
            "bic": self.bic, "delta_bic": self.delta_bic, "gap_after": self.gap_after,
            "gap_reduction": self.gap_reduction, "eligible": self.eligible,
        }


@dataclass(frozen=True, eq=False)
class DiscrepancyResult:
    """Outcome of :func:`find_discrepancy`.

    Attributes
    ----------
    effect : str
        The named effect id, or ``"none"``.
    parameters : dict
        Its fitted parameters [SI] (empty for ``none``).
    region : str
        Where the disagreement of the recalibrated model concentrates (held-out flights).
    gap_metric : str
        Definition of the gap.
    gap_before, gap_recalibrated, gap_after : float
        Held-out gap [mm/s]: input model, recalibrated model, recalibrated + named effect.
    gap_floor : float
        Noise floor of the held-out gap of the final model [mm/s]
        (:func:`~fuelhm_bench.calibration.curve.gap_noise_floor`, with the correlation time of
        its own held-out residuals): a ``gap_after`` near it leaves nothing but noise to explain.
    ranking : tuple of CandidateOutcome
        All candidates and ``none``, by increasing BIC.
    model : LoopModel
        The augmented fleet model (the recalibrated one when ``none``).
    recalibrated_model : LoopModel
        The recalibrated fleet model without effect.
    start_model : LoopModel
        The input model (with the data's frame).
    noise : NoiseModel
        Noise model of the BIC.
    maps : dict
        :class:`RegionMap` on the held-out flights for ``"input"``, ``"recalibrated"``, ``"augmented"``.
    heldout : ReplaySet
        Held-out samples (for curves and plots).
    v_heldout : dict
        Replayed velocity per model label on ``heldout`` [mm/s].
    fit_flights, heldout_flights : tuple
        Flight ids of the split.
    decision_rule : str
        The rule applied.
    frame_s : float
        Sample period [s].
    n2_measured : bool
        Whether N2 came from the file.
    seconds : float
        Wall time [s].
    curve : CurveConfig
        Cells of the gap metric.
    """

    effect: str
    parameters: dict
    region: str
    gap_metric: str
    gap_before: float
    gap_recalibrated: float
    gap_after: float
    gap_floor: float
    ranking: tuple
    model: object
    recalibrated_model: object
    start_model: object
    noise: NoiseModel
    maps: dict
    heldout: rp.ReplaySet
    v_heldout: dict
    fit_flights: tuple
    heldout_flights: tuple
    decision_rule: str
    frame_s: float
    n2_measured: bool
    seconds: float
    curve: CurveConfig

    @property
    def gap_reduction(self) -> float:
        """``1 - gap_after / gap_before`` on the held-out flights [-]."""
        return 1.0 - self.gap_after / self.gap_before if self.gap_before > 0 else float("nan")

    def as_json(self) -> dict:
        """The JSON object printed by ``fuelhm-bench discrepancy --json``."""
        return {
            "effect": self.effect,
            "parameters": {k: {"value": v, "unit": PARAMETER_UNITS.get(k, "")} for k, v in self.parameters.items()},
            "region": self.region,
            "region_levels": [{"factor": lv.factor, "level": lv.level, "samples": lv.count, "score": lv.score,
                               "local_gap": lv.local_gap_mm_s}
                              for lv in self.maps["recalibrated"].ranked()[:5]],
            "gap_metric": self.gap_metric,
            "gap_before": self.gap_before,
            "gap_recalibrated": self.gap_recalibrated,
            "gap_after": self.gap_after,
            "gap_reduction": self.gap_reduction,
            "gap_noise_floor": self.gap_floor,
            "ranking": [c.as_json() for c in self.ranking],
            "decision_rule": self.decision_rule,
            "noise_model": {"n": self.noise.n, "tau_samples": self.noise.tau, "n_eff": self.noise.n_eff,
                            "sigma_mm_s": self.noise.sigma_mm_s},
            "recalibrated": {k: v for k, v in _recal_values(self.model).items()},
            "fit_flights": [_jsonable(f) for f in self.fit_flights],
            "heldout_flights": [_jsonable(f) for f in self.heldout_flights],
            "frame_s": self.frame_s,
            "n2_measured": self.n2_measured,
            "seconds": self.seconds,
        }


def _jsonable(x):
    return x.item() if isinstance(x, np.generic) else x


def _recal_values(model) -> dict:
    return {p.path: {"value": float(model.get(p.path)), "unit": p.unit} for p in RECALIBRATION_PARAMETERS}


# --------------------------------------------------------------------------- split
def split_fit_holdout(flights, fraction: float = 0.3, seed: int = 0) -> tuple[list, list]:
    """Split flights into fit and held-out flights (seeded, by flight, stratified by unit).

    About ``round(fraction * n)`` flights (at least one, at most ``n - 1``) are held out.
    Each unit keeps its first flight (in a seeded shuffle) for fitting as long as possible;
    held-out flights are taken round-robin over the units from their remaining flights, then,
    if still short, whole single-flight units are held out.

    Raises
    ------
    DataFormatError
        Fewer than two flights.
    """
    flights = list(flights)
    n = len(flights)
    if n < 2:
        raise DataFormatError(
            f"Too few flights to hold out: got {n} usable flight(s). The discrepancy workflow fits on some "
            "flights and measures the gap on others it never saw, so it needs at least 2 flights (better 5 or "
            "more, 3 minutes or longer, each with transients such as the engine-start test sweep).")
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), 5150]))
    n_hold = min(max(int(round(fraction * n)), 1), n - 1)
    by_unit: dict = {}
    for idx, f in enumerate(flights):
        by_unit.setdefault(unit_key(f), []).append(idx)
    units = list(by_unit)
    order = [units[j] for j in rng.permutation(len(units))]
    shuffled = {u: [by_unit[u][j] for j in rng.permutation(len(by_unit[u]))] for u in order}
    spare = [shuffled[u][1:] for u in order]
    held: list[int] = []
    depth = 0
    while len(held) < n_hold and any(depth < len(s) for s in spare):
        for s in spare:
            if depth < len(s) and len(held) < n_hold:
                held.append(s[depth])
        depth += 1
    for u in order:
        if len(held) >= n_hold:
            break
        if len(shuffled[u]) == 1:
            held.append(shuffled[u][0])
    held_set = set(held)
    return [f for i, f in enumerate(flights) if i not in held_set], [f for i, f in enumerate(flights) if i in held_set]


# --------------------------------------------------------------------------- candidates
def _with_effect(model, cand: EffectCandidate, values: dict):
    return model.with_effect(cand.effect, **values)


def _rss(models: dict, sets: dict) -> float:
    vs = rp.replay_batch([models[k] for k in sets], [sets[k] for k in sets])
    total = 0.0
    for rs, v in zip(sets.values(), vs):
        r = (rs.v_meas_mm_s - v)[rs.scored]
        total += float(r @ r)
    return total


def heldout_models(unit_models: dict, fleet, held_sets: dict) -> dict:
    """Model per held-out unit: its own recalibrated model, or the fleet model for a unit not fitted."""
    return {k: unit_models.get(k, fleet) for k in held_sets}


def _fit_candidate(cand: EffectCandidate, base: JointFit, fit_sets: dict, held_sets: dict, start_model,
                   parameters: tuple, iterations: int, curve: CurveConfig) -> tuple[JointFit, float, float]:
    """Multi-start grid, joint fit, held-out gap. Returns (fit, held-out gap, seconds).

    Start points: every grid point of the effect, combined with two sets of unit values --
    the recalibrated ones (which may have drifted to mimic the missing effect) and the input
    model's. The fit starts from the combination with the lowest RSS.
    """
    t0 = time.perf_counter()
    origin = {k: {p.path: float(start_model.get(p.path)) for p in parameters} for k in base.unit_models}
    best = None
    for unit_values in (base.unit_values, origin):
        units = {k: apply_values(start_model, unit_values[k]) for k in base.unit_models}
        for point in cand.grid:
            values = cand.start_values(point)
            models = {k: _with_effect(m, cand, values) for k, m in units.items()}
            rss = _rss(models, fit_sets)
            if best is None or rss < best[0]:
                best = (rss, values, unit_values, models)
    _, values, unit_values, models = best
    shared_start = {p.path: models[next(iter(models))].get(p.path) for p in cand.parameters}
    res = fit_joint(models, fit_sets, parameters, cand.parameters, unit_start=unit_values,
                    shared_start=shared_start, max_iterations=iterations, broyden=BROYDEN)
    fleet = apply_values(_with_effect(start_model, cand, cand.start_values({})),
                         {**fleet_values(res.unit_values, parameters), **res.shared_values})
    hm = heldout_models(res.unit_models, fleet, held_sets)
    g = gap(merge_sets(list(held_sets.values())),
            np.concatenate(rp.replay_batch([hm[k] for k in held_sets], list(held_sets.values()))), curve)
    return res, g, time.perf_counter() - t0


_WORKER: dict = {}


def _worker_init(payload: dict) -> None:  # pragma: no cover - runs in worker processes
    _WORKER.update(payload)


def _worker_task(effect: str):  # pragma: no cover - runs in worker processes
    w = _WORKER
    cand = next(c for c in w["candidates"] if c.effect == effect)
    res, g, sec = _fit_candidate(cand, w["base"], w["fit_sets"], w["held_sets"], w["start_model"], w["parameters"],
                                 w["iterations"], w["curve"])
    return effect, res, g, sec


def _run_candidates(cands: list, payload: dict, n_jobs: int, progress) -> dict:
    out = {}
    if n_jobs > 1 and len(cands) > 1 and "fork" in multiprocessing.get_all_start_methods():
        ctx = multiprocessing.get_context("fork")
        with ProcessPoolExecutor(max_workers=min(n_jobs, len(cands)), mp_context=ctx, initializer=_worker_init,
                                 initargs=(payload,)) as pool:
            # Slowest first (direct-mode effects), so the two workers finish together.
            order = sorted(cands, key=lambda c: c.effect not in ("rod_friction", "load_stiffness"))
            futures = [pool.submit(_worker_task, c.effect) for c in order]
            for fut in futures:
                effect, res, g, sec = fut.result()
                out[effect] = (res, g, sec)
                if progress is not None:
                    progress(1)
        return out
    for cand in cands:
        res, g, sec = _fit_candidate(cand, payload["base"], payload["fit_sets"], payload["held_sets"],
                                     payload["start_model"], payload["parameters"], payload["iterations"],
                                     payload["curve"])
        out[cand.effect] = (res, g, sec)
        if progress is not None:
            progress(1)
    return out


# --------------------------------------------------------------------------- decision
def is_eligible(outcome: CandidateOutcome, *, bic_threshold: float, min_gap_reduction: float) -> bool:
    """Whether a candidate earns its parameters: BIC gain > ``bic_threshold`` and held-out gap reduction
    >= ``min_gap_reduction`` (both relative to recalibration alone)."""
    return (outcome.effect != "none" and outcome.delta_bic > bic_threshold
            and outcome.gap_reduction >= min_gap_reduction)


def decide(outcomes: Sequence[CandidateOutcome], *, bic_threshold: float, min_gap_reduction: float) -> str:
    """Apply the decision rule (:attr:`DiscrepancyConfig.decision_rule`): an effect id or ``"none"``.

    Among the eligible candidates (:func:`is_eligible`), the one with the lowest BIC.
    """
    eligible = [c for c in outcomes
                if is_eligible(c, bic_threshold=bic_threshold, min_gap_reduction=min_gap_reduction)]
    if not eligible:
        return "none"
    return min(eligible, key=lambda c: c.bic).effect


# --------------------------------------------------------------------------- workflow
def find_discrepancy(flights, model=None, *, config: DiscrepancyConfig = DiscrepancyConfig(),
                     progress: Callable[[int], None] | None = None,
                     log: Callable[[str], None] | None = None) -> DiscrepancyResult:
    """Run the discrepancy workflow (module docstring) on measured healthy flights.

    Parameters
    ----------
    flights : sequence of FlightArrays
        Checked healthy flights (:func:`fuelhm_bench.io.split_flights`), file units.
    model : LoopModel, optional
        Model to examine (default nominal). Effects it already has are not candidates.
    config : DiscrepancyConfig
        Settings.
    progress : callable, optional
        Called with 1 after the recalibration and after each candidate
        (``1 + number of candidates`` calls).
    log : callable, optional
        Receives one-line progress messages.

    Returns
    -------
    DiscrepancyResult

    Raises
    ------
    DataFormatError
        Fewer than two flights, several sample rates, no scored sample, or not enough excitation.
    """
    from fuelhm_bench.physics.model import LoopModel

    t_start = time.perf_counter()
    say = log if log is not None else (lambda msg: None)
    flights = list(flights)
    if len(flights) < 2:
        split_fit_holdout(flights)  # raises the documented message
    frame_s = rp.estimate_frame(flights)
    start = model_for_data(model if model is not None else LoopModel(), frame_s)
    present = {e.id for e in start.effects}
    cand_ids = tuple(c for c in config.candidates if c not in present)
    cands = get_candidates(cand_ids, start.cylinder.stroke_m)
    cal = config.calibration
    params = tuple(RECALIBRATION_PARAMETERS)

    fit_flights, held_flights = split_fit_holdout(flights, config.holdout_fraction, config.seed)
    say(f"split: {len(fit_flights)} fit flight(s), {len(held_flights)} held-out flight(s)")
    fit_sets = prepare_units(fit_flights, start, cal, frame_s=frame_s, max_frames=cal.fit_max_frames,
                             seed=config.seed)
    check_excitation(fit_sets, "the fit flights")
    held_sets = prepare_units(held_flights, start, cal, frame_s=frame_s, max_frames=config.heldout_max_frames,
                              seed=config.seed + 1)
    held = merge_sets(list(held_sets.values()))

    def held_velocity(models: dict) -> np.ndarray:
        return np.concatenate(rp.replay_batch([models[k] for k in held_sets], list(held_sets.values())))

    v_input = held_velocity({k: start for k in held_sets})
    g_before = gap(held, v_input, cal.curve)
    say(f"held-out gap of the input model: {g_before:.3f} mm/s")

    base = fit_joint({k: start for k in fit_sets}, fit_sets, params, max_iterations=cal.max_iterations)
    noise = noise_model(base, fit_sets)
    say(f"recalibrated ({base.passes} replays): residual sigma {noise.sigma_mm_s:.3f} mm/s, correlation time "
        f"{noise.tau:.1f} samples")
    if progress is not None:
        progress(1)

    payload = {"candidates": cands, "base": base, "fit_sets": fit_sets, "held_sets": held_sets,
               "start_model": start, "parameters": params, "iterations": config.candidate_iterations,
               "curve": cal.curve}
    results = _run_candidates(cands, payload, config.n_jobs, progress)

    # The recalibration alone may have stopped in a poorer local minimum than one a candidate's fit
    # wandered into (the recalibration parameters try to mimic a missing effect). Score the
    # recalibration values of every candidate fit with the effect off, restart the recalibration
    # from the best of them, and keep the better fit, so that every candidate is compared with
    # the best recalibration-only fit found (nested models).
    if results:
        scored = []
        for eff, (res, _, _) in results.items():
            models = {k: apply_values(start, res.unit_values[k]) for k in fit_sets}
            scored.append((_rss(models, fit_sets), eff))
        rss_best, eff_best = min(scored)
        if rss_best < base.rss:
            retry = fit_joint({k: start for k in fit_sets}, fit_sets, params,
                              unit_start=results[eff_best][0].unit_values, max_iterations=cal.max_iterations)
            if retry.rss < base.rss:
                say(f"recalibration improved by a restart from the values of the {eff_best} fit: "
                    f"RSS {base.rss:.1f} -> {retry.rss:.1f} (mm/s)^2")
                base = retry
    fleet0 = apply_values(start, fleet_values(base.unit_values, params))
    v_recal = held_velocity(heldout_models(base.unit_models, fleet0, held_sets))
    g_recal = gap(held, v_recal, cal.curve)
    bic0 = noise.bic(base.rss, base.n_parameters)
    say(f"held-out gap after recalibration: {g_recal:.3f} mm/s")

    outcomes = [CandidateOutcome("none", {}, bic0, 0.0, base.rss, g_recal, 0.0, False, base.passes, 0.0,
                                 base.unit_values)]
    for cand in cands:
        res, g, sec = results[cand.effect]
        bic = noise.bic(res.rss, res.n_parameters)
        eff_model = res.unit_models[next(iter(res.unit_models))].effect(cand.effect)
        red = 1.0 - g / g_recal if g_recal > 0 else 0.0
        outcomes.append(CandidateOutcome(cand.effect, dict(effect_parameters(eff_model)), bic, bic0 - bic, res.rss,
                                         g, red, False, res.passes, sec, res.unit_values))
        say(f"candidate {cand.effect}: dBIC {bic0 - bic:.1f}, held-out gap {g:.3f} mm/s ({100 * red:+.0f} %), "
            f"{res.passes} replays, {sec:.1f} s")
    rule = {"bic_threshold": config.bic_threshold, "min_gap_reduction": config.min_gap_reduction}
    chosen = decide(outcomes, **rule)
    outcomes = [dataclasses.replace(c, eligible=is_eligible(c, **rule)) for c in outcomes]
    ranking = tuple(sorted(outcomes, key=lambda c: c.bic))

    if chosen == "none":
        final_model, v_after, g_after, eff_params = fleet0, v_recal, g_recal, {}
    else:
        res, g_after, _ = results[chosen]
        cand = next(c for c in cands if c.effect == chosen)
        final_model = apply_values(_with_effect(start, cand, cand.start_values({})),
                                   {**fleet_values(res.unit_values, params), **res.shared_values})
        v_after = held_velocity(heldout_models(res.unit_models, final_model, held_sets))
        eff_params = dict(effect_parameters(final_model.effect(chosen)))
    fleet_models = {k: (base.unit_models.get(k, fleet0)) for k in held_sets}
    levels = sample_levels(held, fleet_models,
                           lambda fi: NO_UNIT if held.unit_ids[fi] is None else held.unit_ids[fi])
    maps = {"input": region_map(held, v_input, levels, cal.curve, noise.tau),
            "recalibrated": region_map(held, v_recal, levels, cal.curve, noise.tau),
            "augmented": region_map(held, v_after, levels, cal.curve, noise.tau)}
    floor = gap_noise_floor(held, v_after, cal.curve, correlation_time([held], [v_after]))
    region = maps["recalibrated"].concentration()
    if not maps["recalibrated"].score > SIGNIFICANT_SCORE:
        region = (f"no significant disagreement (misfit score {maps['recalibrated'].score:.2g} over the held-out "
                  f"curve, noise gives about 1); largest local misfit: {region}")
    say(f"decision: {chosen}; held-out gap {g_before:.3f} -> {g_recal:.3f} (recalibrated) -> {g_after:.3f} mm/s")
    return DiscrepancyResult(
        effect=chosen, parameters=eff_params, region=region, gap_metric=gap_metric_text(cal.curve),
        gap_before=g_before, gap_recalibrated=g_recal, gap_after=g_after, gap_floor=floor, ranking=ranking,
        model=final_model,
        recalibrated_model=fleet0, start_model=start, noise=noise, maps=maps, heldout=held,
        v_heldout={"input": v_input, "recalibrated": v_recal, "augmented": v_after},
        fit_flights=tuple(f.flight_id for f in fit_flights), heldout_flights=tuple(f.flight_id for f in held_flights),
        decision_rule=config.decision_rule, frame_s=frame_s, n2_measured=held.n2_measured,
        seconds=time.perf_counter() - t_start, curve=cal.curve)


__all__ = ["CandidateOutcome", "DiscrepancyConfig", "DiscrepancyResult", "NoiseModel", "decide",
           "correlation_time", "find_discrepancy", "is_eligible", "noise_model", "split_fit_holdout"]
