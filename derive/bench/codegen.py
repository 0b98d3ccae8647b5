"""Benchmarks of derivation and generated code (issue "Code generation").

- ``codegen-ops``: arithmetic per call of the generated C (after CSE) for the functions
  of ../shared/TARGETS.md, against the published CasADi-from-Pinocchio counts.
- ``codegen-time``: callgrind instructions and wall time per call of our generated C
  against CasADi's own C code generator run on the same expressions in the same run
  (the reference), both compiled with -O2.
- ``derive-time``: wall time of deriving and rendering each shipped robot's whole set,
  and of sympy.physics.mechanics' Lagrange method on an n-link planar pendulum against
  derive on the same pendulum (same run).
"""

from __future__ import annotations

import json
import re
import shutil
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

import casadi as ca
import numpy as np
import sympy as sp
from sympy.physics import mechanics as me

from derive.codegen.catalogue import function_specs
from derive.codegen.generate import render
from derive.description.model import load_models, parse_models
from derive.resources import CHECKOUT
from derive.symbolic.model import SXModel

ROOT = CHECKOUT

# (robot, function quantity[_frame], TARGETS.md row, CasADi-from-Pinocchio ops, our target ops)
OPS_TARGETS = [
    ("panda", "inverse_dynamics", "Panda inverse dynamics (RNEA)", 1230, 900),
    ("panda", "mass_matrix", "Panda mass matrix (CRBA)", 1085, 800),
    ("panda", "forward_dynamics", "Panda forward dynamics (ABA)", 2687, 1800),
    ("panda", "fk_jacobian_tcp", "Panda FK + 6x7 Jacobian of the TCP", 410, 350),
    ("ur5", "inverse_dynamics", "UR5 (6 dof) RNEA", 574, 450),
    ("ur5", "mass_matrix", "UR5 mass matrix", 305, 260),
]


def _manifest(robot: str) -> dict:
    return json.loads((ROOT / "generated" / robot / "manifest.json").read_text())


def bench_ops(args) -> str:
    rows = ["## Generated C: arithmetic per call (after CSE)", "",
            "| function | derive ops (mul/add/div/trig) | CasADi from Pinocchio<SX> | ratio | our target | met |",
            "|---|---|---|---|---|---|"]
    for robot, short, label, casadi_ops, target in OPS_TARGETS:
        fn = next(f for f in _manifest(robot)["functions"] if f["name"] == f"{robot}_{short}")
        o = fn["ops"]
        rows.append(f"| {label} | {o['total']} ({o['mul']}/{o['add']}/{o['div']}/{o['trig']}) | {casadi_ops} | "
                    f"{o['total'] / casadi_ops:.2f} | <= {target} | {'yes' if o['total'] <= target else 'NO'} |")
    rows += ["", "CasADi-from-Pinocchio counts are ../shared/TARGETS.md's published figures (pinocchio.casadi is not in",
             "the pin wheel here); ops count every +, -, *, /, sqrt and trig call as one."]
    return "\n".join(rows)


HARNESS = r"""
#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <time.h>
%(decl)s
int main(int argc, char **argv) {
    long n = argc > 1 ? atol(argv[1]) : 1000, k;
    int i;
    double acc = 0.0;
%(buffers)s
    struct timespec t0, t1;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    for (k = 0; k < n; ++k) {
%(perturb)s
        %(call)s;
        acc += out0[0];
    }
    clock_gettime(CLOCK_MONOTONIC, &t1);
    printf("%%.17g %%.3f\n", acc, ((t1.tv_sec - t0.tv_sec) * 1e9 + (t1.tv_nsec - t0.tv_nsec)) / (double)(n ? n : 1));
    return 0;
}
"""


def _harness(fn: dict, call: str, decl: str) -> str:
    buffers, perturb = [], []
    for k, item in enumerate(fn["inputs"]):
        size = max(1, int(np.prod(item["shape"])))
        buffers.append(f"    double in{k}[{size}];\n    for (i = 0; i < {size}; ++i) in{k}[i] = 0.1 + 0.01 * i;")
        perturb.append(f"        in{k}[0] += 1e-9;")
    for k, item in enumerate(fn["outputs"]):
        buffers.append(f"    double out{k}[{max(1, int(np.prod(item['shape'])))}];")
    return HARNESS % {"decl": decl, "buffers": "\n".join(buffers), "perturb": "\n".join(perturb), "call": call}


def callgrind_instructions(exe: Path, n: int) -> int | None:
    if not shutil.which("valgrind"):
        return None
    out = subprocess.run(["valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null", str(exe), str(n)],
                         capture_output=True, text=True)
    for line in out.stderr.splitlines():
        if "Collected" in line:
            return int(line.split()[-1].replace(",", ""))
    return None


def bench_time(args) -> str:
    robots = load_models()
    calls = 200 if args.quick else 1000
    rows = ["## Generated C: cost per call against CasADi's C code generator (same run)", "",
            "| function | derive instr/call | CasADi C instr/call | ratio | derive ns/call | CasADi ns/call | ratio |",
            "|---|---|---|---|---|---|---|"]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for robot, short, label, _, _ in OPS_TARGETS:
            fn = next(f for f in _manifest(robot)["functions"] if f["name"] == f"{robot}_{short}")
            spec = next(s for s in function_specs(SXModel(robots[robot])) if s.name == fn["name"])
            args_c = [f"in{k}" for k in range(len(fn["inputs"]))] + [f"out{k}" for k in range(len(fn["outputs"]))]
            # ours
            src = ROOT / "generated" / robot / "c" / fn["c"]["source"].split("/")[-1]
            ours = _harness(fn, f"{fn['name']}({', '.join(args_c)})", f'#include <stdlib.h>\n#include "{fn["name"]}.h"')
            (tmp / "ours.c").write_text(ours)
            subprocess.run(["cc", "-O2", f"-I{src.parent}", "-o", str(tmp / "ours"), str(tmp / "ours.c"),
                            str(src), "-lm"], check=True)
            # CasADi's generator on the same SX
            cf = ca.Function(fn["name"], [x for _, x in spec.inputs], [e for _, e in spec.outputs])
            cf.generate(f"{fn['name']}_casadi.c", {"with_header": True})
            shutil.move(f"{fn['name']}_casadi.c", tmp / "casadi_fn.c")
            shutil.move(f"{fn['name']}_casadi.h", tmp / f"{fn['name']}_casadi.h")
            ins = ", ".join(f"in{k}" for k in range(len(fn["inputs"])))
            outs = ", ".join(f"out{k}" for k in range(len(fn["outputs"])))
            call = (f"{{ const double *a[] = {{{ins}}}; double *r[] = {{{outs}}}; "
                    f"{fn['name']}(a, r, 0, 0, 0); }}")
            (tmp / "theirs.c").write_text(_harness(fn, call, f'#include <stdlib.h>\n#include "{fn["name"]}_casadi.h"'))
            subprocess.run(["cc", "-O2", f"-I{tmp}", "-o", str(tmp / "theirs"), str(tmp / "theirs.c"),
                            str(tmp / "casadi_fn.c"), "-lm"], check=True)
            res = {}
            for name in ("ours", "theirs"):
                exe = tmp / name
                i1, i0 = callgrind_instructions(exe, calls), callgrind_instructions(exe, 0)
                instr = (i1 - i0) / calls if i1 is not None and i0 is not None else float("nan")
                wall = statistics.median(float(subprocess.run([str(exe), "200000" if not args.quick else "20000"],
                                                              capture_output=True, text=True).stdout.split()[1])
                                         for _ in range(5))
                res[name] = (instr, wall)
            (io, wo), (it, wt) = res["ours"], res["theirs"]
            rows.append(f"| {label} | {io:.0f} | {it:.0f} | {io / it:.2f} | {wo:.0f} | {wt:.0f} | {wo / wt:.2f} |")
    rows += ["", "Both compiled with cc -O2 from the same CasADi SX expressions; instructions by valgrind",
             "--tool=callgrind (repeatable), time as the median of 5 runs (noisy on shared machines)."]
    return "\n".join(rows)


def _n_pendulum(n: int) -> str:
    links = ["      - {name: base}"] + [f"      - {{name: l{i}, mass: 1.0, com: [0, 0, -1.0]}}" for i in range(1, n + 1)]
    joints = [f"      - {{name: q{i}, type: revolute, parent: {'base' if i == 1 else f'l{i - 1}'}, child: l{i}, "
              f"axis: [0, 1, 0]{', origin: {xyz: [0, 0, -1.0]}' if i > 1 else ''}}}" for i in range(1, n + 1)]
    return "robots:\n  npend:\n    links:\n" + "\n".join(links) + "\n    joints:\n" + "\n".join(joints) + "\n"


def _mechanics_lagrange(n: int) -> float:
    """sympy.physics.mechanics LagrangesMethod on an n-link planar pendulum of point masses."""
    t0 = time.perf_counter()
    q = me.dynamicsymbols(f"q1:{n + 1}")
    qd = [sp.diff(x, me.dynamicsymbols._t) for x in q]
    N = me.ReferenceFrame("N")
    O = me.Point("O")
    O.set_vel(N, 0)
    frames, points, particles = [N], [O], []
    g = 9.81
    for i in range(n):
        Fi = frames[-1].orientnew(f"F{i}", "Axis", [q[i], N.y])
        Fi.set_ang_vel(N, sum(qd[: i + 1]) * N.y)
        Pi = points[-1].locatenew(f"P{i}", -1.0 * Fi.z)
        Pi.v2pt_theory(points[-1], N, Fi)
        pa = me.Particle(f"pa{i}", Pi, 1.0)
        pa.potential_energy = 1.0 * g * Pi.pos_from(O).dot(N.z)
        frames.append(Fi)
        points.append(Pi)
        particles.append(pa)
    L = me.Lagrangian(N, *particles)
    lm = me.LagrangesMethod(L, q)
    lm.form_lagranges_equations()
    lm.mass_matrix, lm.forcing  # noqa: B018 - force evaluation
    return time.perf_counter() - t0


def bench_derive(args) -> str:
    rows = ["## Derivation time (whole set: FK, J, M, C, g, ID, FD, ODE and Jacobians, C + Python)", "",
            "| robot | derive (s) | CSE + print + render (s) | functions | ops (expression functions) |", "|---|---|---|---|---|"]
    robots = load_models()
    for name in sorted(robots):
        log: list[str] = []
        render(robots[name], "0" * 64, log.append)
        # "  name: derive X s, cse+print+render Y s (N functions, M ops)"
        d, r, nf, ops = re.search(r"derive ([\d.]+) s, cse\+print\+render ([\d.]+) s \((\d+) functions, (\d+) ops",
                                  log[0]).groups()  # ops: of the expression functions
        rows.append(f"| {name} | {d} | {r} | {nf} | {ops} |")
    n = 3 if args.quick else 4
    t_me = _mechanics_lagrange(n)
    t0 = time.perf_counter()
    model = SXModel(parse_models(_n_pendulum(n))["npend"])
    for spec in function_specs(model):
        pass
    t_ours = time.perf_counter() - t0
    rows += ["", f"| {n}-link planar pendulum, M + forcing | derive (all functions, SX) | sympy.physics.mechanics Lagrange | ratio |",
             "|---|---|---|---|",
             f"| same run | {t_ours:.3f} s | {t_me:.2f} s | {t_ours / t_me:.4f} |",
             "", "../shared/TARGETS.md: Panda whole set <= 10 s on 2 cores (sympy.physics.mechanics Kane: 27 s for M + forcing)."]
    return "\n".join(rows)


def benchmarks() -> dict:
    return {"codegen-ops": bench_ops, "codegen-time": bench_time, "derive-time": bench_derive}
