"""Benchmark ``pinocchio-cpp`` (issue "Large robots"): the generated C per call against Pinocchio's C++.

For each robot, only the four functions compared (inverse_dynamics, mass_matrix, forward_dynamics,
ode_jac_x; where ode_jac_x is a template, also the inverse_dynamics_derivatives it calls) are derived
and rendered in C into a temporary folder, then compiled with ``cc -O2
-std=c99`` (times recorded, each stage capped at :data:`CAP_S`). The robot's Pinocchio model
(:func:`derive.reference.pinocchio_model.build_model`, the same q and v) is written out as C++
statements (``addJoint`` with the exact joint model and placement, then the joint's aggregated
inertia), checked against the Python model, and compiled with the generated objects into one
program that times both sides in the same process, on the same seeded states, interleaved:
ours against ``rnea``, ``crba``, ``aba`` and ``computeABADerivatives``. The program also prints
both sides' values at one state, which must agree (a harness check: the generated functions
match Pinocchio in the test suite).
"""

from __future__ import annotations

import contextlib
import io
import json
import multiprocessing
import shutil
import subprocess
import tempfile
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from string import Template
from typing import Callable

import casadi as ca
import numpy as np

from derive.bench.large import generic_chain
from derive.bench.zoo import id_m_fd_specs
from derive.codegen.backends.c import BACKEND as C_BACKEND
from derive.codegen.catalogue import (cheaper_ode_jacobians, inverse_dynamics_derivatives_spec, ode_by_template,
                                      ode_jacobian_templates)
from derive.codegen.checks import check_constants, check_mass_matrix
from derive.codegen.render import render_robot
from derive.codegen.spec import FunctionSpec, TemplateFunction
from derive.description.model import load_models, parse_models, parse_robot
from derive.description.robot import Robot
from derive.description.urdf import example_robot_data_dir, import_urdf_named
from derive.errors import DeriveError
from derive.reference import NumericRobot
from derive.reference.pinocchio_model import build_model
from derive.symbolic.model import SXModel

TITLE = "## Generated C against Pinocchio's C++: ns per call"
FUNCTIONS = ("inverse_dynamics", "mass_matrix", "forward_dynamics", "ode_jac_x")
PINOCCHIO = {"inverse_dynamics": "rnea", "mass_matrix": "crba", "forward_dynamics": "aba",
             "ode_jac_x": "computeABADerivatives"}
TARGET = 2.0
"""The issue's target: the generated C per call within 2x of Pinocchio's C++."""
CAP_S = 300
"""Seconds allowed to each robot's generation, and again to compiling its C files."""
STATES = 64
"""Seeded random states (q in the joint box, v, qdd, tau normal), cycled through by every timing loop."""
SAMPLE_NS = 1e7
"""Each timed sample loops over the states as many times as it takes to last about this long."""

ERD = {"talos_reduced": ("talos_data/robots/talos_reduced.urdf", True), "romeo": ("romeo_description/urdf/romeo.urdf", True),
       "tiago_dual": ("tiago_description/robots/tiago_dual.urdf", False)}
"""The example-robot-data trees measured, label -> (URDF, floating base): imported whole, as ``derive bench
zoo`` does, but without their URDF friction (Pinocchio's algorithms have none)."""
QUICK = ("panda", "ur5", "chain12")

PINOCCHIO_INSTANTIATED = True
"""Call the algorithms that the pin wheel's libpinocchio_default precompiled
(``-DPINOCCHIO_ENABLE_TEMPLATE_INSTANTIATION``, Eigen::Ref arguments) rather than compiling Pinocchio's
templates into the program (header-only, g++ -O2): the faster of the two, measured once (:data:`BUILD_NOTE`)."""
BUILD_NOTE = ("Measured once on this machine, the header-only build (Pinocchio's templates compiled into the program "
              "with g++ -O2 -DNDEBUG, 2.5 minutes per robot) was slower for crba (2.8x on the Panda, 3.6x on chain20) "
              "and aba (1.14x, 1.18x), as fast for rnea (0.96x, 1.01x) and slightly faster for computeABADerivatives "
              "(0.97x, 0.94x), so the ode_jac_x ratios below may be up to 6% favourable to derive.")
"""The comparison behind :data:`PINOCCHIO_INSTANTIATED` (best of 10, same states, same run)."""
CXX_DEFINES = ("-DNDEBUG", "-DBOOST_MPL_LIMIT_LIST_SIZE=30", "-DBOOST_MPL_LIMIT_VECTOR_SIZE=30",
               "-DBOOST_MPL_CFG_NO_PREPROCESSED_HEADERS", "-DBOOST_FUSION_INVOKE_MAX_ARITY=12")


def cases() -> dict[str, Callable[[], Robot]]:
    """Row label -> a loader of its Robot, in table order."""
    out: dict[str, Callable[[], Robot]] = {name: (lambda name=name: load_models()[name]) for name in ("panda", "ur5")}
    for n in (12, 20, 40):
        out[f"chain{n}"] = lambda n=n: parse_models(generic_chain(n))[f"chain{n}"]
    for label, (urdf, floating) in ERD.items():
        out[f"{label} (floating)" if floating else label] = lambda urdf=urdf, floating=floating: _erd_robot(urdf, floating)
    return out


def _erd_robot(urdf: str, floating: bool) -> Robot:
    with contextlib.redirect_stderr(io.StringIO()):  # the importer's warnings about placeholder limits
        name, entry = import_urdf_named("example-robot-data:" + urdf, floating=floating, friction=False)
    return parse_robot(name, entry)


def specs(model: SXModel) -> tuple[list[FunctionSpec], list[TemplateFunction]]:
    """The catalogue's mass_matrix, inverse_dynamics, forward_dynamics and ode_jac_x alone (the
    expressions of :func:`derive.codegen.catalogue.function_specs`, ode_jac_x by its own choice of
    form and algorithm: :func:`derive.codegen.catalogue.ode_by_template`, then the template and the
    inverse_dynamics_derivatives it calls, else :func:`derive.codegen.catalogue.cheaper_ode_jacobians`),
    as (expression specs, template functions)."""
    robot, s = model.robot, model.sym
    out = id_m_fd_specs(model)
    if ode_by_template(model):
        return out + [inverse_dynamics_derivatives_spec(model)], [
            t for t in ode_jacobian_templates(model) if t.quantity == "ode_jac_x"]
    x, u = ca.SX.sym("x", robot.nq + robot.nv), ca.SX.sym("u", robot.nv)

    def in_xu(e: ca.SX) -> ca.SX:
        return ca.substitute(e, ca.vertcat(s.q, s.qd, s.tau), ca.vertcat(x, u))

    A, _, _ = cheaper_ode_jacobians(model, model.forward_dynamics(), [("x", x), ("u", u)], in_xu)
    return out + [FunctionSpec(robot.name, "ode_jac_x", None, (("x", x), ("u", u)), (("A", in_xu(A)),), "df/dx of the ODE.")], []


# ---------------------------------------------------------------------------------------------
# Pinocchio's model as C++


ALIGNED = {f"JointModel{kind}{axis}" for kind in "RP" for axis in "XYZ"}
UNALIGNED = {"JointModelRevoluteUnaligned", "JointModelPrismaticUnaligned"}


def _num(values) -> str:
    return ", ".join(repr(float(v)) for v in np.asarray(values, dtype=float).ravel())


def cpp_model(model) -> str:
    """C++ statements that rebuild the pin.Model ``model`` into a ``Model model`` (``JointIndex j`` declared):
    gravity, joints with their placements, each joint's (aggregated) inertia, armature. Frames are left out."""
    lines = [f"model.gravity = Motion(Motion::Vector3({_num(model.gravity.linear)}), "
             f"Motion::Vector3({_num(model.gravity.angular)}));"]
    for i in range(1, model.njoints):
        joint, kind = model.joints[i], model.joints[i].shortname()
        if kind in ALIGNED or kind == "JointModelFreeFlyer":
            ctor = f"{kind}()"
        elif kind in UNALIGNED:
            ctor = f"{kind}(Eigen::Vector3d({_num(joint.extract().axis)}))"
        else:
            raise DeriveError(f"bench pinocchio-cpp: joint '{model.names[i]}' is a {kind}, which the C++ model writer "
                              f"does not handle (only {', '.join(sorted(ALIGNED | UNALIGNED))} and JointModelFreeFlyer)")
        at, body = model.jointPlacements[i], model.inertias[i]
        lines.append(f"j = model.addJoint({model.parents[i]}, {ctor}, se3({{{_num(at.rotation)}}}, "
                     f"{{{_num(at.translation)}}}), {json.dumps(model.names[i])});")
        lines.append(f"model.inertias[j] = inertia({body.mass!r}, {{{_num(body.lever)}}}, {{{_num(body.inertia)}}});")
    if np.any(model.armature):
        lines.append(f"model.armature << {_num(model.armature)};")
    return "\n  ".join(lines)


HARNESS = Template(r"""
#include <pinocchio/multibody.hpp>
#include <pinocchio/algorithm/rnea.hpp>
#include <pinocchio/algorithm/crba.hpp>
#include <pinocchio/algorithm/aba.hpp>
#include <pinocchio/algorithm/aba-derivatives.hpp>
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <vector>
#include "${robot}_inverse_dynamics.h"
#include "${robot}_mass_matrix.h"
#include "${robot}_forward_dynamics.h"
#include "${robot}_ode_jac_x.h"

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

static void print_rows(const char *name, const Eigen::MatrixXd &m) {  /* row-major, as ours */
  std::vector<double> r(m.size());
  for (int i = 0; i < m.rows(); i++)
    for (int k = 0; k < m.cols(); k++) r[i * m.cols() + k] = m(i, k);
  print(name, r.data(), (int)r.size());
}

int main(int argc, char **argv) {
  const int nq = ${nq}, nv = ${nv}, nx = nq + nv, stride = nq + 3 * nv;  /* a state: q, v, tau, qdd */
  if (argc != 4) return 2;
  const int n = atoi(argv[1]), repeats = atoi(argv[2]);
  std::vector<double> states((size_t)n * stride);
  FILE *f = fopen(argv[3], "rb");
  if (!f || fread(states.data(), sizeof(double), states.size(), f) != states.size()) return 3;
  fclose(f);
  Model model = build();
  Data data(model);
  if (model.nq != nq || model.nv != nv) {
    fprintf(stderr, "the C++ model has nq %d, nv %d\n", (int)model.nq, (int)model.nv);
    return 4;
  }
  const double *S = states.data();
  /* Eigen::Ref arguments: the types libpinocchio_default instantiates (and Pinocchio's Python bindings pass) */
  std::vector<Eigen::VectorXd> vectors;
  for (int i = 0; i < n; i++) {
    const double *s = S + (size_t)i * stride;
    vectors.push_back(Eigen::Map<const Eigen::VectorXd>(s, nq));
    vectors.push_back(Eigen::Map<const Eigen::VectorXd>(s + nq, nv));
    vectors.push_back(Eigen::Map<const Eigen::VectorXd>(s + nx, nv));
    vectors.push_back(Eigen::Map<const Eigen::VectorXd>(s + nx + nv, nv));
  }
  typedef Eigen::Ref<const Eigen::VectorXd> Ref;
  std::vector<Ref> q, v, tau, a;
  for (int i = 0; i < n; i++) {
    q.emplace_back(vectors[4 * i]);
    v.emplace_back(vectors[4 * i + 1]);
    tau.emplace_back(vectors[4 * i + 2]);
    a.emplace_back(vectors[4 * i + 3]);
  }
  std::vector<double> out((size_t)nx * nx);

  /* values at the first state */
  ${robot}_inverse_dynamics(S, S + nq, S + nx + nv, out.data());
  print("derive_inverse_dynamics", out.data(), nv);
  ${robot}_mass_matrix(S, out.data());
  print("derive_mass_matrix", out.data(), nv * nv);
  ${robot}_forward_dynamics(S, S + nq, S + nx, out.data());
  print("derive_forward_dynamics", out.data(), nv);
  ${robot}_ode_jac_x(S, S + nx, out.data());
  print("derive_ode_jac_x", out.data(), nx * nx);
  rnea(model, data, q[0], v[0], a[0]);
  print("pin_rnea", data.tau.data(), nv);
  data.M.setZero();
  crba(model, data, q[0]);
  print_rows("pin_crba", data.M);
  aba(model, data, q[0], v[0], tau[0]);
  print("pin_aba", data.ddq.data(), nv);
  computeABADerivatives(model, data, q[0], v[0], tau[0]);
  print_rows("pin_ddq_dq", data.ddq_dq);
  print_rows("pin_ddq_dv", data.ddq_dv);
  fflush(stdout);

  /* ns per call: best of the repeats, the eight loops interleaved within each */
  double *o = out.data();
  double best[8];
  int passes[8] = {0};
  auto measure = [&](int k, auto fn) {
    if (!passes[k]) {
      passes[k] = std::max(1, (int)std::ceil(${sample_ns} / (per_call(fn, n, 1) * n)));
      best[k] = 1e300;
    }
    best[k] = std::min(best[k], per_call(fn, n, passes[k]));
  };
  for (int r = 0; r < repeats; r++) {
    measure(0, [&](int i) { const double *s = S + (size_t)i * stride; ${robot}_inverse_dynamics(s, s + nq, s + nx + nv, o); });
    measure(1, [&](int i) { rnea(model, data, q[i], v[i], a[i]); });
    measure(2, [&](int i) { ${robot}_mass_matrix(S + (size_t)i * stride, o); });
    measure(3, [&](int i) { crba(model, data, q[i]); });
    measure(4, [&](int i) { const double *s = S + (size_t)i * stride; ${robot}_forward_dynamics(s, s + nq, s + nx, o); });
    measure(5, [&](int i) { aba(model, data, q[i], v[i], tau[i]); });
    measure(6, [&](int i) { const double *s = S + (size_t)i * stride; ${robot}_ode_jac_x(s, s + nx, o); });
    measure(7, [&](int i) { computeABADerivatives(model, data, q[i], v[i], tau[i]); });
  }
  const char *names[4] = {"inverse_dynamics", "mass_matrix", "forward_dynamics", "ode_jac_x"};
  for (int k = 0; k < 4; k++) printf("time %s %.3f %.3f\n", names[k], best[2 * k], best[2 * k + 1]);
  fprintf(stderr, "%g\n", o[0] + data.tau[0] + data.M(0, 0) + data.ddq[0] + data.ddq_dq(0, 0));
  return 0;
}
""")


def pinocchio_flags() -> list[str]:
    """g++ flags for Pinocchio's C++ headers and library as the pin wheel installs them (Eigen from casadi's)."""
    if shutil.which("g++") is None:
        raise DeriveError("bench pinocchio-cpp: needs g++ (a C++17 compiler)")
    try:
        import casadi
        import pinocchio
    except ImportError:
        raise DeriveError("bench pinocchio-cpp: needs pinocchio (the pinocchio extra: make bench installs it)") from None
    prefix = next((p for p in Path(pinocchio.__file__).parents
                   if (p / "include" / "pinocchio" / "multibody.hpp").is_file()
                   and (p / "lib" / "libpinocchio_default.so").is_file()), None)
    eigen = Path(casadi.__file__).parent / "include" / "eigen3"
    if prefix is None or not (eigen / "Eigen" / "Core").is_file():
        raise DeriveError("bench pinocchio-cpp: needs Pinocchio's C++ headers and libpinocchio_default.so (the pin wheel's "
                          "cmeel.prefix) and Eigen's headers (casadi/include/eigen3); not found beside the installed packages")
    # -Wno-deprecated-declarations: Pinocchio 4 marks RigidConstraintModel and constraintDynamics, which the
    # contacts harness calls, deprecated; each use printed a page of template warnings into `make bench`
    return ["-O2", "-std=c++17", "-Wno-deprecated-declarations", *CXX_DEFINES,
            *(["-DPINOCCHIO_ENABLE_TEMPLATE_INSTANTIATION"] if PINOCCHIO_INSTANTIATED else []),
            f"-I{prefix / 'include'}", f"-I{eigen}", f"-L{prefix / 'lib'}", f"-Wl,-rpath,{prefix / 'lib'}"]


# ---------------------------------------------------------------------------------------------
# one robot


@dataclass
class Result:
    label: str
    nv: int
    generate_s: float | None = None
    compile_s: float | None = None
    failed: str = ""  # why there are no times
    derive_ns: dict[str, float] = field(default_factory=dict)
    pinocchio_ns: dict[str, float] = field(default_factory=dict)
    model_error: float = float("nan")  # the C++ model's rnea against the Python model's, relative
    value_error: float = float("nan")  # worst of ours against Pinocchio's C++ at one state, relative


def _generate(robot: Robot, folder: Path) -> None:
    """Derive and render the four functions in C into ``folder`` (run in a child process)."""
    model = SXModel(robot)
    check_mass_matrix(model)
    expressions, templates = specs(model)
    files = render_robot(robot, expressions, "0" * 16, templates=templates, backends=[C_BACKEND],
                         progress=lambda spec, prog: check_constants(robot, spec, prog))
    for name, text in files.items():
        path = folder / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(text)


def _child(robot: Robot, folder: Path) -> None:
    try:
        _generate(robot, folder)
    except BaseException:  # reported by the parent
        (folder / "error.txt").write_text(traceback.format_exc())
        raise


def generate_capped(robot: Robot, folder: Path, cap: float) -> float | None:
    """Seconds of :func:`_generate` in a forked child, or None past ``cap`` seconds (the child is then killed)."""
    start = time.perf_counter()
    child = multiprocessing.get_context("fork").Process(target=_child, args=(robot, folder))
    child.start()
    child.join(cap)
    if child.is_alive():
        child.terminate()
        child.join()
        return None
    seconds = time.perf_counter() - start
    if child.exitcode:
        error = folder / "error.txt"
        raise DeriveError(f"bench pinocchio-cpp: generating {robot.name} failed:\n"
                          + (error.read_text() if error.is_file() else f"exit code {child.exitcode}"))
    return seconds


def compile_capped(c_dir: Path, robot: str, cap: float) -> float | None:
    """Seconds of ``cc -O2 -std=c99 -c`` of the generated files (the four functions and, for an ODE Jacobian
    by template, the inverse_dynamics_derivatives it calls), one at a time, or None past ``cap`` seconds in all."""
    start = time.perf_counter()
    for source in sorted(c_dir.glob(f"{robot}_*.c")):
        left = cap - (time.perf_counter() - start)
        try:
            subprocess.run(["cc", "-O2", "-std=c99", "-c", source.name, "-o", source.with_suffix(".o").name],
                           cwd=c_dir, check=True, timeout=max(left, 1))
        except subprocess.TimeoutExpired:
            return None
    return time.perf_counter() - start


def states(robot: Robot, n: int = STATES, seed: int = 0) -> np.ndarray:
    """(n, nq + 3 nv) states [q, v, tau, qdd]: q in the joint box (unit quaternion), the rest normal."""
    rng = np.random.default_rng(seed)
    ref = NumericRobot(robot)
    return np.array([np.concatenate([ref.random_configuration(rng), rng.normal(size=3 * robot.nv)]) for _ in range(n)])


def _relative(a, b) -> float:
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    return float(np.abs(a - b).max() / max(1.0, np.abs(b).max()))


def run_harness(robot: Robot, c_dir: Path, repeats: int, flags: list[str]) -> Result:
    """Build and run the timing program of ``robot`` (whose objects are in ``c_dir``); check its values."""
    import pinocchio as pin

    model = build_model(robot)
    nq, nv = robot.nq, robot.nv
    source = HARNESS.substitute(robot=robot.name, model=cpp_model(model), nq=nq, nv=nv, sample_ns=repr(SAMPLE_NS))
    (c_dir / "harness.cpp").write_text(source)
    xs = states(robot)
    xs.astype(np.float64).tofile(c_dir / "states.bin")
    objects = sorted(p.name for p in c_dir.glob(f"{robot.name}_*.o"))
    subprocess.run(["g++", "harness.cpp", *objects, "-I.", *flags,
                    "-lpinocchio_default", "-lm", "-o", "harness"], cwd=c_dir, check=True)
    out = subprocess.run(["./harness", str(len(xs)), str(repeats), "states.bin"], cwd=c_dir, check=True,
                         capture_output=True, text=True).stdout
    values = {w[1]: np.array(w[2:], dtype=float) for w in map(str.split, out.splitlines()) if w[0] == "check"}
    times = {w[1]: (float(w[2]), float(w[3])) for w in map(str.split, out.splitlines()) if w[0] == "time"}
    result = Result(robot.name, nv, derive_ns={k: t[0] for k, t in times.items()},
                    pinocchio_ns={k: t[1] for k, t in times.items()})

    q, v, tau, a = np.split(xs[0], [nq, nq + nv, nq + 2 * nv])
    result.model_error = _relative(values["pin_rnea"], pin.rnea(model, model.createData(), q, v, a))
    m = values["pin_crba"].reshape(nv, nv)
    errors = [_relative(values["derive_inverse_dynamics"], values["pin_rnea"]),
              _relative(values["derive_mass_matrix"], (np.triu(m) + np.triu(m, 1).T).ravel()),
              _relative(values["derive_forward_dynamics"], values["pin_aba"])]
    if not robot.floating:  # A = [[0, I], [dqdd/dq, dqdd/dv]]; with a floating base, q holds a quaternion
        jac = values["derive_ode_jac_x"].reshape(2 * nv, 2 * nv)[nv:]
        errors += [_relative(jac[:, :nv], values["pin_ddq_dq"].reshape(nv, nv)),
                   _relative(jac[:, nv:], values["pin_ddq_dv"].reshape(nv, nv))]
    result.value_error = max(errors)
    if result.model_error > 1e-12 or result.value_error > 1e-9:
        raise DeriveError(f"bench pinocchio-cpp: {robot.name}: the C++ model's rnea is {result.model_error:.1e} from the "
                          f"Python model's, ours {result.value_error:.1e} from Pinocchio's C++ (a harness bug)")
    return result


def measure(label: str, robot: Robot, repeats: int, flags: list[str], cap: float = CAP_S,
            log: Callable[[str], None] = print) -> Result:
    if robot.parameters or robot.actuated:
        raise DeriveError(f"bench pinocchio-cpp: {robot.name} has parameters or actuator friction, which the "
                          "harness does not pass or Pinocchio does not model")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        seconds = generate_capped(robot, folder, cap)
        if seconds is None:
            log(f"[pinocchio-cpp] {label}: not generated within {cap:.0f} s")
            return Result(label, robot.nv, failed=f"not generated within {cap:.0f} s")
        log(f"[pinocchio-cpp] {label}: generated in {seconds:.1f} s")
        c_dir = folder / "c"
        compiled = compile_capped(c_dir, robot.name, cap)
        if compiled is None:
            log(f"[pinocchio-cpp] {label}: not compiled within {cap:.0f} s")
            return Result(label, robot.nv, seconds, failed=f"not compiled within {cap:.0f} s")
        log(f"[pinocchio-cpp] {label}: compiled in {compiled:.1f} s")
        result = run_harness(robot, c_dir, repeats, flags)
    result.label, result.generate_s, result.compile_s = label, seconds, compiled
    log(f"[pinocchio-cpp] {label}: " + ", ".join(f"{f} {result.derive_ns[f]:.0f}/{result.pinocchio_ns[f]:.0f} ns"
                                                 for f in FUNCTIONS) + f" (values {result.value_error:.1e})")
    return result


# ---------------------------------------------------------------------------------------------
# the section


def table(results: list[Result]) -> list[str]:
    rows = ["| robot | nv | generate s | compile s | function | derive ns | Pinocchio C++ ns | ratio | met |",
            "|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        if r.failed:
            gen = r.failed if r.generate_s is None else f"{r.generate_s:.1f}"
            comp = "-" if r.generate_s is None else r.failed
            rows.append(f"| {r.label} | {r.nv} | {gen} | {comp} | all four | - | - | - | - |")
            continue
        for k, f in enumerate(FUNCTIONS):
            ours, theirs = r.derive_ns[f], r.pinocchio_ns[f]
            ratio = ours / theirs
            head = f"| {r.label} | {r.nv} | {r.generate_s:.1f} | {r.compile_s:.1f}" if k == 0 else "| | | |"
            rows.append(f"{head} | {f} (vs {PINOCCHIO[f]}) | {ours:.0f} | {theirs:.0f} | {ratio:.2f} | "
                        f"{'yes' if ratio <= TARGET else 'no'} |")
    return rows


def section(results: list[Result], repeats: int, quick: bool, seconds: float) -> str:
    done = [r for r in results if not r.failed]
    met = sum(r.derive_ns[f] / r.pinocchio_ns[f] <= TARGET for r in done for f in FUNCTIONS)
    worst = max((r.value_error for r in done), default=float("nan"))
    build = ("the wheel's precompiled algorithms (libpinocchio_default, `-DPINOCCHIO_ENABLE_TEMPLATE_INSTANTIATION`)"
             if PINOCCHIO_INSTANTIATED else "its templates compiled here, header-only, with g++ -O2")
    return "\n".join([
        TITLE, "",
        f"Target (issue \"Large robots\"): the generated C per call within {TARGET:g}x of Pinocchio's C++ for ID, M, FD "
        "and the ODE Jacobian. Per robot, only inverse_dynamics, mass_matrix, forward_dynamics and ode_jac_x (where it "
        "is a template, loops around calls, also the inverse_dynamics_derivatives it calls) are derived "
        "and rendered in C (generate s: derivation, CSE and C rendering, in a child process) and compiled with "
        "`cc -O2 -std=c99 -c`, one file at a time (compile s)"
        + f"; each stage is capped at {CAP_S} s. Pinocchio {_pin_version()}'s model is built in C++ from the same "
        "Robot (tests' pin_model, now derive.reference.pinocchio_model: `addJoint` with the joint's exact model and "
        "placement, its aggregated inertia; its rnea equals the Python model's to 1e-12), and Pinocchio is "
        f"{build}, called from a program compiled with g++ -O2 -DNDEBUG. {BUILD_NOTE} One program runs "
        f"both sides on the same {STATES} seeded states (q uniform in the joint box, v, tau, qdd normal), cycled "
        f"through; each figure is the best of {repeats} samples of about {SAMPLE_NS / 1e6:g} ms, the eight loops "
        "interleaved. ratio = derive / Pinocchio. Pinocchio's crba fills only the upper triangle of M (ours the "
        "whole matrix); computeABADerivatives gives dqdd/dq, dqdd/dv and M^-1 (nv x nv each), while ode_jac_x is "
        "the whole (nq + nv)^2 df/dx of x' = [dq/dt; qdd], which with a floating base includes the quaternion "
        "kinematics rows and the derivatives with respect to the 4 quaternion coordinates. Values at the first "
        f"state agree (ours against Pinocchio's C++: ID, symmetrised M, FD, and for the fixed bases dqdd/dq and "
        f"dqdd/dv from ode_jac_x; worst relative error {worst:.1e})."
        + (" --quick: panda, ur5 and chain12 only." if quick else ""), "",
        *table(results), "",
        f"{met} of {4 * len(done)} comparisons meet the {TARGET:g}x target. The chains are `derive bench large`'s "
        "generic chains (random placements, axes cycling z, y, x); talos_reduced and romeo are example-robot-data's "
        "URDFs imported whole with a floating base (as in the zoo section), tiago_dual whole with its fixed base, all "
        "without their joints' `<dynamics>` friction "
        "(`--no-friction`: Pinocchio's algorithms have none). Measured on a shared 2-core VM: times "
        f"are indicative, the ratios come from the same run; bench time {seconds:.0f} s."])


def _pin_version() -> str:
    import pinocchio

    return pinocchio.__version__


def bench_pinocchio_cpp(args) -> str:
    start = time.perf_counter()
    flags = pinocchio_flags()
    todo = cases()
    if args.quick:
        todo = {k: v for k, v in todo.items() if k in QUICK}
    elif example_robot_data_dir() is None:
        raise DeriveError("bench pinocchio-cpp: needs example-robot-data (pip install example-robot-data)")
    repeats = 5 if args.quick else 15
    results = [measure(label, load(), repeats, flags, log=lambda line: print(line, flush=True))
               for label, load in todo.items()]
    return section(results, repeats, args.quick, time.perf_counter() - start)


def benchmarks() -> dict:
    return {"pinocchio-cpp": bench_pinocchio_cpp}
