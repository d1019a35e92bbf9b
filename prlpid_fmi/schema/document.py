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

from .messages import key_path, show


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


def _walk(node: yaml.Node, loc: tuple, doc: Document) -> None:
    if isinstance(node, yaml.MappingNode):
        seen: dict = {}
        for key_node, value_node in node.value:
            if not isinstance(key_node, yaml.ScalarNode) or key_node.tag == "tag:yaml.org,2002:merge":
                continue
            key = key_node.value
            child = loc + (key,)
            line = key_node.start_mark.line + 1
            if key in seen:
                doc.duplicates.append((child, seen[key], line))
            else:
                seen[key] = line
                doc.lines[child] = line
            _walk(value_node, child, doc)
    elif isinstance(node, yaml.SequenceNode):
        for i, item in enumerate(node.value):
            doc.lines.setdefault(loc + (i,), item.start_mark.line + 1)
            _walk(item, loc + (i,), doc)


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


def load_yaml(text: str) -> Any:
    """The data of a YAML text, read as scenario files are (floats like 3e-4; last repeated key wins)."""
    return parse_yaml(text).data
