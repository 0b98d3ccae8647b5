"""C99 printer: the DERIVE_* macros of derive_real.h (double by default, float on request).

Temporaries live in a bounded set of work variables ``w<k>``, reused once dead (the linear scan
of :func:`derive.codegen.program.allocate`): without optimisation a compiler gives every local its
own stack slot, so one ``const`` per SSA temporary would need tens of kB of stack in a debug build
(the Panda's ode_jac_x: 8 473 temporaries, about 70 kB at -O0); with reuse it needs as many slots
as temporaries are live at once (444 there: 3.6 kB at -O0 on x86-64). The variable dead the longest is reused first.
Optimising compilers rename the variables back into SSA form, so -O2 code is the same either way.

A function of more than :data:`SPLIT_ABOVE` instructions and output entries is split into parts of
at most :data:`PART_SIZE` instructions, then parts of as many output stores (``static`` functions
the compiler may not inline, ``DERIVE_NOINLINE``): an optimising compiler's time and memory grow
faster than linearly with the size of one straight-line function (12-dof chain, gcc -O2: 8.7k
operations compile in 1.7 s, 60k in 30-43 s and 780 MB), and linearly with the number of parts
(the 60k in 8.6 s and 250 MB in parts of 4000, and 4 % fewer instructions per call; see
:data:`PART_SIZE`). A temporary
that one part computes and a later part reads (every output entry, which store parts write) is
carried in the caller's work array ``W``, its slots reused once dead, so the stack stays bounded."""

from __future__ import annotations

import heapq

from derive.codegen.backends.base import ExpressionPrinter, float_literal
from derive.codegen.program import Program, allocate, last_reads

WORK_PER_LINE = 12
SPLIT_ABOVE = 12000
"""Instructions plus output entries above which a function is split into parts (the shipped
robots' largest, the Panda's ode_jac_x, has 8 473 + 196 and stays one function)."""
PART_SIZE = 1500
"""Most instructions per part of a split function. Smaller parts compile faster and in less memory at
the same speed per call: a 20-joint chain's ode_jac_x (144k ops) compiles in 18.3 s instead of 22.1 s
with parts of 1500 instead of 4000, and runs in 43.2 against 43.3 us; a 40-joint chain's
coriolis_matrix (55k ops, many values carried between parts) in 27 s and 0.59 GB instead of 42 s and
1.35 GB."""


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
        self.slot: dict[int, int] = {}  # a split function's temporaries carried between parts -> slot of W
        self.slots = 0

    def temporary(self, k: int) -> str:
        if k in self.slot:
            return f"W[{self.slot[k]}]"
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


    def split(self, prog: Program, output_names: list[str], size: int | None = None) -> list[dict]:
        """The parts of a split function, in order: each its ``body``, ``work`` declarations, the input
        arrays it reads and output arrays it writes (``reads``, ``writes``: to tell the unused
        parameters); after the computing parts, store parts writing at most ``size`` output entries
        each from W (one function with tens of thousands of stores takes gcc minutes: its alias walks).
        Sets :attr:`slots`, the length of the work array W, and :attr:`computing`, the number of
        computing parts (the store parts follow). ``size``: most instructions a part (default
        :data:`PART_SIZE`)."""
        size = size or PART_SIZE
        self.part_size = size
        n = len(prog.body)
        last = last_reads(prog)
        part = [j // size for j in range(n)]
        final = part[-1] if part else -1
        # carried: read in a later part than the one computing it (an output: by a store part)
        carried = sorted(j for j, end in last.items() if (part[end] if end < n else final + 1) > part[j])
        self.slot, self.slots = {}, 0
        free: list[int] = []  # a heap of the free slots
        ending: dict[int, list[int]] = {}  # the last part reading a slot's value (final + 1: an output) -> slots
        released = -1  # the slots of values last read in parts up to this one are free
        for j in carried:  # linear scan at part granularity: a slot is free after the part last reading it
            while released < part[j] - 1:
                released += 1
                for slot in ending.pop(released, ()):
                    heapq.heappush(free, slot)
            slot = heapq.heappop(free) if free else self.slots
            self.slots = max(self.slots, slot + 1)
            self.slot[j] = slot
            ending.setdefault(part[last[j]] if last[j] < n else final + 1, []).append(slot)
        parts = []
        for p in range(final + 1):
            start, stop = p * size, min(n, (p + 1) * size)
            self.register, self.work = allocate(prog, fixed=self.slot, oldest=True, span=range(start, stop), last=last)
            body = [(self.temporary(k), self.rhs(prog.body[k])) for k in range(start, stop)]
            reads = {a[1] for ins in prog.body[start:stop] for a in ins.args if a[0] == "in"}
            parts.append({"body": body, "work": self.declarations(), "reads": reads, "writes": set(), "stores": [],
                          "uses_slots": any(k in self.slot for k in range(start, stop))
                          or any(a[0] == "t" and a[1] in self.slot for ins in prog.body[start:stop] for a in ins.args)})
        self.computing = len(parts)
        stores = self.stores(prog, output_names)
        for first in range(0, len(prog.results), size):
            results = prog.results[first:first + size]
            parts.append({"body": [], "work": [], "stores": stores[first:first + size],
                          "reads": {a[1] for _, _, a in results if a[0] == "in"},
                          "writes": {output_names[oi] for oi, _, _ in results},
                          "uses_slots": any(a[0] == "t" for _, _, a in results)})
        return parts


FLT_MIN = 1.1754943508222875e-38
"""The smallest normal float: a nonzero constant below it (a product of two tiny model numbers, say)
would be a float literal that compilers truncate to zero with a warning, fatal under -Werror."""


def literal(x: float) -> str:
    """A real constant in the precision the code is compiled for. A nonzero constant too small for a
    float literal is a double literal converted to DERIVE_REAL (rounding to 0 in a float build,
    exact in double), which compilers accept without a warning."""
    if x != 0 and abs(x) < FLT_MIN:
        return f"((DERIVE_REAL){float_literal(x)})"
    return f"DERIVE_LIT({float_literal(x)})"
