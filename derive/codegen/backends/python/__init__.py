"""The Python backend: one module ``python/<robot>.py`` per robot, numpy only.

Functions are named ``<quantity>[_<frame>]`` (no robot prefix: the module is the
namespace) and take the same inputs as the C functions; robots with parameters take
``p=DEFAULT_P``. Templates and support sections: ``templates/python/``.

Every function takes one state or a batch: an input of n elements is an array (..., n), the
batch shapes broadcast, and each output of shape s comes back as (..., *s). An expression
function has ONE printed body (:class:`~derive.codegen.backends.python.printer.BatchPrinter`)
for both: for one state (all inputs 1-D) it binds the inputs to lists of Python floats and the
functions it calls to the math module, for a batch to rows ``x[i]`` (element i of every state,
an array of the batch shape) and to numpy (:data:`~derive.codegen.backends.python.printer.BATCH`).
The floating-point operations are the same, in the same order, so a batch gives bit for bit the
per-state results, and one state gives those of the C code. The outputs are built from the
entries' tuple: ``np.array`` for one state, :func:`_batch` (in the module) for a batch.
Template functions: ``rk4_step`` and ``manipulability_<frame>`` are batched as well; ``ik_<frame>``
(:data:`LOOPS`), iterative per state, solves a batch one state after the other.
"""

from __future__ import annotations

import jinja2

from derive.codegen.backends.base import Backend, Function, RobotContext, float_literal
from derive.codegen.backends.python.printer import BATCH, BATCH_DEFINITIONS, SCALAR, BatchPrinter

SUPPORT = {"ik": ("ik.py",), "manipulability": ("manipulability.py",)}
"""Fixed algorithms -> the sections (templates/python/support/) inserted verbatim into the module."""

LOOPS = {"ik"}
"""Templates whose functions take a batch but loop over it in Python (iterative per state)."""

ENTRIES_PER_LINE = 8
"""Entries per line of a vector output's tuple (a matrix has one line per row)."""


def _args(spec, optional=()) -> list[str]:
    return [("p=DEFAULT_P" if n == "p" else f"{n}=None" if n in optional else n) for n, _ in spec.inputs]


def _returns(outputs, status: bool = False) -> list[dict]:
    """What the Python function returns, in order: a float ndarray per output, of shape (r,) for
    an r x 1 output (a column vector, 1 x 1 included) and (r, c) otherwise, then for a status
    function its int code. One entry: the value itself; more: a tuple of them."""
    out = [{"name": n, "shape": [r] if c == 1 else [r, c]} for n, (r, c) in outputs]
    return out + ([{"name": "status", "shape": [], "type": "int"}] if status else [])


def _entries(var: str, entries: list[str], cols: int) -> str:
    """``<var> = (...)``: an output's entries, row-major, a matrix one row per line."""
    per_line = cols if cols > 1 else ENTRIES_PER_LINE
    lines = [", ".join(entries[k:k + per_line]) for k in range(0, len(entries), per_line)]
    indent = "\n" + " " * (len(var) + 8)
    return f"{var} = (" + ("," + indent).join(lines) + ("," if len(entries) == 1 else "") + ")"


class PythonBackend(Backend):
    name = "python"

    def function_context(self, fn: Function) -> dict:
        spec, prog = fn.spec, fn.program
        printer = BatchPrinter([n for n, _ in spec.inputs])
        body = printer.body(prog)  # first: it gives the temporaries their variables
        functions = printer.functions(prog)
        sizes = [e.shape[0] * e.shape[1] for _, e in spec.outputs]
        outputs = []
        for (n, e), entries in zip(spec.outputs, printer.outputs(prog, sizes)):
            r, c = e.shape
            dims = (r,) if c == 1 else (r, c)
            outputs.append({"var": f"_{n}", "text": _entries(f"_{n}", entries, c), "dims": dims,
                            "dims_text": f"({r},)" if c == 1 else f"({r}, {c})"})
        return {**fn.common, "py_args": _args(spec), "py_template": None, "py_loops": False,
                "py_inputs": [(n, x.shape[0]) for n, x in spec.inputs if x.shape[0] > 0],
                "py_body": body, "py_outputs": outputs, "py_functions": functions,
                "py_scalar": [SCALAR[k] for k in functions], "py_batch": [BATCH[k] for k in functions],
                "py_returns": _returns([(n, e.shape) for n, e in spec.outputs])}

    def template_context(self, fn: Function) -> dict:
        t = fn.spec
        context = self.literals(t.context, float_literal, float_literal)
        return {**fn.common, **context, **dict(t.calls), "py_args": _args(t, t.optional),
                "py_template": self.template(f"{t.template}.py.jinja"),
                "py_support": [s for algorithm in t.support for s in SUPPORT[algorithm]], "py_loops": t.template in LOOPS,
                "py_returns": _returns(t.outputs, t.status),
                "p_arg": ", p" if "p" in [n for n, _ in t.inputs] else ""}

    def sections(self, functions: list[dict]) -> list[dict]:
        names = sorted({name for f in functions for name in f.get("py_support", ())})
        return [{"source": self.support_source(name), "text": self.support_text(name)} for name in names]

    def render(self, env: jinja2.Environment, robot: RobotContext, functions: list[dict]) -> dict[str, str]:
        used = sorted({k for f in functions for k in f.get("py_functions", ()) if k in BATCH_DEFINITIONS})
        text = env.get_template(self.template("module.py.jinja")).render(
            robot.data(), functions=functions, support=self.sections(functions),
            loops=[f["short_name"] for f in functions if f.get("py_loops")],
            elementwise=any(BATCH_DEFINITIONS[k].startswith("_batch") for k in used),
            batch_definitions=[BATCH_DEFINITIONS[k] for k in used])
        return {f"python/{robot.robot}.py": text}

    def manifest_entry(self, robot: RobotContext, f: dict) -> dict:
        """The module, the function and what it returns (see :func:`_returns`)."""
        return {"module": f"python/{robot.robot}.py", "function": f["short_name"], "returns": f["py_returns"]}

    def manifest_support(self, robot: RobotContext, functions: list[dict]) -> list[dict]:
        return [{"file": f"python/{robot.robot}.py", "source": s["source"]} for s in self.sections(functions)]


BACKEND = PythonBackend()
