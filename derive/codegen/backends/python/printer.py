"""Python printers.

:class:`PythonPrinter`: plain float arithmetic with the math module on scalars (``math.sin(q[0])``),
for straight-line code on one state (the toy list backend of the tests prints with it).

:class:`BatchPrinter`: the numpy module's printer. It prints the same arithmetic in the same order,
but calls each function by its bare name (``sin(q[0])``, ``fmin(a, b)``), which the generated
function binds once per call to the scalar version (Python floats, the math module) or to the
array version (numpy arrays of a batch of states); see :data:`SCALAR` and :data:`BATCH`. Its
temporaries are reused once dead, so that a batch keeps only the live intermediate arrays.
"""

from __future__ import annotations

import heapq

from derive.codegen.backends.base import ExpressionPrinter, float_literal
from derive.codegen.program import Program


class PythonPrinter(ExpressionPrinter):
    FUNCS = {**{k: f"math.{k}" for k in ("sin", "cos", "tan", "sqrt", "exp", "log", "fabs", "asin", "acos", "atan", "tanh")},
             "sign": "_sign"}
    BINFUNCS = {"pow": "math.pow", "atan2": "math.atan2", "fmin": "min", "fmax": "max"}

    def const(self, x: float) -> str:
        return float_literal(x) if x >= 0 else f"({float_literal(x)})"


SCALAR = {**{k: f"math.{k}" for k in PythonPrinter.FUNCS if k != "sign"}, "sign": "_sign", "pow": "math.pow",
          "atan2": "math.atan2", "fmin": "min", "fmax": "max"}
"""Function name in the printed body -> its one-state binding: the math module on Python floats,
which is what the C code calls too (the same libm), and Python's min and max."""

BATCH = {"sin": "np.sin", "cos": "np.cos", "sqrt": "np.sqrt", "fabs": "np.fabs", "sign": "np.sign",
         **{k: f"_batch_{k}" for k in ("tan", "exp", "log", "asin", "acos", "atan", "tanh", "pow", "atan2", "fmin", "fmax")}}
"""Function name in the printed body -> its batch binding. numpy's sin and cos on float64 call the
same libm as math.sin and math.cos, and sqrt and fabs are exact: those are numpy ufuncs. numpy's
SIMD tan, exp, log, asin, acos, atan, tanh, arctan2 and power differ from libm in the last bit on
some inputs and machines (AVX-512 builds), so those map the math function over the batch
(``_batch_<name>``, defined in the module: bit for bit the one-state result, at Python speed per
element; the robots' bodies call none of them today); ``fmin``/``fmax`` are ``np.where`` with
Python's min/max rule (the first argument unless the second is strictly smaller/larger), NaN and
signed zeros included. Where the scalar version raises (math.sqrt of a negative number, a float
division by zero in the body), numpy gives nan or inf with a RuntimeWarning."""

BATCH_DEFINITIONS = {
    **{k: f"_batch_{k} = _elementwise(math.{k}, 1)" for k in ("tan", "exp", "log", "asin", "acos", "atan", "tanh")},
    "pow": "_batch_pow = _elementwise(math.pow, 2)",
    "atan2": "_batch_atan2 = _elementwise(math.atan2, 2)",
    "fmin": "def _batch_fmin(a, b):\n    return np.where(b < a, b, a)",
    "fmax": "def _batch_fmax(a, b):\n    return np.where(b > a, b, a)",
    "sign": "def _sign(x):\n    return float((x > 0) - (x < 0))",  # the one-state sign (np.sign for a batch): -1, 0 or 1
}
"""Module-level definitions of the ``_batch_<name>`` functions of :data:`BATCH` (only those used)."""


class BatchPrinter(PythonPrinter):
    """One body for one state and for a batch: functions by bare name, temporaries reused once dead."""

    FUNCS = {k: k for k in PythonPrinter.FUNCS}
    BINFUNCS = {k: k for k in PythonPrinter.BINFUNCS}

    def __init__(self, input_names: list[str]):
        super().__init__(input_names)
        self.register: dict[int, int] = {}

    def allocate(self, prog: Program) -> int:
        """Give each SSA temporary a variable: the lowest one free (dead) when it is assigned; a
        temporary an output reads stays live to the end. Returns the number of variables."""
        last: dict[int, int] = {}
        for j, ins in enumerate(prog.body):
            for a in ins.args:
                if a[0] == "t":
                    last[a[1]] = j
        end = len(prog.body)
        for _, _, a in prog.results:
            if a[0] == "t":
                last[a[1]] = end
        free: list[int] = []
        count = 0
        self.register = {}
        for j, ins in enumerate(prog.body):
            for a in set(ins.args):  # args dying here free their variables before the result takes one
                if a[0] == "t" and last[a[1]] == j:
                    heapq.heappush(free, self.register[a[1]])
            if free:
                self.register[j] = heapq.heappop(free)
            else:
                self.register[j] = count
                count += 1
            if j not in last:  # never read: its variable is free again at once
                heapq.heappush(free, self.register[j])
        return count

    def temporary(self, k: int) -> str:
        return f"t{self.register[k]}"

    def body(self, prog: Program) -> list[tuple[str, str]]:
        self.allocate(prog)
        return super().body(prog)

    @staticmethod
    def functions(prog: Program) -> list[str]:
        """The function names the body calls, sorted."""
        names = {**PythonPrinter.FUNCS, **PythonPrinter.BINFUNCS}
        return sorted({ins.op for ins in prog.body if ins.op in names})

    def outputs(self, prog: Program, sizes: list[int]) -> list[list[str]]:
        """Each output's entries (row-major) as operands: a temporary, an input element or a constant."""
        entries = [["0.0"] * n for n in sizes]
        for oi, idx, a in prog.results:
            entries[oi][idx] = self.operand(a)
        return entries
