"""Simulated data products of a scenario, built once and cached (in memory and on disk).

The environments and the runner need, for a scenario:

* the **published knowledge** (:func:`published_knowledge`): the healthy model,
  ITL and signatures that :func:`fuelhm_bench.datasets.knowledge.build_knowledge` builds
  from the benchmark's own simulations of the published model
  (:meth:`KnowledgeBuild.from_scenario <fuelhm_bench.datasets.knowledge.KnowledgeBuild.from_scenario>`);
* **healthy indicator tables** of the scenario's training fleet
  (:func:`training_indicators`): what methods are fitted on;
* what the **surrogate** is learnt from (:func:`surrogate_knowledge`): healthy
  flights of new units of the scored fleet's model (:func:`surrogate_healthy`)
  and a design of experiments on that model (:func:`surrogate_doe`);
* the **scored fleet's indicators** without maintenance (:func:`scored_indicators`):
  the physics observations of replayed units, simulated once for all methods.

Each costs from seconds to tens of seconds of simulation. They are kept

* in memory, per process, keyed by a SHA-256 (:func:`cache_key`);
* on disk, under ``<cache dir>/fuelhm-v1/<kind>-<scenario id>-<key[:16]>/``
  (``<kind>-<key[:16]>/`` for the products shared by scenarios, below):
  the simulated tables as Parquet and ``meta.json``. Fitted objects (healthy
  model, ITL, signatures) are refitted from the tables on load (milliseconds,
  deterministic), so the cache holds data only, never pickled code.

Fleet tables (:func:`training_indicators`, :func:`scored_indicators`) and the
published knowledge are keyed by their recipe alone (:func:`content_key`: the
:class:`~fuelhm_bench.flights.fleet.FleetConfig` or the
:class:`~fuelhm_bench.datasets.knowledge.KnowledgeBuild`, every field), so
scenarios flying the same fleet share one build: ``low_data`` scores
``paper_2012``'s fleet, ``robustness_drift`` trains on it, and both use its
published knowledge. The other products' key (:func:`cache_key`) covers the kind of product, the scenario's content (every field of
:meth:`Scenario.to_dict <fuelhm_bench.scenarios.Scenario>` except
``description``), the effective flight duration, the build parameters, the
package version, the cache format and the indicator names (a table without a new indicator is
never served): a changed scenario, size or release never reads a stale entry. Both keys also cover
the source of the code that builds products (:func:`code_fingerprint`: the simulator, flights,
indicators, published knowledge, surrogate and scenario loader), so a changed law, kernel or
extractor never reads an entry built by other code, even within one release. The cache directory is, in order: the ``cache_dir``
argument, the environment variable ``FUELHM_BENCH_CACHE``,
``$XDG_CACHE_HOME/fuelhm-bench``, ``~/.cache/fuelhm-bench``; ``cache_dir=False``
keeps products in memory only.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import hashlib
import json
import math
import os
import shutil
import tempfile
import threading
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from fuelhm_bench._numba_cache import CACHE_ENV_VAR  # the variable overriding the cache directory
from fuelhm_bench.errors import ParameterError, parameter_error
from fuelhm_bench.taxonomy import MODE_IDS

__all__ = ["CACHE_ENV_VAR", "KnowledgeSize", "cache_key", "clear_memory_cache", "content_key", "default_cache_dir",
           "knowledge_build", "published_knowledge", "resolve_scenario", "scored_indicators",
           "surrogate_doe", "surrogate_healthy", "surrogate_knowledge", "training_indicators"]

_FORMAT = 1

#: Parts of the package whose source decides what a simulated product holds (code_fingerprint).
_PRODUCT_SOURCES = ("physics", "flights", "indicators", "datasets", "diagnosis", "envs", "scenarios",
                    "taxonomy.py")
_MEMORY: OrderedDict[str, object] = OrderedDict()
_MEMORY_SIZE = 64
_MEMORY_GUARD = threading.Lock()
_KEY_LOCKS: dict[str, threading.Lock] = {}
_KEY_LOCKS_GUARD = threading.Lock()
#: Prefix of the unit-coordinate columns (``unit_z:<parameter path>``) of the surrogate's tables.
COORDINATE_PREFIX = "unit_z:"


@dataclass(frozen=True)
class KnowledgeSize:
    """How much to simulate for the published knowledge and the surrogate.

    The defaults are those of every evaluation
    (a 6-unit design of experiments, the 8 x 5 published healthy fleet of
    :meth:`~fuelhm_bench.datasets.knowledge.KnowledgeBuild.from_scenario`).

    Parameters
    ----------
    doe_units : int, default=6
        Units of the ITL design of experiments (each flies 1 + 7 x
        ``len(doe_intensities)`` flights), >= 1.
    doe_intensities : tuple of float, default=(0.25, 0.5, 0.75, 1.0)
        Intensities of the design of experiments, each in (0, 1] (fraction of
        the Table III maximum).
    healthy_units : int, default=8
        Units of the published healthy fleet (published model), >= 1.
    healthy_flights : int, default=5
        Flights per published healthy unit, >= 1 (units x flights >= 11 for a
        10-indicator Gaussian).
    surrogate_units : int, default=60
        Units of the healthy fleet the surrogate's healthy law is learnt on
        (new units of the scored fleet's model, :func:`surrogate_healthy`), >= 1;
        their unit means are regressed on their 12 manufacturing coordinates.
    surrogate_flights : int, default=4
        Flights per surrogate healthy unit, >= 1.
    surrogate_doe_units : int, default=24
        Units of the design of experiments the surrogate's degraded responses
        are learnt on (the scored fleet's model, the scenario's modes only), >= 1.
    surrogate_doe_intensities : tuple of float, default=(0.1, 0.25, 0.5, 0.75, 1.0)
        Its intensities, each in (0, 1].
    surrogate_doe_missions : int, default=3
        Missions (flight profile and noise) each surrogate DOE unit flies every case
        on, >= 1: the flight-to-flight variation of a unit's response.
    surrogate_doe_pair_intensities : tuple of float, default=(0.5, 1.0)
        For a scenario whose modes occur together (``simultaneous``), the surrogate
        DOE also flies every pair of its modes at every combination of these
        intensities, each in (0, 1]: the interaction of simultaneous modes.
    doe_modes : tuple of str, default=MODE_IDS
        Modes of the published design of experiments (the ITL and signatures
        have these modes only). A study of some modes (the paper's two) need
        not fly the others: the laws of a mode do not depend on which other
        modes are in the design (paired flights, seeded per unit).

    Examples
    --------
    >>> KnowledgeSize.small().doe_units
    1
    """

    doe_units: int = 6
    doe_intensities: tuple[float, ...] = (0.25, 0.5, 0.75, 1.0)
    healthy_units: int = 8
    healthy_flights: int = 5
    surrogate_units: int = 60
    surrogate_flights: int = 4
    surrogate_doe_units: int = 24
    surrogate_doe_intensities: tuple[float, ...] = (0.1, 0.25, 0.5, 0.75, 1.0)
    doe_modes: tuple[str, ...] = MODE_IDS
    surrogate_doe_missions: int = 3
    surrogate_doe_pair_intensities: tuple[float, ...] = (0.5, 1.0)

    def __post_init__(self) -> None:
        def bad(name: str, allowed: str) -> ParameterError:
            return parameter_error(name, "KnowledgeSize", allowed, getattr(self, name))

        for name in ("doe_units", "healthy_units", "healthy_flights", "surrogate_units", "surrogate_flights",
                     "surrogate_doe_units", "surrogate_doe_missions"):
            value = getattr(self, name)
            if not (isinstance(value, int) and not isinstance(value, bool)) or value < 1:
                raise bad(name, "an int >= 1")
        for name in ("doe_intensities", "surrogate_doe_intensities", "surrogate_doe_pair_intensities"):
            try:
                intensities = tuple(float(f) for f in getattr(self, name))
            except (TypeError, ValueError):
                raise bad(name, "a non-empty tuple of floats in (0, 1]") from None
            if not intensities or not all(0.0 < f <= 1.0 for f in intensities):
                raise bad(name, "a non-empty tuple of floats in (0, 1]")
            object.__setattr__(self, name, intensities)
        modes = self.doe_modes
        if isinstance(modes, str) or not isinstance(modes, (tuple, list)) or not modes or len(set(modes)) != len(
                modes) or not all(m in MODE_IDS for m in modes):
            raise bad("doe_modes", f"a non-empty tuple of distinct modes of {', '.join(MODE_IDS)}")
        object.__setattr__(self, "doe_modes", tuple(m for m in MODE_IDS if m in modes))  # one order, one key

    @classmethod
    def small(cls) -> KnowledgeSize:
        """A quick build for tests: 1 DOE unit at 2 intensities, 4 x 4 published and 6 x 5 surrogate healthy
        flights, a surrogate DOE of 2 units at 2 intensities on 2 missions (pairs at 1.0)."""
        return cls(doe_units=1, doe_intensities=(0.5, 1.0), healthy_units=4, healthy_flights=4,
                   surrogate_units=6, surrogate_flights=5, surrogate_doe_units=2,
                   surrogate_doe_intensities=(0.5, 1.0), surrogate_doe_missions=2,
                   surrogate_doe_pair_intensities=(1.0,))

    @classmethod
    def coerce(cls, value: object, owner: str) -> KnowledgeSize:
        """A :class:`KnowledgeSize` from itself, a dict of its fields, or None (the defaults)."""
        if value is None:
            return cls()
        if isinstance(value, cls):
            return value
        if isinstance(value, dict):
            from difflib import get_close_matches

            def did_you_mean(key, names):
                close = get_close_matches(str(key), names, n=1)
                return f" Did you mean {close[0]!r}?" if close else ""

            names = [f.name for f in dataclasses.fields(cls)]
            for key in value:
                if key not in names:
                    raise ParameterError(f"The 'knowledge_size' parameter of {owner} has the unknown field {key!r}; "
                                         f"fields: {', '.join(names)}.{did_you_mean(key, names)}")
            return cls(**value)
        raise ParameterError(f"The 'knowledge_size' parameter of {owner} must be a KnowledgeSize, a dict of its "
                             f"fields or None. Got {type(value).__name__} instead.")


def resolve_scenario(scenario: object):
    """A :class:`~fuelhm_bench.scenarios.Scenario` from itself, a shipped name or a YAML path."""
    from fuelhm_bench.scenarios import Scenario, load_scenario

    if isinstance(scenario, Scenario):
        return scenario
    if isinstance(scenario, (str, os.PathLike)):
        return load_scenario(scenario)
    raise ParameterError(f"The 'scenario' parameter must be a shipped scenario name, a YAML path or a Scenario. "
                         f"Got {type(scenario).__name__} instead.")


def _check_minutes(flight_minutes, owner: str, sc=None) -> None:
    """Refuse a flight-duration override that is not a number, or that takes a run of ``sc`` past its budget.

    A scenario file's own duration is checked against the run budget when it is loaded; an override
    (``--minutes``) must be too, or a 1440-minute override of a 20-minute scenario starts a run of
    thousands of flight-hours without a word.
    """
    if flight_minutes is not None and not (isinstance(flight_minutes, (int, float)) and not isinstance(
            flight_minutes, bool) and math.isfinite(flight_minutes)):
        raise ParameterError(f"The 'flight_minutes' parameter of {owner} must be a finite number or None. "
                             f"Got {flight_minutes!r} instead.")
    if flight_minutes is None or sc is None:
        return
    from fuelhm_bench.scenarios.schema import run_budget

    flights = sc.fleet.units * sc.fleet.flights_per_unit + sc.training.units * sc.training.flights_per_unit
    hours = flights * float(flight_minutes) / 60.0
    budget, origin = run_budget(sc.run_budget_flight_hours)
    if hours > budget:
        raise ParameterError(f"The 'flight_minutes' parameter of {owner}: {flights} flights of {flight_minutes:g} min "
                             f"of scenario {sc.id} are {hours:.4g} flight-hours, over the run budget of {budget:g} "
                             f"({origin}). Choose shorter flights, or raise the budget (run_budget_flight_hours in "
                             f"the scenario file or the environment variable FUELHM_RUN_BUDGET_FLIGHT_HOURS).")


def _with_minutes(config, flight_minutes: float | None):
    if flight_minutes is None:
        return config
    return dataclasses.replace(config, mission=dataclasses.replace(config.mission, duration_s=60.0 * flight_minutes))


def knowledge_build(scenario, *, flight_minutes: float | None = None, size: KnowledgeSize | None = None):
    """The :class:`~fuelhm_bench.datasets.knowledge.KnowledgeBuild` of the published knowledge.

    The recipe:
    :meth:`KnowledgeBuild.from_scenario <fuelhm_bench.datasets.knowledge.KnowledgeBuild.from_scenario>`
    with the training seed (design of experiments and healthy fleet on the
    published model, with the scenario's mission and sensor).

    Parameters
    ----------
    scenario : str, Path or Scenario
    flight_minutes : float or None, default=None
        Flight duration [min]; None: the scenario's.
    size : KnowledgeSize or None, default=None

    Returns
    -------
    KnowledgeBuild
    """
    from fuelhm_bench.datasets.knowledge import KnowledgeBuild

    sc = resolve_scenario(scenario)
    size = KnowledgeSize() if size is None else size
    return KnowledgeBuild.from_scenario(sc, doe_units=size.doe_units, intensities=size.doe_intensities,
                                        minutes=flight_minutes, healthy_units=size.healthy_units,
                                        healthy_flights=size.healthy_flights,
                                        seed=sc.training_fleet_config().seed, modes=size.doe_modes)


def cache_key(kind: str, scenario, *, flight_minutes: float | None = None, **params) -> str:
    """SHA-256 hex digest identifying a cached product (see the module docstring).

    Parameters
    ----------
    kind : str
        ``"knowledge"``, ``"training"`` or ``"scored"``.
    scenario : str, Path or Scenario
    flight_minutes : float or None, default=None
        None and the scenario's own duration give the same key.
    **params
        Build parameters (JSON-serialisable).
    """
    from fuelhm_bench import __version__
    from fuelhm_bench.taxonomy import ALL_INDICATOR_NAMES

    sc = resolve_scenario(scenario)
    content = sc.to_dict()
    content.pop("description", None)
    minutes = float(sc.mission.duration_min if flight_minutes is None else flight_minutes)
    material = {"kind": kind, "format": _FORMAT, "package": __version__, "code": code_fingerprint(),
                "scenario": content,
                "flight_minutes": minutes, "params": params, "indicators": list(ALL_INDICATOR_NAMES)}
    text = json.dumps(material, sort_keys=True, default=repr, allow_nan=True)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def _canonical(value):
    """``value`` as JSON-ready data that names every dataclass's class and holds every field and array element."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        # a field added after recipes were keyed declares ``metadata={"key": "omit-default"}``: at its
        # default (the behaviour from before it existed) it is left out, so those recipes keep their keys
        return {"__class__": f"{type(value).__module__}.{type(value).__qualname__}",
                **{f.name: _canonical(getattr(value, f.name)) for f in dataclasses.fields(value)
                   if not (f.metadata.get("key") == "omit-default" and getattr(value, f.name) == f.default)}}
    if isinstance(value, (list, tuple)):
        return [_canonical(v) for v in value]
    if isinstance(value, dict):
        return {str(k): _canonical(v) for k, v in value.items()}
    if isinstance(value, np.ndarray):
        return {"__ndarray__": value.dtype.str, "shape": list(value.shape), "data": _canonical(value.tolist())}
    if isinstance(value, np.generic):
        return value.item()
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    return {"__repr__": f"{type(value).__module__}.{type(value).__qualname__}", "value": repr(value)}


def recipe_digest(recipe) -> str:
    """SHA-256 hex digest of a frozen dataclass's content (every field, classes named, floats exact).

    A loaded scenario's digest tells two scenario files apart that share a name and version
    (a shipped file copied and edited): the results store keys evaluations on it.
    """
    text = json.dumps(_canonical(recipe), sort_keys=True, allow_nan=True)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


def content_key(kind: str, recipe, **params) -> str:
    """SHA-256 hex digest of a product built from ``recipe`` alone (a frozen dataclass such as a
    :class:`~fuelhm_bench.flights.fleet.FleetConfig`), whichever scenario asks for it.

    Scenarios whose recipes are equal (e.g. two scenarios flying the same training fleet)
    share one cache entry, so the product is simulated once. The key covers the recipe's
    every field (classes named, floats exact), the build parameters, the package version,
    the cache format and the indicator names.

    Parameters
    ----------
    kind : str
        ``"fleet"`` or ``"knowledge"``.
    recipe : dataclass
        Everything the product depends on.
    **params
        Further build parameters (JSON-serialisable).
    """
    from fuelhm_bench import __version__
    from fuelhm_bench.taxonomy import ALL_INDICATOR_NAMES

    material = {"kind": kind, "format": _FORMAT, "package": __version__, "code": code_fingerprint(),
                "recipe": _canonical(recipe), "params": params, "indicators": list(ALL_INDICATOR_NAMES)}
    text = json.dumps(material, sort_keys=True, allow_nan=True)
    return hashlib.sha256(text.encode("utf-8")).hexdigest()


@functools.lru_cache(maxsize=1)
def code_fingerprint() -> str:
    """SHA-256 of the Python source of every module that builds a product (``_PRODUCT_SOURCES``).

    Part of every cache key: an entry is read only by the code that wrote it.
    """
    return source_digest(Path(__file__).resolve().parent.parent, _PRODUCT_SOURCES)


def source_digest(root, parts) -> str:
    """SHA-256 of the ``*.py`` files under ``root / part`` for each part (a folder or one file).

    Files are taken in sorted order of their path relative to ``root``, each with that path
    and its bytes, so the digest is the same on any machine for the same source. A missing
    part contributes nothing.
    """
    root = Path(root)
    files = []
    for part in parts:
        path = root / part
        files.extend([path] if path.is_file() else sorted(path.rglob("*.py")))
    digest = hashlib.sha256()
    for path in sorted(files, key=lambda f: f.relative_to(root).as_posix()):
        digest.update(path.relative_to(root).as_posix().encode("utf-8") + b"\0")
        digest.update(path.read_bytes() + b"\0")
    return digest.hexdigest()


def default_cache_dir() -> Path:
    """The cache directory used when none is given: the project's user cache directory
    (:func:`fuelhm_bench._numba_cache.user_cache_dir`, which also holds numba's caches)."""
    from fuelhm_bench._numba_cache import user_cache_dir

    return user_cache_dir()


def clear_memory_cache() -> None:
    """Forget every product kept in memory by this process (the disk cache is untouched)."""
    _MEMORY.clear()


def _entry(cache_dir, kind: str, sc, key: str) -> Path | None:
    """The entry folder of a product; ``sc`` None for a product shared by scenarios (:func:`content_key`)."""
    if cache_dir is False:
        return None
    directory = Path(default_cache_dir() if cache_dir is None else cache_dir)
    return directory / f"fuelhm-v{_FORMAT}" / (f"{kind}-{key[:16]}" if sc is None else f"{kind}-{sc.id}-{key[:16]}")


def _key_lock(key: str) -> threading.Lock:
    """The lock of one product in this process (threads building products at once,
    :func:`fuelhm_bench.datasets.parallel.run_concurrently`: a second asker of a product waits for the first)."""
    with _KEY_LOCKS_GUARD:
        return _KEY_LOCKS.setdefault(key, threading.Lock())


def _cached(key: str, entry: Path | None, names: tuple[str, ...], build: Callable[[], dict[str, pd.DataFrame]],
            finish: Callable[[dict[str, pd.DataFrame]], object], meta: dict):
    """Memory, then disk, then ``build()``; ``finish`` turns the tables into the product."""
    with _key_lock(key):
        return _cached_locked(key, entry, names, build, finish, meta)


def _cached_locked(key, entry, names, build, finish, meta):
    with _MEMORY_GUARD:
        if key in _MEMORY:
            _MEMORY.move_to_end(key)
            return _MEMORY[key]
    product = _load_product(entry, key, names, finish)
    if product is None:
        # One builder per product at a time: a process that finds another one building it (e.g. two
        # Dask workers building scenarios that share a fleet) waits for it, then reads its entry.
        with _build_lock(entry):
            product = _load_product(entry, key, names, finish)
            if product is None:
                tables = build()
                product = finish(tables)
                if entry is not None:
                    _store(entry, key, tables, meta)
    with _MEMORY_GUARD:
        _MEMORY[key] = product
        if len(_MEMORY) > _MEMORY_SIZE:
            _MEMORY.popitem(last=False)
    return product


def _load_product(entry: Path | None, key: str, names: tuple[str, ...],
                  finish: Callable[[dict[str, pd.DataFrame]], object]):
    """The product stored in ``entry``, or None (no disk cache, absent, stale or damaged: rebuilt, never trusted)."""
    if entry is None:
        return None
    tables = _load(entry, key, names)
    if tables is None:
        return None
    try:
        return finish(tables)
    except Exception:  # noqa: BLE001 - a damaged entry is rebuilt, never trusted
        return None


@contextlib.contextmanager
def _build_lock(entry: Path | None):
    """Hold an exclusive advisory lock on ``fuelhm-v<format>-locks/<entry name>.lock`` (a POSIX record
    lock, ``lockf``) beside the entries' folder while a product is built.

    A record lock belongs to this process only: the processes a build forks (the pools of
    :mod:`fuelhm_bench.datasets.parallel`, which outlive it) inherit the file but not the lock, so
    it is released when the build ends. The lock file is left in place (removing it would race
    with a process about to lock it).
    Without a disk cache, without ``fcntl`` (Windows) or when the lock cannot be taken (a
    read-only or lock-less file system), the build simply goes ahead unlocked: a duplicate
    build only costs time, since entries are written atomically.
    """
    handle = None
    if entry is not None:
        try:
            import fcntl

            locks = entry.parent.with_name(entry.parent.name + "-locks")  # beside the entries, not among them
            locks.mkdir(parents=True, exist_ok=True)
            handle = open(locks / (entry.name + ".lock"), "a")  # noqa: SIM115 - closed below
            fcntl.lockf(handle.fileno(), fcntl.LOCK_EX)
        except (ImportError, OSError):
            if handle is not None:
                handle.close()
            handle = None
    try:
        yield
    finally:
        if handle is not None:
            handle.close()  # releases the lock


def published_knowledge(scenario, *, flight_minutes: float | None = None, size: KnowledgeSize | None = None,
                        cache_dir: str | os.PathLike | bool | None = None,
                        progress: Callable[[int], object] | None = None, workers: int = 1):
    """The published knowledge of a scenario (as :func:`fuelhm_bench.datasets.knowledge.build_knowledge` builds it), cached.

    Parameters
    ----------
    scenario : str, Path or Scenario
        A shipped name, a YAML path or a loaded scenario.
    flight_minutes : float or None, default=None
        Flight duration [min]; None: the scenario's ``mission.duration_min``.
    size : KnowledgeSize or None, default=None
        Build size (``doe_*``, ``healthy_*`` fields); None: the defaults.
    cache_dir : str, path-like, False or None, default=None
        Disk cache directory; None: :func:`default_cache_dir`; False: memory only.
    progress : callable, optional
        Called with numbers of flights simulated (only when building).
    workers : int, default=1
        Processes simulating in parallel (only when building); the product is
        byte-identical for any number (:mod:`fuelhm_bench.datasets.parallel`).

    Returns
    -------
    KnowledgeResult
        The same tables and fitted numbers whichever cache answered.
    """
    from fuelhm_bench.datasets.checks import scenario_label
    from fuelhm_bench.datasets.knowledge import build_knowledge

    sc = resolve_scenario(scenario)
    _check_minutes(flight_minutes, "published_knowledge", sc)
    size = KnowledgeSize() if size is None else size
    params = {"doe_units": size.doe_units, "doe_intensities": list(size.doe_intensities),
              "healthy_units": size.healthy_units, "healthy_flights": size.healthy_flights}
    if size.doe_modes != MODE_IDS:  # (the key of the full design is unchanged by this field)
        params["doe_modes"] = list(size.doe_modes)
    build = knowledge_build(sc, flight_minutes=flight_minutes, size=size)
    key = content_key("knowledge", build)  # scenarios with the same published model, mission and sensor share it

    def make() -> dict[str, pd.DataFrame]:
        result = build_knowledge(build, progress=progress, workers=workers, label=scenario_label(scenario, sc))
        return {"healthy": result.healthy_table, "doe": result.doe_table}

    def finish(tables: dict[str, pd.DataFrame]):
        return _refit(tables["healthy"], tables["doe"], dict(build.max_intensity))

    return _cached(key, _entry(cache_dir, "knowledge", None, key), ("healthy", "doe"), make, finish,
                   {"scenario": sc.id, "kind": "knowledge", "flight_minutes": flight_minutes, **params})


def training_indicators(scenario, *, flight_minutes: float | None = None, units: int | None = None,
                        flights: int | None = None, drifted: bool = False,
                        cache_dir: str | os.PathLike | bool | None = None,
                        progress: Callable[[int], object] | None = None, workers: int = 1) -> pd.DataFrame:
    """Indicator table of the scenario's healthy training fleet (what methods are fitted on), cached.

    Parameters
    ----------
    scenario : str, Path or Scenario
    flight_minutes : float or None, default=None
        Flight duration [min]; None: the scenario's.
    units, flights : int or None, default=None
        Fleet size; None: the scenario's ``training`` section. Flights are
        seeded per (unit, flight), so a larger fleet continues the smaller one.
    drifted : bool, default=False
        Apply the scenario's nominal-parameter drift to the fleet's nominal
        model (the scored fleet's healthy state); training data never has it.
    cache_dir : str, path-like, False or None, default=None
    progress : callable, optional
    workers : int, default=1
        Processes simulating in parallel (only when building; same bytes for any number).

    Returns
    -------
    pandas.DataFrame
        The table of :func:`fuelhm_bench.datasets.fleet_indicators` (a copy).
    """
    sc = resolve_scenario(scenario)
    _check_minutes(flight_minutes, "training_indicators", sc)
    config = _with_minutes(sc.training_fleet_config(), flight_minutes)
    units = config.n_units if units is None else units
    flights = config.n_flights if flights is None else flights
    drifted = bool(drifted) and bool(sc.drift)
    config = dataclasses.replace(config, n_units=units, n_flights=flights,
                                 **({"nominal": sc.drifted_model()} if drifted else {}))
    return _fleet_table("training", sc, config, {"units": units, "flights": flights, "drifted": drifted},
                        flight_minutes, cache_dir, progress, workers)


def scored_indicators(scenario, *, flight_minutes: float | None = None, units: int | None = None,
                      drifted: bool = True, cache_dir: str | os.PathLike | bool | None = None,
                      progress: Callable[[int], object] | None = None, workers: int = 1) -> pd.DataFrame:
    """Indicator table of the scenario's scored fleet, as flown without maintenance, cached.

    These are the physics observations of ``FuelHM/ActuationLoop-v3`` replaying
    units ``0 .. units - 1`` with ``maintenance=False``
    (:meth:`ActuationLoopEnv.load_replays <fuelhm_bench.envs.ActuationLoopEnv.load_replays>`):
    simulated once, then shared by every method evaluated.

    Parameters
    ----------
    scenario : str, Path or Scenario
    flight_minutes : float or None, default=None
    units : int or None, default=None
        Number of scored units; None: the scenario's ``fleet.units``.
    drifted : bool, default=True
        Whether the fleet carries the scenario's nominal-parameter drift.
    cache_dir : str, path-like, False or None, default=None
    progress : callable, optional
    workers : int, default=1
        Processes simulating in parallel (only when building; same bytes for any number).

    Returns
    -------
    pandas.DataFrame
        The indicator table of :func:`fuelhm_bench.datasets.fleet_indicators` (a copy).
    """
    sc = resolve_scenario(scenario)
    _check_minutes(flight_minutes, "scored_indicators", sc)
    config = _with_minutes(sc.test_fleet_config(), flight_minutes)
    units = config.n_units if units is None else units
    drifted = bool(drifted) or not sc.drift
    config = dataclasses.replace(config, n_units=units, **({} if drifted else {"nominal": sc.truth_model()}))
    return _fleet_table("scored", sc, config, {"units": units, "drifted": drifted}, flight_minutes, cache_dir,
                        progress, workers)


def _fleet_table(kind: str, sc, config, params: dict, flight_minutes, cache_dir, progress, workers) -> pd.DataFrame:
    """The indicator table of one simulated fleet (``kind`` "training" or "scored"), cached; a copy.

    The table depends on ``config`` only, so it is keyed by it (:func:`content_key`): scenarios
    flying the same fleet (``low_data`` scores ``paper_2012``'s) share one entry, whatever ``kind``."""
    from fuelhm_bench.datasets.fleets import fleet_indicators

    key = content_key("fleet", config)

    def make() -> dict[str, pd.DataFrame]:
        return {"table": fleet_indicators(config, progress=progress, workers=workers)[0]}

    table = _cached(key, _entry(cache_dir, "fleet", None, key), ("table",), make, lambda t: t["table"],
                    {"scenario": sc.id, "kind": kind, "flight_minutes": flight_minutes, **params})
    return table.copy()


def surrogate_doe(scenario, *, flight_minutes: float | None = None, size: KnowledgeSize | None = None,
                  drifted: bool = True, cache_dir: str | os.PathLike | bool | None = None,
                  progress: Callable[[int], object] | None = None, workers: int = 1) -> pd.DataFrame:
    """Design of experiments on the scored fleet's model (what the surrogate's responses are learnt on), cached.

    Unlike the published DOE (:func:`published_knowledge`, on the published
    model), this one flies the scenario's truth model (hidden effects), with
    the scored fleet's drift when ``drifted``, its mission, sensor and
    dispersion: ``size.surrogate_doe_units`` units at
    ``size.surrogate_doe_intensities``, seeded from the test seed, for the
    modes the scenario schedules (all seven when it schedules none of them).
    Each unit's manufacturing coordinates are in its ``unit_z:<parameter>``
    columns (:func:`fuelhm_bench.physics.model.dispersion_coordinates`).
    Every unit flies its cases on ``size.surrogate_doe_missions`` missions
    (column ``replicate``), and, when the scenario's modes occur together
    (``simultaneous``), every pair of its modes at
    ``size.surrogate_doe_pair_intensities`` (:class:`~fuelhm_bench.datasets.doe.DesignOfExperiments`),
    and, when the scenario declares ``unknown_faults``, each of them at full strength
    (its effect with its parameters; ``mode`` :func:`~fuelhm_bench.datasets.doe.fault_case`),
    on the same missions: the key then names the faults, so scenarios with different
    unknown faults never share a surrogate.

    Returns
    -------
    pandas.DataFrame
        The table of :func:`fuelhm_bench.datasets.doe.run_doe` (a copy).
    """
    from fuelhm_bench.datasets.doe import _STREAM_DOE_UNIT, fault_case, run_doe
    from fuelhm_bench.flights.fleet import rng_for
    from fuelhm_bench.physics.model import manufacture

    sc = resolve_scenario(scenario)
    _check_minutes(flight_minutes, "surrogate_doe", sc)
    size = KnowledgeSize() if size is None else size
    doe = _surrogate_design(sc, flight_minutes, size, drifted)
    params = {"units": size.surrogate_doe_units, "intensities": list(size.surrogate_doe_intensities),
              "drifted": bool(drifted) and bool(sc.drift), "modes": list(doe.modes), "missions": doe.missions,
              "pairs": [list(pr) for pr in doe.pairs], "pair_intensities": list(doe.pair_intensities)}
    if doe.faults:  # (absent without faults: the keys of scenarios without any are unchanged)
        params["unknown_faults"] = [fault_case(f) for f in doe.faults]
    key = cache_key("surrogate-doe", sc, flight_minutes=flight_minutes, **params)

    def make() -> dict[str, pd.DataFrame]:
        return {"table": run_doe(doe, progress=progress, workers=workers)}

    table = _cached(key, _entry(cache_dir, "surrogate-doe", sc, key), ("table",), make, lambda t: t["table"],
                    {"scenario": sc.id, "kind": "surrogate-doe", "flight_minutes": flight_minutes, **params})
    return _with_coordinates(table, [manufacture(doe.nominal, rng_for(doe.seed, _STREAM_DOE_UNIT, u), doe.dispersion)
                                     for u in range(doe.n_units)], doe.nominal, doe.dispersion)


def _surrogate_design(sc, flight_minutes, size, drifted):
    """The design of experiments of :func:`surrogate_doe` (faults of the same physics flown once)."""
    from fuelhm_bench.datasets.doe import DesignOfExperiments, fault_case
    from fuelhm_bench.taxonomy import MODE_IDS

    config = _with_minutes(sc.test_fleet_config(), flight_minutes)
    drifted = bool(drifted) and bool(sc.drift)
    nominal = sc.drifted_model() if drifted else sc.truth_model()
    scheduled = {s.mode for s in sc.mode_schedules()}
    modes = tuple(m for m in MODE_IDS if m in scheduled) or tuple(MODE_IDS)
    pairs = (tuple((a, b) for i, a in enumerate(modes) for b in modes[i + 1:])
             if config.simultaneous and len(scheduled) > 1 else ())
    faults = {}
    for f in config.unknown_faults:
        faults.setdefault(fault_case(f), f)
    return DesignOfExperiments(n_units=size.surrogate_doe_units, intensities=size.surrogate_doe_intensities,
                               modes=modes, mission=config.mission, nominal=nominal, dispersion=config.dispersion,
                               seed=config.seed + 1, missions=size.surrogate_doe_missions, pairs=pairs,
                               pair_intensities=size.surrogate_doe_pair_intensities if pairs else (),
                               faults=tuple(faults.values()))


def _with_coordinates(table: pd.DataFrame, models: list, nominal, dispersion) -> pd.DataFrame:
    """``table`` (a copy) with the ``unit_z:<parameter>`` columns of unit ``unit_id`` = index in ``models``."""
    from fuelhm_bench.physics.model import dispersion_coordinates

    z = np.array([dispersion_coordinates(m, nominal, dispersion) for m in models])
    names = [p for p, _ in dispersion.relative] + [p for p, _ in dispersion.additive]
    index = table["unit_id"].to_numpy(dtype=np.int64)
    extra = pd.DataFrame(z[index], columns=[COORDINATE_PREFIX + n for n in names], index=table.index)
    return pd.concat([table, extra], axis=1)


def surrogate_healthy(scenario, *, flight_minutes: float | None = None, size: KnowledgeSize | None = None,
                      drifted: bool = True, cache_dir: str | os.PathLike | bool | None = None,
                      progress: Callable[[int], object] | None = None, workers: int = 1) -> pd.DataFrame:
    """Healthy flights of new units of the scored fleet's model (what the surrogate's healthy law is learnt on), cached.

    ``size.surrogate_units x size.surrogate_flights`` healthy flights of units
    manufactured like the scored fleet's (truth model with hidden effects, the
    scored fleet's drift when ``drifted``, its mission, sensor and dispersion)
    but seeded apart from both the training fleet and the scored fleet: the
    surrogate must not be learnt on the very flights methods are fitted on
    (a model always looks better on the flights it has seen, so a surrogate
    made of them would flatter every method). Each unit's manufacturing
    coordinates are in its ``unit_z:<parameter>`` columns
    (:func:`fuelhm_bench.physics.model.dispersion_coordinates`).

    Returns
    -------
    pandas.DataFrame
        The table of :func:`fuelhm_bench.datasets.fleet_indicators` (a copy).
    """
    from fuelhm_bench.datasets import fleet_indicators
    from fuelhm_bench.flights.fleet import build_units

    sc = resolve_scenario(scenario)
    _check_minutes(flight_minutes, "surrogate_healthy", sc)
    size = KnowledgeSize() if size is None else size
    config = _with_minutes(sc.test_fleet_config(), flight_minutes)
    drifted = bool(drifted) and bool(sc.drift)
    config = dataclasses.replace(config, n_units=size.surrogate_units, n_flights=size.surrogate_flights,
                                 schedules=(), simultaneous=True, seed=config.seed + 2,
                                 nominal=sc.drifted_model() if drifted else sc.truth_model())
    params = {"units": size.surrogate_units, "flights": size.surrogate_flights, "drifted": drifted}
    key = cache_key("surrogate-healthy", sc, flight_minutes=flight_minutes, **params)

    def make() -> dict[str, pd.DataFrame]:
        return {"table": fleet_indicators(config, progress=progress, workers=workers)[0]}

    table = _cached(key, _entry(cache_dir, "surrogate-healthy", sc, key), ("table",), make, lambda t: t["table"],
                    {"scenario": sc.id, "kind": "surrogate-healthy", "flight_minutes": flight_minutes, **params})
    return _with_coordinates(table, [u.model for u in build_units(config)], config.nominal, config.dispersion)


def surrogate_knowledge(scenario, *, flight_minutes: float | None = None, size: KnowledgeSize | None = None,
                        drifted: bool = True, cache_dir: str | os.PathLike | bool | None = None,
                        progress: Callable[[int], object] | None = None, workers: int = 1):
    """What the surrogate fidelity is learnt from: physics flights of new units of the scored fleet's model.

    ``healthy_table``: :func:`surrogate_healthy` (units independent of the
    training fleet methods are fitted on); ``doe_table``: :func:`surrogate_doe`.
    The ITL and signatures are the published ones (:func:`published_knowledge`);
    the healthy model is the published recipe fitted on ``healthy_table``.
    :meth:`SurrogateModel.from_knowledge <fuelhm_bench.envs.surrogate.SurrogateModel.from_knowledge>`
    learns the surrogate from the two tables.

    Returns
    -------
    KnowledgeResult
    """
    from fuelhm_bench.datasets.checks import check_training_indicators, scenario_label
    from fuelhm_bench.diagnosis.healthy import HealthyModel
    from fuelhm_bench.datasets.knowledge import KnowledgeResult

    size = KnowledgeSize() if size is None else size
    common = {"flight_minutes": flight_minutes, "cache_dir": cache_dir, "progress": progress, "workers": workers}
    published = published_knowledge(scenario, size=size, **common)
    table = surrogate_healthy(scenario, size=size, drifted=drifted, **common)
    check_training_indicators(table, scenario_label(scenario, resolve_scenario(scenario)), fidelity="surrogate",
                              knowledge_flights=len(table), flight_minutes=flight_minutes,
                              flights="healthy flights the surrogate learns from")
    doe = surrogate_doe(scenario, size=size, drifted=drifted, **common)
    return KnowledgeResult(published.itl, HealthyModel().fit(table), published.signatures,
                           dict(published.max_intensity), doe, table)


def _refit(healthy: pd.DataFrame, doe: pd.DataFrame, max_intensity: dict):
    """The fitting half of :func:`fuelhm_bench.datasets.knowledge.build_knowledge`, on stored tables."""
    from fuelhm_bench.diagnosis.healthy import HealthyModel
    from fuelhm_bench.diagnosis.itl import fit_itl
    from fuelhm_bench.diagnosis.signatures import signature_matrix
    from fuelhm_bench.datasets.knowledge import KnowledgeResult

    healthy_model = HealthyModel().fit(healthy)
    itl = fit_itl(doe)
    sig = signature_matrix(itl, healthy_model, max_intensity=max_intensity)
    return KnowledgeResult(itl, healthy_model, sig, dict(max_intensity), doe, healthy)


def _load(entry: Path, key: str, names: tuple[str, ...]) -> dict[str, pd.DataFrame] | None:
    """The stored tables of ``entry``, or None when absent, stale or unreadable."""
    try:
        meta = json.loads((entry / "meta.json").read_text(encoding="utf-8"))
        if meta.get("key") != key:
            return None
        tables = {name: pd.read_parquet(entry / f"{name}.parquet") for name in names}
    except (OSError, ValueError, KeyError, ImportError):
        return None
    for table in tables.values():  # text columns come back as pandas strings; the builders make object columns
        for column in table.columns:
            if isinstance(table[column].dtype, pd.StringDtype):
                table[column] = table[column].astype(object)
    return tables


def _store(entry: Path, key: str, tables: dict[str, pd.DataFrame], meta: dict) -> None:
    """Write an entry atomically (a temporary directory renamed into place); failures only cost a rebuild."""
    from fuelhm_bench import __version__

    try:
        entry.parent.mkdir(parents=True, exist_ok=True)
        tmp = Path(tempfile.mkdtemp(prefix=f".{entry.name}-", dir=entry.parent))
        try:
            for name, table in tables.items():
                table.to_parquet(tmp / f"{name}.parquet", index=False)
            info = {"key": key, **meta, "package_version": __version__, "format": _FORMAT}
            (tmp / "meta.json").write_text(json.dumps(info, indent=2, default=repr), encoding="utf-8")
            if entry.exists():
                shutil.rmtree(entry, ignore_errors=True)
            os.replace(tmp, entry)
        finally:
            if tmp.exists():
                shutil.rmtree(tmp, ignore_errors=True)
    except (OSError, ValueError, ImportError):
        return
