"""Reading a scenario's YAML text: syntax, duplicate keys, and where each key is written.

PyYAML's safe loader lets a repeated key silently replace the first; here the document is composed
into nodes first, every mapping is checked for repeated keys (reported with both line numbers) and
the line of every key path is kept, so errors can be listed in file order. Numbers like ``3e-4`` are
read as floats (YAML 1.2, as editors read them), not as strings (YAML 1.1).
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any

import yaml

from prlpid_fmi.schema.messages import key_path, show


class _Loader(yaml.SafeLoader):
    """SafeLoader that also reads 1e-3, 5E6, -2.5e+2 as floats."""


_Loader.add_implicit_resolver("tag:yaml.org,2002:float", re.compile(r"^[-+]?(\d+\.?\d*|\.\d+)[eE][-+]?\d+$"),
                              list("-+0123456789."))


@dataclass
class Document:
    """A parsed YAML document: its data, the line (1-based) of each key path, and repeated-key errors."""

    data: Any
    lines: dict = field(default_factory=dict)  # loc tuple -> line
    duplicates: list = field(default_factory=list)  # (loc tuple, first line, repeated line)

    def line_of(self, loc: tuple) -> int:
        """Line of the nearest written ancestor of `loc` (0 when unknown)."""
        loc = tuple(p for p in loc if p != "[key]")
        while loc:
            if loc in self.lines:
                return self.lines[loc]
            loc = loc[:-1]
        return 0

    def duplicate_lines(self, file: str) -> list[str]:
        return [f"{file}: {key_path(loc, self.data)}: duplicate key at lines {first} and {again} "
                f"(got {show(loc[-1])} twice; expected each key once per mapping)"
                for loc, first, again in self.duplicates]


class RecursiveAlias(yaml.MarkedYAMLError):
    """An alias used inside its own anchor (``a: &x {b: *x}``): the data would contain itself."""


def _walk(node: yaml.Node, loc: tuple, doc: Document, path: tuple = (), seen_nodes: set | None = None) -> None:
    """Record key lines and repeated keys under `node`. An aliased node is walked once (its keys' lines are its
    anchor's), so nested aliases cost no more than the text; an alias inside its own anchor raises RecursiveAlias."""
    seen_nodes = set() if seen_nodes is None else seen_nodes
    if id(node) in path:
        raise RecursiveAlias(problem="this anchor is used inside itself (an alias to it within it: the data would "
                                     "contain itself)",
                             problem_mark=node.start_mark)
    if id(node) in seen_nodes:
        return
    seen_nodes.add(id(node))
    path = path + (id(node),)
    if isinstance(node, yaml.MappingNode):
        seen: dict = {}
        for key_node, value_node in node.value:
            if not isinstance(key_node, yaml.ScalarNode) or key_node.tag == "tag:yaml.org,2002:merge":
                _walk(value_node, loc, doc, path, seen_nodes)  # a merge key's mapping: checked for recursion too
                continue
            key = key_node.value
            child = loc + (key,)
            line = key_node.start_mark.line + 1
            if key in seen:
                doc.duplicates.append((child, seen[key], line))
            else:
                seen[key] = line
                doc.lines[child] = line
            _walk(value_node, child, doc, path, seen_nodes)
    elif isinstance(node, yaml.SequenceNode):
        for i, item in enumerate(node.value):
            doc.lines.setdefault(loc + (i,), item.start_mark.line + 1)
            _walk(item, loc + (i,), doc, path, seen_nodes)


def parse_yaml(text: str) -> Document:
    """Parse YAML text; raises yaml.YAMLError for a syntax error."""
    loader = _Loader(text)
    try:
        node = loader.get_single_node()
        doc = Document(None)
        if node is not None:
            _walk(node, (), doc)
            doc.data = loader.construct_document(node)
        return doc
    finally:
        loader.dispose()


def syntax_error_line(file: str, exc: yaml.YAMLError) -> str:
    """The one-line message of a YAML syntax error in `file`: where, and what the parser found."""
    mark = getattr(exc, "problem_mark", None)
    where = f"line {mark.line + 1}, column {mark.column + 1}" if mark else "unknown position"
    problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
    return f"{file}: (top level): not valid YAML at {where}: {problem} (got unparsable text; expected a YAML mapping)"


def load_yaml(text: str) -> Any:
    """The data of a YAML text, read as scenario files are (floats like 3e-4; last repeated key wins)."""
    return parse_yaml(text).data
