"""JAX printer: jax.numpy on arrays of any leading batch shape, one state per index of the last axis.

An input element is ``q[..., i]`` (an array of the batch shape), functions are the jnp ufuncs, so
every temporary broadcasts over the batch and the whole body is traceable by jit, vmap and grad.
"""

from __future__ import annotations

from derive.codegen.backends.base import ExpressionPrinter, float_literal


class JaxPrinter(ExpressionPrinter):
    FUNCS = {"sin": "jnp.sin", "cos": "jnp.cos", "tan": "jnp.tan", "sqrt": "jnp.sqrt", "exp": "jnp.exp",
             "log": "jnp.log", "fabs": "jnp.abs", "asin": "jnp.arcsin", "acos": "jnp.arccos", "atan": "jnp.arctan",
             "tanh": "jnp.tanh", "sign": "jnp.sign"}
    BINFUNCS = {"pow": "jnp.power", "atan2": "jnp.arctan2", "fmin": "jnp.minimum", "fmax": "jnp.maximum"}

    def element(self, array: str, index: int) -> str:
        return f"{array}[..., {index}]"

    def const(self, x: float) -> str:
        return float_literal(x) if x >= 0 else f"({float_literal(x)})"

    def entries(self, prog, output: int, size: int) -> list[str]:
        """The operands of one output, row-major (every entry is listed: outputs are dense)."""
        out = [self.const(0.0)] * size
        for oi, idx, a in prog.results:
            if oi == output:
                out[idx] = self.operand(a)
        return out
