"""C99 printer: the DERIVE_* macros of derive_real.h (double by default, float on request).

Temporaries live in a bounded set of work variables ``w<k>``, reused once dead (the linear scan
of :func:`derive.codegen.program.allocate`): without optimisation a compiler gives every local its
own stack slot, so one ``const`` per SSA temporary would need tens of kB of stack in a debug build
(the Panda's ode_jac_x: 10 305 temporaries, 80 kB at -O0); with reuse it needs as many slots as
temporaries are live at once (276 there). The variable dead the longest is reused first. Optimising compilers rename the variables back into
SSA form, so -O2 code is the same either way."""

from __future__ import annotations

from derive.codegen.backends.base import ExpressionPrinter, float_literal
from derive.codegen.program import Program, allocate

WORK_PER_LINE = 12


class CPrinter(ExpressionPrinter):
    FUNCS = {"sin": "DERIVE_SIN", "cos": "DERIVE_COS", "tan": "DERIVE_TAN", "sqrt": "DERIVE_SQRT",
             "exp": "DERIVE_EXP", "log": "DERIVE_LOG", "fabs": "DERIVE_FABS", "asin": "DERIVE_ASIN",
             "acos": "DERIVE_ACOS", "atan": "DERIVE_ATAN", "tanh": "DERIVE_TANH",
             "sign": "DERIVE_SIGN"}
    BINFUNCS = {"pow": "DERIVE_POW", "atan2": "DERIVE_ATAN2", "fmin": "DERIVE_FMIN", "fmax": "DERIVE_FMAX"}
    ONE = "DERIVE_LIT(1.0)"

    def __init__(self, input_names: list[str]):
        super().__init__(input_names)
        self.register: dict[int, int] = {}
        self.work = 0  # the number of work variables

    def temporary(self, k: int) -> str:
        return f"w{self.register[k]}"

    def body(self, prog: Program) -> list[tuple[str, str]]:
        self.register, self.work = allocate(prog, oldest=True)
        return super().body(prog)

    def declarations(self) -> list[str]:
        """The work variables' declaration lines (after :meth:`body`), WORK_PER_LINE names a line."""
        names = [f"w{k}" for k in range(self.work)]
        return [", ".join(names[i:i + WORK_PER_LINE]) for i in range(0, len(names), WORK_PER_LINE)]

    def const(self, x: float) -> str:
        lit = literal(abs(x))
        return f"(-{lit})" if x < 0 or (x == 0 and str(x).startswith("-")) else lit


def literal(x: float) -> str:
    """A real constant in the precision the code is compiled for."""
    return f"DERIVE_LIT({float_literal(x)})"
