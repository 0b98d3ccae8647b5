"""The Python backend: one module ``python/<robot>.py`` per robot, numpy only.

Functions are named ``<quantity>[_<frame>]`` (no robot prefix: the module is the
namespace) and take the same inputs as the C functions; robots with parameters take
``p=DEFAULT_P``. Templates and support sections: ``templates/python/``.
"""

from __future__ import annotations

import jinja2

from derive.codegen.backends.base import Backend, Function, RobotContext, float_literal
from derive.codegen.backends.python.printer import PythonPrinter

SUPPORT = {"ik": ("ik.py",), "manipulability": ("manipulability.py",)}
"""Fixed algorithms -> the sections (templates/python/support/) inserted verbatim into the module."""


def _args(spec, optional=()) -> list[str]:
    return [("p=DEFAULT_P" if n == "p" else f"{n}=None" if n in optional else n) for n, _ in spec.inputs]


class PythonBackend(Backend):
    name = "python"

    def function_context(self, fn: Function) -> dict:
        spec, prog = fn.spec, fn.program
        in_names, out_names = [n for n, _ in spec.inputs], [n for n, _ in spec.outputs]
        printer = PythonPrinter(in_names)
        outputs = [(n, e.shape[0] * e.shape[1], e.shape) for n, e in spec.outputs]
        return {**fn.common, "py_args": _args(spec), "py_template": None,
                "py_inputs": [(n, x.shape[0]) for n, x in spec.inputs if x.shape[0] > 0],
                "py_body": printer.body(prog), "py_outputs": outputs, "py_stores": printer.stores(prog, out_names),
                "py_return": ", ".join(f"{n}.reshape({r}, {c})" if c > 1 else n for n, _, (r, c) in outputs)}

    def template_context(self, fn: Function) -> dict:
        t = fn.spec
        context = self.literals(t.context, float_literal, float_literal)
        return {**fn.common, **context, **dict(t.calls), "py_args": _args(t, t.optional),
                "py_template": self.template(f"{t.template}.py.jinja"),
                "py_support": [s for algorithm in t.support for s in SUPPORT[algorithm]],
                "p_arg": ", p" if "p" in [n for n, _ in t.inputs] else ""}

    def sections(self, functions: list[dict]) -> list[dict]:
        names = sorted({name for f in functions for name in f.get("py_support", ())})
        return [{"source": self.support_source(name), "text": self.support_text(name)} for name in names]

    def render(self, env: jinja2.Environment, robot: RobotContext, functions: list[dict]) -> dict[str, str]:
        text = env.get_template(self.template("module.py.jinja")).render(
            robot.data(), functions=functions, support=self.sections(functions))
        return {f"python/{robot.robot}.py": text}

    def manifest_entry(self, robot: RobotContext, f: dict) -> dict:
        return {"module": f"python/{robot.robot}.py", "function": f["short_name"]}

    def manifest_support(self, robot: RobotContext, functions: list[dict]) -> list[dict]:
        return [{"file": f"python/{robot.robot}.py", "source": s["source"]} for s in self.sections(functions)]


BACKEND = PythonBackend()
