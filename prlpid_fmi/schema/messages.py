"""One line per mistake: ``<file>: <key.path>: <problem> (got <value>; expected <what>)``.

pydantic reports every error of a document with its location; this module names the location as the
file writes it (``plant.loops[0].gains.Kp``), shows the value as written in the file, and says what was
expected: from the error itself when a check says so, otherwise from the field's JSON Schema (type,
bounds, choices, known keys with a did-you-mean for a misspelled key or choice).
"""
from __future__ import annotations

import re
from functools import lru_cache
from typing import Any, Optional

import yaml
from pydantic import ValidationError

from prlpid_fmi.schema.checks import did_you_mean

MISSING = object()  # a key that is not written in the document


def show(value: Any) -> str:
    """A value as YAML flow text (strings quoted), at most 80 characters."""
    if value is MISSING:
        return "nothing"
    text = repr(value) if isinstance(value, str) else yaml.safe_dump(value, default_flow_style=True,
                                                                      width=10_000).strip()
    if text.endswith("\n..."):
        text = text[:-4].strip()
    return text if len(text) <= 80 else text[:77] + "..."


def key_path(loc: tuple, doc: Any = None) -> str:
    """('plant', 'loops', 0, 'gains', 'Kp') -> 'plant.loops[0].gains.Kp' ('[key]' markers dropped)."""
    out = ""
    node = doc
    for part in loc:
        if part == "[key]":
            continue
        if isinstance(part, int) and (node is None or isinstance(node, list)):
            out += f"[{part}]"
        else:
            out += f".{part}" if out else str(part)
        node = _child(node, part)
    return out or "(top level)"


def _child(node: Any, part: Any) -> Any:
    if isinstance(node, dict):
        return node.get(part, MISSING) if part in node else MISSING
    if isinstance(node, list) and isinstance(part, int) and 0 <= part < len(node):
        return node[part]
    return MISSING


def raw_value(doc: Any, loc: tuple) -> Any:
    """The value at `loc` as written in the document; a dict key for a '[key]' location; MISSING if absent."""
    node = doc
    for i, part in enumerate(loc):
        if part == "[key]":
            return loc[i - 1]
        node = _child(node, part)
        if node is MISSING:
            return MISSING
    return node


# ---------------------------------------------------------------------------------------------
# the JSON Schema at a location: what was expected

@lru_cache(maxsize=1)
def _root() -> dict:
    from prlpid_fmi.schema.model import ScenarioModel

    return ScenarioModel.model_json_schema()


def _resolve(node: dict) -> dict:
    while isinstance(node, dict) and "$ref" in node:
        node = _root()["$defs"][node["$ref"].rsplit("/", 1)[1]]
    return node


def _non_null(node: dict) -> dict:
    """The schema without its null branch (an Optional field's value schema)."""
    node = _resolve(node)
    branches = [_resolve(b) for b in node.get("anyOf", ()) if _resolve(b).get("type") != "null"]
    if len(branches) == 1:
        return {**branches[0], **{k: v for k, v in node.items() if k in ("description", "default")}}
    return {**node, "anyOf": branches} if branches else node


def _walk(loc: tuple) -> Optional[dict]:
    node = _root()
    for part in loc:
        node = _non_null(node)
        if part == "[key]":
            return node.get("propertyNames", {"type": "string"})
        if isinstance(part, str) and part in node.get("properties", {}):
            node = node["properties"][part]
        elif node.get("type") == "object" and isinstance(node.get("additionalProperties"), dict):
            node = node["additionalProperties"]
        elif isinstance(part, int) and "prefixItems" in node and part < len(node["prefixItems"]):
            node = node["prefixItems"][part]
        elif isinstance(part, int) and isinstance(node.get("items"), dict):
            node = node["items"]
        else:
            return None
    return node


def schema_at(loc: tuple) -> Optional[dict]:
    """The (resolved, non-null branch of the) JSON Schema of the value at `loc`; None if unknown."""
    node = _walk(loc)
    return None if node is None else _non_null(node)


def _bound_text(value: float) -> str:
    """A bound as written: integers in full (2147483647, not 2.14748e+09), other numbers with %g."""
    return str(value) if isinstance(value, int) else f"{value:g}"


def _bounds(node: dict) -> str:
    lo = ("> ", node["exclusiveMinimum"]) if "exclusiveMinimum" in node else (
        (">= ", node["minimum"]) if "minimum" in node else None)
    hi = ("< ", node["exclusiveMaximum"]) if "exclusiveMaximum" in node else (
        ("<= ", node["maximum"]) if "maximum" in node else None)
    if lo and hi:
        return (f" in {'(' if lo[0] == '> ' else '['}{_bound_text(lo[1])}, {_bound_text(hi[1])}"
                f"{')' if hi[0] == '< ' else ']'}")
    if lo or hi:
        op, v = lo or hi
        return f" {op}{_bound_text(v)}"
    return ""


def expected_at(loc: tuple) -> str:
    """What the schema accepts at `loc`, in words ("a number > 0", "a list of ... or null", ...)."""
    node = _walk(loc)
    if node is None:
        return "a known key"
    nullable = any(_resolve(b).get("type") == "null" for b in _resolve(node).get("anyOf", ()))
    return describe(_non_null(node)) + (" or null" if nullable else "")


def describe(node: dict) -> str:
    if "enum" in node:
        return "one of " + ", ".join(str(v) for v in node["enum"])
    if "const" in node:
        return str(node["const"])
    kind = node.get("type")
    if kind == "number":
        return "a number" + _bounds(node)
    if kind == "integer":
        return "an integer" + _bounds(node)
    if kind == "boolean":
        return "true or false"
    if kind == "string":
        return "a non-empty string"
    if kind == "object":
        if "properties" in node:
            return "a mapping {" + ", ".join(node["properties"]) + "}"
        return "a mapping {name: value}"
    if kind == "array":
        items = node.get("prefixItems")
        if items and all(_non_null(i).get("type") == "number" for i in items):
            return f"a list of {len(items)} numbers"
        if items:
            n_min, n_max = node.get("minItems", len(items)), node.get("maxItems", len(items))
            count = f"{n_max}" if n_min == n_max else f"{n_min} or {n_max}"
            return f"a list of {count} items: " + ", ".join(describe(_non_null(i)) for i in items)
        inner = describe(_non_null(node["items"])) if isinstance(node.get("items"), dict) else "items"
        inner = re.sub(r"^an? (mapping|number|integer|list|non-empty string)", r"\1s", inner)
        at_least = f" (at least {node['minItems']})" if node.get("minItems") else ""
        return f"a list{at_least} of {inner}"
    if "anyOf" in node:
        return " or ".join(describe(_resolve(b)) for b in node["anyOf"])
    return "a valid value"


# ---------------------------------------------------------------------------------------------
# pydantic errors -> lines

PROBLEMS = {  # pydantic error type -> the words of a message line
    "missing": "missing key",
    "extra_forbidden": "unknown key",
    "literal_error": "unknown value",
    "enum": "unknown value",
    "bool_type": "not a boolean",
    "bool_parsing": "not a boolean",
    "string_type": "not a string",
    "string_too_short": "empty",
    "dict_type": "not a mapping",
    "model_type": "not a mapping",
    "model_attributes_type": "not a mapping",
    "list_type": "not a list",
    "tuple_type": "not a list",
    "float_type": "not a number",
    "float_parsing": "not a number",
    "int_type": "not an integer",
    "int_parsing": "not an integer",
    "int_from_float": "not an integer",
    "finite_number": "not finite",
    "greater_than": "out of range",
    "greater_than_equal": "out of range",
    "less_than": "out of range",
    "less_than_equal": "out of range",
    "frozen_instance": "cannot be changed",
}


def error_line(file: str, doc: Any, err: dict) -> str:
    """The one-line message of one pydantic error dict (from ValidationError.errors())."""
    loc = tuple(err["loc"])
    kind = err["type"]
    ctx = err.get("ctx") or {}
    parent = raw_value(doc, loc[:-1]) if loc else MISSING
    if kind == "missing" and loc and isinstance(loc[-1], int) and isinstance(parent, list):
        loc, kind, ctx = loc[:-1], "too_short", {"actual_length": len(parent)}  # a too short [low, high] pair
    raw = raw_value(doc, loc)
    if "got" in ctx:
        got = ctx["got"]
    elif raw is not MISSING:
        got = show(raw)
    else:  # not in the file: a default was checked, or a required key is missing
        default = err.get("input")
        got = "nothing" if default is None or kind == "missing" else f"nothing (default {show(default)})"
    if kind == "scenario":
        problem_text = ctx["problem"]
        expected = ctx.get("expected") or expected_at(loc)
    elif kind == "extra_forbidden":
        parent = schema_at(loc[:-1]) or {}
        known = list(parent.get("properties", ()))
        problem_text, got = "unknown key", show(loc[-1])
        hint = did_you_mean(loc[-1], known)
        expected = f"a known key{hint}" if hint else f"one of {', '.join(known)}"
    elif kind == "missing":
        node = schema_at(loc) or {}
        problem_text = "missing section" if "properties" in node else "missing key"
        expected = (node.get("description") or describe(node)).split(";")[0].rstrip(".")
        if "properties" in node:  # a section: say what it must hold
            required = node.get("required") or []
            expected = (f"a mapping with {', '.join(required)}: " if required else "a mapping: ") + \
                expected[:1].lower() + expected[1:]
    elif kind in ("literal_error", "enum"):
        node = schema_at(loc) or {}
        choices = node.get("enum") or []
        problem_text = f"unknown {str(loc[-1]).replace('_', ' ')}" if isinstance(loc[-1], str) else "unknown value"
        expected = "one of " + ", ".join(str(c) for c in choices) + did_you_mean(raw, choices)
    elif kind in ("too_short", "too_long"):
        length = ctx.get("actual_length", len(raw) if isinstance(raw, (list, dict)) else "?")
        problem_text = f"list of length {length}" if not isinstance(raw, dict) else f"{length} entries"
        expected = expected_at(loc)
    else:
        problem_text = PROBLEMS.get(kind, err.get("msg", "invalid").lower())
        expected = expected_at(loc)
    return f"{file}: {key_path(loc, doc)}: {problem_text} (got {got}; expected {expected})"


def error_lines(file: str, doc: Any, exc: ValidationError) -> list[str]:
    """Every error of a ValidationError as a line, without repeats, in the error order."""
    lines: list[str] = []
    for err in exc.errors():
        line = error_line(file, doc, err)
        if line not in lines:
            lines.append(line)
    return lines
