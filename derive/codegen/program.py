"""CasADi SX expressions -> a straight-line program in SSA form.

The program is the single representation every printer reads: C, Python and
sympy (for inspection and LaTeX). CasADi's ``cse`` merges equal
subexpressions first, then the commuted duplicates it keeps apart (a * b and b * a);
each instruction then becomes ``t<k> = op(args)``, and
outputs are listed as (output index, row-major position, operand).

Operands are tagged tuples: ("t", k) a temporary, ("in", i, j) element j of
input i, ("c", value) a constant.
"""

from __future__ import annotations

import heapq
from collections import deque
from dataclasses import dataclass, field

import casadi as ca

UNARY = {
    ca.OP_NEG: "neg", ca.OP_SQ: "sq", ca.OP_TWICE: "twice", ca.OP_INV: "inv", ca.OP_SQRT: "sqrt",
    ca.OP_SIN: "sin", ca.OP_COS: "cos", ca.OP_TAN: "tan", ca.OP_EXP: "exp", ca.OP_LOG: "log",
    ca.OP_FABS: "fabs", ca.OP_ASIN: "asin", ca.OP_ACOS: "acos", ca.OP_ATAN: "atan", ca.OP_TANH: "tanh",
    ca.OP_ASSIGN: "assign", ca.OP_SIGN: "sign",
}
BINARY = {
    ca.OP_ADD: "add", ca.OP_SUB: "sub", ca.OP_MUL: "mul", ca.OP_DIV: "div", ca.OP_POW: "pow",
    ca.OP_CONSTPOW: "pow", ca.OP_ATAN2: "atan2", ca.OP_FMIN: "fmin", ca.OP_FMAX: "fmax",
}
COMMUTATIVE = {"add", "mul"}
"""IEEE addition and multiplication are exactly commutative: ``build_program`` merges a * b with b * a."""
TRIG = {"sin", "cos", "tan", "asin", "acos", "atan", "atan2"}
# cost class of each op for the "ops" comment: mul, add, div, trig, other
COST = {"add": "add", "sub": "add", "neg": "add", "mul": "mul", "sq": "mul", "twice": "add",
        "div": "div", "inv": "div", "sqrt": "other", "pow": "other", "exp": "other", "log": "other",
        "fabs": "other", "tanh": "other", "sign": "other", "fmin": "other", "fmax": "other", "assign": None}


@dataclass(frozen=True)
class Instr:
    op: str
    args: tuple  # operands


@dataclass
class Program:
    inputs: list[tuple[str, tuple[int, int]]]   # (name, shape)
    outputs: list[tuple[str, tuple[int, int]]]
    body: list[Instr] = field(default_factory=list)
    results: list[tuple[int, int, tuple]] = field(default_factory=list)  # (output idx, row-major idx, operand)

    def ops(self) -> dict[str, int]:
        """Arithmetic cost: {total, mul, add, div, trig, other}."""
        count = {"mul": 0, "add": 0, "div": 0, "trig": 0, "other": 0}
        for ins in self.body:
            cls = "trig" if ins.op in TRIG else COST.get(ins.op, "other")
            if cls:
                count[cls] += 1
        count["total"] = sum(count.values())
        return {k: count[k] for k in ("total", "mul", "add", "div", "trig", "other")}


def build_program(inputs: list[tuple[str, ca.SX]], outputs: list[tuple[str, ca.SX]]) -> Program:
    """Flatten SX outputs of SX inputs into a Program (outputs dense, row-major)."""
    for name, x in inputs:
        if not x.is_valid_input():
            raise ValueError(f"input {name} is not purely symbolic")
    outs = [ca.densify(e) for _, e in outputs]
    outs = ca.cse(outs) if outs else outs
    f = ca.Function("f", [x for _, x in inputs], outs, {"allow_free": False})
    prog = Program([(n, x.shape) for n, x in inputs], [(n, e.shape) for n, e in outputs])
    work: dict[int, tuple] = {}
    seen: dict[tuple, tuple] = {}  # (op, operands; commutative ones sorted) -> its operand
    for k in range(f.n_instructions()):
        op = f.instruction_id(k)
        ins, outs_k = f.instruction_input(k), f.instruction_output(k)
        if op == ca.OP_INPUT:
            work[outs_k[0]] = ("in", ins[0], ins[1])
        elif op == ca.OP_CONST:
            work[outs_k[0]] = ("c", float(f.instruction_constant(k)))
        elif op == ca.OP_OUTPUT:
            oi, nz = outs_k
            rows, cols = outputs[oi][1].shape
            r, c = nz % rows, nz // rows
            prog.results.append((oi, r * cols + c, work[ins[0]]))
        elif op in UNARY or op in BINARY:
            name = UNARY.get(op) or BINARY[op]
            args = tuple(work[a] for a in ins[: 1 if op in UNARY else 2])
            if name == "assign":
                work[outs_k[0]] = args[0]
                continue
            key = (name, tuple(sorted(args, key=repr)) if name in COMMUTATIVE else args)
            if key in seen:  # a * b after b * a (CasADi's CSE tells them apart): the same number, exactly
                work[outs_k[0]] = seen[key]
                continue
            prog.body.append(Instr(name, args))
            work[outs_k[0]] = seen[key] = ("t", len(prog.body) - 1)
        else:
            raise NotImplementedError(f"CasADi operation {op} has no printer")
    prog.results.sort(key=lambda r: (r[0], r[1]))
    return prog


def last_reads(prog: Program) -> dict[int, int]:
    """Temporary -> the index of the last instruction reading it; one an output reads: len(body)."""
    last: dict[int, int] = {}
    for j, ins in enumerate(prog.body):
        for a in ins.args:
            if a[0] == "t":
                last[a[1]] = j
    for _, _, a in prog.results:
        if a[0] == "t":
            last[a[1]] = len(prog.body)
    return last


def allocate(prog: Program, fixed=(), in_place: bool = False, oldest: bool = False, span: range | None = None,
             last: dict[int, int] | None = None) -> tuple[dict[int, int], int]:
    """Give each SSA temporary not in ``fixed`` a variable: with ``in_place``, that of its first
    argument dying there if any (the ufunc then writes where it reads), else a free (dead) one when it
    is assigned: the lowest, or with ``oldest`` the one dead the longest (the C printer's choice: it
    perturbs an optimising compiler's register allocation least); a temporary an output reads stays
    live to the end. ``span``: only the instructions in that range (a part of a split function, whose
    temporaries living beyond it are in ``fixed``); ``last``: :func:`last_reads` if already known.
    Returns (temporary -> variable, the number of variables)."""
    last = last_reads(prog) if last is None else last
    free: list[int] = []
    queue: deque[int] = deque()  # with ``oldest``: free variables, longest dead first
    count = 0
    register: dict[int, int] = {}

    def release(variable: int) -> None:
        queue.append(variable) if oldest else heapq.heappush(free, variable)

    for j in span if span is not None else range(len(prog.body)):
        ins = prog.body[j]
        dying = []  # args dying here free their variables before the result takes one
        for a in sorted({a for a in ins.args if a[0] == "t"}, key=lambda a: a[1]) if oldest else ins.args:
            if a[0] == "t" and last[a[1]] == j and a[1] in register and register[a[1]] not in dying:
                dying.append(register[a[1]])
        reuse = in_place and dying and j not in fixed
        for variable in dying[1:] if reuse else dying:
            release(variable)
        if j in fixed:
            continue
        if reuse:
            register[j] = dying[0]
        elif free or queue:
            register[j] = queue.popleft() if oldest else heapq.heappop(free)
        else:
            register[j] = count
            count += 1
        if j not in last:  # never read: its variable is free again at once
            release(register[j])
    return register, count
