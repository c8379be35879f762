"""Load scenario YAML into :class:`~fuelhm_bench.scenarios.schema.Scenario`, with located errors.

The document is *composed* with PyYAML's safe loader (``yaml.SafeLoader``: no
arbitrary Python objects), which keeps the position of every key and value;
scalars are then built with the same safe constructor. The node tree is walked
against the schema dataclasses: unknown keys, missing keys, wrong types and
out-of-range values are collected and raised together as one
:class:`~fuelhm_bench.scenarios._fields.ScenarioValidationError` (a
:class:`~fuelhm_bench.errors.ScenarioError`) whose every line reads::

    scenarios/x.yaml:14: degradations[2].growth must be one of step, linear, exponential. Got 'expo' instead. Did you mean 'exponential'?

Notes
-----
* YAML 1.1 (PyYAML) reads ``1e-5`` (no dot) as a string; in number fields a
  plain (unquoted) scalar that Python's ``float`` accepts is read as a number.
* Anchors, aliases and merge keys (``<<: *base``) are supported; a key given
  twice in one mapping is an error.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import yaml

from fuelhm_bench.errors import ScenarioError
from fuelhm_bench.scenarios._fields import (
    MISSING,
    Problem,
    ScenarioValidationError,
    allowed_text,
    field_kinds,
    join,
    parents,
    show,
    unknown_key,
)
from fuelhm_bench.scenarios.schema import SUPPORTED_SCHEMA_VERSIONS, Scenario

__all__ = ["load_scenario_file", "parse_scenario"]

_FAILED = object()


class _Walker:
    """State of one document conversion: the safe constructor, key lines and problems."""

    def __init__(self, source: str, constructor: yaml.SafeLoader) -> None:
        self.source = source
        self.constructor = constructor
        self.lines: dict[str, int] = {}
        self.problems: list[Problem] = []

    # ------------------------------------------------------------------ values
    def scalar(self, node: yaml.Node):
        return self.constructor.construct_object(node, deep=True)

    def number_or_value(self, node: yaml.Node):
        """A plain scalar such as ``1e-5`` (a string in YAML 1.1) read as a float when possible."""
        value = self.scalar(node)
        if isinstance(node, yaml.ScalarNode) and node.style is None and isinstance(value, str):
            try:
                return float(value)
            except ValueError:
                return value
        return value

    # ----------------------------------------------------------------- mappings
    def mapping_items(self, node: yaml.MappingNode, path: str) -> dict[str, yaml.Node] | None:
        """Keys of a mapping node (merges resolved) after recording their lines; None on a bad key."""
        ok = True
        explicit: set = set()
        for key_node, _ in node.value:
            if key_node.tag == "tag:yaml.org,2002:merge":
                continue
            key = self.scalar(key_node)
            if not isinstance(key, str):
                self.add(Problem(path or "", "a mapping with string keys", show(key)), key_node)
                ok = False
            elif key in explicit:
                self.add(Problem(join(path, key), "given once in its mapping (a key may not repeat)", show(key)),
                         key_node)
                ok = False
            explicit.add(key if isinstance(key, str) else repr(key))
        self.constructor.flatten_mapping(node)
        items: dict[str, yaml.Node] = {}
        for key_node, value_node in node.value:  # merged keys first, explicit keys override them
            key = self.scalar(key_node)
            if isinstance(key, str):
                items[key] = value_node
                self.lines[join(path, key)] = key_node.start_mark.line + 1
        return items if ok else None

    def spec(self, cls: type, node: yaml.Node, path: str):
        """Build a spec dataclass from a mapping node; ``_FAILED`` after recording problems."""
        fields = {f.name: f for f in dataclasses.fields(cls)}
        if not isinstance(node, yaml.MappingNode):
            self.add(Problem(path, f"a mapping with the keys {', '.join(fields)}", show(self.scalar(node))), node)
            return _FAILED
        before = len(self.problems)
        items = self.mapping_items(node, path)
        if items is None:
            return _FAILED
        kinds = field_kinds(cls)
        kwargs = {}
        misspelt = set()  # fields that an unknown key probably meant
        for key, value_node in items.items():
            if key not in fields:
                problem = unknown_key(join(path, key), key, list(fields))
                misspelt.add(problem.hint.partition("'")[2].rpartition("'")[0])
                self.add(problem, value_node, key_path=join(path, key))
                continue
            value = self.value(fields[key], kinds[key], value_node, join(path, key))
            if value is not _FAILED:
                kwargs[key] = value
        for name, f in fields.items():
            if (name not in items and name not in misspelt and f.default is MISSING
                    and f.default_factory is MISSING):
                self.add(Problem(join(path, name), f"given ({allowed_text(f, kinds[name])})", show(MISSING)), node,
                         key_path=path or None)
        if len(self.problems) > before:
            return _FAILED
        try:
            return cls(**kwargs)
        except ScenarioValidationError as exc:
            self.problems.extend(p.under(path) for p in exc.problems)
            return _FAILED

    def value(self, f: dataclasses.Field, kind, node: yaml.Node, path: str):
        """Convert one field's node according to its kind."""
        is_null = isinstance(node, yaml.ScalarNode) and node.tag == "tag:yaml.org,2002:null"
        if kind.item is float:
            if not isinstance(node, yaml.SequenceNode):
                return self.scalar(node)  # the dataclass reports the wrong type
            for i, item_node in enumerate(node.value):
                self.lines[f"{path}[{i}]"] = item_node.start_mark.line + 1
            return tuple(self.number_or_value(n) for n in node.value)
        if kind.item is not None:
            if is_null:
                return ()
            if not isinstance(node, yaml.SequenceNode):
                self.add(Problem(path, f"a list of mappings ({kind.item.__name__})", show(self.scalar(node))), node)
                return _FAILED
            items = []
            for i, item_node in enumerate(node.value):
                self.lines[f"{path}[{i}]"] = item_node.start_mark.line + 1
                items.append(self.spec(kind.item, item_node, f"{path}[{i}]"))
            return _FAILED if any(v is _FAILED for v in items) else tuple(items)
        if dataclasses.is_dataclass(kind.base):
            if is_null and (f.default is not MISSING or f.default_factory is not MISSING):
                return f.default_factory() if f.default_factory is not MISSING else f.default
            return self.spec(kind.base, node, path)
        if f.metadata.get("number_map"):
            if is_null:
                return ()
            if not isinstance(node, yaml.MappingNode):
                self.add(Problem(path, "a mapping of names to numbers", show(self.scalar(node))), node)
                return _FAILED
            items = self.mapping_items(node, path)
            if items is None:
                return _FAILED
            return tuple((k, self.number_or_value(v)) for k, v in items.items())
        if kind.base is float:
            return self.number_or_value(node)
        return self.scalar(node)

    # ----------------------------------------------------------------- problems
    def add(self, problem: Problem, node: yaml.Node, key_path: str | None = None) -> None:
        line = self.lines.get(key_path) if key_path else None
        self.problems.append(dataclasses.replace(problem, line=line or node.start_mark.line + 1))

    def located(self) -> list[Problem]:
        """Problems with source and line (from the field, its ``near`` paths, then its parents)."""
        out = []
        for p in self.problems:
            line = p.line
            if line is None:
                for candidate in (p.field, *p.near, *parents(p.field)):
                    if candidate in self.lines:
                        line = self.lines[candidate]
                        break
            out.append(dataclasses.replace(p, source=self.source, line=line or 1))
        return sorted(out, key=lambda p: p.line)


def _fail(source: str, line: int | None, text_allowed: str, given: str, hint: str = "") -> ScenarioValidationError:
    return ScenarioValidationError([Problem("", text_allowed, given, hint, source=source, line=line)])


def parse_scenario(text: str, source: str = "<string>") -> Scenario:
    """Parse and validate scenario YAML text.

    Parameters
    ----------
    text : str
        The YAML document.
    source : str, default="<string>"
        Name used in error messages (normally the file path).

    Returns
    -------
    Scenario

    Raises
    ------
    ScenarioError
        (:class:`~fuelhm_bench.scenarios._fields.ScenarioValidationError`) with
        every problem found, each naming ``source``, the line, the field path,
        what is allowed and the value given.
    """
    loader = yaml.SafeLoader(text)
    try:
        root = loader.get_single_node()
        keys = ", ".join(f.name for f in dataclasses.fields(Scenario))
        if root is None:
            raise _fail(source, 1, f"a mapping with the keys {keys}", "an empty document")
        walker = _Walker(source, loader)
        if not isinstance(root, yaml.MappingNode):
            raise _fail(source, root.start_mark.line + 1, f"a mapping with the keys {keys}",
                        show(walker.scalar(root)))
        _check_schema_version(walker, root)
        scenario = walker.spec(Scenario, root, "")
        if scenario is _FAILED:
            raise ScenarioValidationError(walker.located())
        return scenario
    except yaml.MarkedYAMLError as exc:  # malformed YAML, or a tag the safe loader refuses
        mark = exc.problem_mark or exc.context_mark
        line = mark.line + 1 if mark is not None else None
        lines = text.splitlines()
        got = repr(lines[line - 1].strip()) if line is not None and 0 < line <= len(lines) else "unreadable text"
        reason = " ".join(str(x) for x in (exc.context, exc.problem) if x)
        col = f", column {mark.column + 1}" if mark is not None else ""
        raise _fail(source, line, f"well-formed YAML ({reason}{col})", f"the line {got}") from None
    except yaml.YAMLError as exc:
        raise _fail(source, None, f"well-formed YAML ({exc})", "unreadable text") from None
    finally:
        loader.dispose()


def _check_schema_version(walker: _Walker, root: yaml.MappingNode) -> None:
    """Refuse a file format this package cannot read before looking at anything else."""
    for key_node, value_node in root.value:
        if key_node.tag != "tag:yaml.org,2002:merge" and walker.scalar(key_node) == "schema_version":
            value = walker.scalar(value_node)
            if value not in SUPPORTED_SCHEMA_VERSIONS or isinstance(value, bool):
                supported = ", ".join(map(str, SUPPORTED_SCHEMA_VERSIONS))
                raise ScenarioValidationError([Problem(
                    "schema_version", f"one of {supported} (the scenario file formats this fuelhm-bench reads)",
                    show(value), "A newer file format needs a newer fuelhm-bench." if isinstance(value, int) else "",
                    source=walker.source, line=key_node.start_mark.line + 1)])


def load_scenario_file(path: str | Path) -> Scenario:
    """Load and validate a scenario YAML file.

    Parameters
    ----------
    path : str or pathlib.Path
        The file; it is named as given in error messages.

    Returns
    -------
    Scenario

    Raises
    ------
    ScenarioError
        If the file cannot be read, is not well-formed YAML or fails validation.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        reason = getattr(exc, "strerror", None) or str(exc)
        raise ScenarioError(f"Cannot read the scenario file {path}: {reason}.") from None
    return parse_scenario(text, source=str(path))
