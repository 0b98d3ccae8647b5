"""The Python backend: one module ``python/<robot>.py`` per robot, numpy only.

Functions are named ``<quantity>[_<frame>]`` (no robot prefix: the module is the
namespace) and take the same inputs as the C functions; robots with parameters take
``p=DEFAULT_P``. Templates and support sections: ``templates/python/``.

Every function takes one state or a batch: an input of n elements is an array (..., n), the
batch shapes broadcast, and each output of shape s comes back as (..., *s). An expression
function prints its SSA program twice, the same instructions in the same order, so that a batch
gives bit for bit the per-state results, and one state those of the C code:

- for one state (all inputs 1-D), straight-line Python on floats
  (:class:`~derive.codegen.backends.python.printer.StatePrinter`): the inputs bound to lists of
  floats, the functions it calls to the math module; the outputs ``np.array`` of the entries' tuple;
- for a batch, the function ``_<name>_chunk`` (:class:`~derive.codegen.backends.python.printer.ChunkPrinter`):
  one numpy ufunc call per instruction on rows of a chunk of states (element i of every state),
  each writing into a preallocated row; the module's ``_batch`` runs it over the batch chunk by
  chunk and lays the output rows out as (..., *s).

Template functions: ``rk4_step``, ``manipulability_<frame>`` and the ODE Jacobians of large robots are batched as well; ``ik_<frame>``
(:data:`LOOPS`), iterative per state, solves a batch one state after the other.

A module of more than :data:`WHOLE_OPS` operations defines at most :data:`EAGER_OPS` of them when it
is imported: its largest functions, one after the other until the rest fits, are defined lazily.
The definition of each (both bodies) is the file ``python/<robot>_parts/<name>.py``, and the module
holds a stand-in of the same name, signature and docstring whose first call compiles that file into
the module's namespace (the module's ``_part``). Compiling the source is what a first import costs
(about 0.5 s per MB; the floating Unitree H1-2's 12 MB took 6.5 s), so a big robot's module imports
in a fraction of that, and each big function pays its own compilation on its first call. The
committed robots are written whole: their modules have no parts.

Every function first checks its inputs (the module's ``_array``, and ``_matrix`` for IK's T): numbers
only (bool, int, float; None, complex or text is a TypeError) of the right last axis (a ValueError),
each error naming the function and the argument; IK's q0 and w may be None. The check converts an
input once (``np.asarray``) and loops over nothing, so one state's call costs about the same.
"""

from __future__ import annotations

import jinja2

from derive.codegen.backends.base import Backend, Function, RobotContext, float_literal
from derive.codegen.backends.python.printer import BATCH_DEFINITIONS, PARAMETERS, SCALAR, ChunkPrinter, StatePrinter, functions

SUPPORT = {"ik": ("ik.py",), "manipulability": ("manipulability.py",), "ltdl": ("ltdl.py",)}
"""Fixed algorithms -> the sections (templates/python/support/) inserted verbatim into the module."""

LOOPS = {"ik"}
"""Templates whose functions take a batch but loop over it in Python (iterative per state)."""

CHUNK = 16384
"""Most states per chunk of a batch (``_CHUNK`` in the module). Each ufunc call of a batch body costs
about 0.27 µs on top of its arithmetic (0.1 ns per state from the L1 cache, 0.25 from the L2 or
L3), so chunks are large: Panda's inverse_dynamics body takes 973, 431, 373, 342 and 331 ns per
state in chunks of 250, 1000, 2000, 4000 and 8000 states, and the 10 000 states of the
python-speed bench are one chunk."""

CHUNK_FLOATS = 4_000_000
"""Most floats per buffer of a chunk's rows (``_FLOATS``, 30.5 MB): glibc's malloc keeps reusing blocks
under 32 MB from call to call, and maps a larger one anew each time (page faults on every call)."""

WHOLE_OPS = 45_000
"""Most operations (after CSE, summed over the expression functions) of a module written whole, every
function defined when it is imported (:class:`PythonBackend`'s ``whole_ops``; see
:func:`lazy_functions`): about a second of compiling on a first import. The Panda's module is
40 225 (2.2 MB), the UR5's 18 335."""

EAGER_OPS = 20_000
"""Most operations a larger module defines when it is imported (``eager_ops``): about half a second
of compiling. The floating H1-2 with hands totals 216 455 operations (12 MB of Python)."""

ENTRIES_PER_LINE = 8
"""Entries per line of a vector output's tuple (a matrix has one line per row)."""


def _args(spec, optional=()) -> list[str]:
    return [("p=DEFAULT_P" if n == "p" else f"{n}=None" if n in optional else n) for n, _ in spec.inputs]


def _checks(t) -> list[str]:
    """A template function's first lines: each input through the module's ``_array`` (a vector),
    or ``_matrix`` (a matrix), an optional one only when given (not None)."""
    lines = []
    for n, (r, c) in t.inputs:
        if r * c == 0:
            continue
        call = f'_matrix({n}, {r}, {c}, "{t.short_name}", "{n}")' if c > 1 else f'_array({n}, {r}, "{t.short_name}", "{n}")'
        lines.append(f"{n} = None if {n} is None else {call}" if n in t.optional else f"{n} = {call}")
    return lines


def _returns(outputs, status: bool = False) -> list[dict]:
    """What the Python function returns, in order: a float ndarray per output, of shape (r,) for
    an r x 1 output (a column vector, 1 x 1 included) and (r, c) otherwise, then for a status
    function its int code. One entry: the value itself; more: a tuple of them."""
    out = [{"name": n, "shape": [r] if c == 1 else [r, c]} for n, (r, c) in outputs]
    return out + ([{"name": "status", "shape": [], "type": "int"}] if status else [])


def _wrap(names: list[str], width: int = 100) -> list[str]:
    """Comma-separated names in lines of at most about ``width`` characters."""
    lines, line = [], ""
    for name in names:
        if line and len(line) + len(name) + 2 > width:
            lines.append(line + ",")
            line = ""
        line = f"{line}, {name}" if line else name
    return lines + [line] if line else lines


def _unpack(names: list[str], value: str) -> str | None:
    """``a, b, c = value`` (in parentheses over lines of about 100 characters), None for no names."""
    if not names:
        return None
    lines = _wrap(names)
    if len(lines) == 1:
        return f"{lines[0]}{',' if len(names) == 1 else ''} = {value}"
    return "(" + "\n     ".join(lines) + f") = {value}"


def _entries(var: str, entries: list[str], cols: int) -> str:
    """``<var> = (...)``: an output's entries, row-major, a matrix one row per line."""
    per_line = cols if cols > 1 else ENTRIES_PER_LINE
    lines = [", ".join(entries[k:k + per_line]) for k in range(0, len(entries), per_line)]
    indent = "\n" + " " * (len(var) + 8)
    return f"{var} = (" + ("," + indent).join(lines) + ("," if len(entries) == 1 else "") + ")"


def _chunk_context(name: str, prog, inputs: list[tuple[str, int]], outputs: list[tuple[str, int]],
                   dims: list[str]) -> dict:
    """What the template needs of a function's batch body ``_<name>_chunk`` and its ``_batch`` call."""
    chunk = ChunkPrinter(inputs, outputs)
    statements = chunk.body(prog)
    names = [n for n, size in inputs if size > 0]
    if any(n in PARAMETERS for n in names[:-1]):  # _batch: the parameters' temporaries shared iff the last input is
        raise ValueError(f"{name}: the parameters must be the last input, got {names}")
    options = ([f"fixed=_{name}_fixed"] if any(chunk.fixed) else []) + \
        ([f"pure={chunk.pure_registers}"] if chunk.pure_registers else [])
    return {"call": f"_batch(_{name}_chunk, ({', '.join(names)}{',' if len(names) == 1 else ''}), {chunk.registers}, "
                    f"({' '.join(f'{d},' for d in dims)})" + "".join(f", {o}" for o in options) + ")",
            "body": statements, "ufuncs": chunk.functions(statements),
            "unpack": [line for line in (_unpack([r for rows in chunk.inputs for r in rows], "x"),
                                         _unpack([f"t{k}" for k in range(chunk.registers)], "t"),
                                         _unpack([f"s{k}" for k in range(chunk.pure_registers)], "s"),
                                         _unpack(chunk.outputs, "y"),
                                         _unpack([f"k{k}" for k in range(len(chunk.constants))], f"_{name}_constants"))
                       if line],
            "literals": _wrap(chunk.constant_values()),
            "fixed": [_wrap([f"{j}: {v}" for j, v in sorted(fixed.items())]) for fixed in chunk.fixed]
            if any(chunk.fixed) else None}


def lazy_functions(functions: list[dict], whole: int, eager: int) -> set[str]:
    """The short names of the functions a module defines lazily: none when its expression functions
    total at most ``whole`` operations; else those, most operations first (then by name), until the
    others total at most ``eager``. Template functions (ops None) cost little to compile and stay."""
    sized = sorted((-f["ops"]["total"], f["short_name"]) for f in functions if f["ops"])  # largest first
    rest = -sum(minus for minus, _ in sized)
    lazy: set[str] = set()
    if rest <= whole:
        return lazy
    for minus, name in sized:
        if rest <= eager:
            break
        lazy.add(name)
        rest += minus
    return lazy


def _part_path(robot: RobotContext, f: dict) -> str:
    """The file defining a lazy function: ``python/<robot>_parts/<name>.py``."""
    return f"python/{robot.robot}_parts/{f['short_name']}.py"


class PythonBackend(Backend):
    name = "python"
    whole_ops: int = WHOLE_OPS
    eager_ops: int = EAGER_OPS

    def function_context(self, fn: Function) -> dict:
        spec, prog = fn.spec, fn.program
        printer = StatePrinter([n for n, _ in spec.inputs])
        body = printer.body(prog)  # first: it gives the temporaries their variables
        called = functions(prog)
        sizes = [e.shape[0] * e.shape[1] for _, e in spec.outputs]
        outputs = []
        for (n, e), entries in zip(spec.outputs, printer.outputs(prog, sizes)):
            r, c = e.shape
            dims = (r,) if c == 1 else (r, c)
            outputs.append({"var": f"_{n}", "text": _entries(f"_{n}", entries, c), "dims": dims,
                            "dims_text": f"({r},)" if c == 1 else f"({r}, {c})"})
        inputs = [(n, x.shape[0]) for n, x in spec.inputs if x.shape[0] > 0]
        return {**fn.common, "py_args": _args(spec), "py_template": None, "py_loops": False,
                "py_names": [n for n, _ in spec.inputs],
                "py_inputs": inputs, "py_body": body, "py_outputs": outputs, "py_functions": called,
                "py_scalar": [SCALAR[k] for k in called],
                "py_chunk": _chunk_context(spec.short_name, prog, [(n, x.shape[0]) for n, x in spec.inputs],
                                           list(zip([n for n, _ in spec.outputs], sizes)), [o["dims_text"] for o in outputs]),
                "py_returns": _returns([(n, e.shape) for n, e in spec.outputs])}

    def template_context(self, fn: Function) -> dict:
        t = fn.spec
        context = self.literals(t.context, float_literal, float_literal)
        return {**fn.common, **context, **dict(t.calls), "py_args": _args(t, t.optional),
                "py_template": self.template(f"{t.template}.py.jinja"), "py_checks": _checks(t),
                "py_matrix": any(c > 1 for _, (_, c) in t.inputs),
                "py_support": [s for algorithm in t.support for s in SUPPORT[algorithm]], "py_loops": t.template in LOOPS,
                "py_returns": _returns(t.outputs, t.status),
                "p_arg": ", p" if "p" in [n for n, _ in t.inputs] else ""}

    def sections(self, functions: list[dict]) -> list[dict]:
        names = sorted({name for f in functions for name in f.get("py_support", ())})
        return [{"source": self.support_source(name), "text": self.support_text(name)} for name in names]

    def render(self, env: jinja2.Environment, robot: RobotContext, functions: list[dict]) -> dict[str, str]:
        lazy = lazy_functions(functions, self.whole_ops, self.eager_ops)
        for f in functions:  # read again by manifest_entry
            f["py_lazy"] = f["short_name"] in lazy
        lazy = [f["short_name"] for f in functions if f["py_lazy"]]
        used = sorted({k for f in functions for k in f.get("py_functions", ()) if k in BATCH_DEFINITIONS})
        text = env.get_template(self.template("module.py.jinja")).render(
            robot.data(), functions=functions, support=self.sections(functions),
            loops=[f["short_name"] for f in functions if f.get("py_loops")],
            elementwise=any(BATCH_DEFINITIONS[k].startswith("_batch") for k in used),
            matrices=any(f.get("py_matrix") for f in functions),
            chunk_size=CHUNK, chunk_floats=f"{CHUNK_FLOATS:_}",
            batch_definitions=[BATCH_DEFINITIONS[k] for k in used],
            lazy=lazy, eager_ops=f"{self.eager_ops:,}".replace(",", " "))
        part = env.get_template(self.template("part.py.jinja"))
        return {f"python/{robot.robot}.py": text, **{
            _part_path(robot, f): part.render(robot.data(), f=f) for f in functions if f["py_lazy"]}}

    def manifest_entry(self, robot: RobotContext, f: dict) -> dict:
        """The module, the function and what it returns (see :func:`_returns`); for a function defined
        lazily (as :meth:`render` marked it), also ``part``: the file that defines it."""
        return {"module": f"python/{robot.robot}.py", "function": f["short_name"], "returns": f["py_returns"],
                **({"part": _part_path(robot, f)} if f.get("py_lazy") else {})}

    def manifest_support(self, robot: RobotContext, functions: list[dict]) -> list[dict]:
        return [{"file": f"python/{robot.robot}.py", "source": s["source"]} for s in self.sections(functions)]


BACKEND = PythonBackend()
