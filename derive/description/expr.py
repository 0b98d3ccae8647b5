"""Parameter expressions in model values, without sympy.

A numeric field of a model may hold a number, a parameter name (``m_r``) or an
arithmetic expression of parameters (``"l/2"``, ``"-g"``, ``"sqrt(2)*L1"``).
Expressions are parsed once with :mod:`ast` into a small whitelist of nodes and
evaluated against any scalar algebra (floats, sympy symbols, CasADi SX) through
a namespace of functions, so the model layer never imports a CAS.
"""

from __future__ import annotations

import ast
import math
from typing import Any, Callable, Mapping

from derive.description.numbers import MIN_MAGNITUDE, tiny

Value = "float | str"

FUNCTIONS = ("sin", "cos", "tan", "sqrt", "atan2")
ARITY = {"sin": 1, "cos": 1, "tan": 1, "sqrt": 1, "atan2": 2}
CONSTANTS = {"pi": math.pi}

MAX_LENGTH = 500      # characters of one expression
MAX_NODES = 400       # syntax-tree nodes of one expression
MAX_DEPTH = 100       # nesting of operations and calls (a sum of n terms nests n deep)
MAX_EXPONENT = 64     # |e| of x**e; e must be a number, so no 9**9**9 can be written

_BINOPS = {
    ast.Add: lambda a, b: a + b,
    ast.Sub: lambda a, b: a - b,
    ast.Mult: lambda a, b: a * b,
    ast.Div: lambda a, b: a / b,
    ast.Pow: lambda a, b: a**b,
}


class ExpressionError(ValueError):
    """An expression that is not arithmetic over known parameters."""


def shown(text: str, width: int = 40) -> str:
    """``text`` for an error message: at most ``width`` characters."""
    return text if len(text) <= width else text[: width - 3] + "..."


def _depth(node: ast.AST, limit: int) -> int:
    """Nesting depth of ``node``, counting no further than ``limit`` + 1 (no recursion)."""
    deepest, stack = 0, [(node, 1)]
    while stack:
        n, d = stack.pop()
        deepest = max(deepest, d)
        if deepest > limit:
            break
        stack.extend((c, d + 1) for c in ast.iter_child_nodes(n))
    return deepest


def _exponent(node: ast.expr) -> float | None:
    """The value of a numeric literal (possibly signed), else None."""
    sign = 1.0
    while isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.UAdd, ast.USub)):
        sign = -sign if isinstance(node.op, ast.USub) else sign
        node = node.operand
    if isinstance(node, ast.Constant) and isinstance(node.value, (int, float)) and not isinstance(node.value, bool):
        return sign * float(node.value)
    return None


def parse(text: str) -> ast.expr:
    """Parse ``text`` and check it uses only numbers, names, + - * / ** and FUNCTIONS.

    Limits, checked before anything is evaluated: MAX_LENGTH characters, MAX_NODES nodes,
    MAX_DEPTH levels, and exponents that are numbers of magnitude at most MAX_EXPONENT.
    """
    if len(text) > MAX_LENGTH:
        raise ExpressionError(f"'{shown(text)}' is longer than {MAX_LENGTH} characters")
    try:
        tree = ast.parse(text.strip(), mode="eval").body
    except (SyntaxError, ValueError) as exc:
        raise ExpressionError(f"'{shown(text)}' is not an arithmetic expression") from exc
    except (RecursionError, MemoryError):
        raise ExpressionError(f"'{shown(text)}' is nested too deeply") from None
    if _depth(tree, MAX_DEPTH) > MAX_DEPTH:
        raise ExpressionError(f"'{shown(text)}' is nested deeper than {MAX_DEPTH} levels")
    nodes = list(ast.walk(tree))
    if len(nodes) > MAX_NODES:
        raise ExpressionError(f"'{shown(text)}' has more than {MAX_NODES} terms and operations")
    text = shown(text)
    for node in nodes:
        if isinstance(node, ast.Call):
            if not (isinstance(node.func, ast.Name) and node.func.id in FUNCTIONS) or node.keywords:
                raise ExpressionError(f"'{text}' calls something other than {', '.join(FUNCTIONS)}")
            if len(node.args) != ARITY[node.func.id] or any(isinstance(a, ast.Starred) for a in node.args):
                n = ARITY[node.func.id]
                raise ExpressionError(f"'{text}': {node.func.id} takes {n} argument{'s' if n > 1 else ''}, "
                                      f"got {len(node.args)}")
        elif isinstance(node, ast.Constant):
            if isinstance(node.value, bool) or not isinstance(node.value, (int, float)):
                raise ExpressionError(f"'{text}' contains the non-numeric constant {node.value!r}")
            if isinstance(node.value, float) and tiny(node.value):  # it would be a literal of the generated code
                raise ExpressionError(f"'{text}': the constant {node.value:g} is not 0 but smaller than "
                                      f"{MIN_MAGNITUDE:.3g} in magnitude (the smallest normal float: the generated "
                                      "code must build in single precision too)")
        elif isinstance(node, ast.BinOp):
            if type(node.op) not in _BINOPS:
                raise ExpressionError(f"'{text}' uses an operator other than + - * / **")
            if isinstance(node.op, ast.Pow):
                e = _exponent(node.right)
                if e is None or not abs(e) <= MAX_EXPONENT:
                    raise ExpressionError(f"'{text}': an exponent must be a number between -{MAX_EXPONENT} "
                                          f"and {MAX_EXPONENT}")
        elif isinstance(node, ast.UnaryOp):
            if not isinstance(node.op, (ast.UAdd, ast.USub)):
                raise ExpressionError(f"'{text}' uses a unary operator other than + -")
        elif not isinstance(node, (ast.Name, ast.Load, ast.operator, ast.unaryop, ast.expr_context)):
            raise ExpressionError(f"'{text}' is not plain arithmetic ({type(node).__name__})")
    return tree


def names(text: str) -> list[str]:
    """Parameter names an expression refers to, in order of first appearance."""
    seen: list[str] = []
    for node in ast.walk(parse(text)):
        if isinstance(node, ast.Name) and node.id not in FUNCTIONS and node.id not in CONSTANTS:
            if node.id not in seen:
                seen.append(node.id)
    return seen


def evaluate(value: Any, env: Mapping[str, Any], functions: Mapping[str, Callable] | None = None,
             pi: Any = math.pi) -> Any:
    """Evaluate a model value (number or expression string) in the algebra of ``env``.

    Args:
        value: a number, or a string expression over the names in ``env``.
        env: parameter name -> scalar (float, sympy.Symbol, casadi.SX, ...).
        functions: name -> callable for FUNCTIONS; defaults to :mod:`math`.
        pi: the value of ``pi`` in this algebra (e.g. ``sympy.pi``).
    """
    if not isinstance(value, str):
        return value
    fns = functions or {name: getattr(math, name) for name in FUNCTIONS}

    def ev(node: ast.expr) -> Any:
        if isinstance(node, ast.Constant):
            return float(node.value)  # never Python's unbounded integers
        if isinstance(node, ast.Name):
            if node.id == "pi":
                return pi
            if node.id not in env:
                raise ExpressionError(f"unknown parameter '{node.id}'")
            return env[node.id]
        if isinstance(node, ast.BinOp):
            return _BINOPS[type(node.op)](ev(node.left), ev(node.right))
        if isinstance(node, ast.UnaryOp):
            operand = ev(node.operand)
            return -operand if isinstance(node.op, ast.USub) else operand
        if isinstance(node, ast.Call):
            return fns[node.func.id](*[ev(arg) for arg in node.args])
        raise ExpressionError(f"cannot evaluate {ast.dump(node)}")

    return ev(parse(value))
