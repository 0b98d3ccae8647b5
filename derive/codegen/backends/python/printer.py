"""Python printer: plain float arithmetic with the math module on scalars."""

from __future__ import annotations

from derive.codegen.backends.base import ExpressionPrinter, float_literal


class PythonPrinter(ExpressionPrinter):
    FUNCS = {k: f"math.{k}" for k in ("sin", "cos", "tan", "sqrt", "exp", "log", "fabs", "asin", "acos", "atan", "tanh")}
    BINFUNCS = {"pow": "math.pow", "atan2": "math.atan2", "fmin": "min", "fmax": "max"}

    def const(self, x: float) -> str:
        return float_literal(x) if x >= 0 else f"({float_literal(x)})"
