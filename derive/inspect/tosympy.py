"""SX expressions -> sympy, for inspection, LaTeX and exact symbolic checks.

Constants that are exactly a short rational in double precision (0.5, 0.25,
1/12 ...) become sympy Rationals, so results like the pendulum's eq. 18 come
out exact; other constants stay Floats.
"""

from __future__ import annotations

from fractions import Fraction

import casadi as ca
import sympy as sp

from derive.codegen.program import build_program

_FUNCS = {
    "neg": lambda a: -a, "sq": lambda a: a**2, "twice": lambda a: 2 * a, "inv": lambda a: 1 / a,
    "sqrt": sp.sqrt, "sin": sp.sin, "cos": sp.cos, "tan": sp.tan, "exp": sp.exp, "log": sp.log,
    "fabs": sp.Abs, "asin": sp.asin, "acos": sp.acos, "atan": sp.atan, "tanh": sp.tanh,
    "add": lambda a, b: a + b, "sub": lambda a, b: a - b, "mul": lambda a, b: a * b,
    "div": lambda a, b: a / b, "pow": lambda a, b: a**b, "atan2": sp.atan2,
    "fmin": sp.Min, "fmax": sp.Max,
}


def constant(x: float) -> sp.Expr:
    if float(x).is_integer():
        return sp.Integer(int(x))
    frac = Fraction(x).limit_denominator(10000)
    if float(frac) == x:
        return sp.Rational(frac.numerator, frac.denominator)
    return sp.Float(x, 17)


def to_sympy(expressions: list[ca.SX], inputs: list[tuple[ca.SX, list[sp.Symbol]]]) -> list[sp.Matrix]:
    """Convert SX matrices to sympy Matrices, mapping each SX input to sympy symbols."""
    prog = build_program([(f"i{k}", x) for k, (x, _) in enumerate(inputs)],
                         [(f"o{k}", e) for k, e in enumerate(expressions)])
    values: list[sp.Expr] = []

    def operand(a: tuple) -> sp.Expr:
        if a[0] == "t":
            return values[a[1]]
        if a[0] == "in":
            return inputs[a[1]][1][a[2]]
        return constant(a[1])

    for ins in prog.body:
        values.append(_FUNCS[ins.op](*(operand(a) for a in ins.args)))
    mats = [sp.zeros(*e.shape) for e in expressions]
    for oi, idx, a in prog.results:
        rows, cols = expressions[oi].shape
        mats[oi][idx // cols, idx % cols] = operand(a)
    return mats
