"""The published knowledge of the benchmark: healthy model, ITL and signature matrix.

The paper's on-ground method needs (i) a healthy Gaussian model of the
indicators, learnt on healthy flights, and (ii) the signatures of the
degradations, built from indicator transformation laws computed on a physical
model. :func:`build_knowledge` produces both from simulations of the *published*
nominal model (hidden effects and nominal-parameter drift of a scenario are never
included: methods are not told about them), and :func:`write_knowledge` writes
``itl.csv``, ``signatures.csv``, ``signatures.md``, ``healthy_indicators.csv``,
``doe_indicators.csv`` and the plots ``itl.png`` and ``signatures.png``.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd

from fuelhm_bench.datasets.doe import DesignOfExperiments, run_doe
from fuelhm_bench.diagnosis.healthy import HealthyModel
from fuelhm_bench.diagnosis.itl import ITL, fit_itl, plot_itl
from fuelhm_bench.diagnosis.signatures import plot_signature_heatmap, signature_matrix, signature_to_markdown
from fuelhm_bench.flights.fleet import FleetConfig
from fuelhm_bench.flights.mission import MissionProfile
from fuelhm_bench.taxonomy import MODE_IDS


@dataclass(frozen=True)
class KnowledgeBuild:
    """What to simulate to build the published knowledge.

    Parameters
    ----------
    doe : DesignOfExperiments
        Design of experiments for the ITL.
    healthy_fleet : FleetConfig
        Healthy fleet for the healthy model (its schedules must be empty).
    max_intensity : dict, default=all modes 1.0
        Maximum intensity of each mode (signatures are taken there, eq. 9).
    """

    doe: DesignOfExperiments = field(default_factory=DesignOfExperiments)
    healthy_fleet: FleetConfig = field(default_factory=lambda: FleetConfig(
        n_units=8, n_flights=5, mission=MissionProfile(duration_s=900.0), seed=1))
    max_intensity: dict = field(default_factory=lambda: {m: 1.0 for m in MODE_IDS})

    @property
    def n_flights(self) -> int:
        """Flights simulated in total."""
        return self.doe.n_flights + self.healthy_fleet.n_units * self.healthy_fleet.n_flights

    @classmethod
    def from_scenario(cls, scenario=None, *, doe_units: int = 8, intensities=(0.25, 0.5, 0.75, 1.0),
                      minutes: float | None = None, healthy_units: int = 8, healthy_flights: int = 5,
                      seed: int = 0, modes: tuple = MODE_IDS) -> KnowledgeBuild:
        """Build settings, from a scenario's published nominal model and mission when given.

        Parameters
        ----------
        scenario : str, Path, Scenario or None
            A shipped scenario name, a YAML path or a loaded scenario; ``None``: nominal model,
            15-minute flights.
        doe_units, intensities, minutes, healthy_units, healthy_flights, seed
            Size of the design and of the healthy fleet; ``minutes`` overrides the flight duration.
        modes : tuple of str, default=MODE_IDS
            Modes of the design of experiments.
        """
        nominal = FleetConfig().nominal
        mission = MissionProfile(duration_s=900.0)
        dispersion = FleetConfig().dispersion
        max_intensity = {m: 1.0 for m in MODE_IDS}
        if scenario is not None:
            from fuelhm_bench.scenarios import load_scenario

            sc = load_scenario(scenario) if not hasattr(scenario, "training_fleet_config") else scenario
            train = sc.training_fleet_config()
            nominal = _published(train.nominal)
            mission = train.mission
            dispersion = train.dispersion
            for s in sc.test_fleet_config().schedules:
                max_intensity[s.mode] = s.max_intensity
        if minutes is not None:
            mission = dataclasses.replace(mission, duration_s=60.0 * minutes)
        doe = DesignOfExperiments(n_units=doe_units, intensities=tuple(intensities), modes=tuple(modes),
                                  mission=mission, nominal=nominal, dispersion=dispersion, seed=seed)
        healthy = FleetConfig(n_units=healthy_units, n_flights=healthy_flights, mission=mission, nominal=nominal,
                              dispersion=dispersion, seed=seed + 1)
        return cls(doe=doe, healthy_fleet=healthy, max_intensity=max_intensity)


def _published(model):
    """The published model: the same unit without any (hidden) optional effect."""
    for e in model.effects:
        model = model.without_effect(e.id)
    return model


@dataclass(frozen=True)
class KnowledgeResult:
    """Published knowledge and the data it was computed from."""

    itl: ITL
    healthy_model: HealthyModel
    signatures: pd.DataFrame
    max_intensity: dict
    doe_table: pd.DataFrame
    healthy_table: pd.DataFrame

    def as_method_knowledge(self):
        """The :class:`fuelhm_bench.methods.Knowledge` handed to methods."""
        from fuelhm_bench.methods import Knowledge

        return Knowledge(itl=self.itl.table, signatures=self.signatures, max_intensity=dict(self.max_intensity))


def build_knowledge(build: KnowledgeBuild = KnowledgeBuild(), *, extraction=None,
                    progress: Callable[[int], object] | None = None, workers: int = 1,
                    label: str = "the published knowledge") -> KnowledgeResult:
    """Simulate the healthy fleet and the design of experiments; fit the healthy model, ITL and signatures.

    ``workers`` processes simulate in parallel (:mod:`fuelhm_bench.datasets.parallel`); the
    result is byte-identical for any number. The healthy flights are checked first
    (:func:`~fuelhm_bench.datasets.checks.check_training_indicators`, the scenario named by
    ``label``): too few valid indicators for the healthy model is refused before the design is simulated.
    """
    from fuelhm_bench.datasets.checks import check_training_indicators
    from fuelhm_bench.datasets.fleets import fleet_indicators

    healthy_table, _ = fleet_indicators(build.healthy_fleet, extraction=extraction, progress=progress,
                                        workers=workers)
    check_training_indicators(healthy_table, label, fidelity="physics", knowledge_flights=len(healthy_table),
                              flights="healthy flights of its published knowledge")
    doe_table = run_doe(build.doe, extraction=extraction, progress=progress, workers=workers)
    healthy_model = HealthyModel().fit(healthy_table)
    itl = fit_itl(doe_table)
    sig = signature_matrix(itl, healthy_model, max_intensity=build.max_intensity)
    return KnowledgeResult(itl, healthy_model, sig, dict(build.max_intensity), doe_table, healthy_table)


def write_knowledge(result: KnowledgeResult, out_dir) -> list[Path]:
    """Write the knowledge files into ``out_dir`` (existing files of the same names are replaced)."""
    out = Path(out_dir)
    paths = []
    p = out / "itl.csv"
    result.itl.table.to_csv(p, index=False)
    paths.append(p)
    p = out / "signatures.csv"
    result.signatures.to_csv(p, index_label="mode")
    paths.append(p)
    p = out / "signatures.md"
    p.write_text(signature_to_markdown(result.signatures) + "\n")
    paths.append(p)
    for name, table in (("healthy_indicators.csv", result.healthy_table), ("doe_indicators.csv", result.doe_table)):
        p = out / name
        table.to_csv(p, index=False)
        paths.append(p)
    paths.append(plot_itl(result.itl, result.doe_table, out / "itl.png"))
    paths.append(plot_signature_heatmap(result.signatures, out / "signatures.png"))
    return paths
