"""Command-line and configuration values of the harness: hyperparameters given as ``NAME=VALUE``."""

from __future__ import annotations

from fuelhm_bench.errors import ParameterError

__all__ = ["parse_params"]


def parse_params(items: list[str], option: str = "--param") -> dict:
    """Parse ``NAME=VALUE`` strings; values are read as YAML scalars (numbers, ``1e-3`` too, booleans, strings, lists).

    Raises
    ------
    ParameterError
        Naming the option and the item that does not parse.
    """
    import yaml

    from fuelhm_bench.yamlfiles import safe_load

    out = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise ParameterError(f"{option} must look like NAME=VALUE. Got '{item}' instead.")
        try:
            out[key.strip()] = safe_load(value) if value.strip() else ""
        except yaml.YAMLError as exc:
            first = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise ParameterError(f"{option} {item}: the value '{value}' does not parse as a YAML scalar "
                                 f"({first}); quote strings, e.g. {key.strip()}='\"text\"'.") from None
    return out
