"""Tests of the generated JSON Schema (fuelhm_bench.scenarios.jsonschema).

``jsonschema`` is not a dependency, so a small validator of the keywords the
generator emits checks the schema against the shipped files and broken ones.
"""

from __future__ import annotations

import dataclasses
import json
import re
from pathlib import Path

import pytest
import yaml

from fuelhm_bench.physics.effects import EFFECTS
from fuelhm_bench.scenarios import Scenario, scenario_json_schema
from fuelhm_bench.scenarios._fields import Spec, parameter_docs
from fuelhm_bench.scenarios import schema as schema_module

ROOT = Path(__file__).resolve().parents[1]
BROKEN = Path(__file__).parent / "data" / "scenarios_broken"
KEYWORDS = {"$schema", "$id", "$defs", "$ref", "title", "description", "default", "type", "properties", "required",
            "additionalProperties", "items", "minItems", "enum", "const", "pattern", "minimum", "maximum",
            "exclusiveMinimum", "exclusiveMaximum", "allOf", "anyOf", "if", "then"}
TYPES = {"object": dict, "array": list, "string": str, "boolean": bool, "null": type(None)}


def _errors(schema: dict, value, root: dict, path: str = "") -> list[str]:
    """Validation errors of ``value`` against the subset of JSON Schema the generator uses."""
    if "$ref" in schema:
        return _errors(root["$defs"][schema["$ref"].split("/")[-1]], value, root, path)
    errs: list[str] = []
    for sub in schema.get("allOf", []):
        errs += _errors(sub, value, root, path)
    if "anyOf" in schema and all(_errors(s, value, root, path) for s in schema["anyOf"]):
        errs.append(f"{path}: matches no anyOf branch")
    if "if" in schema and not _errors(schema["if"], value, root, path):
        errs += _errors(schema["then"], value, root, path)
    if "type" in schema:
        types = schema["type"] if isinstance(schema["type"], list) else [schema["type"]]
        ok = any((t == "integer" and isinstance(value, int) and not isinstance(value, bool))
                 or (t == "number" and isinstance(value, (int, float)) and not isinstance(value, bool))
                 or (t in TYPES and isinstance(value, TYPES[t]) and not (t != "boolean" and isinstance(value, bool)))
                 for t in types)
        if not ok:
            return errs + [f"{path}: type {types}"]
    if "enum" in schema and value not in schema["enum"]:
        errs.append(f"{path}: not in enum")
    if "const" in schema and value != schema["const"]:
        errs.append(f"{path}: not const")
    if isinstance(value, str) and "pattern" in schema and not re.search(schema["pattern"], value):
        errs.append(f"{path}: pattern")
    if isinstance(value, (int, float)) and not isinstance(value, bool):
        for key, bad in (("minimum", lambda v, b: v < b), ("maximum", lambda v, b: v > b),
                         ("exclusiveMinimum", lambda v, b: v <= b), ("exclusiveMaximum", lambda v, b: v >= b)):
            if key in schema and bad(value, schema[key]):
                errs.append(f"{path}: {key}")
    if isinstance(value, dict):
        for key in schema.get("required", []):
            if key not in value:
                errs.append(f"{path}.{key}: required")
        props = schema.get("properties", {})
        for key, item in value.items():
            if key in props:
                errs += _errors(props[key], item, root, f"{path}.{key}")
            elif schema.get("additionalProperties") is False:
                errs.append(f"{path}.{key}: additional property")
            elif isinstance(schema.get("additionalProperties"), dict):
                errs += _errors(schema["additionalProperties"], item, root, f"{path}.{key}")
    if isinstance(value, list):
        if len(value) < schema.get("minItems", 0):
            errs.append(f"{path}: minItems")
        if "items" in schema:
            for i, item in enumerate(value):
                errs += _errors(schema["items"], item, root, f"{path}[{i}]")
    return errs


@pytest.fixture(scope="module")
def schema() -> dict:
    return scenario_json_schema()


def test_schema_is_json_and_uses_known_keywords(schema):
    assert json.loads(json.dumps(schema)) == schema
    assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"

    def walk(node, under_properties=False):
        if isinstance(node, dict):
            if not under_properties:
                assert set(node) <= KEYWORDS, set(node) - KEYWORDS
            for key, value in node.items():
                walk(value, under_properties=key in ("properties", "$defs") and not under_properties)
        elif isinstance(node, list):
            for item in node:
                walk(item)

    walk(schema)


def test_schema_lists_all_top_level_keys(schema):
    keys = [f.name for f in dataclasses.fields(Scenario)]
    assert list(schema["properties"]) == keys
    assert schema["additionalProperties"] is False
    assert set(schema["required"]) == {"schema_version", "name", "version", "description", "fleet", "training",
                                       "seeds"}
    for name in keys:
        assert schema["properties"][name]["description"], name


def test_schema_constraints_come_from_the_dataclasses(schema):
    deg = schema["$defs"]["DegradationSpec"]["properties"]
    assert deg["growth"]["enum"] == ["step", "linear", "exponential"]
    assert (deg["probability"]["minimum"], deg["probability"]["maximum"]) == (0.0, 1.0)
    assert deg["max_intensity"]["exclusiveMinimum"] == 0.0
    assert schema["$defs"]["SensorSpec"]["properties"]["adc_bits"] == {
        "type": "integer", "minimum": 0, "maximum": 24,
        "description": parameter_docs(schema_module.SensorSpec)["adc_bits"], "default": 12}
    assert schema["properties"]["healthy_probability"]["type"] == ["number", "null"]
    drift = schema["$defs"]["DriftSpec"]["properties"]["parameter"]["anyOf"][0]["enum"]
    assert "servovalve.spool_time_constant_s" in drift and "controller.frame_s" not in drift
    effects = schema["$defs"]["HiddenEffectSpec"]["allOf"]
    assert [b["if"]["properties"]["effect"]["const"] for b in effects] == list(EFFECTS)


@pytest.mark.parametrize("path", sorted((ROOT / "scenarios").glob("*.yaml")), ids=lambda p: p.stem)
def test_shipped_files_satisfy_the_schema(schema, path):
    assert _errors(schema, yaml.safe_load(path.read_text()), schema) == []


@pytest.mark.parametrize("name, fragment", [
    ("unknown_key_typo", ".fleet.flights_per_unti: additional property"),
    ("wrong_type", ".sensor.adc_bits: type"),
    ("out_of_range", ".degradations[1].probability: maximum"),
    ("unknown_mode", ".degradations[1].mode: not in enum"),
    ("unknown_effect", ".hidden_effects[0].effect: not in enum"),
    ("effect_parameter_out_of_range", None),  # range of effect parameters: checked by the loader only
    ("future_schema_version", ".schema_version: not in enum"),
])
def test_schema_rejects_broken_files(schema, name, fragment):
    errors = _errors(schema, yaml.safe_load((BROKEN / f"{name}.yaml").read_text()), schema)
    if fragment is None:
        assert errors == []
    else:
        assert any(fragment in e for e in errors), errors


def test_every_field_is_documented():
    """The numpydoc Parameters section is the single source of field descriptions."""
    specs = [cls for cls in vars(schema_module).values()
             if isinstance(cls, type) and issubclass(cls, Spec) and cls is not Spec]
    assert len(specs) == 12  # UnknownFaultSpec (faults outside the seven modes) is the twelfth
    for cls in specs:
        docs = parameter_docs(cls)
        assert list(docs) == [f.name for f in dataclasses.fields(cls)], cls.__name__
        assert all(docs.values()), cls.__name__
