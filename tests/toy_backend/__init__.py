"""A toy backend: a second Python flavour with plain lists and the math module, no numpy.

It exists to show (tests/test_generate.py) that a new output language is this one folder
(the backend, its printer choice and its templates) plus one line in
``derive.codegen.backends.REGISTRY``; nothing else of derive changes. Template-bodied
functions (IK, RK4, manipulability) are left out of this flavour and listed as such.
"""

from __future__ import annotations

from pathlib import Path

import jinja2

from derive.codegen.backends.base import Backend, Function, RobotContext
from derive.codegen.backends.python.printer import PythonPrinter


class ListBackend(Backend):
    name = "pylist"
    template_dir = Path(__file__).resolve().parent / "templates"

    def function_context(self, fn: Function) -> dict:
        spec, prog = fn.spec, fn.program
        printer = PythonPrinter([n for n, _ in spec.inputs])
        return {**fn.common, "expression": True,
                "args": ["p=DEFAULT_P" if n == "p" else n for n, _ in spec.inputs],
                "sizes": [(n, e.shape[0] * e.shape[1]) for n, e in spec.outputs],
                "body": printer.body(prog), "stores": printer.stores(prog, [n for n, _ in spec.outputs])}

    def template_context(self, fn: Function) -> dict:
        return {**fn.common, "expression": False}

    def render(self, env: jinja2.Environment, robot: RobotContext, functions: list[dict]) -> dict[str, str]:
        text = env.get_template(self.template("module.py.jinja")).render(robot.data(), functions=functions)
        return {f"pylist/{robot.robot}.py": text}

    def manifest_entry(self, robot: RobotContext, f: dict) -> dict | None:
        return {"module": f"pylist/{robot.robot}.py", "function": f["short_name"]} if f["expression"] else None


BACKEND = ListBackend()
