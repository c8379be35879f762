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
* Bounds, so that any file is accepted or refused within a second and a few
  tens of MB: a file holds at most :data:`MAX_FILE_BYTES`, nests at most
  :data:`MAX_DEPTH` levels, and expands to at most :data:`MAX_EXPANDED_NODES`
  YAML values once its aliases are expanded (the "billion laughs" shape is
  refused before anything is built); recursive aliases are refused.
"""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import yaml

from fuelhm_bench.errors import ScenarioError
from fuelhm_bench.filetypes import check_file_type
from fuelhm_bench.yamlfiles import SafeLoader
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
from fuelhm_bench.scenarios.schema import NAME_PATTERN, SUPPORTED_SCHEMA_VERSIONS, Scenario

__all__ = ["MAX_DEPTH", "MAX_EXPANDED_NODES", "MAX_FILE_BYTES", "load_scenario_file", "parse_scenario"]

_FAILED = object()

#: Largest scenario file read, in bytes (shipped files are 2-4 KB; PyYAML reads about 100 KB per second).
MAX_FILE_BYTES: int = 100_000
#: Deepest nesting of YAML collections, counting alias expansion (a scenario needs about 5).
MAX_DEPTH: int = 50
#: Most YAML values (scalars, lists, mappings) once aliases are expanded (a scenario needs a few hundred).
MAX_EXPANDED_NODES: int = 100_000


_BRACKETS = re.compile(r"[\[\]{}]")


class _TooDeep(Exception):
    """Raised by the composer past :data:`MAX_DEPTH` (carries the position)."""

    def __init__(self, mark) -> None:
        super().__init__(mark)
        self.mark = mark


class _BoundedLoader(SafeLoader):
    """The safe loader (:class:`fuelhm_bench.yamlfiles.SafeLoader`) whose composer refuses nesting deeper than :data:`MAX_DEPTH`."""

    def __init__(self, stream) -> None:
        super().__init__(stream)
        self._depth = 0

    def compose_node(self, parent, index):
        self._depth += 1
        try:
            if self._depth > MAX_DEPTH:
                raise _TooDeep(self.peek_event().start_mark)
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1


def _bracket_depth_line(text: str) -> int | None:
    """1-based line where flow brackets (``[``, ``{``) first nest deeper than :data:`MAX_DEPTH`, else None.

    A raw count (brackets inside strings count too): PyYAML's scanner is
    quadratic in the nesting of flow collections, so they are bounded before it runs.
    """
    depth = 0
    for match in _BRACKETS.finditer(text):
        depth = depth + 1 if match.group() in "[{" else max(depth - 1, 0)
        if depth > MAX_DEPTH:
            return text.count("\n", 0, match.start()) + 1
    return None


def _children(node: yaml.Node) -> list:
    if isinstance(node, yaml.SequenceNode):
        return list(node.value)
    if isinstance(node, yaml.MappingNode):
        return [n for pair in node.value for n in pair]
    return []


def _expansion_problem(root: yaml.Node) -> tuple[str, str, int] | None:
    """``(allowed, given, line)`` if the node graph, aliases expanded, is too big, too deep or cyclic.

    Iterative depth-first walk with one memo entry per distinct node, so the
    cost is the size of the *file*, not of its expansion.
    """
    size: dict[int, int] = {}
    depth: dict[int, int] = {}
    on_path: set[int] = set()
    stack: list[tuple[yaml.Node, bool]] = [(root, False)]
    while stack:
        node, done = stack.pop()
        key = id(node)
        if done:
            kids = _children(node)
            size[key] = 1 + sum(size[id(k)] for k in kids)
            depth[key] = 1 + max((depth[id(k)] for k in kids), default=0)
            on_path.discard(key)
            line = node.start_mark.line + 1
            if size[key] > MAX_EXPANDED_NODES:
                return (f"at most {MAX_EXPANDED_NODES} YAML values once its aliases (*name) are "
                        f"expanded", f"more than {MAX_EXPANDED_NODES} (the value at line {line} alone expands to "
                        f"{size[key]})", line)
            if depth[key] > MAX_DEPTH:
                return (f"nested at most {MAX_DEPTH} levels deep, aliases (*name) expanded",
                        f"a value nested deeper (at line {line})", line)
            continue
        if key in size:
            continue
        if key in on_path:
            line = node.start_mark.line + 1
            return ("free of recursive aliases (an anchor used inside its own value)",
                    f"a recursive alias (the value at line {line} contains itself)", line)
        on_path.add(key)
        stack.append((node, True))
        for kid in _children(node):
            if id(kid) not in size:
                stack.append((kid, False))
    return None


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


def parse_scenario(text: str, source: str = "<string>", *, file_name: str | None = None) -> Scenario:
    """Parse and validate scenario YAML text.

    Parameters
    ----------
    text : str
        The YAML document.
    source : str, default="<string>"
        Name used in error messages (normally the file path).
    file_name : str or None, default=None
        The name of the file without its suffix (``"paper_2012"``): the ``name`` the document
        must declare (:func:`load_scenario_file` passes it); None: not checked.

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
    if not isinstance(text, str):
        raise _fail(source, None, "YAML text (str)", show(text))
    if len(text) > MAX_FILE_BYTES:
        raise _fail(source, None, f"a scenario file of at most {MAX_FILE_BYTES} characters",
                    f"{len(text)} characters")
    deep_line = _bracket_depth_line(text)
    if deep_line is not None:
        raise _fail(source, deep_line, f"nested at most {MAX_DEPTH} levels deep", "brackets nested deeper")
    try:
        loader = _BoundedLoader(text)
    except yaml.YAMLError as exc:  # e.g. a control character the YAML reader refuses
        raise _fail(source, None, f"well-formed YAML ({exc})".replace("\n", " "), "unreadable text") from None
    try:
        try:
            root = loader.get_single_node()
        except _TooDeep as exc:
            raise _fail(source, exc.mark.line + 1, f"nested at most {MAX_DEPTH} levels deep",
                        "a value nested deeper") from None
        keys = ", ".join(f.name for f in dataclasses.fields(Scenario))
        if root is None:
            raise _fail(source, 1, f"a mapping with the keys {keys}", "an empty document")
        problem = _expansion_problem(root)
        if problem is not None:
            allowed, given, line = problem
            raise _fail(source, line, allowed, given)
        walker = _Walker(source, loader)
        if not isinstance(root, yaml.MappingNode):
            raise _fail(source, root.start_mark.line + 1, f"a mapping with the keys {keys}",
                        show(walker.scalar(root)))
        _check_schema_version(walker, root)
        scenario = walker.spec(Scenario, root, "")
        if file_name is not None:
            _check_file_name(walker, root, file_name)
        if scenario is _FAILED or walker.problems:
            raise ScenarioValidationError(walker.located())
        return scenario
    except yaml.MarkedYAMLError as exc:  # malformed YAML, or a tag the safe loader refuses
        mark = exc.problem_mark or exc.context_mark
        line = mark.line + 1 if mark is not None else None
        lines = text.splitlines()
        got = show(lines[line - 1].strip()) if line is not None and 0 < line <= len(lines) else "unreadable text"
        reason = " ".join(str(x) for x in (exc.context, exc.problem) if x)
        col = f", column {mark.column + 1}" if mark is not None else ""
        raise _fail(source, line, f"well-formed YAML ({reason}{col})", f"the line {got}") from None
    except yaml.YAMLError as exc:
        raise _fail(source, None, f"well-formed YAML ({exc})", "unreadable text") from None
    except RecursionError:  # defence in depth: the bounds above should make this unreachable
        raise _fail(source, None, f"nested at most {MAX_DEPTH} levels deep", "a value nested deeper") from None
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


def _check_file_name(walker: _Walker, root: yaml.MappingNode, file_name: str) -> None:
    """A problem on ``name`` when it differs from the file's name: a scenario's id is ``<name>-v<version>``,
    so an edited copy saved under another file name would otherwise be reported under the original's id."""
    named = [(k, v) for k, v in root.value if k.tag != "tag:yaml.org,2002:merge" and walker.scalar(k) == "name"]
    if not named:
        return  # reported as a missing key
    value_node = named[-1][1]  # merged keys first (flattened by the walk), explicit keys override them
    name = walker.scalar(value_node)
    if not isinstance(name, str) or name == file_name or not re.fullmatch(NAME_PATTERN, name):
        return  # equal, or reported as an invalid name
    hint = (f"Set name: {file_name}, or rename the file to {name}.yaml." if re.fullmatch(NAME_PATTERN, file_name)
            else f"Rename the file to {name}.yaml ('{file_name}' is not a scenario name: a lowercase identifier).")
    walker.add(Problem("name", f"'{file_name}', the file's name without its suffix (the id is <name>-v<version>)",
                       show(name), hint), value_node)


def load_scenario_file(path: str | Path) -> Scenario:
    """Load and validate a scenario YAML file.

    Its ``name`` must be the file's name without the suffix (``scenarios/paper_2012.yaml``
    declares ``name: paper_2012``).

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
        If the file cannot be read, is not well-formed YAML or fails validation (including a
        ``name`` other than the file's).
    """
    path = Path(path)
    try:
        if path.is_file():
            check_file_type(path, "yaml", what="scenario file", error=ScenarioError)
        if path.stat().st_size > MAX_FILE_BYTES:
            raise ScenarioError(f"{path}: the scenario file must be at most {MAX_FILE_BYTES} bytes. Got "
                                f"{path.stat().st_size} bytes instead.")
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        reason = getattr(exc, "strerror", None) or str(exc)
        raise ScenarioError(f"Cannot read the scenario file {path}: {reason}.") from None
    return parse_scenario(text, source=str(path), file_name=path.stem)
