"""Benchmark ``contacts`` (issue 27): the generated contact dynamics and its derivatives against Pinocchio's C++.

solo12 from example-robot-data (floating, its four feet as point contacts, one stance) is generated in C with
only contact_dynamics_stance and contact_dynamics_derivatives_stance, compiled with ``cc -O2 -std=c99`` and linked
into one C++ program with Pinocchio (the model written out by :func:`derive.bench.pinocchio_cpp.cpp_model`, the
contacts as ``RigidConstraintModel`` CONTACT_3D, LOCAL_WORLD_ALIGNED, on the foot frames' joints and placements,
no proximal regularisation: mu = 0, one iteration). The program times, on the same seeded states, interleaved:

- ours ``contact_dynamics_stance`` (qdd, lambda, status) against ``constraintDynamics``;
- ours ``contact_dynamics_derivatives_stance`` (d(qdd, lambda)/d(q, v, tau), from scratch) against
  ``constraintDynamics`` followed by ``computeConstraintDynamicsDerivatives`` (which needs the former's
  factorisation at the state: what a DDP node calls), and the derivatives call alone for reference.

The program prints both sides' qdd and lambda at one state, which must agree (a harness check).
"""

from __future__ import annotations

import re
import shutil
import subprocess
import tempfile
import time
from pathlib import Path
from string import Template

import numpy as np

from derive.bench.pinocchio_cpp import SAMPLE_NS, STATES, cpp_model, pinocchio_flags, states
from derive.codegen.backends.c import BACKEND as C_BACKEND
from derive.codegen.catalogue import function_specs, selected, template_functions
from derive.codegen.render import render_robot
from derive.description.model import parse_robot
from derive.description.robot import Robot
from derive.description.urdf import example_robot_data_dir, import_urdf_named
from derive.errors import DeriveError
from derive.reference.pinocchio_model import build_model
from derive.symbolic.model import SXModel

TITLE = "## Contact dynamics against Pinocchio's C++: ns per call"
TARGET = 0.5
"""The issue's target: the generated C per call at most 0.5x of Pinocchio's C++."""
FEET = ("FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT")
URDF = "solo_description/robots/solo12.urdf"


def solo12() -> Robot:
    name, entry = import_urdf_named("example-robot-data:" + URDF, floating=True, friction=False)
    entry = {**entry, "contacts": [{"frame": f} for f in FEET], "contact_sets": {"stance": list(FEET)},
             "generate": {"quantities": ["contact_dynamics", "contact_dynamics_derivatives"]}}
    return parse_robot(name, entry)


HARNESS = Template(r"""
#include <pinocchio/multibody.hpp>
#include <pinocchio/algorithm/constrained-dynamics.hpp>
#include <pinocchio/algorithm/constrained-dynamics-derivatives.hpp>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <vector>
#include "${robot}_contact_dynamics_stance.h"
#include "${robot}_contact_dynamics_derivatives_stance.h"

using namespace pinocchio;
typedef std::array<double, 3> D3;
typedef std::array<double, 9> D9;

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

static double now_ns() {
  return std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

template <class F> static double per_call(F f, int n, int passes) {
  double t0 = now_ns();
  for (int p = 0; p < passes; p++)
    for (int i = 0; i < n; i++) f(i);
  return (now_ns() - t0) / ((double)n * passes);
}

static void print(const char *name, const double *x, int n) {
  printf("check %s", name);
  for (int k = 0; k < n; k++) printf(" %.17g", x[k]);
  printf("\n");
}

int main(int argc, char **argv) {
  const int nq = ${nq}, nv = ${nv}, m = ${m}, nx = nq + nv, stride = nq + 3 * nv;  /* a state: q, v, tau, qdd */
  if (argc != 4 && argc != 5) return 2;
  const int n = atoi(argv[1]), repeats = atoi(argv[2]);  /* with argv[4]: repeats passes of one side, untimed */
  std::vector<double> states((size_t)n * stride);
  FILE *f = fopen(argv[3], "rb");
  if (!f || fread(states.data(), sizeof(double), states.size(), f) != states.size()) return 3;
  fclose(f);
  Model model = build();
  Data data(model);
  typedef std::vector<RigidConstraintModel, Eigen::aligned_allocator<RigidConstraintModel>> Models;
  typedef std::vector<RigidConstraintData, Eigen::aligned_allocator<RigidConstraintData>> Datas;
  Models contacts;
  ${contacts}
  Datas datas;
  for (auto &c : contacts) datas.push_back(RigidConstraintData(c));
  initConstraintDynamics(model, data, contacts, datas);
  ProximalSettings prox(1e-14, 0.0, 1);
  const double *S = states.data();
  std::vector<Eigen::VectorXd> q, v, tau;
  for (int i = 0; i < n; i++) {
    const double *s = S + (size_t)i * stride;
    q.push_back(Eigen::Map<const Eigen::VectorXd>(s, nq));
    v.push_back(Eigen::Map<const Eigen::VectorXd>(s + nq, nv));
    tau.push_back(Eigen::Map<const Eigen::VectorXd>(s + nx, nv));
  }
  Eigen::MatrixXd ddq_dq(nv, nv), ddq_dv(nv, nv), ddq_dtau(nv, nv), dl_dq(m, nv), dl_dv(m, nv), dl_dtau(m, nv);
  std::vector<double> out((size_t)(nv + m) * (nq + 2 * nv) + 1);
  double *o = out.data(), *o2 = o + nv, *o3 = o + nv + m;

  ${robot}_contact_dynamics_stance(S, S + nq, S + nx, o, o2, o3);
  print("derive_qdd", o, nv);
  print("derive_lambda", o2, m);
  constraintDynamics(model, data, q[0], v[0], tau[0], contacts, datas, prox);
  print("pin_qdd", data.ddq.data(), nv);
  print("pin_lambda", data.lambda_c.data(), m);
  fflush(stdout);
  if (argc == 5) {  /* for callgrind: each state's derivatives, ours or Pinocchio's, repeats times over */
    const bool ours = argv[4][0] == 'o';
    for (int r = 0; r < repeats; r++)
      for (int i = 0; i < n; i++) {
        const double *s = S + (size_t)i * stride;
        if (ours) {
          ${robot}_contact_dynamics_derivatives_stance(s, s + nq, s + nx, o, o + nv * (nq + 2 * nv));
        } else {
          constraintDynamics(model, data, q[i], v[i], tau[i], contacts, datas, prox);
          computeConstraintDynamicsDerivatives(model, data, contacts, datas, prox, ddq_dq, ddq_dv, ddq_dtau, dl_dq,
                                               dl_dv, dl_dtau);
        }
      }
    return 0;
  }

  double best[5];
  int passes[5] = {0};
  auto measure = [&](int k, auto fn) {
    if (!passes[k]) {
      passes[k] = std::max(1, (int)std::ceil(${sample_ns} / (per_call(fn, n, 1) * n)));
      best[k] = 1e300;
    }
    best[k] = std::min(best[k], per_call(fn, n, passes[k]));
  };
  for (int r = 0; r < repeats; r++) {
    measure(0, [&](int i) { const double *s = S + (size_t)i * stride; ${robot}_contact_dynamics_stance(s, s + nq, s + nx, o, o2, o3); });
    measure(1, [&](int i) { constraintDynamics(model, data, q[i], v[i], tau[i], contacts, datas, prox); });
    measure(2, [&](int i) { const double *s = S + (size_t)i * stride;
                            ${robot}_contact_dynamics_derivatives_stance(s, s + nq, s + nx, o, o + nv * (nq + 2 * nv)); });
    measure(3, [&](int i) {
      constraintDynamics(model, data, q[i], v[i], tau[i], contacts, datas, prox);
      computeConstraintDynamicsDerivatives(model, data, contacts, datas, prox, ddq_dq, ddq_dv, ddq_dtau, dl_dq, dl_dv, dl_dtau);
    });
    constraintDynamics(model, data, q[0], v[0], tau[0], contacts, datas, prox);
    measure(4, [&](int i) {
      (void)i;
      computeConstraintDynamicsDerivatives(model, data, contacts, datas, prox, ddq_dq, ddq_dv, ddq_dtau, dl_dq, dl_dv, dl_dtau);
    });
  }
  printf("time forward %.3f %.3f\n", best[0], best[1]);
  printf("time derivatives %.3f %.3f %.3f\n", best[2], best[3], best[4]);
  fprintf(stderr, "%g\n", o[0] + data.ddq[0] + ddq_dq(0, 0));
  return 0;
}
""")


BREAKDOWN = ("Where the derivatives' operations go (solo12, four feet, measured once by building the parts alone, "
             "counted with casadi's cse: 63.1k, where the generated code has 61.6k, 125 of them divisions; 85.1k "
             "before this wave's forms, 68.0k before the quaternion's columns in closed form): "
             "the solution itself (the forward dynamics) 8.4k; the KKT residual's Jacobian dF/d(q, v) without the "
             "quaternion 14.5k (one RNEA by AD: the contact forces carried by its backward pass as external "
             "wrenches, J a + a0 from its forward pass; 28.7k with the quaternion, as J^T lambda and J a + a0 built "
             "from J); the d/dtau columns, the KKT inverse's symmetric top-left block and the one below it, 13.5k; "
             "dF's 33 other columns through the KKT inverse 25.1k: the 24 sparse ones (a leg joint's, at most m "
             "nonzeros) by those blocks, the 6 dense ones (the base's velocity) by the shared factors, about 1.5k "
             "each (two tree half-solves, W^T z, the 12 x 12 Schur solve, D^-1 W lambda); and the quaternion's four "
             "1.6k (they rotate gravity and the contact forces only: -[u; 0] - D1^T R u and D2 R u - w, D1 and D2 "
             "the blocks' rows and columns at the contacts' linear rows summed; 7.9k by AD and the solve). In "
             "instructions it is far below Pinocchio (the callgrind line above); the time ratio is higher because "
             "the operations are 722 KB of straight-line x86-64 code (789 KB with the quaternion by AD, 924 KB "
             "before this wave's forms), fetched from L2 on every call, where Pinocchio's loops stay in the "
             "instruction cache. Tried, not kept: the solve as C loops around a straight-line helper (M, J and dF "
             "at the solution) ran slower at -O2 (the loops cannot skip the zeros the straight-line code never "
             "computes). Ways to cut it further, not done: Pinocchio's analytic RNEA derivatives for dF instead of "
             "AD; the outputs written where they are computed instead of copied out of the work array at the end "
             "(1 560 loads and stores). Pinocchio's figures vary by up to 1.6x between runs on this shared machine "
             "(53-87 us for the derivatives).")


def _num(values) -> str:
    return ", ".join(repr(float(x)) for x in np.asarray(values, dtype=float).ravel())


def contacts_cpp(model) -> str:
    """C++ statements adding the four feet as CONTACT_3D, LOCAL_WORLD_ALIGNED, to ``contacts``."""
    lines = []
    for foot in FEET:
        frame = model.frames[model.getFrameId(foot)]
        at = frame.placement
        lines.append(f"contacts.push_back(RigidConstraintModel(CONTACT_3D, model, {frame.parentJoint}, "
                     f"se3({{{_num(at.rotation)}}}, {{{_num(at.translation)}}}), LOCAL_WORLD_ALIGNED));")
    return "\n  ".join(lines)


def instructions(c_dir: Path, n: int, side: str) -> float | None:
    """Instructions per call of one side's derivatives ("ours" or "pinocchio": constraintDynamics then
    computeConstraintDynamicsDerivatives) under callgrind, which counts the same on a loaded machine: the
    harness's count mode run with 1 and with 3 passes over its n states, the difference over 2 n calls (what
    the program does besides, loading the model and the states, cancels). None without valgrind."""
    if shutil.which("valgrind") is None:
        return None
    counts = []
    for passes in (1, 3):
        res = subprocess.run(["valgrind", "--tool=callgrind", "--callgrind-out-file=/dev/null", "./harness", str(n),
                              str(passes), "states.bin", side], cwd=c_dir, capture_output=True, text=True)
        found = re.search(r"Collected : (\d+)", res.stderr)
        if res.returncode != 0 or found is None:
            raise DeriveError(f"bench contacts: callgrind of the harness ({side}, {passes} passes) failed: "
                              f"{(res.stderr.strip().splitlines() or ['no output'])[-1]}")
        counts.append(int(found.group(1)))
    return (counts[1] - counts[0]) / (2 * n)


def measure(repeats: int, flags: list[str], log=print) -> dict:
    robot = solo12()
    m = 3 * len(FEET)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        t0 = time.perf_counter()
        model = SXModel(robot)
        specs, _ = selected(robot, function_specs(model), template_functions(model))
        ops = {}
        files = render_robot(robot, specs, "0" * 16, backends=[C_BACKEND],
                             progress=lambda spec, prog: ops.__setitem__(spec.quantity, prog.ops()["total"]))
        for name, text in files.items():
            path = folder / name
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(text)
        generated = time.perf_counter() - t0
        c_dir = folder / "c"
        t0 = time.perf_counter()
        for source in sorted(c_dir.glob(f"{robot.name}_*.c")):
            subprocess.run(["cc", "-O2", "-std=c99", "-c", source.name, "-o", source.with_suffix(".o").name],
                           cwd=c_dir, check=True)
        compiled = time.perf_counter() - t0
        log(f"[contacts] {robot.name}: generated in {generated:.1f} s, compiled in {compiled:.1f} s")
        pm = build_model(robot)
        source = HARNESS.substitute(robot=robot.name, model=cpp_model(pm), contacts=contacts_cpp(pm), nq=robot.nq,
                                    nv=robot.nv, m=m, sample_ns=repr(SAMPLE_NS))
        (c_dir / "harness.cpp").write_text(source)
        xs = states(robot)
        xs.astype(np.float64).tofile(c_dir / "states.bin")
        objects = sorted(p.name for p in c_dir.glob(f"{robot.name}_*.o"))
        t0 = time.perf_counter()
        subprocess.run(["g++", "harness.cpp", *objects, "-I.", *flags, "-lpinocchio_default", "-lm", "-o", "harness"],
                       cwd=c_dir, check=True)
        log(f"[contacts] harness compiled in {time.perf_counter() - t0:.1f} s")
        out = subprocess.run(["./harness", str(len(xs)), str(repeats), "states.bin"], cwd=c_dir, check=True,
                             capture_output=True, text=True).stdout
        counted = {side: instructions(c_dir, len(xs), side) for side in ("ours", "pinocchio")}
    values = {w[1]: np.array(w[2:], dtype=float) for w in map(str.split, out.splitlines()) if w[0] == "check"}
    times = {w[1]: [float(x) for x in w[2:]] for w in map(str.split, out.splitlines()) if w[0] == "time"}
    error = max(float(np.abs(values[f"derive_{k}"] - values[f"pin_{k}"]).max() / max(1.0, np.abs(values[f"pin_{k}"]).max()))
                for k in ("qdd", "lambda"))
    if error > 1e-9:
        raise DeriveError(f"bench contacts: ours is {error:.1e} from Pinocchio's C++ constraintDynamics (a harness bug)")
    log(f"[contacts] forward {times['forward'][0]:.0f}/{times['forward'][1]:.0f} ns, derivatives "
        f"{times['derivatives'][0]:.0f}/{times['derivatives'][1]:.0f} ns (values {error:.1e})")
    if counted["ours"] is not None:
        log(f"[contacts] derivatives: {counted['ours']:.0f} / {counted['pinocchio']:.0f} instructions a call (callgrind)")
    return {"times": times, "ops": ops, "error": error, "generated": generated, "compiled": compiled, "nv": robot.nv,
            "instructions": counted}


def _pin_version() -> str:
    import pinocchio

    return pinocchio.__version__


def section(r: dict, repeats: int, seconds: float) -> str:
    fwd, der = r["times"]["forward"], r["times"]["derivatives"]
    rows = [("contact_dynamics_stance", "constraintDynamics", r["ops"]["contact_dynamics"], fwd[0], fwd[1]),
            ("contact_dynamics_derivatives_stance", "constraintDynamics + computeConstraintDynamicsDerivatives",
             r["ops"]["contact_dynamics_derivatives"], der[0], der[1])]
    table = ["| derive (solo12, four feet) | ops | derive ns | Pinocchio C++ | Pinocchio ns | ratio | met |",
             "|---|---|---|---|---|---|---|"]
    for ours, theirs, ops, a, b in rows:
        table.append(f"| {ours} | {ops} | {a:.0f} | {theirs} | {b:.0f} | {a / b:.2f} | {'yes' if a / b <= TARGET else 'no'} |")
    return "\n".join([
        TITLE, "",
        f"Target (issue 27): the generated C per call at most {TARGET:g}x Pinocchio's C++. solo12 (example-robot-data, "
        f"floating, nv {r['nv']}), its four feet as point contacts (m = 12), generated in C with only the two functions "
        f"({r['generated']:.1f} s) and compiled with `cc -O2 -std=c99` ({r['compiled']:.1f} s); Pinocchio "
        f"{_pin_version()} (the pin wheel's libpinocchio_default and its headers, g++ -O2 -DNDEBUG) on the same model "
        "(derive.reference.pinocchio_model written out as C++), the feet as `RigidConstraintModel` CONTACT_3D, "
        "LOCAL_WORLD_ALIGNED, `ProximalSettings(1e-14, 0, 1)` (no regularisation, one iteration: the exact KKT "
        f"solve). One program, the same {STATES} seeded states cycled through, each figure the best of {repeats} samples "
        f"of about {SAMPLE_NS / 1e6:g} ms, the loops interleaved; the two sides' qdd and lambda at the first state agree "
        f"to {r['error']:.1e}. The derivatives are compared with what a DDP node calls: `constraintDynamics` then "
        "`computeConstraintDynamicsDerivatives` (which reuses the former's factorisation), since ours computes its "
        f"own solution; `computeConstraintDynamicsDerivatives` alone takes {der[2]:.0f} ns.", "",
        *table, "",
        _instructions_line(r["instructions"]), "",
        BREAKDOWN, "",
        f"Measured on a shared 2-core VM: times are indicative, the ratios come from the same run; bench time "
        f"{seconds:.0f} s."])


def _instructions_line(counted: dict) -> str:
    ours, theirs = counted["ours"], counted["pinocchio"]
    if ours is None:
        return "Instructions per call (callgrind): not measured, valgrind is not installed."
    return (f"Instructions per call of the derivatives, counted by callgrind (the same on a loaded machine, where the "
            f"times are not): derive {ours / 1e3:.1f}k, Pinocchio's constraintDynamics + "
            f"computeConstraintDynamicsDerivatives {theirs / 1e3:.1f}k, {ours / theirs:.2f}x.")


def bench_contacts(args) -> str:
    start = time.perf_counter()
    flags = pinocchio_flags()
    if example_robot_data_dir() is None:
        raise DeriveError("bench contacts: needs example-robot-data (pip install example-robot-data)")
    repeats = 5 if args.quick else 15
    result = measure(repeats, flags, log=lambda line: print(line, flush=True))
    return section(result, repeats, time.perf_counter() - start)


def benchmarks() -> dict:
    return {"contacts": bench_contacts}
