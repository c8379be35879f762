"""Fidelity check: does the surrogate rank methods as the physics does?

:func:`fidelity_check` evaluates a panel of methods on one scenario at both
fidelities (the same scored units, the same methods, the same training data)
and compares what a user would conclude from each:

* **ranking**: Kendall's tau (``scipy.stats.kendalltau``, tau-b: ties
  allowed) between the methods' summary scores at the two fidelities;
* **summary score**: each method's surrogate minus physics difference;
* **per mode**: each method's detection rate at its own alarm (``1 -
  fnr_standard`` of the ``method_alarm`` rows of Table V) and false
  classification rate (``fcr``) at both fidelities.

The targets (:data:`TARGETS`) are those of the benchmark: tau >= 0.8, every
summary score within 5 points, every per-mode false classification rate
within 0.05. :class:`FidelityReport` says which are met and which are not
(:attr:`FidelityReport.failures`). Running the panel goes through one
function, :func:`_run_panel`, which is the only caller of the evaluation
harness here.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from fuelhm_bench.errors import ParameterError

__all__ = ["PANEL", "TARGETS", "FidelityReport", "compare_outcomes", "fidelity_check", "healthy_distances",
           "plot_fidelity"]

#: The reference panel: the shipped baselines and detectors of different inductive biases
#: (short name -> ``module:Class`` entry point of ``baselines/``).
PANEL: dict[str, str] = {
    "null": "fuelhm_baselines.trivial:NullMethod",
    "random": "fuelhm_baselines.trivial:RandomMethod",
    "paper-mahalanobis": "fuelhm_baselines.paper_mahalanobis:PaperMahalanobis",
    "isolation-forest": "fuelhm_baselines.isolation_forest:IsolationForestMethod",
    "itl-classifier": "fuelhm_baselines.itl_classifier:ITLClassifierMethod",
    "full-gaussian": "fuelhm_baselines.gaussian_full:FullGaussianMethod",
    "gaussian-mixture": "fuelhm_baselines.gaussian_mixture:GaussianMixtureMethod",
    "one-class-svm": "fuelhm_baselines.one_class_svm:OneClassSVMMethod",
    "nearest-neighbour": "fuelhm_baselines.nearest_neighbour:NearestNeighbourMethod",
}

#: Agreement targets: minimum Kendall tau, maximum |summary-score difference| [points],
#: maximum |per-mode false-classification-rate difference|.
TARGETS: dict[str, float] = {"kendall_tau": 0.8, "summary_points": 5.0, "fcr": 0.05}

FIDELITIES = ("physics", "surrogate")


@dataclass(frozen=True, eq=False)
class FidelityReport:
    """What :func:`fidelity_check` measured on one scenario.

    Attributes
    ----------
    scenario : str
        Scenario id.
    methods : pandas.DataFrame
        One row per method: ``method``, ``status_physics``, ``status_surrogate``,
        ``summary_physics``, ``summary_surrogate``, ``summary_diff`` (surrogate
        minus physics, points), ``message`` (what went wrong, if a run failed),
        ``rank_physics``, ``rank_surrogate`` (1 = best).
    modes : pandas.DataFrame
        One row per (method, mode): ``detection_physics``, ``detection_surrogate``,
        ``detection_diff``, ``fcr_physics``, ``fcr_surrogate``, ``fcr_diff``
        (NaN where a rate is undefined, e.g. no alarm on that mode).
    kendall_tau : float
        Between the summary scores of the methods that ran at both fidelities.
    kendall_p : float
        Its two-sided p-value (no association).
    targets : dict
        The targets checked (:data:`TARGETS`).
    seconds : dict
        Wall time per fidelity [s] (data preparation and the panel).
    labels : tuple of str, default=("physics", "surrogate")
        The two runs compared (the column suffixes): the reference first.
    noise_floor : FidelityReport or None, default=None
        The same panel at physics fidelity under the reference seed and another
        master seed (:func:`fidelity_check` with ``noise_seed``): how far apart two
        physics runs are, the scale against which the targets are to be read.
    """

    scenario: str
    methods: pd.DataFrame
    modes: pd.DataFrame
    kendall_tau: float
    kendall_p: float
    targets: dict = field(default_factory=lambda: dict(TARGETS))
    seconds: dict = field(default_factory=dict)
    labels: tuple = FIDELITIES
    noise_floor: FidelityReport | None = None

    @property
    def failures(self) -> list[str]:
        """Every target not met, in words (empty when all are met)."""
        t = self.targets
        a, b = self.labels
        out = []
        if not (self.kendall_tau >= t["kendall_tau"]):
            out.append(f"Kendall tau {self.kendall_tau:.2f} < {t['kendall_tau']:g}")
        for _, row in self.methods.iterrows():
            if row[f"status_{a}"] != "ok" or row[f"status_{b}"] != "ok":
                out.append(f"{row['method']} did not run in both runs ({row[f'status_{a}']}/"
                           f"{row[f'status_{b}']})")
            elif abs(row["summary_diff"]) > t["summary_points"]:
                out.append(f"{row['method']} summary {row[f'summary_{b}']:.1f} ({b}) vs "
                           f"{row[f'summary_{a}']:.1f} ({a})")
        for _, row in self.modes.iterrows():
            if np.isfinite(row["fcr_diff"]) and abs(row["fcr_diff"]) > t["fcr"]:
                out.append(f"{row['method']} FCR on {row['mode']} {row[f'fcr_{b}']:.2f} ({b}) vs "
                           f"{row[f'fcr_{a}']:.2f} ({a})")
        return out

    @property
    def passed(self) -> bool:
        """True when every target is met."""
        return not self.failures

    def summary(self) -> pd.Series:
        """One line of the fidelity table: tau, worst differences, verdict (and the noise floor's, when measured)."""
        a, b = self.labels
        ok = self.methods[(self.methods[f"status_{a}"] == "ok") & (self.methods[f"status_{b}"] == "ok")]
        fcr = self.modes["fcr_diff"].abs()
        det = self.modes["detection_diff"].abs()
        worst = ok.loc[ok["summary_diff"].abs().idxmax()] if len(ok) else None
        noise = {}
        if self.noise_floor is not None:
            n = self.noise_floor.summary()
            noise = {"noise_tau": n["kendall_tau"], "noise_max_summary_diff": n["max_summary_diff"],
                     "noise_max_fcr_diff": n["max_fcr_diff"]}
        return pd.Series({
            "scenario": self.scenario, "methods": int(len(ok)), "kendall_tau": round(self.kendall_tau, 3),
            "max_summary_diff": round(float(ok["summary_diff"].abs().max()), 1) if len(ok) else np.nan,
            "worst_method": "" if worst is None else worst["method"],
            "max_fcr_diff": round(float(fcr.max()), 3) if fcr.notna().any() else np.nan,
            "max_detection_diff": round(float(det.max()), 3) if det.notna().any() else np.nan,
            "verdict": "pass" if self.passed else f"FAIL ({len(self.failures)})", **noise})

    def to_markdown(self) -> str:
        """The report as Markdown (summary line, per-method table, per-mode table, failures)."""
        a, b = self.labels
        title = "Fidelity check" if self.labels == FIDELITIES else f"Comparison {b} vs {a}"
        lines = [f"# {title}: {self.scenario}", "",
                 f"Kendall tau (summary scores, {len(self.methods)} methods): {self.kendall_tau:.3f} "
                 f"(p = {self.kendall_p:.3g}); targets: tau >= {self.targets['kendall_tau']:g}, "
                 f"|summary diff| <= {self.targets['summary_points']:g} points, |FCR diff| <= "
                 f"{self.targets['fcr']:g}.", "", "## Methods", "",
                 _markdown(self.methods.round(2)), "", "## Per mode (detection at the method's alarm, FCR)", "",
                 _markdown(self.modes.round(3)), "", "## Verdict", ""]
        lines += [f"- {f}" for f in self.failures] or ["All targets met."]
        if self.noise_floor is not None:
            n = self.noise_floor
            lines += ["", f"## Noise floor: physics vs physics ({n.labels[1]})", "",
                      "The same panel at physics fidelity under two master seeds: differences this large arise "
                      "between two physics runs, with no surrogate involved.", "",
                      _markdown(pd.DataFrame([n.summary()]).drop(columns=["scenario"])), "",
                      _markdown(n.methods.round(2))]
        return "\n".join(lines) + "\n"

    def write(self, out: Path) -> list[Path]:
        """Write ``methods.csv``, ``modes.csv``, ``report.md`` and ``fidelity.png`` into ``out``."""
        out = Path(out)
        out.mkdir(parents=True, exist_ok=True)
        paths = [out / "methods.csv", out / "modes.csv", out / "report.md", out / "fidelity.png"]
        self.methods.to_csv(paths[0], index=False)
        self.modes.to_csv(paths[1], index=False)
        paths[2].write_text(self.to_markdown(), encoding="utf-8")
        plot_fidelity(self, paths[3])
        if self.noise_floor is not None:
            paths += self.noise_floor.write(out / "noise_floor")
        return paths


def _markdown(table: pd.DataFrame) -> str:
    cols = [str(c) for c in table.columns]
    rows = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    for _, r in table.iterrows():
        rows.append("| " + " | ".join("" if (isinstance(v, float) and np.isnan(v)) else str(v) for v in r) + " |")
    return "\n".join(rows)


def _per_mode(scorecard) -> pd.DataFrame:
    """Detection rate at the method's alarm and FCR, per true mode (``"all"`` excluded)."""
    from fuelhm_bench.scoring.detection import ALL_MODES, METHOD_ALARM

    det = scorecard.detection
    det = det[(det["operating_point"] == METHOD_ALARM) & (det["mode"] != ALL_MODES)]
    detection = pd.Series(1.0 - det["fnr_standard"].to_numpy(dtype=float), index=det["mode"].to_numpy())
    cls = scorecard.classification
    cls = cls[cls["mode"] != ALL_MODES]
    fcr = pd.Series(cls["fcr"].to_numpy(dtype=float), index=cls["mode"].to_numpy())
    return pd.DataFrame({"detection": detection, "fcr": fcr})


def compare_outcomes(scenario: str, outcomes: dict[str, dict], *, targets: dict | None = None,
                     seconds: dict | None = None, labels: tuple = FIDELITIES) -> FidelityReport:
    """Compare the outcomes of a panel at the two fidelities (pure: outcomes in, report out).

    Parameters
    ----------
    scenario : str
        Scenario id.
    outcomes : dict
        ``{"physics": {name: outcome}, "surrogate": {name: outcome}}``; an outcome
        has ``ok``, ``status`` and ``score()`` (:class:`fuelhm_bench.benchmark.harness.Outcome`).
    targets : dict or None, default=None
        Overrides of :data:`TARGETS`.
    seconds : dict or None, default=None
    labels : tuple of two str, default=("physics", "surrogate")
        The keys of ``outcomes`` (reference first); the column suffixes of the report.

    Returns
    -------
    FidelityReport
    """
    from scipy.stats import kendalltau

    labels = tuple(labels)
    ref, other = labels
    names = list(dict.fromkeys([*outcomes[ref], *outcomes[other]]))
    rows, mode_rows = [], []
    for name in names:
        row = {"method": name}
        cards = {}
        for fid in labels:
            out = outcomes[fid].get(name)
            row[f"status_{fid}"] = "missing" if out is None else out.status
            cards[fid] = out.score() if out is not None and out.ok else None
            row[f"summary_{fid}"] = float(cards[fid].summary_score) if cards[fid] is not None else np.nan
        row["summary_diff"] = row[f"summary_{other}"] - row[f"summary_{ref}"]
        messages = [getattr(outcomes[f].get(name), "message", "") or "" for f in labels]
        row["message"] = next((m.strip().splitlines()[-1] for m in messages if m.strip()), "")
        rows.append(row)
        if all(c is not None for c in cards.values()):
            pm = {fid: _per_mode(c) for fid, c in cards.items()}
            for mode in pm[ref].index.union(pm[other].index):
                r = {"method": name, "mode": mode}
                for what in ("detection", "fcr"):
                    for fid in labels:
                        r[f"{what}_{fid}"] = float(pm[fid][what].get(mode, np.nan))
                    r[f"{what}_diff"] = r[f"{what}_{other}"] - r[f"{what}_{ref}"]
                mode_rows.append(r)
    methods = pd.DataFrame(rows)
    ok = methods[f"summary_{ref}"].notna() & methods[f"summary_{other}"].notna()
    for fid in labels:
        methods[f"rank_{fid}"] = methods[f"summary_{fid}"].rank(ascending=False, method="min")
    if ok.sum() >= 2:
        res = kendalltau(methods.loc[ok, f"summary_{ref}"], methods.loc[ok, f"summary_{other}"])
        tau, p = float(res.statistic), float(res.pvalue)
    else:
        tau, p = float("nan"), float("nan")
    columns = ["method", "mode"] + [f"{w}_{s}" for w in ("detection", "fcr") for s in (*labels, "diff")]
    modes = pd.DataFrame(mode_rows, columns=columns)
    return FidelityReport(scenario, methods, modes, tau, p, {**TARGETS, **(targets or {})}, dict(seconds or {}),
                          labels)


def _run_panel(methods: dict, scenario, fidelity: str, *, seed, scale, flight_minutes, knowledge_size,
               cache_dir, random_state, timeout_s, progress) -> dict:
    """The one place that calls the evaluation harness: prepare a fidelity once, run every method on it."""
    from fuelhm_bench.benchmark.harness import prepare_evaluation, run_in_env

    evaluation = prepare_evaluation(scenario, fidelity=fidelity, seed=seed, scale=scale,
                                    flight_minutes=flight_minutes, robustness=False,
                                    knowledge_size=knowledge_size, cache_dir=cache_dir)
    out = {}
    for name, method in methods.items():
        if progress is not None:
            progress(f"{evaluation.scenario.id}: {name} at {fidelity} fidelity")
        out[name] = run_in_env(method, evaluation, random_state=random_state, timeout_s=timeout_s)
    return out


def fidelity_check(scenario, *, methods: dict | None = None, seed: int | None = None, scale: float = 1.0,
                   flight_minutes: float | None = None, knowledge_size=None, cache_dir=None,
                   random_state: int = 0, timeout_s: float = 600.0, noise_seed: int | None = None,
                   progress: Callable[[str], object] | None = None) -> FidelityReport:
    """Evaluate a panel of methods at both fidelities and compare their results.

    Parameters
    ----------
    scenario : str, Path or Scenario
    methods : dict or None, default=None
        ``{name: BaseMethod instance}``; None: :data:`PANEL` with default
        hyperparameters (``baselines`` must be importable: run from the
        repository root).
    seed, scale, flight_minutes, knowledge_size, cache_dir
        See :func:`fuelhm_bench.benchmark.harness.prepare_evaluation` (the same for both fidelities).
    random_state : int, default=0
        Passed to every ``fit``.
    timeout_s : float, default=600.0
        Time limit of each method run [s].
    noise_seed : int or None, default=None
        Also run the panel at physics fidelity with this master seed (new training,
        knowledge and scored fleets) and compare it with the physics run
        (:attr:`FidelityReport.noise_floor`): the differences between two physics
        runs that no surrogate can be expected to beat. None: not measured.
    progress : callable, optional
        Called with a line of text before each run.

    Returns
    -------
    FidelityReport
    """
    import time

    from fuelhm_bench.datasets.cache import resolve_scenario

    sc = resolve_scenario(scenario)
    if methods is None:
        from fuelhm_bench.methods.loading import load_method

        methods = {name: load_method(spec) for name, spec in PANEL.items()}
    if not isinstance(methods, dict) or len(methods) < 2:
        raise ParameterError(f"The 'methods' parameter of fidelity_check must be a dict of at least two named "
                             f"methods (a ranking needs two). Got {methods!r:.100} instead.")
    if noise_seed is not None:  # checked before any run
        if isinstance(noise_seed, bool) or not isinstance(noise_seed, (int, np.integer)) or noise_seed < 0:
            raise ParameterError(f"The 'noise_seed' parameter of fidelity_check must be an int >= 0 or None. "
                                 f"Got {noise_seed!r} instead.")
        reference = sc.seeds.master if seed is None else seed
        if int(noise_seed) == int(reference):
            raise ParameterError(f"The 'noise_seed' parameter of fidelity_check must differ from the master seed "
                                 f"of the run ({reference}); two runs with one seed are the same run.")
    outcomes, seconds = {}, {}
    for fid in FIDELITIES:
        t0 = time.perf_counter()
        outcomes[fid] = _run_panel(methods, sc, fid, seed=seed, scale=scale, flight_minutes=flight_minutes,
                                   knowledge_size=knowledge_size, cache_dir=cache_dir,
                                   random_state=random_state, timeout_s=timeout_s, progress=progress)
        seconds[fid] = round(time.perf_counter() - t0, 1)
    report = compare_outcomes(sc.id, outcomes, seconds=seconds)
    if noise_seed is None:
        return report
    label = f"physics_seed{int(noise_seed)}"
    t0 = time.perf_counter()
    other = _run_panel(methods, sc, "physics", seed=int(noise_seed), scale=scale, flight_minutes=flight_minutes,
                       knowledge_size=knowledge_size, cache_dir=cache_dir, random_state=random_state,
                       timeout_s=timeout_s, progress=progress)
    noise = compare_outcomes(sc.id, {"physics": outcomes["physics"], label: other}, labels=("physics", label),
                             seconds={"physics": seconds["physics"], label: round(time.perf_counter() - t0, 1)})
    return dataclasses.replace(report, noise_floor=noise)


def _scored_fleet(env, units: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Indicators (NaN where invalid), intensities and unit of every scored flight, as the environment serves them."""
    xs, fs, us = [], [], []
    base = env.unwrapped if hasattr(env, "unwrapped") else env
    for k in range(units):
        obs, _ = base.reset(options={"unit": k})
        rows = []
        while True:
            rows.append(np.where(obs["valid"] == 1, obs["indicators"].astype(np.float64), np.nan))
            obs, _, done, _, info = base.step({"alarm": 0, "guilt": np.zeros(7, dtype=np.float32)})
            if done:
                intens = info["episode_truth"]["intensity"]
                break
        xs.append(np.array(rows))
        fs.append(np.asarray(intens, dtype=np.float64))
        us.append(np.full(len(rows), k))
    return np.vstack(xs), np.vstack(fs), np.concatenate(us)


def healthy_distances(scenario, *, seed: int | None = None, flight_minutes: float | None = None,
                      knowledge_size=None, cache_dir=None,
                      quantiles: tuple[float, ...] = (0.1, 0.5, 0.9, 0.975)) -> pd.DataFrame:
    """Where the scored fleet's healthy flights sit at each fidelity (the diagnosis behind the fidelity check).

    The scored fleet is drawn from both environments (no maintenance); its healthy flights (every mode at
    intensity 0) are standardised with the mean and standard deviation of the physics training flights
    (what the methods are fitted on) and their Mahalanobis distance taken under the covariance of those
    standardised training flights (pseudo-inverse: exact relations of the indicators have no variance).

    Returns
    -------
    pandas.DataFrame
        One row per fidelity (``physics``, ``surrogate``): ``flights``, the distance quantiles
        (``q10``, ``q50``, ...), and ``between_std_min`` / ``between_std_max``: the smallest and largest
        standard deviation across units of the units' mean Z-scores (the unit-to-unit spread).
    """
    from fuelhm_bench.benchmark.harness import prepare_evaluation
    from fuelhm_bench.taxonomy import INDICATOR_NAMES

    rows = []
    reference = None
    for fid in FIDELITIES:
        ev = prepare_evaluation(scenario, fidelity=fid, seed=seed, flight_minutes=flight_minutes, robustness=False,
                                knowledge_size=knowledge_size, cache_dir=cache_dir)
        if reference is None:
            train = pd.concat([ev.fit_indicators, ev.calibration_indicators], ignore_index=True)
            names = list(INDICATOR_NAMES)
            xt = np.where(train[[f"{n}_valid" for n in names]].to_numpy(bool), train[names].to_numpy(float), np.nan)
            mu, sd = np.nanmean(xt, axis=0), np.nanstd(xt, axis=0, ddof=1)
            sd = np.where(sd > 0, sd, 1.0)
            zt = (xt - mu) / sd
            zt = zt[np.isfinite(zt).all(axis=1)]
            reference = (mu, sd, np.linalg.pinv(np.cov(zt, rowvar=False)))
        mu, sd, prec = reference
        x, f, units = _scored_fleet(ev.env, len(ev.units))
        healthy = (f == 0).all(axis=1)
        z = np.nan_to_num((x[healthy] - mu) / sd)
        d = np.sqrt(np.einsum("ij,jk,ik->i", z, prec, z))
        means = pd.DataFrame(z).groupby(units[healthy]).mean()
        between = means.std(ddof=1).to_numpy() if len(means) > 1 else np.full(z.shape[1], np.nan)
        row = {"fidelity": fid, "flights": int(healthy.sum())}
        row.update({f"q{100 * q:g}": float(np.quantile(d, q)) if len(d) else np.nan for q in quantiles})
        row.update({"between_std_min": float(np.nanmin(between)), "between_std_max": float(np.nanmax(between))})
        rows.append(row)
    return pd.DataFrame(rows).set_index("fidelity")


def plot_fidelity(report: FidelityReport, path) -> Path:
    """Figure of a report: summary scores (surrogate vs physics, with the +/- target band) and FCR differences."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fuelhm_bench.scoring.figures import apply_tight_layout

    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.5))
    m = report.methods
    a, b = report.labels
    lo = float(np.nanmin([m[f"summary_{a}"].min(), m[f"summary_{b}"].min(), 0.0])) - 5
    hi = float(np.nanmax([m[f"summary_{a}"].max(), m[f"summary_{b}"].max(), 100.0])) + 5
    band = report.targets["summary_points"]
    ax1.fill_between([lo, hi], [lo - band, hi - band], [lo + band, hi + band], color="0.9",
                     label=f"within {band:g} points")
    ax1.plot([lo, hi], [lo, hi], color="0.5", lw=1)
    ax1.scatter(m[f"summary_{a}"], m[f"summary_{b}"], zorder=3)
    for _, r in m.iterrows():
        if np.isfinite(r[f"summary_{a}"]) and np.isfinite(r[f"summary_{b}"]):
            ax1.annotate(r["method"], (r[f"summary_{a}"], r[f"summary_{b}"]), fontsize=7,
                         xytext=(3, 3), textcoords="offset points")
    ax1.set_xlabel(f"summary score, {a}")
    ax1.set_ylabel(f"summary score, {b}")
    ax1.set_title(f"{report.scenario}: Kendall tau = {report.kendall_tau:.2f}")
    ax1.legend(loc="upper left", fontsize=8)
    modes = report.modes.dropna(subset=["fcr_diff"])
    if len(modes):
        pivot = modes.pivot(index="mode", columns="method", values="fcr_diff")
        pivot.plot.bar(ax=ax2, width=0.8, legend=False)
        ax2.legend(fontsize=6, ncol=2)
    t = report.targets["fcr"]
    ax2.axhspan(-t, t, color="0.9", zorder=0)
    ax2.axhline(0, color="0.5", lw=1)
    ax2.set_ylabel(f"FCR, {b} - {a}")
    ax2.set_title("false classification rate per mode")
    ax2.tick_params(axis="x", labelrotation=30, labelsize=7)
    apply_tight_layout(fig)
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
