"""JAX printer: jax.numpy with the batch in the LAST axes, one row per input element.

An input element is ``q_[i]``, a row of ``q_ = jnp.moveaxis(q, -1, 0)`` (n, *batch): every temporary
is a contiguous array of the batch shape, functions are the jnp ufuncs, and each output is one
``jnp.stack`` of its entries moved back to (*batch, n). The body is traceable by jit, vmap and grad.

Why some temporaries are wrapped in ``_keep`` (``t / one``, ``one`` a runtime 1.0 of the batch shape,
so x / one == x exactly and d/dx = 1): XLA fuses cheap elementwise producers (add, sub, mul) into
every consumer, recomputing a shared subexpression once per use (and per operand of a
concatenate), which on the generated DAGs multiplies the arithmetic 10-300x (panda
inverse_dynamics 170 us per state through one stack). A divide is "expensive" to XLA, which never
duplicates it: a kept temporary is computed once, stored, and read by its users. Keeping every
shared temporary makes one kernel per temporary (kernel overhead, and each kernel reads its
operands from memory); a temporary is kept where the arithmetic XLA would repeat, (uses - 1) x its
inlined tree (up to already-kept values), reaches ``KEEP_WASTE`` operations.

Input elements are kept the same way where at least ``KEEP_INPUT_USES`` operations read them: under
``jax.vmap`` an element ``x_[i]`` is a strided column of the (batch, n) input, which every kernel
using it would read again, one cache line per state; kept, it is read once into a contiguous row.

Large functions are evaluated in blocks of states on the CPU (``@_blocks(block, sizes)``, see its
docstring in the module): the stored temporaries are arrays of the whole batch, which on a large batch
outgrow the caches, and XLA's buffer for them outgrows malloc's reuse (Panda's ode_jac_x at 10 000
states: 40 MB of temporaries per call, on fresh zeroed pages each call; under perf, 28 % of its time
in the kernel, faulting them in). :meth:`JaxPrinter.block` picks the functions, BLOCK the size.
"""

from __future__ import annotations

from derive.codegen.backends.base import ExpressionPrinter, float_literal

KEEP_WASTE = 8
"""A shared temporary is kept (computed once) where (uses - 1) x its inlined tree's operations reaches
this. Panda, jit(vmap) per state on one CPU core at 10 000 states against the NumPy batch, same
process, interleaved (a loaded shared machine, so +-15 %): the former rule (kept at >= 2 uses and a
tree of >= 16 operations) and this one (with the kept input elements) gave inverse_dynamics 0.83-1.04x
-> 0.48-0.64x, mass_matrix 0.73-0.79x -> 0.69-0.72x, forward_dynamics 0.78-0.86x -> 0.71-0.81x, and
ode_jac_x about the same (1.0-1.3x either way; the arithmetic XLA runs went from 22 500 to 14 500
operations per state, its kernels from 789 to 945). KEEP_WASTE 4 kept more for no gain, 16 and 32 less
and were slower."""
KEEP_INPUT_USES = 3
"""An input element read by at least this many operations is kept (see the module docstring); with
2 (mass_matrix: each q_i read by one sin and one cos, both kept) it was 20 % slower."""

BLOCK = 2048
"""States per block (at most) of a blocked function. Panda at 10 000 states, jit(vmap) per state on one
CPU core against the NumPy batch, same process, interleaved: ode_jac_x (755 stored values) unblocked
1.11x, in blocks of 300 / 600 / 1250 / 2500 states 0.76x / 0.64x / 0.62x / 0.62x (in blocks of 50:
1.5x; each block runs each of the function's ~930 kernels once, about 0.4 us each);
inverse_dynamics (94) 0.66x, in blocks of 250 to 2000 0.56-0.57x, of 4000 0.65x; forward_dynamics
(152) 0.66x, in blocks of 250 to 2000 0.53-0.55x, of 4000 0.57x. A block of 2048 states keeps
ode_jac_x's temporaries at 8 MB, which malloc reuses from call to call."""
MIN_STORED = 64
"""Functions storing fewer values are not blocked: their temporaries take less than 5 MB at 10 000
states, and blocks would add their overhead (a loop, the copies in and out) to every small function."""
STORED_PER_ENTRY = 2
"""Blocked only where the stored values are at least this many per output entry: blocks add a copy of
the outputs (the blocks' results into the batch), which outweighs the gain where the output is most of
the traffic (Panda mass_matrix, 68 stored for 49 entries: 0.59x the NumPy batch unblocked, 0.68-0.70x
in blocks of 250 to 2000; inverse_dynamics, 94 for 7: 0.66x -> 0.57x)."""

STORED = ("div", "inv")
"""The ops XLA computes once (a divide is expensive to it, never copied into its users). The others
it may copy into each user: add, sub, mul, and (measured, jaxlib 0.10 on the CPU) sin and cos too."""
TRANSCENDENTAL_COST = 20
"""A sin, cos, sqrt, ... counts as this many operations."""


class JaxPrinter(ExpressionPrinter):
    FUNCS = {"sin": "jnp.sin", "cos": "jnp.cos", "tan": "jnp.tan", "sqrt": "jnp.sqrt", "exp": "jnp.exp",
             "log": "jnp.log", "fabs": "jnp.abs", "asin": "jnp.arcsin", "acos": "jnp.arccos", "atan": "jnp.arctan",
             "tanh": "jnp.tanh", "sign": "jnp.sign"}
    BINFUNCS = {"pow": "jnp.power", "atan2": "jnp.arctan2", "fmin": "jnp.minimum", "fmax": "jnp.maximum"}

    def element(self, array: str, index: int) -> str:
        return f"{array}_[{index}]"

    def const(self, x: float) -> str:
        return float_literal(x) if x >= 0 else f"({float_literal(x)})"

    def kept(self, prog) -> set[int]:
        """The temporaries to compute once (see the module docstring): those used at least twice
        (outputs included) whose repeated arithmetic, (uses - 1) x inlined tree, reaches KEEP_WASTE."""
        uses = [0] * len(prog.body)
        for ins in prog.body:
            for a in ins.args:
                if a[0] == "t":
                    uses[a[1]] += 1
        for _, _, a in prog.results:
            if a[0] == "t":
                uses[a[1]] += 1
        cost, keep = [0] * len(prog.body), set()
        for k, ins in enumerate(prog.body):
            if ins.op in STORED:
                continue  # XLA computes it once; its users see a stored value (cost 0)
            own = TRANSCENDENTAL_COST if ins.op in self.FUNCS or ins.op in self.BINFUNCS else 1
            cost[k] = own + sum(cost[a[1]] for a in ins.args if a[0] == "t")
            if uses[k] >= 2 and (uses[k] - 1) * cost[k] >= KEEP_WASTE:
                keep.add(k)
                cost[k] = 0
        return keep

    def kept_inputs(self, prog) -> dict[str, tuple[int, ...]]:
        """Input name -> its elements read by at least KEEP_INPUT_USES operations (outputs included), to
        be read once into contiguous rows (see the module docstring); inputs with none are left out."""
        uses: dict[tuple[int, int], int] = {}
        for a in [a for ins in prog.body for a in ins.args] + [a for _, _, a in prog.results]:
            if a[0] == "in":
                uses[a[1], a[2]] = uses.get((a[1], a[2]), 0) + 1
        out: dict[str, tuple[int, ...]] = {}
        for (i, j), count in sorted(uses.items()):
            if count >= KEEP_INPUT_USES:
                out[self.input_names[i]] = out.get(self.input_names[i], ()) + (j,)
        return out

    def block(self, prog) -> int | None:
        """BLOCK where the function is evaluated in blocks of states on the CPU (see the module
        docstring), None where it is not: where its stored values (kept temporaries and kept input
        rows) are at least MIN_STORED and STORED_PER_ENTRY per output entry."""
        stored = len(self.kept(prog)) + sum(len(v) for v in self.kept_inputs(prog).values())
        entries = sum(r * c for _, (r, c) in prog.outputs)
        if stored < MIN_STORED or stored < STORED_PER_ENTRY * entries:
            return None
        return BLOCK

    def body(self, prog) -> list[tuple[str, str]]:
        keep = self.kept(prog)
        return [(self.temporary(k), f"_keep({self.rhs(ins)}, one)" if k in keep else self.rhs(ins))
                for k, ins in enumerate(prog.body)]

    def entries(self, prog, output: int, size: int) -> list[str]:
        """The operands of one output, row-major (every entry is listed: outputs are dense)."""
        out = [self.const(0.0)] * size
        for oi, idx, a in prog.results:
            if oi == output:
                out[idx] = self.operand(a)
        return out
