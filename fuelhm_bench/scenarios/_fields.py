"""Declarative field constraints shared by validation, YAML loading and the JSON Schema.

Every scenario section is a frozen dataclass whose fields carry their
constraints in ``dataclasses.field(metadata=...)`` (built with :func:`option`).
The same declarations drive three things, so nothing is written twice:

* validation in ``__post_init__`` (:class:`Spec`), which also normalises
  values (``int`` to ``float`` for number fields, lists to tuples);
* the wording of error messages (:func:`allowed_text`);
* the JSON Schema (:mod:`fuelhm_bench.scenarios.jsonschema`), whose field
  descriptions are read from the numpydoc ``Parameters`` section of each class
  (:func:`parameter_docs`).

Problems are collected as :class:`Problem` records (field path, allowed, given)
and raised together as one :class:`ScenarioValidationError`; the YAML loader
adds the file name and line number of each.
"""

from __future__ import annotations

import dataclasses
import inspect
import math
import re
import types
import typing
from collections.abc import Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass
from functools import cache
from typing import Any

from fuelhm_bench.errors import ScenarioValidationError, did_you_mean, show_value

MISSING = dataclasses.MISSING


# ----------------------------------------------------------------------------- problems
@dataclass(frozen=True)
class Problem:
    """One validation failure.

    Parameters
    ----------
    field : str
        Field path relative to the object that found the problem, e.g.
        ``"growth"`` or ``"degradations[2].growth"``; ``""`` for the object itself.
    allowed : str
        What is allowed, e.g. ``"one of step, linear, exponential"``.
    given : str
        The offending value, already rendered (see :func:`show`).
    hint : str, default=""
        Extra sentence, e.g. ``"Did you mean 'exponential'?"``.
    unknown_key : bool, default=False
        The problem is a key that the mapping does not accept (``field`` is the
        path of that key).
    near : tuple of str, default=()
        Other field paths (same base as ``field``) whose line may locate the
        problem when ``field`` itself is absent from the file.
    source : str or None, default=None
        File the problem was found in (set by the loader).
    line : int or None, default=None
        1-based line in ``source`` (set by the loader).
    """

    field: str
    allowed: str
    given: str
    hint: str = ""
    unknown_key: bool = False
    near: tuple = ()
    source: str | None = None
    line: int | None = None

    def under(self, prefix: str) -> Problem:
        """The same problem with ``prefix`` prepended to its field paths."""
        return dataclasses.replace(self, field=join(prefix, self.field),
                                   near=tuple(join(prefix, n) for n in self.near))

    def message(self, owner: str = "") -> str:
        """The problem as one sentence, prefixed with ``file:line:`` when known.

        Parameters
        ----------
        owner : str, default=""
            Name prepended to the field path when the problem has no source file
            (e.g. ``"DegradationSpec"`` for an object built in Python).
        """
        where = ""
        if self.source is not None:
            where = f"{self.source}:{self.line}: " if self.line is not None else f"{self.source}: "
        prefix = owner if self.source is None else ""  # objects built in Python: name their class
        name = join(prefix, self.field)
        hint = f" {self.hint}" if self.hint else ""
        if self.unknown_key:
            parent = join(prefix, _split_last(self.field)[0])
            scope = f"the keys of {parent}" if parent else "top-level keys"
            return (f"{where}{name} is not an allowed key; {scope} must be one of {self.allowed}. "
                    f"Got {self.given} instead.{hint}")
        return f"{where}{name or 'the document'} must be {self.allowed}. Got {self.given} instead.{hint}"


def join(prefix: str, field: str) -> str:
    """Join two field paths (``"fleet" + "units"``, ``"drift" + "[0]"``)."""
    if not prefix:
        return field
    if not field:
        return prefix
    return prefix + field if field.startswith("[") else f"{prefix}.{field}"


def _split_last(path: str) -> tuple[str, str, str]:
    """Split ``a.b[2].c`` into ``("a.b[2]", ".", "c")``; ``a[2]`` into ``("a", "[", "2]")``."""
    m = re.match(r"^(.*?)(\.|\[)([^.\[]*)$", path)
    if not m:
        return "", "", path
    return m.group(1), m.group(2), m.group(3)


def parents(path: str) -> Iterator[str]:
    """``path`` then each enclosing path up to (excluding) the root."""
    while path:
        yield path
        path = _split_last(path)[0]


def show(value: Any) -> str:
    """Render a given value for a message (YAML words for booleans and null)."""
    if value is MISSING:
        return "nothing (the key is missing)"
    if value is None:
        return "null"
    if isinstance(value, bool):
        return "true" if value else "false"
    return show_value(value)  # bounded: never the repr of a huge expanded value


def suggest(name: Any, options: Iterable[str]) -> str:
    """``"Did you mean 'x'?"`` (no leading space) from :func:`fuelhm_bench.errors.did_you_mean`."""
    return did_you_mean(name, options, sep="")


def unknown_key(field: str, key: Any, allowed: Sequence[str]) -> Problem:
    """Problem for a key that a mapping does not accept."""
    return Problem(field, ", ".join(allowed), show(key), suggest(key, allowed), unknown_key=True)


# ----------------------------------------------------------------------------- options
def option(default: Any = MISSING, *, default_factory: Any = MISSING, ge: float | None = None,
           gt: float | None = None, le: float | None = None, lt: float | None = None,
           choices: Sequence | None = None, pattern: str | None = None,
           number_map: bool = False, min_items: int | None = None) -> Any:
    """A dataclass field with declared constraints.

    Parameters
    ----------
    default, default_factory
        As for :func:`dataclasses.field`; omit both for a required field.
    ge, gt, le, lt : float, optional
        Inclusive / exclusive bounds of a number field.
    choices : sequence, optional
        Allowed values (strings get a did-you-mean suggestion).
    pattern : str, optional
        Regular expression a string must match in full.
    number_map : bool, default=False
        The field is a mapping ``name -> number`` stored as a tuple of
        ``(name, float)`` pairs (YAML mapping at the boundary).
    min_items : int, optional
        Minimum length of a list field.

    Notes
    -----
    For a list of numbers (``tuple[float, ...]``) the bounds apply to each item.
    """
    meta = {"ge": ge, "gt": gt, "le": le, "lt": lt, "choices": tuple(choices) if choices is not None else None,
            "pattern": pattern, "number_map": number_map, "min_items": min_items}
    return dataclasses.field(default=default, default_factory=default_factory, metadata=meta)


def _meta(f: dataclasses.Field) -> dict:
    return {"ge": None, "gt": None, "le": None, "lt": None, "choices": None, "pattern": None, "number_map": False,
            "min_items": None, **dict(f.metadata)}


@dataclass(frozen=True)
class FieldKind:
    """What a field holds, derived from its annotation.

    Parameters
    ----------
    base : type
        ``int``, ``float``, ``bool``, ``str``, a spec class, or ``tuple`` for
        lists (of specs or of numbers) and for number maps.
    optional : bool
        ``None`` is accepted.
    item : type or None
        Item type of a list: a spec class or ``float``.
    """

    base: type
    optional: bool = False
    item: type | None = None


@cache
def field_kinds(cls: type) -> dict[str, FieldKind]:
    """``{field name: FieldKind}`` of a spec dataclass, from its type hints."""
    hints = typing.get_type_hints(cls)
    kinds = {}
    for f in dataclasses.fields(cls):
        tp = hints[f.name]
        optional = False
        origin = typing.get_origin(tp)
        if origin in (typing.Union, types.UnionType):
            args = [a for a in typing.get_args(tp) if a is not type(None)]
            optional = len(args) < len(typing.get_args(tp))
            if len(args) != 1:
                raise TypeError(f"{cls.__name__}.{f.name}: unsupported annotation {tp!r}")
            tp = args[0]
            origin = typing.get_origin(tp)
        item = None
        if origin is tuple:
            args = typing.get_args(tp)
            if len(args) == 2 and args[1] is Ellipsis and (dataclasses.is_dataclass(args[0]) or args[0] is float):
                item = args[0]
            elif not _meta(f)["number_map"]:
                raise TypeError(f"{cls.__name__}.{f.name}: unsupported annotation {tp!r}")
            tp = tuple
        kinds[f.name] = FieldKind(tp, optional, item)
    return kinds


def _fmt(x: float) -> str:
    return str(x) if isinstance(x, int) else f"{x:g}"  # an int bound exactly (a seed's 2**63 - 1)


def range_text(meta: Mapping) -> str:
    """``"in [0, 1]"``, ``"> 0"``, ... from the bounds of a field (``""`` if unbounded)."""
    lo, lo_inc = (meta["ge"], True) if meta["ge"] is not None else (meta["gt"], False)
    hi, hi_inc = (meta["le"], True) if meta["le"] is not None else (meta["lt"], False)
    if lo is not None and hi is not None:
        return f"in {'[' if lo_inc else '('}{_fmt(lo)}, {_fmt(hi)}{']' if hi_inc else ')'}"
    if lo is not None:
        return f"{'>=' if lo_inc else '>'} {_fmt(lo)}"
    if hi is not None:
        return f"{'<=' if hi_inc else '<'} {_fmt(hi)}"
    return ""


def allowed_text(f: dataclasses.Field, kind: FieldKind) -> str:
    """Human-readable description of what a field accepts."""
    meta = _meta(f)
    if meta["choices"] is not None:
        text = "one of " + ", ".join(show(c) if not isinstance(c, str) else c for c in meta["choices"])
    elif kind.base is bool:
        text = "true or false"
    elif kind.base is int:
        rng = range_text(meta)
        text = "an integer" + (f" {rng}" if rng else "")
    elif kind.base is float:
        rng = range_text(meta)
        text = "a number" + (f" {rng}" if rng else "")
    elif kind.base is str:
        text = f"a string matching {meta['pattern']}" if meta["pattern"] else "a string"
    elif kind.item is float:
        rng = range_text(meta)
        text = ("a non-empty list" if meta["min_items"] else "a list") + " of numbers" + (f" {rng}" if rng else "")
    elif kind.item is not None:
        text = f"a list of {kind.item.__name__} mappings"
    elif meta["number_map"]:
        text = "a mapping of names to numbers"
    else:
        text = f"a {getattr(kind.base, '__name__', kind.base)} mapping"
    return text + (" or null" if kind.optional else "")


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _check_value(f: dataclasses.Field, kind: FieldKind, value: Any) -> tuple[Any, Problem | None]:
    """Type-check, normalise and range-check one value; return ``(value, problem)``."""
    meta = _meta(f)
    bad = Problem(f.name, allowed_text(f, kind), show(value))
    if value is None:
        return (None, None) if kind.optional else (value, bad)
    if kind.base is bool:
        return (value, None) if isinstance(value, bool) else (value, bad)
    if kind.base is int:
        if not _is_int(value):
            return value, bad
    elif kind.base is float:
        if not _is_number(value) or not math.isfinite(value):
            return value, bad
        value = float(value)
    elif kind.base is str:
        if not isinstance(value, str):
            return value, bad
        if meta["pattern"] and not re.fullmatch(meta["pattern"], value):
            return value, bad
    elif kind.item is float:
        if not isinstance(value, (list, tuple)) or len(value) < (meta["min_items"] or 0):
            return value, bad
        for i, v in enumerate(value):
            if not _is_number(v) or not math.isfinite(v) or not _in_range(meta, v):
                return value, Problem(f"{f.name}[{i}]", "a number" + (f" {range_text(meta)}" if range_text(meta)
                                                                      else ""), show(v))
        return tuple(float(v) for v in value), None
    elif kind.item is not None:
        if isinstance(value, (list, tuple)) and all(isinstance(v, kind.item) for v in value):
            return tuple(value), None
        return value, bad
    elif meta["number_map"]:
        pairs = list(value.items()) if isinstance(value, Mapping) else value
        try:
            items = [(k, v) for k, v in pairs]
        except (TypeError, ValueError):
            return value, bad
        for k, v in items:
            if not isinstance(k, str):
                return value, Problem(f.name, "a mapping with string keys", show(k))
            if not _is_number(v) or not math.isfinite(v):
                return value, Problem(join(f.name, k), "a number", show(v))
        return tuple((k, float(v)) for k, v in items), None
    else:  # nested spec
        return (value, None) if isinstance(value, kind.base) else (value, bad)
    if meta["choices"] is not None and value not in meta["choices"]:
        return value, dataclasses.replace(bad, hint=suggest(value, [c for c in meta["choices"] if isinstance(c, str)]))
    if _is_number(value) and not _in_range(meta, value):
        return value, bad
    return value, None


def _in_range(meta: Mapping, value: float) -> bool:
    lo_ok = (meta["ge"] is None or value >= meta["ge"]) and (meta["gt"] is None or value > meta["gt"])
    hi_ok = (meta["le"] is None or value <= meta["le"]) and (meta["lt"] is None or value < meta["lt"])
    return lo_ok and hi_ok


class Spec:
    """Mixin of the scenario section dataclasses: validates fields on construction.

    Subclasses are frozen dataclasses whose fields are declared with
    :func:`option`; they may override :meth:`_checks` to add cross-field
    checks (run only when every field is individually valid).
    """

    def __post_init__(self) -> None:
        problems = []
        kinds = field_kinds(type(self))
        for f in dataclasses.fields(self):
            value, problem = _check_value(f, kinds[f.name], getattr(self, f.name))
            if problem is not None:
                problems.append(problem)
            else:
                object.__setattr__(self, f.name, value)
        if not problems:
            problems.extend(self._checks())
        if problems:
            raise ScenarioValidationError(problems, owner=type(self).__name__)

    def _checks(self) -> Iterable[Problem]:
        """Cross-field checks; field paths relative to this object."""
        return ()

    def to_dict(self) -> dict:
        """Plain YAML-ready representation (keys in declaration order)."""
        out: dict = {}
        kinds = field_kinds(type(self))
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            kind = kinds[f.name]
            if kind.item is float:
                out[f.name] = list(value)
            elif kind.item is not None:
                out[f.name] = [v.to_dict() for v in value]
            elif _meta(f)["number_map"]:
                out[f.name] = dict(value)
            elif isinstance(value, Spec):
                out[f.name] = value.to_dict()
            else:
                out[f.name] = value
        return out


# ----------------------------------------------------------------------------- docstrings
@cache
def parameter_docs(cls: type) -> dict[str, str]:
    """Descriptions of the ``Parameters`` section of a numpydoc class docstring.

    Returns
    -------
    dict
        ``{parameter name: description joined on one line}``; names listed
        together (``a, b : float``) share the description.
    """
    lines = inspect.cleandoc(cls.__doc__ or "").splitlines()
    docs: dict[str, str] = {}
    try:
        start = next(i for i in range(len(lines) - 1)
                     if lines[i].strip() == "Parameters" and set(lines[i + 1].strip()) == {"-"})
    except StopIteration:
        return docs
    names: list[str] = []
    desc: list[str] = []

    def flush() -> None:
        for n in names:
            docs[n] = " ".join(desc).strip()

    for i in range(start + 2, len(lines)):
        line = lines[i]
        if line and not line.startswith(" "):
            if i + 1 < len(lines) and lines[i + 1].strip() and set(lines[i + 1].strip()) == {"-"}:
                break  # next section
            flush()
            names = [n.strip() for n in line.split(" : ")[0].split(",")]
            desc = []
        elif line.strip():
            desc.append(line.strip())
    flush()
    return docs
