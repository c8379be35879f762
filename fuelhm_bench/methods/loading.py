"""Build a method from its entry point ``"module:Class"`` and keyword hyperparameters."""

from __future__ import annotations

import importlib
import os
import sys

from fuelhm_bench.errors import MethodError

__all__ = ["load_method"]


def load_method(spec: str, params: dict | None = None):
    """Instantiate ``module:Class`` with keyword hyperparameters.

    The module is imported from the import path plus the current directory (a
    submission next to the user, as ``python -m`` would find it). The harness
    calls this only inside the sealed process (:mod:`fuelhm_bench.methods.sandbox`).

    Raises
    ------
    MethodError
        Naming what could not be found or built.
    """
    from fuelhm_bench.methods.base import BaseMethod

    module_name, sep, cls_name = str(spec).partition(":")
    if not sep or not module_name or not cls_name:
        raise MethodError(f"--method must look like 'package.module:Class'. Got '{spec}' instead.")
    if os.getcwd() not in sys.path:
        sys.path.insert(0, os.getcwd())
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise MethodError(f"Cannot import the method module '{module_name}': {exc}.") from None
    cls = getattr(module, cls_name, None)
    if cls is None:
        public = sorted(n for n, v in vars(module).items()
                        if isinstance(v, type) and issubclass(v, BaseMethod) and v is not BaseMethod)
        raise MethodError(f"Module '{module_name}' has no class '{cls_name}'. Methods it defines: "
                          f"{', '.join(public) or 'none'}.")
    if not (isinstance(cls, type) and issubclass(cls, BaseMethod)):
        raise MethodError(f"'{spec}' is not a subclass of fuelhm_bench.methods.BaseMethod.")
    try:
        return cls(**(params or {}))
    except TypeError as exc:
        names = sorted(cls._get_param_names()) if hasattr(cls, "_get_param_names") else []
        raise MethodError(f"Cannot build {cls_name} with {params}: {exc}. Its hyperparameters: "
                          f"{', '.join(names) or 'none'}.") from None
