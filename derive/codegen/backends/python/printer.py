"""Python printers.

:class:`PythonPrinter`: plain float arithmetic with the math module on scalars (``math.sin(q[0])``),
for straight-line code on one state (the toy list backend of the tests prints with it).

:class:`StatePrinter`: the numpy module's one-state body. It prints the same arithmetic, but calls
each function by its bare name (``sin(q[0])``, ``fmin(a, b)``), which the generated function binds
once per call to the math module (:data:`SCALAR`), and reuses a temporary's variable once it is dead.

:class:`ChunkPrinter`: the numpy module's batch body, the same instructions in the same order as
ufunc calls that write into preallocated rows (``multiply(t1, qd_0, t2)``: ``t2 = t1 * qd[0]`` for
every state of a chunk at once); see :data:`UFUNCS` and :data:`BATCH`.
"""

from __future__ import annotations

from derive.codegen.backends.base import ExpressionPrinter, float_literal
from derive.codegen.program import Instr, Program, allocate


class PythonPrinter(ExpressionPrinter):
    FUNCS = {**{k: f"math.{k}" for k in ("sin", "cos", "tan", "sqrt", "exp", "log", "fabs", "asin", "acos", "atan", "tanh")},
             "sign": "_sign"}
    BINFUNCS = {"pow": "math.pow", "atan2": "math.atan2", "fmin": "min", "fmax": "max"}

    def const(self, x: float) -> str:
        return float_literal(x) if x >= 0 else f"({float_literal(x)})"


SCALAR = {**{k: f"math.{k}" for k in PythonPrinter.FUNCS if k != "sign"}, "sign": "_sign", "pow": "math.pow",
          "atan2": "math.atan2", "fmin": "min", "fmax": "max"}
"""Function name in the one-state body -> its binding: the math module on Python floats, which is
what the C code calls too (the same libm), and Python's min and max."""

UFUNCS = {"add": "add", "sub": "subtract", "mul": "multiply", "div": "divide", "neg": "negative",
          "sq": "multiply", "twice": "add", "inv": "divide", "sin": "sin", "cos": "cos", "sqrt": "sqrt",
          "fabs": "fabs", "sign": "sign"}
"""Instruction -> the numpy ufunc of the batch body (``sq`` is ``multiply(a, a, out)``, ``twice``
``add(a, a, out)``, ``inv`` ``divide(1.0, a, out)``). IEEE arithmetic, sqrt, fabs and sign (-1, 0 or 1) are exact, and
numpy's sin and cos on float64 call the same libm as math.sin and math.cos: bit for bit the
one-state results."""

BATCH = {k: f"_batch_{k}" for k in ("tan", "exp", "log", "asin", "acos", "atan", "tanh", "pow", "atan2", "fmin", "fmax")}
"""The other functions of the batch body, each called as ``_batch_<name>(*args, out)`` (defined in
the module, only those used: :data:`BATCH_DEFINITIONS`). numpy's SIMD tan, exp, log, asin, acos,
atan, tanh, arctan2 and power differ from libm in the last bit on some inputs and machines
(AVX-512 builds), so those map the math function over the chunk (bit for bit the one-state result,
at Python speed per element; the robots' bodies call none of them today); ``fmin``/``fmax`` are
``np.where`` with Python's min/max rule (the first argument unless the second is strictly
smaller/larger), NaN and signed zeros included. Where the one-state body raises (math.sqrt of a
negative number, a float division by zero), numpy gives nan or inf with a RuntimeWarning."""

BATCH_DEFINITIONS = {
    **{k: f"_batch_{k} = _elementwise(math.{k}, 1)" for k in ("tan", "exp", "log", "asin", "acos", "atan", "tanh")},
    "pow": "_batch_pow = _elementwise(math.pow, 2)",
    "atan2": "_batch_atan2 = _elementwise(math.atan2, 2)",
    "fmin": "def _batch_fmin(a, b, out):\n    np.copyto(out, np.where(b < a, b, a))",
    "fmax": "def _batch_fmax(a, b, out):\n    np.copyto(out, np.where(b > a, b, a))",
    "sign": "def _sign(x):\n    return float((x > 0) - (x < 0))",  # the one-state sign (np.sign in a batch): -1, 0 or 1
}
"""Module-level definitions of the ``_batch_<name>`` functions of :data:`BATCH` (only those used)."""


PARAMETERS = {"p"}
"""Inputs that are parameters: one array for all states, most often (the default p)."""


def functions(prog: Program) -> list[str]:
    """The function names a body calls (math functions, min and max), sorted."""
    names = {**PythonPrinter.FUNCS, **PythonPrinter.BINFUNCS}
    return sorted({ins.op for ins in prog.body if ins.op in names})


class StatePrinter(PythonPrinter):
    """The one-state body: functions by bare name, temporaries' variables reused once dead."""

    FUNCS = {k: k for k in PythonPrinter.FUNCS}
    BINFUNCS = {k: k for k in PythonPrinter.BINFUNCS}

    def __init__(self, input_names: list[str]):
        super().__init__(input_names)
        self.register: dict[int, int] = {}

    def temporary(self, k: int) -> str:
        return f"t{self.register[k]}"

    def body(self, prog: Program) -> list[tuple[str, str]]:
        self.register, _ = allocate(prog)
        return super().body(prog)

    def outputs(self, prog: Program, sizes: list[int]) -> list[list[str]]:
        """Each output's entries (row-major) as operands: a temporary, an input element or a constant."""
        entries = [["0.0"] * n for n in sizes]
        for oi, idx, a in prog.results:
            entries[oi][idx] = self.operand(a)
        return entries


class ChunkPrinter:
    """The batch body: each instruction one ufunc call on rows of a chunk of states, in place.

    Every number of the body is a row (one float per state of the chunk): the inputs' elements
    ``<input>_<i>``, the temporaries ``t<k>`` (a row reused once its temporary is dead) and the
    output entries ``<output>_<i>`` (i the row-major index), into which the instruction computing
    an entry writes directly. Constants are the 0-d arrays ``k<i>`` (numpy broadcasts them, faster
    than a Python float). A temporary computed from the parameters alone (the input ``p``: see
    :data:`PARAMETERS`) and constants is an ``s<k>`` instead, which ``_batch`` makes a 0-d array,
    computed once per chunk, when one p serves all states (a 1-D p, the default), and a row
    otherwise; an input shared by all states is a 0-d array too. An entry that is an input element,
    a parameters' temporary or a temporary already in another entry is copied after the arithmetic;
    a constant entry has no row (:attr:`fixed`: ``_batch`` writes it once into the output).
    """

    def __init__(self, inputs: list[tuple[str, int]], outputs: list[tuple[str, int]]):
        names = {n for n, _ in inputs}
        self.inputs = [[f"{n}_{i}" for i in range(size)] for n, size in inputs]
        self.parameters = {k for k, (n, _) in enumerate(inputs) if n in PARAMETERS}
        self.prefixes = [f"{n}_out" if n in names else n for n, _ in outputs]
        self.sizes = [size for _, size in outputs]
        self.outputs: list[str] = []  # the rows of the computed output entries, in order
        self.fixed: list[dict[int, str]] = [{} for _ in outputs]  # per output: constant entry -> literal
        self.constants: dict[str, int] = {}  # literal -> index
        self.output_row: dict[int, str] = {}  # temporary -> the output entry's row it is written to
        self.register: dict[int, int] = {}
        self.registers = 0
        self.pure: set[int] = set()  # the temporaries of the parameters alone
        self.pure_registers = 0

    def variable(self, k: int) -> str:
        if k in self.output_row:
            return self.output_row[k]
        return f"{'s' if k in self.pure else 't'}{self.register[k]}"

    def operand(self, a: tuple) -> str:
        if a[0] == "t":
            return self.variable(a[1])
        if a[0] == "in":
            return self.inputs[a[1]][a[2]]
        return f"k{self.constants.setdefault(float_literal(a[1]), len(self.constants))}"

    def call(self, ins: Instr, out: str) -> str:
        a = [self.operand(x) for x in ins.args]
        op = ins.op
        if op in ("sq", "twice"):
            a = [a[0], a[0]]
        elif op == "inv":
            a = [self.operand(("c", 1.0)), a[0]]
        name = UFUNCS.get(op) or BATCH.get(op)
        if name is None:
            raise NotImplementedError(op)
        return f"{name}({', '.join(a)}, {out})"

    def body(self, prog: Program) -> list[str]:
        """The statements: the instructions' ufunc calls, then the copies into output entries."""
        for j, ins in enumerate(prog.body):
            if all(a[0] == "c" or (a[0] == "in" and a[1] in self.parameters) or (a[0] == "t" and a[1] in self.pure)
                   for a in ins.args):
                self.pure.add(j)
        entries = {(oi, idx): ("c", 0.0) for oi, size in enumerate(self.sizes) for idx in range(size)}
        entries.update(((oi, idx), a) for oi, idx, a in prog.results)
        copies = []
        for (oi, idx), a in sorted(entries.items()):
            if a[0] == "c":
                self.fixed[oi][idx] = float_literal(a[1])
                continue
            row = f"{self.prefixes[oi]}_{idx}"
            self.outputs.append(row)
            if a[0] == "t" and a[1] not in self.output_row and a[1] not in self.pure:
                self.output_row[a[1]] = row
            else:
                copies.append((row, a))
        others = set(range(len(prog.body))) - self.pure
        registers, self.registers = allocate(prog, self.pure | set(self.output_row), in_place=True)
        pure, self.pure_registers = allocate(prog, others, in_place=True)
        self.register = {**registers, **pure}
        lines = [self.call(ins, self.variable(j)) for j, ins in enumerate(prog.body)]
        return lines + [f"copyto({row}, {self.operand(a)})" for row, a in copies]

    def functions(self, lines: list[str]) -> list[str]:
        """The numpy functions the statements call (bound to local names in the body), sorted."""
        return sorted({line.split("(", 1)[0] for line in lines} - set(BATCH.values()))

    def constant_values(self) -> list[str]:
        """The constants' literals, in the order of their names k0, k1, ..."""
        return sorted(self.constants, key=self.constants.get)
