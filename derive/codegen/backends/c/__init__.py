"""The C99 backend: one ``.c`` and ``.h`` per function, ``derive_real.h``, an umbrella header,
and the drop-in build files (``CMakeLists.txt``, ``<robot>.mk``, ``example/main.c``).

No malloc, no globals, only ``<math.h>``; ``DERIVE_REAL`` is double, or float with
``-DDERIVE_FLOAT``. Functions are ``<robot>_<quantity>[_<frame>]`` taking inputs, then
outputs, as row-major arrays. Templates and support headers: ``templates/c/``.
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import re

import jinja2

from derive.codegen.backends.base import Backend, Function, RobotContext, float_literal
from derive.codegen.backends.c import printer as c_printer
from derive.codegen.backends.c.printer import CPrinter, literal
from derive.codegen.program import Program

MATH_FUNCTIONS = [("SIN", "sin"), ("COS", "cos"), ("TAN", "tan"), ("SQRT", "sqrt"), ("EXP", "exp"),
                  ("LOG", "log"), ("FABS", "fabs"), ("ASIN", "asin"), ("ACOS", "acos"), ("ATAN", "atan"),
                  ("TANH", "tanh"), ("POW", "pow"), ("ATAN2", "atan2"), ("FMIN", "fmin"), ("FMAX", "fmax")]
SUPPORT = {"ik": ("derive_linalg.h", "derive_ik.h"), "manipulability": ("derive_linalg.h", "derive_manipulability.h"),
           "ltdl": ("derive_ltdl.h",)}
"""Fixed algorithms -> the header-only support files (templates/c/support/) that implement them."""

LANES_HEADER = "derive_lanes.h"
"""The lane mode's header (templates/c/support/), written for every robot: with -DDERIVE_LANES=4 it
makes DERIVE_REAL a vector of 4 doubles, so the same .c files evaluate 4 states per call. No
generated file includes it (the firmware's translation units and their hashes stay as they were)."""

LANE_TEMPLATES = ("rk4_step", "ode_jac_x", "ode_jac_u")
"""Template functions that run lane-wise: their loops count array indices and nothing branches on
a real (rk4_step's stages, the LTDL factor and solve). ik and manipulability test reals (convergence,
the singular values) and stay scalar-only."""

HEADER_NOTES = {
    "manipulability": (
        "-ffast-math / -Ofast / -ffinite-math-only: the compiler may then assume that no value is",
        "infinite, so at a singularity mu1 and mu2 (+inf by IEEE division here) are unspecified; test",
        "mu3 (finite, near 0 at a singularity) against a threshold instead."),
}
"""Notes for the header comment of template functions, by template: what -ffast-math changes.
(ik_<frame> states its own in ik.h.jinja: its non-finite checks read bits, which fast-math keeps.)"""

BUILD_FILES = (("CMakeLists.txt", "CMakeLists.txt.jinja"), ("{robot}.mk", "robot.mk.jinja"),
               ("example/main.c", "example_main.c.jinja"))
"""Drop-in build files under c/: (path, template): a CMake static library, a Makefile fragment and an
example control loop that uses them."""

EXAMPLE_SIGNATURES = {"mass_matrix": ["q"], "inverse_dynamics": ["q", "qd", "qdd"],
                      "forward_dynamics": ["q", "qd", "tau"], "rk4_step": ["x", "u", "dt"]}
"""The inputs (before p) of the functions example/main.c calls, as its template spells the calls."""

INCLUDE = re.compile(r'^#include "([^"]+)"', re.MULTILINE)


class CBackend(Backend):
    name = "c"

    def _signature(self, spec) -> list[str]:
        return ([f"const DERIVE_REAL *{n}" for n, _ in spec.inputs] + [f"DERIVE_REAL *{n}" for n, _ in spec.outputs])

    def _files(self, spec) -> dict:
        return {"header": f"{spec.name}.h", "source": f"{spec.name}.c", "args": self._signature(spec)}

    @staticmethod
    def _arrays(items, nullable=()) -> list[dict]:
        """The arrays of a signature in order: name, length in reals, row-major; NULL-able inputs say so."""
        return [{"name": n, "length": r * c, "layout": "row-major", **({"nullable": True} if n in nullable else {})}
                for n, (r, c) in items]

    def _contract(self, inputs, outputs, status: bool = False, nullable=()) -> dict:
        return {"c_returns": "int" if status else "void", "c_reads": self._arrays(inputs, nullable),
                "c_writes": self._arrays(outputs)}

    def function_context(self, fn: Function) -> dict:
        spec, prog = fn.spec, fn.program
        in_names = [n for n, _ in spec.inputs]
        used = {a[1] for ins in prog.body for a in ins.args if a[0] == "in"}
        used |= {a[1] for _, _, a in prog.results if a[0] == "in"}
        printer = CPrinter(in_names)
        out_names = [n for n, _ in spec.outputs]
        context = {**fn.common, **self._files(spec),
                   **self._contract([(n, x.shape) for n, x in spec.inputs], [(n, e.shape) for n, e in spec.outputs]),
                   "unused": [n for i, n in enumerate(in_names) if i not in used], "header_notes": []}
        if len(prog.body) + len(prog.results) <= c_printer.SPLIT_ABOVE:
            body, stores = printer.body(prog), printer.stores(prog, out_names)
            return {**context, "parts": None, "body": body, "work": printer.declarations(), "stores": stores,
                    "lanes": lane_wise(body + stores)}
        fills, prog = zero_fills(prog, [math.prod(e.shape) for _, e in spec.outputs])
        parts = printer.split(prog, out_names)
        for k, part in enumerate(parts):
            part["name"] = f"{spec.name}_part{k}"
            part["unused"] = ([n for i, n in enumerate(in_names) if i not in part["reads"]]
                              + [n for n in out_names if n not in part["writes"]] + ([] if part["uses_slots"] else ["W"]))
        return {**context, "parts": parts, "slots": max(1, printer.slots), "part_size": printer.part_size,
                "lanes": lane_wise([line for part in parts for line in part["body"] + part["stores"]]),
                "fills": [(out_names[oi], size) for oi, size in fills], "computing": printer.computing,
                "part_args": self._signature(spec) + ["DERIVE_REAL *W"], "call_args": in_names + out_names + ["W"]}

    def template_context(self, fn: Function) -> dict:
        t = fn.spec
        context = self.literals(t.context, float_literal, literal)
        calls = {role: f"{t.robot}_{short}" for role, short in t.calls}
        in_names = [n for n, _ in t.inputs]
        header = f"{t.template}.h.jinja"
        return {**fn.common, **self._files(t), **context, **calls,
                **self._contract(t.inputs, t.outputs, t.status, t.optional),
                "macro": t.name.upper(), "c_return": "int" if t.status else "void",
                "header_notes": list(HEADER_NOTES.get(t.template, ())),
                "c_template": self.template(f"{t.template}.c.jinja"),
                "h_template": self.template(header) if self.has_template(header) else self.template("function.h.jinja"),
                "call_headers": [f"{t.robot}_{short}.h" for short in t.callees],
                "support_headers": [h for algorithm in t.support for h in SUPPORT[algorithm]],
                "p_arg": ", p" if "p" in in_names else "", "has_p": "p" in in_names,
                "lanes": t.template in LANE_TEMPLATES}

    def render(self, env: jinja2.Environment, robot: RobotContext, functions: list[dict]) -> dict[str, str]:
        base = {**robot.data(), "prefix": robot.robot.upper()}
        files = {"c/derive_real.h": env.get_template(self.template("derive_real.h.jinja")).render(functions=MATH_FUNCTIONS)}
        for name in self.support_files(functions) + [LANES_HEADER]:
            files[f"c/{name}"] = env.get_template(self.template("support.jinja")).render(
                source=self.support_source(name), text=self.support_text(name))
        for f in functions:
            guard = f"{f['name'].upper()}_H"
            files[f"c/{f['header']}"] = env.get_template(f.get("h_template") or self.template("function.h.jinja")).render(
                base, f=f, guard=guard)
            files[f"c/{f['source']}"] = env.get_template(f.get("c_template") or self.template("function.c.jinja")).render(
                base, f=f)
        files[f"c/{robot.robot}.h"] = env.get_template(self.template("robot.h.jinja")).render(
            base, guard=f"{robot.robot.upper()}_DERIVE_H", headers=[f["header"] for f in functions])
        if not self.complete(functions):  # a partial set (the zoo bench's ID, M and FD): no build files
            return files
        build = self.build_context(robot, functions)
        for path, template in BUILD_FILES:
            files[f"c/{path.format(robot=robot.robot)}"] = env.get_template(self.template(template)).render(base, **build)
        return files

    @staticmethod
    def complete(functions: list[dict]) -> bool:
        """Whether ``functions`` hold every function example/main.c calls (a robot's whole set does)."""
        present = {f["quantity"] for f in functions if f["frame"] is None}
        return all(quantity in present for quantity in EXAMPLE_SIGNATURES)

    @staticmethod
    def build_context(robot: RobotContext, functions: list[dict]) -> dict:
        """What the build files and the example need: the sources, and how the example's calls are spelled."""
        by_quantity = {f["quantity"]: f for f in functions if f["frame"] is None}
        has_p = bool(robot.parameters)
        for quantity, inputs in EXAMPLE_SIGNATURES.items():
            got = [a["name"] for a in by_quantity[quantity]["c_reads"]]
            if got != inputs + (["p"] if has_p else []):  # the template's calls would not compile
                raise AssertionError(f"example/main.c calls {quantity}({', '.join(inputs)}), the C has {got}")
        return {"sources": sorted(f["source"] for f in functions), "has_p": has_p, "p_arg": ", p" if has_p else "",
                "quaternion": by_quantity["rk4_step"]["quaternion"]}

    @staticmethod
    def support_files(functions: list[dict]) -> list[str]:
        return sorted({name for f in functions for name in f.get("support_headers", ())})

    def manifest_entry(self, robot: RobotContext, f: dict) -> dict:
        """Header, source and the call's contract: ``returns`` ("void", or "int" for a status code),
        ``reads`` (the inputs) and ``writes`` (the outputs), each array in signature order with its
        length in DERIVE_REALs, row-major (``nullable``: the caller may pass NULL); ``form``: "whole"
        (one straight-line function), "split" (``parts`` static functions, ``zero_filled``: the outputs
        whose zero entries one loop writes) or "template" (calls and loops around other functions);
        ``lanes``: whether it compiles in lane mode (derive_lanes.h: DERIVE_REAL a vector, one state
        per lane), false for the functions that branch on a real (ik, manipulability)."""
        entry = {"header": f"c/{f['header']}", "source": f"c/{f['source']}", "returns": f["c_returns"],
                 "reads": f["c_reads"], "writes": f["c_writes"], "lanes": f["lanes"]}
        if "parts" not in f:
            return {**entry, "form": "template"}
        if not f["parts"]:
            return {**entry, "form": "whole"}
        return {**entry, "form": "split", "parts": len(f["parts"]), "zero_filled": [name for name, _ in f["fills"]]}

    def manifest_support(self, robot: RobotContext, functions: list[dict]) -> list[dict]:
        """The support headers (verbatim copies), then the build files: ``build`` says which tool
        uses each (``cmake``: its library target; ``make``: the variables it defines; ``example``)."""
        prefix = f"{robot.robot.upper()}_DERIVE"
        uses = [{"build": "cmake", "target": f"{robot.robot}_derive", "options": [f"{prefix}_FLOAT", f"{prefix}_EXAMPLE"]},
                {"build": "make", "variables": [f"{prefix}_{v}" for v in ("SRC", "INC", "CFLAGS", "LDLIBS", "EXAMPLE")],
                 "options": [f"{prefix}_FLOAT"]},
                {"build": "example", "target": f"{robot.robot}_derive_example"}]
        build = [{"file": f"c/{path.format(robot=robot.robot)}", "source": f"templates/{self.name}/{template}", **use}
                 for (path, template), use in zip(BUILD_FILES, uses)] if self.complete(functions) else []
        support = self.support_files(functions) + [LANES_HEADER]
        return [{"file": f"c/{name}", "source": self.support_source(name)} for name in support] + build


def lane_wise(lines: list[tuple[str, str]]) -> bool:
    """Whether printed (lhs, rhs) lines compile with DERIVE_REAL a vector: all but a literal too small
    for a float, which the printer casts, ``((DERIVE_REAL)1e-40)`` (a scalar cannot be cast to a vector)."""
    return not any("((DERIVE_REAL)" in rhs for _, rhs in lines)


ZERO_FILL_MIN = 256
"""Fewest zero entries of an output of a split function that are written by one loop instead of a
store each, when they are at least half its entries. The regressors of large robots are mostly
zeros (tiago_dual's base_regressor: 87 253 of 93 224 entries), and gcc spends minutes on functions of
thousands of stores (its alias analysis); functions small enough to stay whole keep their stores."""


def zero_fills(prog: Program, sizes: list[int]) -> tuple[list[tuple[int, int]], Program]:
    """The outputs to fill with zeros by a loop (:data:`ZERO_FILL_MIN`), as (output index, length), and
    the program without their zero stores (a -0.0 keeps its store)."""
    def zero(a: tuple) -> bool:
        return a[0] == "c" and a[1] == 0.0 and math.copysign(1.0, a[1]) > 0

    zeros: dict[int, int] = {}
    for oi, _, a in prog.results:
        if zero(a):
            zeros[oi] = zeros.get(oi, 0) + 1
    filled = {oi for oi, count in zeros.items() if count >= ZERO_FILL_MIN and 2 * count >= sizes[oi]}
    if not filled:
        return [], prog
    kept = [r for r in prog.results if not (r[0] in filled and zero(r[2]))]
    return [(oi, sizes[oi]) for oi in sorted(filled)], dataclasses.replace(prog, results=kept)


def translation_unit(files: dict[str, bytes], source: str) -> list[str]:
    """The files one C source compiles from: ``source`` (a path of ``files``, e.g. ``c/panda_gravity.c``)
    and every generated header it includes, directly or not, sorted. Headers outside ``files``
    (``<math.h>``) are the toolchain's."""
    folder = source.rpartition("/")[0]
    seen, todo = set(), [source]
    while todo:
        path = todo.pop()
        if path in seen or path not in files:
            continue
        seen.add(path)
        text = files[path].decode("utf-8", "replace")
        todo += [f"{folder}/{name}" if folder else name for name in INCLUDE.findall(text)]
    return sorted(seen)


def translation_unit_hash(files: dict[str, bytes], source: str, model_hash: str) -> str:
    """sha256 of what compiling ``source`` reads (:func:`translation_unit`), with the model hash of
    the banners left out: a model edit that does not change a function's code (a new frame, say)
    keeps its hash. Firmware figures (text, stack) are recorded against it."""
    h = hashlib.sha256()
    for path in translation_unit(files, source):
        h.update(f"\0{path}\0".encode())
        h.update(files[path].replace(model_hash.encode(), b"MODEL") if model_hash else files[path])
    return h.hexdigest()


BACKEND = CBackend()
