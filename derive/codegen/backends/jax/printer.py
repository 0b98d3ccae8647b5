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
shared temporary makes one kernel per temporary (kernel overhead); only those whose inlined tree
(up to already-kept values) has at least ``KEEP_COST`` operations are kept, the rest XLA inlines.
"""

from __future__ import annotations

from derive.codegen.backends.base import ExpressionPrinter, float_literal

KEEP_COST = 16
"""A shared temporary whose inlined tree has at least this many operations is kept (computed once):
panda, jit(vmap) on the CPU at 10 000 states, one run: ode_jac_x 9.4 us per state at 16, 12.6 at 10,
22.6 at 24 (NumPy batch 7.4); at 48 mass_matrix and forward_dynamics are 5x slower than at 16."""

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
        (outputs included) whose inlined tree reaches KEEP_COST operations."""
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
            if uses[k] >= 2 and cost[k] >= KEEP_COST:
                keep.add(k)
                cost[k] = 0
        return keep

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
