"""The actuation-loop model: a composition of component parameter sets and optional effects.

A :class:`LoopModel` is immutable. Everything that changes a unit returns a new
model: :meth:`LoopModel.degraded` (degradation modes), :meth:`LoopModel.with_effect`
(optional physical effects), :meth:`LoopModel.with_parameters` (set parameters by
dotted path, e.g. ``"servovalve.null_bias_a"`` or ``"effect.rod_friction.coulomb_n"``),
:func:`manufacture` (seeded manufacturing dispersion). Models round-trip through
plain dicts and YAML files (:func:`save_model`, :func:`load_model`), which is the
format of ``fuelhm-bench calibrate`` output and of ``simulate --model``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from fuelhm_bench.errors import FuelHMError, ModelFileError, OutputPathError, UnknownNameError, range_error
from fuelhm_bench.physics import degradations as _deg
from fuelhm_bench.physics.controller import ControllerParams
from fuelhm_bench.physics.cylinder import CylinderParams, LoadParams
from fuelhm_bench.physics.driver import CurrentDriverParams
from fuelhm_bench.physics.effects import EFFECTS, Effect, _suggest, effect_parameters, make_effect
from fuelhm_bench.physics.fluid import FluidParams
from fuelhm_bench.physics.lvdt import LvdtParams
from fuelhm_bench.physics.servovalve import ServovalveParams

COMPONENTS: dict[str, type] = {
    "fluid": FluidParams,
    "servovalve": ServovalveParams,
    "cylinder": CylinderParams,
    "load": LoadParams,
    "controller": ControllerParams,
    "driver": CurrentDriverParams,
    "lvdt": LvdtParams,
}

MODEL_FORMAT_VERSION = 1


@dataclass(frozen=True)
class LoopModel:
    """Parameters of one actuation loop (controller, driver, servovalve, cylinder, LVDT).

    Parameters
    ----------
    fluid, servovalve, cylinder, load, controller, driver, lvdt : parameter dataclasses
        Component parameters (SI units in the field names); defaults are the
        nominal values of docs/physics.md §3 Nominal parameters.
    effects : tuple of effects, default=()
        Optional physical effects switched on (at most one of each id).
    """

    fluid: FluidParams = field(default_factory=FluidParams)
    servovalve: ServovalveParams = field(default_factory=ServovalveParams)
    cylinder: CylinderParams = field(default_factory=CylinderParams)
    load: LoadParams = field(default_factory=LoadParams)
    controller: ControllerParams = field(default_factory=ControllerParams)
    driver: CurrentDriverParams = field(default_factory=CurrentDriverParams)
    lvdt: LvdtParams = field(default_factory=LvdtParams)
    effects: tuple = ()

    def __post_init__(self) -> None:
        ids = [e.id for e in self.effects]
        if len(set(ids)) != len(ids):
            raise range_error("LoopModel.effects", "at most one effect of each id", ids)
        # Canonical order so that equal models compare (and hash) equal.
        object.__setattr__(self, "effects", tuple(sorted(self.effects, key=lambda e: list(EFFECTS).index(e.id))))

    # ------------------------------------------------------------------ effects
    def effect(self, effect_id: str) -> Effect | None:
        """The enabled effect with this id, or None."""
        for e in self.effects:
            if e.id == effect_id:
                return e
        return None

    def with_effect(self, effect: Effect | str, **params: float) -> LoopModel:
        """Return a model with an effect switched on (replacing one of the same id).

        Parameters
        ----------
        effect : effect instance or str
            An effect, or its id (then ``params`` override its defaults).
        **params : float
            Parameters when ``effect`` is an id.
        """
        if isinstance(effect, str):
            effect = make_effect(effect, **params)
        kept = tuple(e for e in self.effects if e.id != effect.id)
        return dataclasses.replace(self, effects=kept + (effect,))

    def without_effect(self, effect_id: str) -> LoopModel:
        """Return a model with an effect switched off."""
        return dataclasses.replace(self, effects=tuple(e for e in self.effects if e.id != effect_id))

    # ---------------------------------------------------------- degradations
    def degraded(self, intensities: Mapping[str, float]) -> LoopModel:
        """Return the model with degradation intensities applied (see :mod:`~fuelhm_bench.physics.degradations`)."""
        return _deg.degrade(self, intensities)

    # ------------------------------------------------------------ parameters
    def get(self, path: str) -> float:
        """Value of a parameter by dotted path (``"servovalve.null_bias_a"``, ``"effect.lvdt_lag.time_constant_s"``)."""
        parts = path.split(".")
        if parts[0] == "effect" and len(parts) == 3:
            eff = self.effect(parts[1])
            if eff is None:
                raise UnknownNameError(f"Parameter path '{path}': effect '{parts[1]}' is not enabled in this model.")
            return float(effect_parameters(eff)[parts[2]]) if parts[2] in effect_parameters(eff) else _bad_path(path)
        if len(parts) != 2 or parts[0] not in COMPONENTS:
            _bad_path(path)
        comp = getattr(self, parts[0])
        if not hasattr(comp, parts[1]) or parts[1] not in {f.name for f in dataclasses.fields(comp)}:
            _bad_path(path)
        return float(getattr(comp, parts[1]))

    def with_parameters(self, values: Mapping[str, float]) -> LoopModel:
        """Return a model with parameters set by dotted path (validated).

        Consecutive paths of one component are set together (one validation of the component).
        """
        model = self
        pending: dict = {}  # component -> {field: value}, flushed when another kind of path comes

        def flush(m):
            for name, fields in pending.items():
                m = dataclasses.replace(m, **{name: dataclasses.replace(getattr(m, name), **fields)})
            pending.clear()
            return m

        for path, value in values.items():
            parts = path.split(".")
            if parts[0] == "effect" and len(parts) == 3:
                eff = model.effect(parts[1])
                if eff is None:
                    raise UnknownNameError(f"Parameter path '{path}': effect '{parts[1]}' is not enabled in this model.")
                if parts[2] not in effect_parameters(eff):
                    _bad_path(path)
                model = flush(model).with_effect(dataclasses.replace(eff, **{parts[2]: float(value)}))
                continue
            if len(parts) != 2 or parts[0] not in COMPONENTS:
                _bad_path(path)
            comp = getattr(model, parts[0])
            if parts[1] not in {f.name for f in dataclasses.fields(comp)}:
                _bad_path(path)
            if parts[0] not in pending and pending:
                model = flush(model)
            cast = int if parts[1] == "adc_bits" else float
            pending.setdefault(parts[0], {})[parts[1]] = cast(value)
        return flush(model)

    # --------------------------------------------------------- serialisation
    def to_dict(self) -> dict:
        """Plain-dict representation (YAML-ready)."""
        out: dict = {"format_version": MODEL_FORMAT_VERSION}
        for name in COMPONENTS:
            out[name] = dataclasses.asdict(getattr(self, name))
        out["effects"] = {e.id: effect_parameters(e) for e in self.effects}
        return out

    @classmethod
    def from_dict(cls, data: Mapping, *, source: str = "<dict>") -> LoopModel:
        """Build a model from :meth:`to_dict` output; missing fields take nominal values.

        Raises
        ------
        ModelFileError
            Unknown section or field, or a value out of range, naming ``source``.
        """
        if not isinstance(data, Mapping):
            raise ModelFileError(f"{source}: a model file must be a mapping of sections. Got {type(data).__name__}.")
        version = data.get("format_version", MODEL_FORMAT_VERSION)
        if version != MODEL_FORMAT_VERSION:
            raise ModelFileError(f"{source}: format_version must be {MODEL_FORMAT_VERSION}. Got {version!r} instead.")
        kwargs: dict = {}
        for key, section in data.items():
            if key == "format_version":
                continue
            if key == "effects":
                effs = []
                if not isinstance(section or {}, Mapping):
                    raise ModelFileError(f"{source}: section 'effects' must be a mapping of effect id to its "
                                         f"parameters (e.g. 'rod_friction: {{coulomb_n: 500}}'). Got "
                                         f"{type(section).__name__} instead.")
                for eid, params in (section or {}).items():
                    if not isinstance(params or {}, Mapping):
                        raise ModelFileError(f"{source}: effects.{eid} must be a mapping of the effect's parameters "
                                             f"(or empty for its defaults). Got {params!r} instead.")
                    try:
                        effs.append(make_effect(eid, **(params or {})))
                    except FuelHMError as exc:
                        raise ModelFileError(f"{source}: effects.{eid}: {exc}") from None
                kwargs["effects"] = tuple(effs)
                continue
            if key not in COMPONENTS:
                raise ModelFileError(f"{source}: unknown section '{key}'. Allowed: {', '.join(COMPONENTS)}, effects."
                                     f"{_suggest(str(key), list(COMPONENTS) + ['effects'])}")
            comp_cls = COMPONENTS[key]
            names = [f.name for f in dataclasses.fields(comp_cls)]
            section = section or {}
            if not isinstance(section, Mapping):
                raise ModelFileError(f"{source}: section '{key}' must be a mapping of parameters.")
            for pname in section:
                if pname not in names:
                    raise ModelFileError(f"{source}: unknown parameter '{key}.{pname}'.{_suggest(str(pname), names)}")
            try:
                kwargs[key] = comp_cls(**dict(section))
            except FuelHMError as exc:
                raise ModelFileError(f"{source}: {exc}") from None
        return cls(**kwargs)


def _bad_path(path: str):
    raise UnknownNameError(
        f"Unknown parameter path '{path}'. Use 'component.field' with component in "
        f"{', '.join(COMPONENTS)}, or 'effect.<id>.<field>'.")


def save_model(model: LoopModel, path: str | Path, *, overwrite: bool = False, header: str | None = None) -> Path:
    """Write a model to a YAML file (refuses to overwrite unless ``overwrite``)."""
    path = Path(path)
    if path.exists() and not overwrite:
        raise OutputPathError(f"{path} exists; refusing to overwrite it (pass --force / overwrite=True).")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        text = yaml.safe_dump(model.to_dict(), sort_keys=False)
        if header:
            text = "".join(f"# {line}\n" for line in header.splitlines()) + text
        path.write_text(text)
    except OSError as exc:
        raise OutputPathError(f"Cannot write the model file {path}: {exc.strerror or exc}.") from None
    return path


def load_model(path: str | Path) -> LoopModel:
    """Load a model YAML file (safe loader), with errors naming the file and field."""
    from fuelhm_bench.yamlfiles import read_yaml

    data = read_yaml(path, "model file", ModelFileError)
    return LoopModel.from_dict(data or {}, source=str(path))


#: Manufacturing draws are truncated at this many standard deviations (:func:`manufacturing_draws`).
DISPERSION_TRUNCATION: float = 3.0
#: Largest :attr:`Dispersion.scale`. The draws being truncated at 3 standard deviations, the most dispersed
#: parameters of the default dispersion (spool friction, aerodynamic load: 10 %) then stay within 90 % of
#: their nominal value, so no manufactured parameter changes sign (at 3.33 the spool friction reaches 0).
MAX_DISPERSION_SCALE: float = 3.0


@dataclass(frozen=True)
class Dispersion:
    """Manufacturing dispersion of a unit around its nominal parameters.

    Each listed parameter is multiplied by ``1 + rel_std * N(0, 1)`` (truncated
    at :data:`DISPERSION_TRUNCATION` = 3 sigma) except additive ones (currents in A,
    drawn as ``+ std * N(0,1)``).

    Parameters
    ----------
    scale : float, default=1.0
        Multiplies every standard deviation (0 gives identical units), in [0, :data:`MAX_DISPERSION_SCALE`].
    relative : tuple of (path, rel_std)
        Multiplicative dispersions.
    additive : tuple of (path, std)
        Additive dispersions (SI units).
    """

    scale: float = 1.0
    relative: tuple = (
        ("servovalve.spool_time_constant_s", 0.05),
        ("servovalve.slot_width_null_m", 0.02),
        ("servovalve.slot_width_outer_m", 0.02),
        ("servovalve.radial_clearance_m", 0.05),
        ("servovalve.discharge_coefficient", 0.02),
        ("servovalve.rated_current_a", 0.02),
        ("servovalve.spool_friction_n", 0.10),
        ("cylinder.diaphragm_diameter_m", 0.03),
        ("load.aero_force_at_100pct_n", 0.10),
        ("driver.gain", 0.01),
    )
    additive: tuple = (
        ("servovalve.null_bias_a", 1e-4),
        ("driver.offset_a", 2e-5),
    )

    def __post_init__(self) -> None:
        if not (isinstance(self.scale, (int, float)) and math.isfinite(self.scale)
                and 0.0 <= self.scale <= MAX_DISPERSION_SCALE):
            raise range_error("Dispersion.scale", f"in [0, {MAX_DISPERSION_SCALE:g}]", self.scale)

    def extremes(self, nominal: LoopModel) -> list[tuple[str, float]]:
        """``(path, value)`` of each dispersed parameter at both ends of its truncated draws around ``nominal``.

        A unit's parameters lie within these values (each one alone; every corner of the box is a
        unit too). Relative parameters first, then additive ones, low end before high end.
        """
        n_rel = len(self.relative)
        out = []
        for i, (path, std) in enumerate((*self.relative, *self.additive)):
            for z in (-DISPERSION_TRUNCATION, DISPERSION_TRUNCATION):
                step = std * z * self.scale
                out.append((path, nominal.get(path) * (1.0 + step) if i < n_rel else nominal.get(path) + step))
        return out


def dispersion_error(nominal: LoopModel, dispersion: Dispersion = Dispersion()) -> FuelHMError | None:
    """The physics error of a unit that ``dispersion`` can manufacture around ``nominal``, or None if there is none.

    Each dispersed parameter is set, alone, to both ends of its truncated draws
    (:meth:`Dispersion.extremes`); the first value its component refuses gives the error
    (``"The 'ServovalveParams.discharge_coefficient' parameter must be ..."``).
    """
    for path, value in dispersion.extremes(nominal):
        try:
            nominal.with_parameters({path: value})
        except FuelHMError as exc:
            return exc
    return None


def max_dispersion_scale(nominal: LoopModel, dispersion: Dispersion = Dispersion()) -> float:
    """Largest scale in [0, :data:`MAX_DISPERSION_SCALE`] at which :func:`dispersion_error` finds no error (to 1e-3).

    Examples
    --------
    >>> max_dispersion_scale(LoopModel())
    3.0
    """
    def ok(scale: float) -> bool:
        return dispersion_error(nominal, dataclasses.replace(dispersion, scale=scale)) is None

    if ok(MAX_DISPERSION_SCALE):
        return MAX_DISPERSION_SCALE
    low, high = 0.0, MAX_DISPERSION_SCALE
    while high - low > 1e-3:
        mid = 0.5 * (low + high)
        low, high = (mid, high) if ok(mid) else (low, mid)
    return math.floor(low * 1e3) / 1e3


def manufacturing_draws(rng: np.random.Generator, dispersion: Dispersion = Dispersion()) -> np.ndarray:
    """The standardised draws of :func:`manufacture` (relative parameters, then additive), clipped at
    :data:`DISPERSION_TRUNCATION`.

    What :func:`dispersion_coordinates` recovers from the unit (where the dispersion is not 0), without
    building the unit.
    """
    n = len(dispersion.relative) + len(dispersion.additive)
    return np.clip(rng.standard_normal(n), -DISPERSION_TRUNCATION, DISPERSION_TRUNCATION)


def dispersion_coordinates(model: LoopModel, nominal: LoopModel, dispersion: Dispersion = Dispersion(),
                           names: tuple | None = None) -> np.ndarray:
    """The standardised draws ``z`` of :func:`manufacture` that made ``model`` from ``nominal`` (its inverse).

    For a relative dispersion ``(path, s)``: ``(value / nominal - 1) / (s * scale)``; for an additive
    one: ``(value - nominal) / (s * scale)``; 0 where the dispersion is 0.

    Parameters
    ----------
    model, nominal : LoopModel
        A manufactured unit and the nominal model it was manufactured around.
    dispersion : Dispersion
    names : tuple of str or None, default=None
        Parameter paths wanted, in order; None: every dispersed one (relative, then additive).

    Returns
    -------
    ndarray of shape (len(names),)

    Examples
    --------
    >>> unit = manufacture(LoopModel(), np.random.default_rng(0))
    >>> z = dispersion_coordinates(unit, LoopModel())
    >>> bool(np.allclose(z, np.clip(np.random.default_rng(0).standard_normal(len(z)), -3, 3)))
    True
    """
    terms = {path: (std, True) for path, std in dispersion.relative}
    terms.update({path: (std, False) for path, std in dispersion.additive})
    names = tuple(terms) if names is None else tuple(names)
    unknown = [n for n in names if n not in terms]
    if unknown:
        raise range_error("dispersion_coordinates.names", f"dispersed parameters ({list(terms)})", unknown)
    out = np.zeros(len(names))
    for i, path in enumerate(names):
        std, relative = terms[path]
        scale = float(std) * float(dispersion.scale)
        if scale != 0.0:
            value, value0 = float(model.get(path)), float(nominal.get(path))
            out[i] = ((value / value0 - 1.0) if relative else (value - value0)) / scale
    return out


def manufacture(nominal: LoopModel, rng: np.random.Generator, dispersion: Dispersion = Dispersion()) -> LoopModel:
    """Draw one manufactured unit around ``nominal`` (seeded, deterministic).

    Parameters
    ----------
    nominal : LoopModel
        Nominal model.
    rng : numpy.random.Generator
        Source of randomness (the only one).
    dispersion : Dispersion
        Dispersion specification.

    Returns
    -------
    LoopModel
    """
    n_rel = len(dispersion.relative)
    draws = manufacturing_draws(rng, dispersion) * dispersion.scale
    values: dict[str, float] = {}
    for (path, std), z in zip(dispersion.relative, draws[:n_rel]):
        values[path] = nominal.get(path) * (1.0 + std * z)
    for (path, std), z in zip(dispersion.additive, draws[n_rel:]):
        values[path] = nominal.get(path) + std * z
    return nominal.with_parameters(values)
