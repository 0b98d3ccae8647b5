"""The JAX backend: one module ``jax/<robot>.py`` per robot, pure ``jax.numpy``.

The functions are those of the Python backend, with the same short names and argument order
(``p=DEFAULT_P`` last where the robot has parameters), written on arrays of any leading batch
shape: an input of n elements is an array (..., n), an output of shape s comes back as
(..., *s), the batch shapes of the inputs broadcast, and one 1-D state returns exactly the shapes
of the numpy module. Every body is straight-line jnp code on rows (element ``q_[i]`` of the input
moved to the batch-last layout, jnp ufuncs, one ``jnp.stack`` per output; shared temporaries that
XLA would recompute, and input elements read often, marked computed-once, see :mod:`.printer`), so ``jax.jit``, ``jax.vmap`` and
``jax.grad`` apply to them. Large ones are decorated ``@_blocks(block, sizes)``: on the CPU a batch of
more than ``block`` states is evaluated in blocks (``jax.lax.map``), under ``jax.vmap`` too.
Importing the module changes no JAX setting: the functions compute in JAX's default float type,
float64 where the user has turned on ``jax_enable_x64`` (a jit call converts float64 arguments to
float32 on entry otherwise, so a float64 scope inside the function could not keep the caller's
precision).

Template-bodied functions are provided where ``templates/jax/<template>.py.jinja`` exists
(``rk4_step``, ``manipulability_<frame>``, the ODE Jacobians of large robots). IK is not: its Levenberg-Marquardt is a data-dependent
loop with early exits, seeded restarts and a status code, which does not trace into one jit-able
or differentiable graph without a different algorithm (fixed iteration count, ``lax.while_loop``),
so it would be a second IK with its own results rather than a translation of the first. Such a
function is listed as not provided in the module's docstring, and its manifest entry is null.
Generation writes text only: jax is not needed to generate.
"""

from __future__ import annotations

import jinja2

from derive.codegen.backends.base import Backend, Function, RobotContext, float_literal
from derive.codegen.backends.jax.printer import JaxPrinter

SUPPORT = {"manipulability": ("manipulability.py",), "ltdl": ("ltdl.py",)}
"""Fixed algorithms -> the sections (templates/jax/support/) inserted verbatim into the module."""


def _args(spec) -> list[str]:
    return ["p=DEFAULT_P" if n == "p" else n for n, _ in spec.inputs]


def returns(outputs) -> list[dict]:
    """What a JAX function returns per state, in order, as the Python entry says it: shape (r,) for
    an r x 1 output and (r, c) otherwise (a batch of inputs puts its shape in front). One entry:
    the value itself; more: a tuple of them."""
    return [{"name": n, "shape": [r] if c == 1 else [r, c]} for n, (r, c) in outputs]


class JaxBackend(Backend):
    name = "jax"

    def function_context(self, fn: Function) -> dict:
        spec, prog = fn.spec, fn.program
        printer = JaxPrinter([n for n, _ in spec.inputs])
        outputs = []
        for k, (n, e) in enumerate(spec.outputs):
            r, c = e.shape
            outputs.append({"name": n, "entries": printer.entries(prog, k, r * c),
                            "shape": f"({r}, {c})" if c > 1 else None})
        inputs = [(n, x.shape[0] * x.shape[1]) for n, x in spec.inputs if x.numel() > 0]
        block = printer.block(prog) if len(inputs) == len(spec.inputs) else None  # every argument an input row
        return {**fn.common, "jax_provided": True, "jax_template": None, "jax_args": _args(spec),
                "jax_inputs": inputs, "jax_block": block,
                "jax_body": printer.body(prog), "jax_outputs": outputs,
                "jax_kept_inputs": [(n, repr(kept)) for n, kept in printer.kept_inputs(prog).items()],
                "jax_returns": returns([(n, e.shape) for n, e in spec.outputs])}

    def template_context(self, fn: Function) -> dict:
        t = fn.spec
        template = f"{t.template}.py.jinja"
        provided = self.has_template(template) and all(a in SUPPORT for a in t.support) and not t.status
        context = self.literals(t.context, float_literal, float_literal)
        return {**fn.common, **context, **dict(t.calls), "jax_provided": provided,
                "jax_template": self.template(template) if provided else None, "jax_block": None, "jax_args": _args(t),
                "jax_support": [s for algorithm in t.support for s in SUPPORT.get(algorithm, ())] if provided else [],
                "jax_returns": returns(t.outputs),
                "p_arg": ", p" if "p" in [n for n, _ in t.inputs] else ""}

    def sections(self, functions: list[dict]) -> list[dict]:
        names = sorted({name for f in functions for name in f.get("jax_support", ())})
        return [{"source": self.support_source(name), "text": self.support_text(name)} for name in names]

    def render(self, env: jinja2.Environment, robot: RobotContext, functions: list[dict]) -> dict[str, str]:
        text = env.get_template(self.template("module.py.jinja")).render(
            robot.data(), functions=functions, support=self.sections(functions),
            missing=[f["short_name"] for f in functions if not f["jax_provided"]],
            jax_aliases=[(a, n) for a, n in robot.aliases if n in {f["short_name"] for f in functions if f["jax_provided"]}])
        return {f"jax/{robot.robot}.py": text}

    def manifest_entry(self, robot: RobotContext, f: dict) -> dict | None:
        """The module, the function and what it returns per state (see :func:`returns`); None where
        this flavour does not provide the function (IK)."""
        if not f["jax_provided"]:
            return None
        return {"module": f"jax/{robot.robot}.py", "function": f["short_name"], "returns": f["jax_returns"]}

    def manifest_support(self, robot: RobotContext, functions: list[dict]) -> list[dict]:
        return [{"file": f"jax/{robot.robot}.py", "source": s["source"]} for s in self.sections(functions)]


BACKEND = JaxBackend()
