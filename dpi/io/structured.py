"""YAML and JSON files read with limits: size, nesting depth, YAML aliases and the size of a YAML document with its
aliases expanded are bounded before anything is built, so a hostile file (an alias bomb, a deep nest, a huge file)
stops in well under a second with one line
naming the file, instead of a MemoryError or a RecursionError traceback. Parse errors are one line too, with the
line and column. Messages never quote the file's contents."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any

import yaml

MAX_BYTES = 8 << 20
"""largest YAML or JSON file dpi reads by default (a transforms.json of thousands of frames is far below)"""
MAX_DEPTH = 32
"""deepest nesting of mappings and lists a file may have"""
MAX_ALIASES = 64
"""most YAML aliases (`*name`) a file may use: an alias bomb needs many more"""
MAX_NODES = MAX_BYTES // 4
"""most values a YAML document may hold with its aliases expanded: as many as a file of MAX_BYTES could spell out
without aliases (a few aliases that each repeat the one before double the size at every step)"""


class StructuredFileError(ValueError):
    """A YAML or JSON file that cannot be read within the limits; the message names the file."""


def _read_text(path: Path, max_bytes: int) -> str:
    """The file's UTF-8 text, refused before reading when it is larger than `max_bytes`."""
    try:
        size = path.stat().st_size
    except OSError as exc:
        raise StructuredFileError(f"{path}: cannot be read ({exc.strerror})") from None
    if size > max_bytes:
        raise StructuredFileError(f"{path}: {size} bytes, more than the {max_bytes} a settings file may have")
    try:
        return path.read_bytes().decode("utf-8")
    except UnicodeDecodeError as exc:
        raise StructuredFileError(f"{path}: not UTF-8 text (byte {exc.start})") from None
    except OSError as exc:
        raise StructuredFileError(f"{path}: cannot be read ({exc.strerror})") from None


class _LimitedLoader(yaml.SafeLoader):
    """PyYAML's safe loader, counting nesting depth and aliases as it composes the node graph."""

    def __init__(self, stream: str):
        super().__init__(stream)
        self.depth = 0
        self.aliases = 0

    def compose_node(self, parent: Any, index: Any) -> Any:
        """Refuse the node that goes past MAX_ALIASES or MAX_DEPTH, at its position in the file."""
        mark = self.peek_event().start_mark
        if self.check_event(yaml.AliasEvent):
            self.aliases += 1
            if self.aliases > MAX_ALIASES:
                raise yaml.composer.ComposerError(None, None, f"more than {MAX_ALIASES} aliases", mark)
        self.depth += 1
        try:
            if self.depth > MAX_DEPTH:
                raise yaml.composer.ComposerError(None, None, f"nested deeper than {MAX_DEPTH} levels", mark)
            return super().compose_node(parent, index)
        finally:
            self.depth -= 1


    def get_single_node(self) -> Any:
        """The document's node graph, refused when its aliases would expand it past MAX_NODES values."""
        node = super().get_single_node()
        if node is not None and expanded_size(node) > MAX_NODES:
            raise yaml.composer.ComposerError(None, None, f"its aliases expand it to more than {MAX_NODES} values",
                                              node.start_mark)
        return node


def expanded_size(root: yaml.Node) -> int:
    """Values in a composed YAML node graph with every alias expanded, counted without expanding (an aliased node is
    one shared object: its size is counted once and reused)."""
    sizes: dict[int, int] = {}
    stack: list[tuple[yaml.Node, bool]] = [(root, False)]
    while stack:
        node, done = stack.pop()
        if id(node) in sizes:
            continue
        children = [] if isinstance(node, yaml.ScalarNode) else \
            [part for pair in node.value for part in pair] if isinstance(node, yaml.MappingNode) else list(node.value)
        if done or not children:
            sizes[id(node)] = 1 + sum(sizes[id(c)] for c in children)
        else:
            stack.append((node, True))
            stack.extend((c, False) for c in children if id(c) not in sizes)
    return sizes[id(root)]


def yaml_problem(exc: yaml.YAMLError) -> str:
    """A YAML error on one line: the problem and where (line and column), never the offending text."""
    mark = getattr(exc, "problem_mark", None)
    where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
    problem = getattr(exc, "problem", None) or type(exc).__name__
    return f"{problem}{where}"


def parse_yaml(text: str, source: str) -> Any:
    """The value of a YAML document within the limits; errors name `source`."""
    if len(text.encode("utf-8", "surrogatepass")) > MAX_BYTES:
        raise StructuredFileError(f"{source}: more than the {MAX_BYTES} bytes a settings file may have")
    loader = _LimitedLoader(text)
    try:
        return loader.get_single_data()
    except yaml.YAMLError as exc:
        raise StructuredFileError(f"{source}: invalid YAML ({yaml_problem(exc)})") from None
    finally:
        loader.dispose()


def read_yaml(path: str | os.PathLike, max_bytes: int = MAX_BYTES) -> Any:
    """The value of a YAML file within the limits (None for an empty file)."""
    path = Path(path)
    return parse_yaml(_read_text(path, max_bytes), str(path))


def _depth(value: Any) -> int:
    """Nesting depth of a JSON value (a scalar is 0), without recursion."""
    deepest, stack = 0, [(value, 1)]
    while stack:
        node, level = stack.pop()
        children = node.values() if isinstance(node, dict) else node if isinstance(node, list) else None
        if children is None:
            continue
        deepest = max(deepest, level)
        if level <= MAX_DEPTH:
            stack.extend((child, level + 1) for child in children)
    return deepest


def read_json(path: str | os.PathLike, max_bytes: int = MAX_BYTES) -> Any:
    """The value of a JSON file within the limits; a syntax error names the line and column."""
    path = Path(path)
    text = _read_text(path, max_bytes)
    try:
        value = json.loads(text)
    except json.JSONDecodeError as exc:
        raise StructuredFileError(f"{path}: invalid JSON ({exc.msg} at line {exc.lineno}, column {exc.colno})") \
            from None
    except RecursionError:
        raise StructuredFileError(f"{path}: nested deeper than {MAX_DEPTH} levels") from None
    if _depth(value) > MAX_DEPTH:
        raise StructuredFileError(f"{path}: nested deeper than {MAX_DEPTH} levels")
    return value
