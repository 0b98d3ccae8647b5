"""The backend contract: what a new output language provides.

A backend is one folder ``derive/codegen/backends/<name>/`` whose ``__init__.py`` defines
``BACKEND``, an instance of a :class:`Backend` subclass, plus one line in
:data:`derive.codegen.backends.REGISTRY`. It holds:

- a printer (:class:`ExpressionPrinter` subclass): SSA instructions -> (lhs, rhs) strings;
- its templates and verbatim support files, in ``template_dir`` (by default the shipped
  ``templates/<name>/``; a backend may keep them in its own folder);
- :meth:`Backend.function_context` / :meth:`Backend.template_context`: plain data for
  one function's templates, and :meth:`Backend.render`: the robot's files in this language;
- :meth:`Backend.manifest_entry`: what manifest.json says of one function in this language.

Backends never see mechanics: they get specs, SSA programs and plain data.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import jinja2

from derive.codegen.program import Instr, Program
from derive.codegen.spec import FunctionSpec, TemplateFunction
from derive.resources import TEMPLATES


def float_literal(x: float) -> str:
    """Shortest round-trip decimal of ``x`` that reads as a float in C and Python (``1.0``, ``2.5e-05``)."""
    text = repr(float(x))
    if "e" not in text and "." not in text and "inf" not in text and "nan" not in text:
        text += ".0"
    return text


def shape_text(shape: tuple[int, int]) -> str:
    r, c = shape
    return f"{r}" if c == 1 else f"{r}x{c}"


def ops_comment(ops: dict[str, int]) -> str:
    extra = f", {ops['other']} other" if ops["other"] else ""
    return f"{ops['total']} ops: {ops['mul']} mul, {ops['add']} add, {ops['div']} div, {ops['trig']} trig{extra}"


class ExpressionPrinter:
    """Straight-line SSA code as (lhs, rhs) statement pairs; subclasses spell functions and constants."""

    FUNCS: dict[str, str] = {}     # unary op -> function name
    BINFUNCS: dict[str, str] = {}  # binary op -> function name
    ONE = "1.0"

    def __init__(self, input_names: list[str]):
        self.input_names = input_names

    def temporary(self, k: int) -> str:
        return f"t{k}"

    def element(self, array: str, index: int) -> str:
        return f"{array}[{index}]"

    def operand(self, a: tuple) -> str:
        if a[0] == "t":
            return self.temporary(a[1])
        if a[0] == "in":
            return self.element(self.input_names[a[1]], a[2])
        return self.const(a[1])

    def const(self, x: float) -> str:
        raise NotImplementedError

    def rhs(self, ins: Instr) -> str:
        a = [self.operand(x) for x in ins.args]
        op = ins.op
        if op == "add":
            return f"{a[0]} + {a[1]}"
        if op == "sub":
            return f"{a[0]} - {a[1]}"
        if op == "mul":
            return f"{a[0]} * {a[1]}"
        if op == "div":
            return f"{a[0]} / {a[1]}"
        if op == "neg":
            return f"-{a[0]}"
        if op == "sq":
            return f"{a[0]} * {a[0]}"
        if op == "twice":
            return f"{a[0]} + {a[0]}"
        if op == "inv":
            return f"{self.ONE} / {a[0]}"
        if op in self.FUNCS:
            return f"{self.FUNCS[op]}({a[0]})"
        if op in self.BINFUNCS:
            return f"{self.BINFUNCS[op]}({a[0]}, {a[1]})"
        raise NotImplementedError(op)

    def body(self, prog: Program) -> list[tuple[str, str]]:
        return [(self.temporary(k), self.rhs(ins)) for k, ins in enumerate(prog.body)]

    def stores(self, prog: Program, output_names: list[str]) -> list[tuple[str, str]]:
        return [(self.element(output_names[oi], idx), self.operand(a)) for oi, idx, a in prog.results]


@dataclass
class Function:
    """One generated function on its way through the backends: its spec, and for an expression
    function its SSA program; ``common`` is the language-free plain data every template sees."""

    spec: FunctionSpec | TemplateFunction
    program: Program | None
    common: dict = field(default_factory=dict)


@dataclass
class RobotContext:
    """Language-free plain data of one robot for the templates."""

    robot: str
    model_hash: str
    joints: list[str]
    nq: int
    nv: int
    parameters: list[tuple[str, float]]
    left_out: tuple[str, ...] = ()  # short names of the usual functions not generated (M(q) singular), and why
    left_out_reason: str = ""
    aliases: tuple[tuple[str, str], ...] = ()  # (alias, function) short names: a frame's other name, same function

    def data(self) -> dict:
        return {"robot": self.robot, "model_hash": self.model_hash, "joints": self.joints, "nq": self.nq,
                "nv": self.nv, "np": len(self.parameters),
                "parameters": [(n, float_literal(v)) for n, v in self.parameters],
                "left_out": list(self.left_out), "left_out_reason": self.left_out_reason,
                "aliases": list(self.aliases)}


class Backend:
    """One output language. Subclasses set ``name`` and implement the four hooks below."""

    name: str = ""
    template_dir: Path | None = None  # None: the shipped templates/<name>/

    @property
    def templates(self) -> Path:
        return Path(self.template_dir) if self.template_dir else TEMPLATES / self.name

    def template(self, relative: str) -> str:
        """A template's name in the shared environment: ``<backend>/<relative>``."""
        return f"{self.name}/{relative}"

    def has_template(self, relative: str) -> bool:
        return (self.templates / relative).is_file()

    def support_text(self, file: str) -> str:
        """A support file's text, to be copied verbatim (its final newline is the template's)."""
        return (self.templates / "support" / file).read_text().rstrip("\n")

    def support_source(self, file: str) -> str:
        """How generated files name a support file's origin."""
        return f"templates/{self.name}/support/{file}"

    def literals(self, context, scalar, element) -> dict:
        """A template function's plain-data context with its floats spelled for this language:
        ``scalar(x)`` for a float, ``element(x)`` for each entry of a tuple of floats."""
        out = {}
        for key, value in context:
            if isinstance(value, float):
                value = scalar(value)
            elif isinstance(value, tuple) and value and all(isinstance(v, float) for v in value):
                value = tuple(element(v) for v in value)
            out[key] = value
        return out

    def function_context(self, fn: Function) -> dict:
        raise NotImplementedError

    def template_context(self, fn: Function) -> dict:
        raise NotImplementedError

    def render(self, env: jinja2.Environment, robot: RobotContext, functions: list[dict]) -> dict[str, str]:
        """{path relative to generated/<robot>/: text} of this language."""
        raise NotImplementedError

    def manifest_entry(self, robot: RobotContext, f: dict) -> dict:
        raise NotImplementedError

    def manifest_support(self, robot: RobotContext, functions: list[dict]) -> list[dict]:
        return []
