"""Run an IEC 61131-3 FUNCTION_BLOCK parsed by blark (a PyPI ST grammar), for testing the ST export.

Covers the subset the exported block uses: scalar and array (any bounds, any rank) variables of
LREAL / INT / BOOL with initial values; :=, IF/ELSIF/ELSE, FOR ... TO ... DO, RETURN; + - * /,
comparisons, AND / OR / NOT, unary minus; SQRT and ABS. LREAL arithmetic is IEEE double, as
Python's float. Names are case-insensitive, as in ST. Anything else raises NotImplementedError, so
a construct this interpreter does not know cannot pass silently.
"""
from __future__ import annotations

import math
import operator

from blark import parse_source_code
from blark import transform as tf

_BINARY = {"+": operator.add, "-": operator.sub, "*": operator.mul, "<": operator.lt, ">": operator.gt,
           "<=": operator.le, ">=": operator.ge, "=": operator.eq, "<>": operator.ne}
_FUNCTIONS = {"SQRT": math.sqrt, "ABS": abs}
_SECTIONS = {"InputDeclarations": "input", "OutputDeclarations": "output", "VariableDeclarations": "var",
             "TemporaryVariableDeclarations": "temp"}


class _Return(Exception):
    pass


def parse_block(source: str) -> tf.FunctionBlock:
    """The one FUNCTION_BLOCK in `source`; raises ValueError with blark's message when it does not parse."""
    result = parse_source_code(source)
    if result.exception is not None:
        raise ValueError(f"blark could not parse the block: {result.exception}")
    items = result.transform().items
    blocks = [item for item in items if isinstance(item, tf.FunctionBlock)]
    if len(blocks) != 1 or len(items) != 1:
        raise ValueError(f"expected one FUNCTION_BLOCK, got {[type(i).__name__ for i in items]}")
    return blocks[0]


def literal(node):
    """The value of a constant node (Real, Integer, Boolean, a signed literal)."""
    if isinstance(node, tf.Real):
        return float(str(node.value))
    if isinstance(node, tf.Integer):
        return int(str(node.value), int(node.base or 10))
    if isinstance(node, tf.Boolean):
        return str(node.value).upper() == "TRUE"
    if isinstance(node, tf.UnaryOperation) and str(node.op) == "-":
        return -literal(node.expr)
    raise NotImplementedError(f"literal {type(node).__name__}: {node}")


def array_elements(init: tf.ArrayInitialization) -> list:
    """The flat element values of an array initialiser (blark nests the elements after the first)."""
    out = []
    for element in init.elements:
        if element.count is not None:
            raise NotImplementedError("repeated array initial elements n(v)")
        if isinstance(element.element, tf.ArrayInitialization):
            out += array_elements(element.element)
        else:
            out.append(literal(element.element))
    return out


class Variable:
    """One declared variable: section ("input", "output", "var", "temp", "constant"), type name, bounds, value."""

    def __init__(self, name, section, type_name, bounds, init):
        self.name, self.section, self.type_name, self.bounds = name, section, type_name, bounds
        zero = {"LREAL": 0.0, "REAL": 0.0, "INT": 0, "BOOL": False}[type_name]
        if bounds:
            shape = [hi - lo + 1 for lo, hi in bounds]
            size = math.prod(shape)
            values = list(init) if init is not None else [zero] * size
            if len(values) != size:
                raise ValueError(f"{name}: {len(values)} initial values for {size} elements")
            self.value = values
        else:
            self.value = init if init is not None else zero

    def offset(self, index: tuple) -> int:
        """Row-major position of an index tuple (last index fastest); IndexError outside the bounds."""
        if len(index) != len(self.bounds):
            raise IndexError(f"{self.name}: {len(index)} subscripts for {len(self.bounds)} dimensions")
        pos = 0
        for i, (lo, hi) in zip(index, self.bounds):
            if not lo <= i <= hi:
                raise IndexError(f"{self.name}{list(index)}: outside [{lo}..{hi}]")
            pos = pos * (hi - lo + 1) + (i - lo)
        return pos


def declarations(block: tf.FunctionBlock) -> dict[str, Variable]:
    """Every variable of the block by upper-case name."""
    out = {}
    for section in block.declarations:
        kind = _SECTIONS.get(type(section).__name__)
        if kind is None:
            raise NotImplementedError(f"declaration section {type(section).__name__}")
        attrs = str(getattr(section, "attrs", "") or "").upper()
        if "CONSTANT" in attrs:
            kind = "constant"
        for item in section.items:
            init = item.init
            if isinstance(init, tf.ArrayTypeInitialization):
                spec = init.spec
                bounds = [(literal(r.start), literal(r.stop)) for r in spec.subranges]
                type_name = str(spec.type.type_name).upper()
                value = array_elements(init.value) if init.value is not None else None
            elif isinstance(init, tf.TypeInitialization):
                bounds, type_name = [], str(init.spec.type).upper()
                value = literal(init.value) if init.value is not None else None
            else:
                raise NotImplementedError(f"declaration {type(init).__name__}")
            if type_name in ("LREAL", "REAL") and value is not None:
                value = [float(v) for v in value] if bounds else float(value)
            for declared in item.variables:
                name = str(declared.variable.name)
                out[name.upper()] = Variable(name, kind, type_name, bounds, value)
    return out


class FunctionBlockInstance:
    """An instance of the block: set inputs, call(), read outputs (names case-insensitive)."""

    def __init__(self, source: str):
        self.block = parse_block(source)
        self.name = str(self.block.name)
        self.variables = declarations(self.block)

    def __getitem__(self, name: str):
        v = self.variables[name.upper()]
        return list(v.value) if v.bounds else v.value

    def __setitem__(self, name: str, value) -> None:
        v = self.variables[name.upper()]
        if v.section != "input":
            raise KeyError(f"{name} is not an input")
        if v.bounds:
            if len(value) != len(v.value):
                raise ValueError(f"{name}: {len(value)} values for {len(v.value)} elements")
            v.value = [float(x) for x in value] if v.type_name == "LREAL" else list(value)
        else:
            v.value = float(value) if v.type_name == "LREAL" else value

    def call(self) -> None:
        try:
            self._statements(self.block.body)
        except _Return:
            pass

    # -- statements ----------------------------------------------------------------------------
    def _statements(self, body: tf.StatementList) -> None:
        for statement in body.statements:
            self._statement(statement)

    def _statement(self, s) -> None:
        if isinstance(s, tf.AssignmentStatement):
            value = self._eval(s.expression)
            for target in s.variables:
                self._assign(target, value)
        elif isinstance(s, tf.IfStatement):
            if self._bool(s.if_expression):
                self._statements(s.statements)
                return
            for clause in s.else_ifs:
                if self._bool(clause.if_expression):
                    self._statements(clause.statements)
                    return
            if s.else_clause is not None:
                self._statements(s.else_clause.statements)
        elif isinstance(s, tf.ForStatement):
            if s.step is not None:
                raise NotImplementedError("FOR ... BY")
            start, stop = self._eval(s.from_), self._eval(s.to)
            i = start
            while i <= stop:
                self._assign(s.control, i)
                self._statements(s.statements)
                i += 1
        elif isinstance(s, tf.ReturnStatement):
            raise _Return()
        else:
            raise NotImplementedError(f"statement {type(s).__name__}: {s}")

    def _assign(self, target, value) -> None:
        var, index = self._place(target)
        if var.section == "constant":
            raise ValueError(f"assignment to the constant {var.name}")
        if var.section == "input":
            raise ValueError(f"assignment to the input {var.name}")
        expected = {"LREAL": float, "REAL": float, "INT": int, "BOOL": bool}[var.type_name]
        if type(value) is not expected:
            raise TypeError(f"{var.name} := {value!r}: expected {var.type_name}")
        if index is None:
            var.value = value
        else:
            var.value[var.offset(index)] = value

    def _place(self, node) -> tuple[Variable, tuple | None]:
        if isinstance(node, tf.SimpleVariable):
            var = self.variables[str(node.name).upper()]
            if var.bounds:
                raise TypeError(f"{var.name} is an array; use a subscript")
            return var, None
        if isinstance(node, tf.MultiElementVariable):
            if len(node.elements) != 1 or not isinstance(node.elements[0], tf.SubscriptList):
                raise NotImplementedError(f"variable {node}")
            var = self.variables[str(node.name.name).upper()]
            return var, tuple(self._eval(e) for e in node.elements[0].subscripts)
        raise NotImplementedError(f"variable {type(node).__name__}: {node}")

    # -- expressions ---------------------------------------------------------------------------
    def _bool(self, node) -> bool:
        value = self._eval(node)
        if type(value) is not bool:
            raise TypeError(f"condition {node} is not BOOL")
        return value

    def _eval(self, node):
        if isinstance(node, (tf.Real, tf.Integer, tf.Boolean)):
            return literal(node)
        if isinstance(node, (tf.SimpleVariable, tf.MultiElementVariable)):
            var, index = self._place(node)
            return var.value if index is None else var.value[var.offset(index)]
        if isinstance(node, tf.ParenthesizedExpression):
            return self._eval(node.expr)
        if isinstance(node, tf.UnaryOperation):
            op = str(node.op).upper()
            if op == "NOT":
                return not self._bool(node.expr)
            if op == "-":
                return -self._eval(node.expr)
        if isinstance(node, tf.BinaryOperation):
            op = str(node.op).upper()
            if op in ("AND", "OR"):
                a, b = self._bool(node.left), self._bool(node.right)  # ST evaluates both operands
                return (a and b) if op == "AND" else (a or b)
            a, b = self._eval(node.left), self._eval(node.right)
            if (type(a) is float) != (type(b) is float) and op not in ("=", "<>"):
                raise TypeError(f"{node}: mixed INT and LREAL operands")
            if op == "/":
                if type(a) is int:
                    q = abs(a) // abs(b)
                    return q if (a >= 0) == (b > 0) else -q
                return a / b
            if op in _BINARY:
                return _BINARY[op](a, b)
        if isinstance(node, tf.FunctionCall):
            name = str(node.name.name).upper() if hasattr(node.name, "name") else str(node.name).upper()
            if name in _FUNCTIONS and len(node.parameters) == 1:
                arg = self._eval(node.parameters[0].value)
                return _FUNCTIONS[name](arg)
        raise NotImplementedError(f"expression {type(node).__name__}: {node}")
