"""JSON Schema of scenario files, generated from the schema dataclasses.

Nothing here is written by hand: property names, types, bounds, enumerations,
defaults and required keys come from the dataclass fields and their
:func:`~fuelhm_bench.scenarios._fields.option` constraints; descriptions come
from the numpydoc ``Parameters`` sections of the classes; hidden-effect
parameters come from the effect dataclasses. Editors use it for completion
and inline checks, e.g. with the YAML language server::

    # yaml-language-server: $schema=scenario.schema.json

The Python loader remains the reference: it also checks what JSON Schema cannot
express (onset windows against the number of flights, probability sums, drift
paths against enabled effects, physics ranges).
"""

from __future__ import annotations

import dataclasses

from fuelhm_bench.scenarios._fields import MISSING, _meta, field_kinds, parameter_docs
from fuelhm_bench.scenarios.schema import SUPPORTED_SCHEMA_VERSIONS, Scenario

__all__ = ["scenario_json_schema"]

_DRAFT = "https://json-schema.org/draft/2020-12/schema"


def _field_schema(f: dataclasses.Field, kind, doc: str, defs: dict) -> dict:
    meta = _meta(f)
    if kind.item is float:
        out = {"type": "array", "items": _number_schema(meta)}
        if meta["min_items"]:
            out["minItems"] = meta["min_items"]
    elif kind.item is not None:
        out: dict = {"type": "array", "items": {"$ref": f"#/$defs/{_object(kind.item, defs)}"}}
    elif meta["number_map"]:
        out = {"type": "object", "additionalProperties": {"type": "number"}}
    elif dataclasses.is_dataclass(kind.base):
        out = {"$ref": f"#/$defs/{_object(kind.base, defs)}"}
    else:
        out = {"type": {bool: "boolean", int: "integer", float: "number", str: "string"}[kind.base]}
        out.update({k: v for k, v in _number_schema(meta).items() if k != "type"})
        if meta["choices"] is not None:
            out["enum"] = list(meta["choices"])
        if meta["pattern"] is not None:
            out["pattern"] = f"^{meta['pattern']}$"
        if kind.optional:
            out["type"] = [out["type"], "null"]
    if "$ref" in out:
        out = {"allOf": [out]}  # siblings of $ref are ignored by some editors
    out["description"] = doc
    if f.default is not MISSING and not dataclasses.is_dataclass(f.default):
        out["default"] = list(f.default) if isinstance(f.default, tuple) else f.default
    return out


def _number_schema(meta: dict) -> dict:
    out: dict = {"type": "number"}
    for key, json_key in (("ge", "minimum"), ("gt", "exclusiveMinimum"), ("le", "maximum"), ("lt", "exclusiveMaximum")):
        if meta[key] is not None:
            out[json_key] = meta[key]
    return out


def _object(cls: type, defs: dict) -> str:
    """Add the object schema of a spec class to ``defs`` (once) and return its name."""
    name = cls.__name__
    if name in defs:
        return name
    defs[name] = {}  # placeholder against recursion
    docs = parameter_docs(cls)
    kinds = field_kinds(cls)
    props = {f.name: _field_schema(f, kinds[f.name], docs.get(f.name, ""), defs) for f in dataclasses.fields(cls)}
    required = [f.name for f in dataclasses.fields(cls) if f.default is MISSING and f.default_factory is MISSING]
    summary = (cls.__doc__ or "").strip().splitlines()[0]
    schema: dict = {"type": "object", "title": name, "description": summary, "properties": props,
                    "required": required, "additionalProperties": False}
    extra = getattr(cls, "json_schema_extra", None)
    if extra is not None:
        for key, value in extra().items():
            if key == "properties":
                for prop, more in value.items():
                    props[prop].update(more)
            else:
                schema[key] = value
    defs[name] = schema
    return name


def scenario_json_schema() -> dict:
    """The JSON Schema (draft 2020-12) of scenario files, for editors' completion.

    Returns
    -------
    dict
        A JSON-serialisable schema whose root object is the
        :class:`~fuelhm_bench.scenarios.schema.Scenario` mapping.

    Examples
    --------
    >>> schema = scenario_json_schema()
    >>> schema["properties"]["schema_version"]["enum"]
    [1]
    """
    defs: dict = {}
    root = _object(Scenario, defs)
    body = defs.pop(root)
    version = max(SUPPORTED_SCHEMA_VERSIONS)
    return {"$schema": _DRAFT, "$id": f"urn:fuelhm-bench:scenario:schema-v{version}",
            **body, "title": f"fuelhm-bench scenario (schema_version {version})", "$defs": defs}
