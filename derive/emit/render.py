"""Specs -> files: C99 sources and headers, a Python module, a manifest.

Emitting is a pure function of the spec list: each spec becomes a Program
(CasADi CSE, SSA temporaries), printers turn it into (lhs, rhs) pairs, and
jinja2 templates lay them out. Nothing here knows mechanics. Algorithms that are not one
expression graph (IK's solver, the singular values) are fixed support files under
templates/c/support/ and templates/python/support/, copied verbatim into each robot's
output (listed under "support" in its manifest.json); templates only lay out the calls.
"""

from __future__ import annotations

import json
from pathlib import Path

import jinja2

from ..graph import Program, build_program
from ..model import Robot
from ..spec import FunctionSpec, TemplateFunction
from .printers import CPrinter, PythonPrinter, _float_literal

TEMPLATES = Path(__file__).resolve().parent.parent.parent / "templates"
SUPPORT = {"c": "c/support", "python": "python/support"}  # fixed, robot-independent sources, copied verbatim
MATH_FUNCTIONS = [("SIN", "sin"), ("COS", "cos"), ("TAN", "tan"), ("SQRT", "sqrt"), ("EXP", "exp"),
                  ("LOG", "log"), ("FABS", "fabs"), ("ASIN", "asin"), ("ACOS", "acos"), ("ATAN", "atan"),
                  ("TANH", "tanh"), ("POW", "pow"), ("ATAN2", "atan2"), ("FMIN", "fmin"), ("FMAX", "fmax")]


def environment() -> jinja2.Environment:
    return jinja2.Environment(
        loader=jinja2.FileSystemLoader(str(TEMPLATES)),
        undefined=jinja2.StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
        keep_trailing_newline=True,
        autoescape=False,
    )


def _shape_text(shape: tuple[int, int]) -> str:
    r, c = shape
    return f"{r}" if c == 1 else f"{r}x{c}"


def ops_comment(ops: dict[str, int]) -> str:
    extra = f", {ops['other']} other" if ops["other"] else ""
    return f"{ops['total']} ops: {ops['mul']} mul, {ops['add']} add, {ops['div']} div, {ops['trig']} trig{extra}"


def function_context(spec: FunctionSpec, prog: Program) -> dict:
    """Plain data for the templates of one function."""
    in_names = [n for n, _ in spec.inputs]
    out_names = [n for n, _ in spec.outputs]
    used = {a[1] for ins in prog.body for a in ins.args if a[0] == "in"}
    used |= {a[1] for _, _, a in prog.results if a[0] == "in"}
    cp, pp = CPrinter(in_names), PythonPrinter(in_names)
    io_lines = [f"in  {n} [{_shape_text(x.shape)}]" for n, x in spec.inputs]
    io_lines += [f"out {n} [{_shape_text(e.shape)}]" for n, e in spec.outputs]
    ops = prog.ops()
    py_outputs = [(n, e.shape[0] * e.shape[1], e.shape) for n, e in spec.outputs]
    returns = [f"{n}.reshape({r}, {c})" if c > 1 else n for n, _, (r, c) in py_outputs]
    return {
        "name": spec.name,
        "short_name": spec.short_name,
        "quantity": spec.quantity,
        "frame": spec.frame,
        "doc_lines": [spec.doc],
        "io_lines": io_lines,
        "ops": ops,
        "ops_comment": ops_comment(ops),
        "header": f"{spec.name}.h",
        "source": f"{spec.name}.c",
        "args": [f"const DERIVE_REAL *{n}" for n in in_names] + [f"DERIVE_REAL *{n}" for n in out_names],
        "unused": [n for i, n in enumerate(in_names) if i not in used],
        "body": cp.body(prog),
        "stores": cp.stores(prog, out_names),
        "py_args": [n if n != "p" else "p=DEFAULT_P" for n in in_names],
        "py_template": None,
        "py_inputs": [(n, x.shape[0]) for n, x in spec.inputs if x.shape[0] > 0],
        "py_body": pp.body(prog),
        "py_outputs": py_outputs,
        "py_stores": pp.stores(prog, out_names),
        "py_return": ", ".join(returns),
        "inputs": [{"name": n, "shape": list(x.shape)} for n, x in spec.inputs],
        "outputs": [{"name": n, "shape": list(e.shape)} for n, e in spec.outputs],
    }


def template_context(t: TemplateFunction) -> dict:
    """Plain data for a template-bodied function (see spec.TemplateFunction)."""
    in_names = [n for n, _ in t.inputs]
    out_names = [n for n, _ in t.outputs]
    io_lines = [f"in  {n} [{_shape_text(s)}]" for n, s in t.inputs] + [f"out {n} [{_shape_text(s)}]" for n, s in t.outputs]
    return {
        "name": t.name, "short_name": t.short_name, "quantity": t.quantity, "frame": t.frame,
        "doc_lines": [t.doc], "io_lines": io_lines, "ops": None,
        "ops_comment": f"cost: the arithmetic of {', '.join(t.calls)} per call, plus loops" if t.calls else "cost: loops",
        "header": f"{t.name}.h", "source": f"{t.name}.c",
        "args": [f"const DERIVE_REAL *{n}" for n in in_names] + [f"DERIVE_REAL *{n}" for n in out_names],
        "call_headers": [f"{c}.h" for c in t.calls], "calls": list(t.calls),
        "p_arg": ", p" if "p" in in_names else "", "has_p": "p" in in_names,
        "support_headers": list(t.c_support), "py_support": list(t.py_support),
        "py_args": [n if n != "p" else "p=DEFAULT_P" for n in in_names],
        "c_template": t.c_template, "py_template": t.py_template,
        "inputs": [{"name": n, "shape": list(s)} for n, s in t.inputs],
        "outputs": [{"name": n, "shape": list(s)} for n, s in t.outputs],
        **dict(t.context),
    }


def _support_text(language: str, name: str) -> str:
    """A support file's text, to be copied verbatim (its final newline is the template's)."""
    return (TEMPLATES / SUPPORT[language] / name).read_text().rstrip("\n")


def render_robot(robot: Robot, specs: list[FunctionSpec], model_hash: str, progress=None,
                 templates: list[TemplateFunction] = ()) -> dict[str, str]:
    """All files of one robot, as {path relative to generated/<robot>/: text}."""
    env = environment()
    files: dict[str, str] = {}
    functions = []
    for spec in specs:
        prog = build_program(list(spec.inputs), list(spec.outputs))
        functions.append(function_context(spec, prog))
        if progress:
            progress(spec, prog)
    functions += [template_context(t) for t in templates]
    joints = [c.name for c in robot.coordinates]  # one per entry of q
    params = [(p.name, _float_literal(p.default)) for p in robot.parameters]
    base = {"robot": robot.name, "model_hash": model_hash, "joints": joints, "nq": robot.nq, "nv": robot.nv,
            "np": len(params), "parameters": params, "prefix": robot.name.upper()}
    files["c/derive_real.h"] = env.get_template("c/derive_real.h.jinja").render(functions=MATH_FUNCTIONS)
    c_support = sorted({name for f in functions for name in f.get("support_headers", ())})
    py_support = [{"source": f"templates/{SUPPORT['python']}/{name}", "text": _support_text("python", name)}
                  for name in sorted({name for f in functions for name in f.get("py_support", ())})]
    for name in c_support:
        files[f"c/{name}"] = env.get_template("c/support.jinja").render(
            source=f"templates/{SUPPORT['c']}/{name}", text=_support_text("c", name))
    for f in functions:
        guard = f"{f['name'].upper()}_H"
        files[f"c/{f['header']}"] = env.get_template(f.get("h_template") or "c/function.h.jinja").render(
            base, f=f, guard=guard)
        files[f"c/{f['source']}"] = env.get_template(f.get("c_template") or "c/function.c.jinja").render(base, f=f)
    files[f"c/{robot.name}.h"] = env.get_template("c/robot.h.jinja").render(
        base, guard=f"{robot.name.upper()}_DERIVE_H", headers=[f["header"] for f in functions])
    files[f"python/{robot.name}.py"] = env.get_template("python/module.py.jinja").render(
        base, functions=functions, support=py_support)
    manifest = {
        "robot": robot.name,
        "model_hash": model_hash,
        "nq": robot.nq,
        "nv": robot.nv,
        "joints": [{"name": j.name, "type": j.type, "lower": j.limits.lower, "upper": j.limits.upper,
                    "velocity": j.limits.velocity, "effort": j.limits.effort} for j in robot.coordinates],
        "frames": [fr.name for fr in robot.frames],
        "parameters": [{"name": p.name, "default": p.default} for p in robot.parameters],
        "support": [{"file": f"c/{name}", "source": f"templates/{SUPPORT['c']}/{name}"} for name in c_support]
        + [{"file": f"python/{robot.name}.py", "source": section["source"]} for section in py_support],
        "functions": [{
            "name": f["name"], "quantity": f["quantity"], "frame": f["frame"],
            "inputs": f["inputs"], "outputs": f["outputs"],
            "c": {"header": f"c/{f['header']}", "source": f"c/{f['source']}"},
            "python": {"module": f"python/{robot.name}.py", "function": f["short_name"]},
            "ops": {k: f["ops"][k] for k in ("total", "mul", "add", "div", "trig")} if f["ops"] else None,
            "calls": f.get("calls", []),
            **dict(f.get("manifest", ())),  # a template function's own plain-data facts (e.g. task_rows)
        } for f in functions],
    }
    files["manifest.json"] = env.get_template("manifest/manifest.json.jinja").render(
        manifest_json=json.dumps(manifest, indent=2))
    return files
