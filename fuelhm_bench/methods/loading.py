"""Build a method from its entry point ``"module:Class"`` and keyword hyperparameters."""

from __future__ import annotations

import importlib
import os
import re
import sys

from fuelhm_bench.errors import MethodError

__all__ = ["METHOD_INTERFACE", "entry_point_problem", "load_method"]

#: What the harness and the checks call on a method (a method need not inherit from ``BaseMethod``).
METHOD_INTERFACE = ("get_params", "fit", "start_unit", "decide", "decide_unit")

_IDENTIFIER = r"[A-Za-z_][A-Za-z0-9_]*"
_ENTRY_POINT = re.compile(rf"{_IDENTIFIER}(\.{_IDENTIFIER})*:{_IDENTIFIER}(\.{_IDENTIFIER})*")


def entry_point_problem(spec) -> str | None:
    """What is wrong with the form of a method's entry point, or None when it reads ``package.module:Class``.

    Only the form is checked (dotted Python identifiers, one colon): whether the module imports
    and the class builds is found out in the sealed process, as the method's own failure. A
    malformed entry point is the caller's mistake, refused before any data is built.
    """
    if not isinstance(spec, str):
        return f"must be a string 'package.module:Class'. Got {spec!r} ({type(spec).__name__}) instead."
    if _ENTRY_POINT.fullmatch(spec) is None:
        return f"must look like 'package.module:Class' (dotted Python names, one colon). Got {spec!r} instead."
    return None


def load_method(spec: str, params: dict | None = None, shared: dict | None = None):
    """Instantiate ``module:Class`` with keyword hyperparameters.

    ``shared`` holds hyperparameters meant for every method that has them (``--param``): those
    the constructor takes by name are passed to it (so a hyperparameter without a default can be
    given that way), the others are left to the caller; ``params`` wins over ``shared``.

    The module is imported from the import path plus the current directory (a
    submission next to the user, as ``python -m`` would find it). The harness
    calls this only inside the sealed process (:mod:`fuelhm_bench.methods.sandbox`).

    Raises
    ------
    MethodError
        Naming what could not be found or built.
    """
    from fuelhm_bench.methods.base import BaseMethod

    problem = entry_point_problem(spec)
    if problem is not None:
        raise MethodError(f"The method's entry point {problem}")
    module_name, _, cls_name = spec.partition(":")
    if os.getcwd() not in sys.path:
        sys.path.insert(0, os.getcwd())
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise MethodError(f"Cannot import the method module '{module_name}': {exc}.") from None
    cls = module
    for part in cls_name.split("."):  # a nested class: Outer.Inner
        cls = getattr(cls, part, None)
        if cls is None:
            break
    if cls is None:
        public = sorted(n for n, v in vars(module).items()
                        if isinstance(v, type) and issubclass(v, BaseMethod) and v is not BaseMethod)
        raise MethodError(f"Module '{module_name}' has no class '{cls_name}'. Methods it defines: "
                          f"{', '.join(public) or 'none'}.")
    if not isinstance(cls, type):
        raise MethodError(f"'{spec}' is not a class (got {type(cls).__name__}).")
    if not issubclass(cls, BaseMethod):  # a method need not inherit from BaseMethod (docs/methods.md section 4)
        missing = [n for n in METHOD_INTERFACE if not callable(getattr(cls, n, None))]
        if missing:
            raise MethodError(f"'{spec}' is not a method: it neither subclasses fuelhm_bench.methods.BaseMethod "
                              f"nor defines {', '.join(missing)} (the interface: {', '.join(METHOD_INTERFACE)}).")
    kwargs = {**accepted_params(cls, shared or {}), **(params or {})}
    try:
        return cls(**kwargs)
    except TypeError as exc:
        names = sorted(cls._get_param_names()) if hasattr(cls, "_get_param_names") else []
        raise MethodError(f"Cannot build {cls_name} with {kwargs}: {exc}. Its hyperparameters: "
                          f"{', '.join(names) or 'none'}.") from None


def accepted_params(cls: type, values: dict) -> dict:
    """The items of ``values`` that ``cls``'s constructor takes by keyword."""
    import inspect

    if not values:
        return {}
    try:
        parameters = inspect.signature(cls).parameters
    except (TypeError, ValueError):
        return {}
    named = {n for n, q in parameters.items() if q.kind in (q.POSITIONAL_OR_KEYWORD, q.KEYWORD_ONLY)}
    return {k: v for k, v in values.items() if k in named}
