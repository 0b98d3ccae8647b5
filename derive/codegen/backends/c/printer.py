"""C99 printer: the DERIVE_* macros of derive_real.h (double by default, float on request)."""

from __future__ import annotations

from derive.codegen.backends.base import ExpressionPrinter, float_literal


class CPrinter(ExpressionPrinter):
    FUNCS = {"sin": "DERIVE_SIN", "cos": "DERIVE_COS", "tan": "DERIVE_TAN", "sqrt": "DERIVE_SQRT",
             "exp": "DERIVE_EXP", "log": "DERIVE_LOG", "fabs": "DERIVE_FABS", "asin": "DERIVE_ASIN",
             "acos": "DERIVE_ACOS", "atan": "DERIVE_ATAN", "tanh": "DERIVE_TANH",
             "sign": "DERIVE_SIGN"}
    BINFUNCS = {"pow": "DERIVE_POW", "atan2": "DERIVE_ATAN2", "fmin": "DERIVE_FMIN", "fmax": "DERIVE_FMAX"}
    ONE = "DERIVE_LIT(1.0)"

    def const(self, x: float) -> str:
        lit = literal(abs(x))
        return f"(-{lit})" if x < 0 or (x == 0 and str(x).startswith("-")) else lit


def literal(x: float) -> str:
    """A real constant in the precision the code is compiled for."""
    return f"DERIVE_LIT({float_literal(x)})"
