"""Print a Program (straight-line SSA code) as C99 or Python statements.

Printers return plain data for the templates: (lhs, rhs) assignment pairs and
output stores. All maths formatting happens here; templates only loop.
"""

from __future__ import annotations

from ..graph import Instr, Program


def _float_literal(x: float) -> str:
    text = repr(float(x))
    if "e" not in text and "." not in text and "inf" not in text and "nan" not in text:
        text += ".0"
    return text


class CPrinter:
    """C99 with the DERIVE_* macros of derive_real.h (double by default, float on request)."""

    FUNCS = {"sin": "DERIVE_SIN", "cos": "DERIVE_COS", "tan": "DERIVE_TAN", "sqrt": "DERIVE_SQRT",
             "exp": "DERIVE_EXP", "log": "DERIVE_LOG", "fabs": "DERIVE_FABS", "asin": "DERIVE_ASIN",
             "acos": "DERIVE_ACOS", "atan": "DERIVE_ATAN", "tanh": "DERIVE_TANH"}
    BINFUNCS = {"pow": "DERIVE_POW", "atan2": "DERIVE_ATAN2", "fmin": "DERIVE_FMIN", "fmax": "DERIVE_FMAX"}

    def __init__(self, input_names: list[str]):
        self.input_names = input_names

    def operand(self, a: tuple) -> str:
        if a[0] == "t":
            return f"t{a[1]}"
        if a[0] == "in":
            return f"{self.input_names[a[1]]}[{a[2]}]"
        return self.const(a[1])

    def const(self, x: float) -> str:
        lit = f"DERIVE_LIT({_float_literal(abs(x))})"
        return f"(-{lit})" if x < 0 or (x == 0 and str(x).startswith("-")) else lit

    def rhs(self, ins: Instr) -> str:
        a = [self.operand(x) for x in ins.args]
        op = ins.op
        if op == "add":
            return f"{a[0]} + {a[1]}"
        if op == "sub":
            return f"{a[0]} - {a[1]}"
        if op == "mul":
            return f"{a[0]} * {a[1]}"
        if op == "div":
            return f"{a[0]} / {a[1]}"
        if op == "neg":
            return f"-{a[0]}"
        if op == "sq":
            return f"{a[0]} * {a[0]}"
        if op == "twice":
            return f"{a[0]} + {a[0]}"
        if op == "inv":
            return f"DERIVE_LIT(1.0) / {a[0]}"
        if op in self.FUNCS:
            return f"{self.FUNCS[op]}({a[0]})"
        if op in self.BINFUNCS:
            return f"{self.BINFUNCS[op]}({a[0]}, {a[1]})"
        raise NotImplementedError(op)

    def body(self, prog: Program) -> list[tuple[str, str]]:
        return [(f"t{k}", self.rhs(ins)) for k, ins in enumerate(prog.body)]

    def stores(self, prog: Program, output_names: list[str]) -> list[tuple[str, str]]:
        return [(f"{output_names[oi]}[{idx}]", self.operand(a)) for oi, idx, a in prog.results]


class PythonPrinter(CPrinter):
    """Python with the math module on scalars."""

    FUNCS = {k: f"math.{k}" for k in ("sin", "cos", "tan", "sqrt", "exp", "log", "fabs", "asin", "acos", "atan", "tanh")}
    BINFUNCS = {"pow": "math.pow", "atan2": "math.atan2", "fmin": "min", "fmax": "max"}

    def const(self, x: float) -> str:
        return _float_literal(x) if x >= 0 else f"({_float_literal(x)})"

    def rhs(self, ins: Instr) -> str:
        if ins.op == "inv":
            return f"1.0 / {self.operand(ins.args[0])}"
        return super().rhs(ins)
