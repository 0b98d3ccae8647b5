"""Benchmark ``throughput``: states per second per core, every way derive evaluates a batch, and Pinocchio.

For the Panda (generated/) and a 30-dof chain (``derive bench large``'s generic chain, its four
functions generated into a temporary folder; ``--quick``: a 12-dof one), on the same seeded states
(q uniform in the joint box, v, qdd, tau normal), inverse_dynamics, mass_matrix, forward_dynamics and
ode_jac_x as:

- the scalar C (cc -O2, a plain loop of one call per state), the lane C (the same .c files with
  ``-DDERIVE_LANES=<n> -include derive_lanes.h``, each double width this CPU has: AVX2 4, AVX-512F 8;
  inputs already laid out in lanes) and Pinocchio's C++ rnea, crba, aba and computeABADerivatives
  (its analytic dqdd/dq, dqdd/dv, the counterpart of the ODE Jacobian), all in one program, the loops
  interleaved in each repeat;
- derive.compiled's batch (packing into lanes in C where the host has them), the generated NumPy
  vectorised over the batch and the JAX flavour's jax.jit(jax.vmap(f)) on the CPU (float64), in
  one Python process, interleaved.

Per core: the program and the Python process each run pinned to one CPU (XLA's threads share it),
so the figures are what one core does; the machines are shared, so best of several repeats.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from string import Template

import numpy as np

from derive.bench.jax_speed import pinned
from derive.bench.large import generic_chain
from derive.bench.lanes import lane_widths
from derive.bench.pinocchio_cpp import PINOCCHIO, cpp_model, pinocchio_flags, states
from derive.codegen.generate import generate
from derive.description.model import load_models, parse_models
from derive.errors import DeriveError
from derive.reference.pinocchio_model import build_model
from derive.resources import CHECKOUT
from derive.runtime.build import read_generated, signatures

TITLE = "## Throughput: states per second per core"
FUNCTIONS = ("inverse_dynamics", "mass_matrix", "forward_dynamics", "ode_jac_x")
CHAIN, QUICK_CHAIN = 30, 12
JAX_CAP_S = 900
"""Seconds allowed to the Python process of one robot (JAX's jit compiles each function in it;
the 30-dof chain's are large); past it, the JAX column says so."""
INPUTS = {"q": "q", "qd": "v", "qdd": "qdd", "tau": "tau", "x": "x", "u": "tau"}
"""A generated function's input name -> the state array it reads (x = [q, v]; u the torques)."""

PROGRAM = Template(r"""
#include <pinocchio/multibody.hpp>
#include <pinocchio/algorithm/rnea.hpp>
#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/aba-derivatives.hpp>
#include <algorithm>
#include <array>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <vector>

using namespace pinocchio;
typedef std::array<double, 3> D3;
typedef std::array<double, 9> D9;
typedef double v4d __attribute__((vector_size(32)));
typedef double v8d __attribute__((vector_size(64)));
extern "C" {
${declarations}
}

static SE3 se3(const D9 &r, const D3 &p) {
  SE3::Matrix3 R;
  R << r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7], r[8];
  return SE3(R, SE3::Vector3(p[0], p[1], p[2]));
}

static Inertia inertia(double mass, const D3 &c, const D9 &I) {
  Inertia::Matrix3 J;
  J << I[0], I[1], I[2], I[3], I[4], I[5], I[6], I[7], I[8];
  return Inertia(mass, Inertia::Vector3(c[0], c[1], c[2]), J);
}

static Model build() {
  Model model;
  JointIndex j;
  ${model}
  (void)j;
  return model;
}

static double now() { return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count(); }

template <class T> static T *alloc(size_t count) {
  void *p = NULL;
  if (posix_memalign(&p, 64, count * sizeof(T) + 64)) exit(5);
  return (T *)p;
}

/* states (n x len, row-major) -> blocks of L lanes: element j of block b, lane k = state L b + k */
template <class V, int L> static V *pack(const double *src, long n, int len) {
  V *dst = alloc<V>((size_t)(n / L) * len);
  for (long b = 0; b < n / L; b++)
    for (int j = 0; j < len; j++)
      for (int k = 0; k < L; k++) dst[b * len + j][k] = src[(L * b + k) * len + j];
  return dst;
}

int main(int argc, char **argv) {
  const int nq = ${nq}, nv = ${nv};
  if (argc != 4) return 2;
  const long n = atol(argv[1]);
  const int repeats = atoi(argv[2]);
  double *q = alloc<double>(n * nq), *v = alloc<double>(n * nv), *qdd = alloc<double>(n * nv),
         *tau = alloc<double>(n * nv), *x = alloc<double>(n * (nq + nv));
  FILE *f = fopen(argv[3], "rb");
  if (!f || fread(q, sizeof(double), n * nq, f) != (size_t)(n * nq) || fread(v, sizeof(double), n * nv, f) != (size_t)(n * nv)
      || fread(qdd, sizeof(double), n * nv, f) != (size_t)(n * nv) || fread(tau, sizeof(double), n * nv, f) != (size_t)(n * nv))
    return 3;
  fclose(f);
  for (long i = 0; i < n; i++) {
    for (int k = 0; k < nq; k++) x[(nq + nv) * i + k] = q[nq * i + k];
    for (int k = 0; k < nv; k++) x[(nq + nv) * i + nq + k] = v[nv * i + k];
  }
  Model model = build();
  Data data(model);
  std::vector<Eigen::VectorXd> qs, vs, as, taus;
  for (long i = 0; i < n; i++) {
    qs.push_back(Eigen::Map<const Eigen::VectorXd>(q + nq * i, nq));
    vs.push_back(Eigen::Map<const Eigen::VectorXd>(v + nv * i, nv));
    as.push_back(Eigen::Map<const Eigen::VectorXd>(qdd + nv * i, nv));
    taus.push_back(Eigen::Map<const Eigen::VectorXd>(tau + nv * i, nv));
  }
  typedef Eigen::Ref<const Eigen::VectorXd> Ref;
  double *out = alloc<double>(n * ${out_max});
  double sink = 0, t0;
${setup}
  for (int r = 0; r < repeats; r++) {  /* interleaved: a burst of load hits all alike */
${timed}
  }
${report}
  fprintf(stderr, "%g\n", sink + data.tau[0] + data.M(0, 0) + data.ddq[0] + data.ddq_dq(0, 0));
  return 0;
}
""")

PINOCCHIO_CALL = {"inverse_dynamics": "rnea(model, data, Ref(qs[i]), Ref(vs[i]), Ref(as[i]))",
                  "mass_matrix": "crba(model, data, Ref(qs[i]))",
                  "forward_dynamics": "aba(model, data, Ref(qs[i]), Ref(vs[i]), Ref(taus[i]))",
                  "ode_jac_x": "computeABADerivatives(model, data, Ref(qs[i]), Ref(vs[i]), Ref(taus[i]))"}


def _program(robot, sigs, widths) -> tuple[str, list[tuple[str, str, list[str]]]]:
    """The C++ timing program and its lane objects: (source file, object, flags)."""
    vtype = {4: "v4d", 8: "v8d"}
    lengths = {"q": robot.nq, "v": robot.nv, "qdd": robot.nv, "tau": robot.nv, "x": robot.nq + robot.nv}
    by_name = {s.name: s for s in sigs}
    renames = sorted({c for name in FUNCTIONS for c in (by_name[name].cname, *by_name[name].calls)})
    decls, setup, timed, report, objects = [], [], [], [], []
    for name in FUNCTIONS:
        s = by_name[name]
        ins = [INPUTS[a.name] for a in s.inputs]
        m = s.outputs[0].length
        decls.append(f"void {s.cname}({', '.join(['const double *'] * len(ins) + ['double *'])});")
        call = ", ".join(f"{a} + {lengths[a]} * i" for a in ins)
        setup.append(f"  double best_{name} = 1e300, pin_{name} = 1e300;")
        timed += [f"    t0 = now(); for (long i = 0; i < n; i++) {s.cname}({call}, out + {m} * i);",
                  f"    t0 = now() - t0; best_{name} = std::min(best_{name}, t0); sink += out[0];",
                  f"    t0 = now(); for (long i = 0; i < n; i++) {PINOCCHIO_CALL[name]};",
                  f"    t0 = now() - t0; pin_{name} = std::min(pin_{name}, t0);"]
        report += [f'  printf("scalar {name} %.6g\\n", best_{name} / n);',
                   f'  printf("pinocchio {name} %.6g\\n", pin_{name} / n);']
        if not s.lanes:
            continue
        for w, (_, lanes, _, flags) in enumerate(widths):
            vt, fn = vtype[lanes], f"{s.cname}_w{w}"
            decls.append(f"void {fn}({', '.join([f'const {vt} *'] * len(ins) + [f'{vt} *'])});")
            for a in sorted(set(ins)):
                setup.append(f"  {vt} *{a}_w{w}_{name} = pack<{vt}, {lanes}>({a}, n, {lengths[a]});")
            setup += [f"  {vt} *out_w{w}_{name} = alloc<{vt}>((size_t)(n / {lanes}) * {m});",
                      f"  double best_{name}_w{w} = 1e300;"]
            lane_call = ", ".join(f"{a}_w{w}_{name} + {lengths[a]} * b" for a in ins)
            timed += [f"    t0 = now(); for (long b = 0; b < n / {lanes}; b++) {fn}({lane_call}, out_w{w}_{name} + {m} * b);",
                      f"    t0 = now() - t0; best_{name}_w{w} = std::min(best_{name}_w{w}, t0); sink += out_w{w}_{name}[0][0];"]
            report.append(f'  printf("lanes{w} {name} %.6g\\n", best_{name}_w{w} / (n / {lanes} * {lanes}));')
    for w, (_, lanes, _, flags) in enumerate(widths):
        units = sorted({c for name in FUNCTIONS if by_name[name].lanes for c in (by_name[name].cname, *by_name[name].calls)})
        for c in units:
            objects.append((f"{c}.c", f"{c}_w{w}.o", [*flags, f"-DDERIVE_LANES={lanes}", *(f"-D{r}={r}_w{w}" for r in renames)]))
    out_max = max(by_name[name].outputs[0].length for name in FUNCTIONS)
    source = PROGRAM.substitute(declarations="\n".join(decls), model=cpp_model(build_model(robot)), nq=robot.nq,
                                nv=robot.nv, out_max=out_max, setup="\n".join(setup), timed="\n".join(timed),
                                report="\n".join(report))
    return source, objects


def _run_c(robot, folder: Path, sigs, widths, arrays: dict, n: int, repeats: int) -> dict:
    c_dir = folder / robot.name / "c"
    source, objects = _program(robot, sigs, widths)
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        (tmp / "main.cpp").write_text(source)
        np.concatenate([arrays[k][:n].ravel() for k in ("q", "v", "qdd", "tau")]).astype(np.float64).tofile(tmp / "states.bin")
        by_name = {s.name: s for s in sigs}
        objs = []
        for cname in sorted({c for name in FUNCTIONS for c in (by_name[name].cname, *by_name[name].calls)}):
            obj = tmp / f"{cname}.o"
            subprocess.run(["cc", "-std=c99", "-O2", f"-I{c_dir}", "-c", str(c_dir / f"{cname}.c"), "-o", str(obj)],
                           check=True)
            objs.append(str(obj))
        for src, obj, flags in objects:
            subprocess.run(["cc", "-std=c99", "-O2", *flags, f"-I{c_dir}", "-include", "derive_lanes.h", "-c",
                            str(c_dir / src), "-o", str(tmp / obj)], check=True)
            objs.append(str(tmp / obj))
        subprocess.run(["g++", str(tmp / "main.cpp"), *objs, *pinocchio_flags(), "-lpinocchio_default", "-lm",
                        "-o", str(tmp / "main")], check=True)
        out = subprocess.run([str(tmp / "main"), str(n), str(repeats), str(tmp / "states.bin")], check=True,
                             capture_output=True, text=True, preexec_fn=pinned).stdout
    return {(w[0], w[1]): float(w[2]) for w in map(str.split, out.splitlines())}


CHILD = r"""
import importlib.util, json, sys, time
import numpy as np
from derive.runtime import loader
from derive.solvers.simulate import load_generated
robot, folder, states_file, repeats = sys.argv[1], sys.argv[2], sys.argv[3], int(sys.argv[4])
functions = sys.argv[5].split(",")
data = np.load(states_file)
batches = {k: data[k] for k in data.files}
inputs = json.loads(sys.argv[6])
compiled, py = loader.compiled(robot, folder), load_generated(robot, folder)
def best(fn, args):
    t = time.perf_counter(); fn(*args); return time.perf_counter() - t
n = len(batches["q"])
for name in functions:
    args = [batches[a] for a in inputs[name]]
    tc = tn = float("inf")
    for _ in range(repeats):
        tc = min(tc, best(getattr(compiled, name), args)); tn = min(tn, best(getattr(py, name), args))
    print("compiled", name, tc / n, flush=True); print("numpy", name, tn / n, flush=True)
import jax
jax.config.update("jax_enable_x64", True)
spec = importlib.util.spec_from_file_location("derive_bench_throughput_jax", f"{folder}/{robot}/jax/{robot}.py")
jx = importlib.util.module_from_spec(spec); spec.loader.exec_module(jx)
for name in functions:
    args = [batches[a] for a in inputs[name]]
    t = time.perf_counter()
    f = jax.jit(jax.vmap(getattr(jx, name))).lower(*args).compile()
    print("jax_compile", name, time.perf_counter() - t, flush=True)
    tj = float("inf")
    for _ in range(repeats):
        t = time.perf_counter(); f(*args).block_until_ready(); tj = min(tj, time.perf_counter() - t)
    print("jax", name, tj / n, flush=True)
"""


def _run_python(robot, folder: Path, sigs, arrays: dict, repeats: int, cap: float) -> tuple[dict, str]:
    """derive.compiled, NumPy and JAX per state, from a child process pinned to one CPU; and a note
    where JAX did not finish within ``cap`` seconds."""
    by_name = {s.name: s for s in sigs}
    inputs = {name: [INPUTS[a.name] for a in by_name[name].inputs] for name in FUNCTIONS}
    with tempfile.TemporaryDirectory() as tmp:
        states_file = Path(tmp) / "states.npz"
        np.savez(states_file, **arrays)
        command = [sys.executable, "-c", CHILD, robot.name, str(folder), str(states_file), str(repeats),
                   ",".join(FUNCTIONS), json.dumps(inputs)]
        env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(CHECKOUT), os.environ.get("PYTHONPATH", "")])}
        note = ""
        try:
            out = subprocess.run(command, check=True, capture_output=True, text=True, timeout=cap, preexec_fn=pinned,
                                 env=env).stdout
        except subprocess.TimeoutExpired as e:
            out = (e.stdout or b"").decode() if isinstance(e.stdout, bytes) else (e.stdout or "")
            note = f"{robot.name}: the JAX process did not finish within {cap:.0f} s (jit compiling)"
        except subprocess.CalledProcessError as e:
            raise DeriveError(f"bench throughput: {robot.name}: the Python measurement failed:\n{e.stderr}") from None
    return {(w[0], w[1]): float(w[2]) for w in map(str.split, out.splitlines()) if len(w) == 3}, note


def _robots(quick: bool, tmp: Path) -> list[tuple[str, object, Path, float]]:
    """(label, Robot, generated folder, seconds to generate or 0) of each robot measured."""
    out = [("Panda", load_models()["panda"], CHECKOUT / "generated", 0.0)]
    n = QUICK_CHAIN if quick else CHAIN
    chain = parse_models(generic_chain(n) + "    generate: {frames: [tcp], quantities: [" + ", ".join(FUNCTIONS) + "]}\n")
    robot = chain[f"chain{n}"]
    start = time.perf_counter()
    generate({robot.name: robot}, tmp, log=lambda s: None)
    out.append((f"chain{n} (generic, {n} revolute)", robot, tmp, time.perf_counter() - start))
    return out


def _rate(seconds_per_state: float | None) -> str:
    if seconds_per_state is None:
        return "-"
    rate = 1.0 / seconds_per_state
    return f"{rate / 1e6:.2f} M" if rate >= 1e6 else f"{rate / 1e3:.0f} k"


def bench_throughput(args) -> str:
    widths = [w for w in lane_widths() if not w[2]]  # double lanes: the table is float64 throughout
    n = 1024 if args.quick else 4096
    repeats = 3 if args.quick else 9
    rows, notes = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for label, robot, folder, gen_s in _robots(args.quick, Path(tmp)):
            sigs = signatures(read_generated(robot.name, folder / robot.name).manifest)
            xs = states(robot, n)
            nq, nv = robot.nq, robot.nv
            arrays = {"q": xs[:, :nq], "v": xs[:, nq:nq + nv], "tau": xs[:, nq + nv:nq + 2 * nv], "qdd": xs[:, nq + 2 * nv:]}
            arrays = {k: np.ascontiguousarray(a) for k, a in arrays.items()}
            arrays["x"] = np.concatenate([arrays["q"], arrays["v"]], axis=1)
            print(f"[throughput] {label}: C and Pinocchio ...", flush=True)
            c = _run_c(robot, folder, sigs, widths, arrays, n, repeats)
            print(f"[throughput] {label}: derive.compiled, NumPy, JAX ...", flush=True)
            py, note = _run_python(robot, folder, sigs, arrays, repeats, JAX_CAP_S)
            if note:
                notes.append(note)
            for name in FUNCTIONS:
                lanes = [_rate(c.get((f"lanes{w}", name))) for w in range(len(widths))]
                compile_s = py.get(("jax_compile", name))
                rows.append(f"| {label} | {name} | {_rate(c[('scalar', name)])} | {' | '.join(lanes)} | "
                            f"{_rate(py.get(('compiled', name)))} | {_rate(py.get(('numpy', name)))} | "
                            f"{_rate(py.get(('jax', name)))} | {'-' if compile_s is None else f'{compile_s:.0f}'} | "
                            f"{_rate(c[('pinocchio', name)])} ({PINOCCHIO[name]}) |")
            if gen_s:
                notes.append(f"{label}: its four functions generated (C, Python, JAX) in {gen_s:.0f} s")
    lane_heads = "".join(f" lane C, {label} |" for label, _, _, _ in widths)
    header = (f"| robot | function | scalar C |{lane_heads} derive.compiled batch | NumPy batch | JAX jit(vmap) | "
              "JAX compile s | Pinocchio C++ |")
    return "\n".join([
        TITLE, "",
        f"States per second on one core (M = 1e6, k = 1e3), float64, {n} seeded states (q uniform in the joint box, v, "
        f"qdd, tau normal), the same in every column; best of {repeats} interleaved repeats. Scalar C: the generated C "
        "(cc -O2), one call per state. Lane C: the same .c files compiled with `-DDERIVE_LANES=<n> -include "
        "derive_lanes.h`, inputs already laid out in lanes (no packing); each double width this CPU has. Pinocchio: "
        "its C++ rnea, crba, aba and computeABADerivatives (dqdd/dq and dqdd/dv: what ode_jac_x holds below its "
        "identity block) from libpinocchio_default, in the same program as the C columns. derive.compiled (the "
        "host's lanes, packing and unpacking in C), the generated NumPy over the batch and jax.jit(jax.vmap(f)) of the "
        "JAX flavour on the CPU (compile s: lower and compile, not in the rate) in one Python process. Each process "
        "pinned to one CPU (XLA's threads share it). A shared 2-core VM: the figures are indicative.", "",
        header, "|" + "---|" * (header.count("|") - 1), *rows, "",
        *([f"Notes: {'; '.join(notes)}."] if notes else [])])


def benchmarks() -> dict:
    return {"throughput": bench_throughput}
