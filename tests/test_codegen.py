"""Generated code: C (double and float, via ctypes), Python and CasADi agree with each
other and with the numpy reference at 20 seeded states (10 of a closed chain); the C compiles
clean under -std=c99 -Wall -Wextra -Werror -pedantic and runs clean under ASan/UBSan (every
quantity in every C form, SANITIZED); generated/ is byte-identical to a fresh regeneration.
"""

from __future__ import annotations

import ctypes
import json
import shutil
import subprocess
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from derive.codegen.generate import check, generate
from derive.reference import NumericRobot
from derive.reference.closure import ClosedChainReference
from derive.codegen.catalogue import function_specs
from util import assert_close, closed_inputs, compile_objects, load_module, params, random_q, robots, states, sx_model

ROOT = Path(__file__).resolve().parent.parent
GENERATED = ROOT / "generated"
CFLAGS = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic"]
ROBOTS = sorted(robots())
N_STATES = 20
"""Seeded random states per open chain (each function in C, float C, Python and CasADi against the reference)."""
CLOSED_STATES = 10
"""States per closed chain: its reference solves the closure by Newton and ode_jac_x by 4 ODE calls per
column; 10 states cost a pendulum's 50."""
CLOSED_JAC_STATES = 2
"""Of those, the states where a closed chain's ode_jac_x is also checked against the reference (Richardson
differences, 8 ny closures each: example2's took 10 s of 10 states); at the others C, Python, CasADi and
float C are checked against each other."""


def load_python(robot: str):
    path = GENERATED / robot / "python" / f"{robot}.py"
    module = load_module(path, f"generated_{robot}")
    return module


class CFunctions:
    def __init__(self, lib: Path, manifest: dict, ctype):
        self.lib, self.manifest, self.ctype, self.np_type = ctypes.CDLL(str(lib)), manifest, ctype, (
            np.float64 if ctype is ctypes.c_double else np.float32)

    def __call__(self, fn: dict, args: dict) -> list[np.ndarray]:
        ptr = ctypes.POINTER(self.ctype)
        ins = [np.ascontiguousarray(args[i["name"]], dtype=self.np_type) for i in fn["inputs"]]
        outs = [np.zeros(o["shape"], dtype=self.np_type) for o in fn["outputs"]]
        f = getattr(self.lib, fn["name"])
        f.restype = None
        f(*[a.ctypes.data_as(ptr) for a in ins + outs])
        return [o.astype(float) for o in outs]


CLOSED = {"closure", "velocity_map", "mass_matrix_y", "bias_y", "inverse_dynamics_y", "forward_dynamics_y",
          "constraint_forces", "regressor_y", "base_regressor_y"}
"""The quantities of a closed chain in y; its ode_rhs, ode_jac_x, ode_jac_u and rk4_step are in x = [y; yd]."""


RESIDUAL = ("closure", "motor_to_joint_position", "joint_to_motor_position")
"""The functions returning a closure's residual max |phi| (rounding, compared with a bound)."""


def closed_reference(ref: ClosedChainReference, fn: dict, a: dict):
    """A closed chain's function in y from the numpy reference (Newton closure from the reference
    configuration, K from the frame Jacobians, Kdot qd by complex step, Featherstone's RNEA and CRBA)."""
    kind = fn["quantity"]
    ny = len(ref.y)

    def f(x, u):  # the ODE x' = [yd; ydd]
        q, _ = ref.closure(x[:ny])
        return np.concatenate([x[ny:], ref.forward_dynamics(q, x[ny:], u)])

    if kind in ("ode_rhs", "ode_jac_x", "ode_jac_u", "rk4_step"):
        x, u = a["x"], a["u"]
        if kind == "ode_rhs":
            return f(x, u)
        if kind == "ode_jac_u":
            return np.vstack([np.zeros((ny, ny)), np.linalg.inv(ref.mass_matrix(ref.closure(x[:ny])[0]))])
        if kind == "ode_jac_x":  # central differences, Richardson-extrapolated (error O(h^4): the Delta's
            # A ~ 1e3 has a 1e-9 relative truncation error at h = 1e-3, 16 times less at h = 2.5e-4)
            return richardson(lambda v: f(v, u), x)
        h = a["dt"][0]
        k1 = f(x, u)
        k2 = f(x + h / 2 * k1, u)
        k3 = f(x + h / 2 * k2, u)
        k4 = f(x + h * k3, u)
        return x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    if fn.get("coordinates") == "outputs":  # joint -> motor: the loops closed with the joints o held, by Newton
        q, residual = ref.closure_from_outputs(a["o"])
        J = ref.output_jacobian(q)
        if kind == "joint_to_motor_position":
            return [q[ref.y], np.array([1.0]), np.array([residual])]
        if kind == "joint_to_motor_velocity":
            return np.linalg.solve(J, a["od"])
        if kind == "joint_to_motor_torque":
            return J.T @ a["tau_o"]
        raise AssertionError(kind)
    q, residual = ref.closure(a["y"])
    yd, ydd, tau = a["yd"], a["ydd"], a["tau_y"]
    if kind.startswith("motor_to_joint_"):  # J = d o / d y, G's rows of the outputs
        J = ref.output_jacobian(q)
        names = [c.name for c in ref.robot.coordinates]
        if kind == "motor_to_joint_position":
            return [q[[names.index(c) for c in ref.robot.outputs]], np.array([1.0]), np.array([residual])]
        return J @ yd if kind == "motor_to_joint_velocity" else np.linalg.solve(J.T, tau)
    if kind == "closure":  # the residual is compared with 1e-12, not with the reference's own rounding
        return [q, np.array([1.0]), np.array([residual])]
    if kind == "velocity_map":
        return ref.projection(q)
    if kind == "mass_matrix_y":
        return ref.mass_matrix(q)
    if kind == "bias_y":
        return ref.bias(q, yd)
    if kind == "inverse_dynamics_y":
        return ref.inverse_dynamics(q, yd, ydd)
    if kind == "forward_dynamics_y":
        return ref.forward_dynamics(q, yd, tau)
    if kind == "regressor_y":  # G^T Y of the reference's own Y (Featherstone's linear form)
        return ref.regressor(q, yd, ydd)
    if kind == "base_regressor_y":  # its base columns
        return ref.regressor(q, yd, ydd)[:, [b["column"] for b in fn["base_parameters"]]]
    if kind == "constraint_forces":  # the tree's KKT multiplier at tau = S^T tau_y
        return ref.kkt_forward_dynamics(q, ref.projection(q) @ yd, ref.actuation(tau))[1]
    raise AssertionError(kind)


def richardson(g, x: np.ndarray, h: float = 2.5e-4) -> np.ndarray:
    """dg/dx by central differences at h and h/2, Richardson-extrapolated: (4 D(h/2) - D(h)) / 3."""
    eye = np.eye(len(x))

    def d(step):
        return np.array([(g(x + step * eye[k]) - g(x - step * eye[k])) / (2 * step) for k in range(len(x))]).T

    return (4 * d(h / 2) - d(h)) / 3


def reference(ref: NumericRobot, fn: dict, a: dict) -> np.ndarray:
    if fn.get("coordinates") in ("y", "outputs"):
        return closed_reference(a["closed"], fn, a)
    q, qd, qdd, tau = a["q"], a["qd"], a["qdd"], a["tau"]
    nq, nv = len(q), len(qd)
    kind = fn["quantity"]
    wrenches = {f: a["w"][6 * k:6 * k + 6] for k, f in enumerate(a["wrench_frames"])}

    def f(x, u):  # the ODE x' = [dq/dt; qdd]
        return np.concatenate([ref.q_dot(x[:nq], x[nq:]), ref.aba(x[:nq], x[nq:], u)])

    if kind == "bundle":  # each output is the quantity of its name
        return [reference(ref, part, a) for part in fn["bundle"]]
    if kind == "bias":
        return ref.rnea(q, qd, np.zeros(nv))
    if kind == "jdot_qd":
        return ref.jdot_v(q, qd, fn["frame"])
    if kind == "frame_acceleration":
        return ref.frame_acceleration(q, qd, qdd, fn["frame"])
    if kind == "com":
        return ref.com(q)
    if kind == "com_jacobian":
        return ref.com_jacobian(q)
    if kind == "centroidal_map":
        return ref.centroidal_map(q)
    if kind == "inverse_dynamics_fext":
        return ref.rnea(q, qd, qdd, wrenches)
    if kind == "forward_dynamics_fext":
        return ref.aba(q, qd, tau, wrenches)
    if kind == "fk_jacobian":
        return [ref.frame_pose(q, fn["frame"]), ref.jacobian(q, fn["frame"])]
    if kind == "fk":
        return ref.frame_pose(q, fn["frame"])
    if kind == "fk_all":  # every link's pose, stacked in the manifest's order of links
        poses = ref.fk(q)
        return np.vstack([poses[link] for link in fn["links"]])
    if kind == "jacobian":
        return ref.jacobian(q, fn["frame"])
    if kind == "manipulability":  # eq. 30 from the singular values of the task rows (mu3 = sqrt det J J^T)
        s = np.linalg.svd(ref.jacobian(q, fn["frame"])[fn["task_rows"]], compute_uv=False)
        return np.array([s[0] / s[-1], (s[0] / s[-1]) ** 2, np.prod(s)])
    if kind == "mass_matrix":
        return ref.crba(q)
    if kind == "coriolis_matrix":
        return ref.coriolis_matrix(q, qd)
    if kind == "gravity":
        return ref.gravity(q)
    if kind == "inverse_dynamics":
        return ref.rnea(q, qd, qdd)
    if kind == "forward_dynamics":
        return ref.aba(q, qd, tau)
    if kind == "ode_rhs":
        return f(np.concatenate([q, qd]), tau)
    if kind == "rk4_step":
        h, x = a["dt"][0], np.concatenate([q, qd])
        k1 = f(x, tau)
        k2 = f(x + h / 2 * k1, tau)
        k3 = f(x + h / 2 * k2, tau)
        k4 = f(x + h * k3, tau)
        x = x + h / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        if ref.floating:  # rk4_step projects the base quaternion back onto the unit sphere
            x[3:7] /= np.linalg.norm(x[3:7])
        return x
    if kind == "regressor":  # the reference's own Y (Featherstone's linear form); pi in the manifest
        return ref.regressor(q, qd, qdd)
    if kind == "base_regressor":  # its base columns
        return ref.regressor(q, qd, qdd)[:, [b["column"] for b in fn["base_parameters"]]]
    if kind == "ode_jac_u":
        return np.vstack([np.zeros((nq, nv)), np.linalg.inv(ref.crba(q))])
    if kind == "inverse_dynamics_derivatives":  # complex step through the reference RNEA (friction smoothed)
        return complex_step(lambda x: ref.rnea(x[:nq], x[nq:], qdd.astype(complex), smooth=True), np.concatenate([q, qd]))
    if kind == "ode_jac_x":  # complex step through the reference ABA
        return complex_step(lambda x: f(x, tau.astype(complex)), np.concatenate([q, qd]))
    raise AssertionError(kind)


def complex_step(g, x: np.ndarray, h: float = 1e-30) -> np.ndarray:
    """dg/dx of a function g that takes complex arguments, column by column by the complex step:
    Im g(x + i h e_k) / h, exact to rounding (no subtraction)."""
    eye = np.eye(len(x))
    return np.array([g(x + 1j * h * eye[k]).imag / h for k in range(len(x))]).T


@pytest.mark.parametrize("robot", ROBOTS)
def test_generated_c_python_casadi_match_reference(robot, committed_library):
    """All of generated/<robot>/c built (conftest.py: -std=c99 -Wall -Wextra -Werror -pedantic), double (-O1) and float (-O0)."""
    manifest = json.loads((GENERATED / robot / "manifest.json").read_text())
    c_double = CFunctions(committed_library(robot), manifest, ctypes.c_double)
    c_float = CFunctions(committed_library(robot, ["-DDERIVE_FLOAT"]), manifest, ctypes.c_float)
    py = load_python(robot)
    model = sx_model(robot)
    casadi_fns = {s.name: ca.Function(s.name, [x for _, x in s.inputs], [e for _, e in s.outputs])
                  for s in function_specs(model)}
    expression_fns = [f["name"] for f in manifest["functions"] if f["ops"] is not None]
    assert sorted(casadi_fns) == sorted(expression_fns)
    r = robots()[robot]
    ref = NumericRobot(r)
    p = params(r)
    rng = np.random.default_rng(1)
    closed = ClosedChainReference(r) if r.closed else None
    for index, (q, qd, qdd) in enumerate(states(r, n=CLOSED_STATES if r.closed else N_STATES)):
        tau = rng.normal(size=r.nv) * 5
        a = {"q": q, "qd": qd, "qdd": qdd, "tau": tau, "x": np.concatenate([q, qd]), "u": tau, "p": p,
             "dt": np.array([0.01]), "w": rng.normal(size=6 * len(r.wrench_frames)) * 5,
             "wrench_frames": manifest["wrench_frames"]}
        if closed:  # the functions in y near the reference configuration; the tree's at the closed q
            a |= closed_inputs(r, rng) | {"closed": closed}
            a["q"] = closed.closure(a["y"])[0]
        at = np.array2string(q)  # once per state: formatting q for every output took 1 s of Panda's 20
        for fn in manifest["functions"]:
            if fn["quantity"] == "ik":
                continue   # a solver, not a formula: tests/test_ik.py
            shapes = [tuple(o["shape"]) for o in fn["outputs"]]
            args = [a[i["name"]] for i in fn["inputs"]]

            def outputs(value) -> list[np.ndarray]:
                value = value if isinstance(value, (list, tuple)) else [value]
                return [np.asarray(v, dtype=float).reshape(shp) for v, shp in zip(value, shapes, strict=True)]

            got_c = outputs(c_double(fn, a))
            against_reference = not (closed and fn["quantity"] == "ode_jac_x" and index >= CLOSED_JAC_STATES)
            expected = outputs(reference(ref, fn, a)) if against_reference else got_c
            got_py = outputs(getattr(py, fn["python"]["function"])(*args))
            # template-bodied functions (loops, calls) have no single expression graph to evaluate
            got_ca = outputs(casadi_fns[fn["name"]](*args)) if fn["name"] in casadi_fns else None
            got_float = outputs(c_float(fn, a))
            for k, o in enumerate(fn["outputs"]):
                what = f"{fn['name']} output {o['name']} at q = {at}"
                if fn["quantity"] in RESIDUAL and o["name"] == "residual":  # max |phi|: rounding, not a value
                    assert got_c[k][0] <= 1e-12 and got_py[k][0] <= 1e-12 and got_ca[k][0] <= 1e-12, what
                    assert got_float[k][0] <= 1e-5, what
                    continue
                if against_reference:  # else expected is got_c: the others are checked against the C
                    assert_close(got_c[k], expected[k], what="C " + what)
                assert_close(got_py[k], got_c[k], rtol=1e-12, what="Python vs C " + what)
                if got_ca is not None:
                    assert_close(got_ca[k], got_c[k], rtol=1e-12, what="CasADi vs C " + what)
                assert_close(got_float[k], expected[k], rtol=1e-4, what="float C " + what)


@pytest.mark.parametrize("robot", ROBOTS)
def test_python_returns_what_the_manifest_declares(robot):
    """Every generated Python function of every robot returns exactly manifest["functions"][k]["python"]
    ["returns"]: one entry, the value itself; more, a tuple in that order; shape [] an int (a status),
    else a float ndarray of exactly that shape. The C entry's writes match the language-free outputs."""
    manifest = json.loads((GENERATED / robot / "manifest.json").read_text())
    py = load_python(robot)
    r = robots()[robot]
    rng = np.random.default_rng(2)
    q = random_q(r, rng)
    a = {"q": q, "qd": rng.normal(size=r.nv), "qdd": rng.normal(size=r.nv), "tau": rng.normal(size=r.nv),
         "x": np.concatenate([q, rng.normal(size=r.nv)]), "u": rng.normal(size=r.nv), "p": params(r),
         "dt": np.array([0.01]), "q0": None}
    if r.closed:
        a |= closed_inputs(r, rng)
    assert manifest["functions"]
    for fn in manifest["functions"]:
        a["w"] = rng.normal(size=6 * len(r.wrench_frames)) if fn["quantity"].endswith("_fext") else None
        if fn["quantity"] == "ik":
            a["T"] = getattr(py, f"fk_{fn['frame']}")(q)
        returns = fn["python"]["returns"]
        value = getattr(py, fn["python"]["function"])(*[a[i["name"]] for i in fn["inputs"]])
        values = value if len(returns) > 1 else (value,)
        assert isinstance(values, tuple) and len(values) == len(returns), fn["name"]
        for v, declared in zip(values, returns):
            what = f"{fn['name']} -> {declared['name']}"
            if declared["shape"] == []:
                assert declared["type"] == "int" and isinstance(v, int), what
            else:
                assert isinstance(v, np.ndarray) and v.dtype == np.float64, what
                assert list(v.shape) == declared["shape"], f"{what}: {v.shape} != {declared['shape']}"
        # the language-free outputs (row x col) and the C arrays name the same things
        arrays = [o for o in returns if o["shape"]]
        assert [o["name"] for o in arrays] == [o["name"] for o in fn["outputs"]], fn["name"]
        assert [int(np.prod(o["shape"])) for o in fn["outputs"]] == [w["length"] for w in fn["c"]["writes"]]
        assert [int(np.prod(o["shape"])) for o in arrays] == [w["length"] for w in fn["c"]["writes"]]
        assert [i["name"] for i in fn["inputs"]] == [x["name"] for x in fn["c"]["reads"]]
        assert fn["c"]["returns"] == ("int" if fn["quantity"] == "ik" else "void")


def test_python_functions_check_their_inputs():
    py = load_python("planar_2r")
    with pytest.raises(ValueError, match="q must have 2 elements"):
        py.mass_matrix([0.0, 1.0, 2.0])
    assert py.mass_matrix([0.1, 0.2]).shape == (2, 2)
    assert py.jacobian_tcp([0.1, 0.2]).shape == (6, 2)


SANITIZED = ("cartpole", "delta", "fourbar", "parallel_ankle", "pendulum", "planar_2r", "rrprr")
"""The robots of the sanitizer run: every quantity in every C form (straight line or template) that any
shipped robot has, nv 1 to 5, prismatic joints, planar and spatial closures, motor maps (a third of the
C, without Panda's 1.2 MB, UR5's and example2's: 30 s of CPU to 12)."""


def test_generated_c_runs_clean_under_sanitizers(tmp_path):
    """Every function of the SANITIZED robots called from a C driver built with ASan and UBSan; those
    robots have every (quantity, C form) that any shipped robot has."""
    def forms(robot: str) -> set:
        manifest = json.loads((GENERATED / robot / "manifest.json").read_text())
        return {(fn["quantity"], fn["c"]["form"]) for fn in manifest["functions"]}

    missing = set().union(*map(forms, ROBOTS)) - set().union(*map(forms, SANITIZED))
    assert not missing, f"add a robot with {sorted(missing)} to SANITIZED"
    lines = ['#include <stdio.h>']
    calls = []
    sources = []
    for robot in SANITIZED:
        manifest = json.loads((GENERATED / robot / "manifest.json").read_text())
        lines.append(f'#include "{robot}.h"')
        sources += sorted((GENERATED / robot / "c").glob("*.c"))
        for fn in manifest["functions"]:
            decls, args = [], []
            for k, item in enumerate(fn["inputs"] + fn["outputs"]):
                size = max(1, int(np.prod(item["shape"])))
                decls.append(f"DERIVE_REAL a{k}[{size}];")
                decls.append(f"for (i = 0; i < {size}; ++i) a{k}[i] = (DERIVE_REAL)(0.1 + 0.01 * i);")
                if item["name"] in ("y", "x") and k < len(fn["inputs"]) and "closed_chain" in manifest:
                    # a closed chain's y at its reference configuration: an assembly exists there
                    decls += [f"a{k}[{i}] = (DERIVE_REAL){v!r};" for i, v in enumerate(manifest["closed_chain"]["reference_y"])]
                args.append(f"a{k}")
            out = len(fn["inputs"])
            size = int(np.prod(fn["outputs"][0]["shape"]))
            calls.append("{ int i; " + " ".join(decls) + f" {fn['name']}({', '.join(args)});"
                         f" for (i = 0; i < {size}; ++i) sum += a{out}[i]; }}")  # first output
    lines.append("int main(void) {\n    double sum = 0.0;\n    " + "\n    ".join(calls)
                 + '\n    printf("%g\\n", sum);\n    return 0;\n}')
    driver = tmp_path / "driver.c"
    driver.write_text("\n".join(lines) + "\n")
    includes = [f"-I{GENERATED / r / 'c'}" for r in SANITIZED]
    exe = tmp_path / "driver"
    # no -g: a finding still names its function (7 s of the compiler's 28 s of CPU)
    argv = ["cc", *CFLAGS, "-O0", "-fsanitize=address,undefined", "-fno-sanitize-recover=all", *includes]
    # one translation unit per robot that includes its C files (each file alone is a unit of the
    # Cortex-M builds, tests/test_firmware.py): half the compiler's CPU time of one process per file
    units = []
    for robot in SANITIZED:
        unit = tmp_path / f"unit_{robot}.c"
        unit.write_text("".join(f'#include "{s}"\n' for s in sources if s.parent.parent.name == robot))
        units.append(unit)
    objects = compile_objects(argv, [driver, *units], tmp_path)  # one unit per process, CPUs at once
    subprocess.run([*argv, "-o", str(exe), *map(str, objects), "-lm"], check=True, capture_output=True, text=True)
    run = subprocess.run([str(exe)], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert np.isfinite(float(run.stdout))
    assert "runtime error" not in run.stderr


def test_regeneration_is_byte_identical(tmp_path):
    """Regenerate into a temporary folder without the cache and compare with generated/, which
    tests/test_batch.py, test_ik.py, test_jax.py and test_trajopt.py copy (conftest.py's generated_copy)."""
    out = tmp_path / "generated"
    generate(robots(), out, use_cache=False, log=lambda s: None)
    fresh = {p.relative_to(out).as_posix(): p.read_bytes() for p in out.rglob("*") if p.is_file()}
    # not Python's byte-code cache, which importing a generated module writes beside it
    committed = {p.relative_to(GENERATED).as_posix(): p.read_bytes() for p in GENERATED.rglob("*")
                 if p.is_file() and "__pycache__" not in p.parts}
    assert sorted(fresh) == sorted(committed)
    differing = [k for k in fresh if fresh[k] != committed[k]]
    assert not differing, f"regeneration differs from generated/: {differing[:10]}"


def test_check_names_stale_files(tmp_path):
    out = tmp_path / "generated"
    shutil.copytree(GENERATED, out)
    assert check(robots(), out) == []
    victim = out / "pendulum" / "c" / "pendulum_gravity.c"
    victim.write_text(victim.read_text() + "/* edited */\n")
    (out / "planar_2r" / "python" / "planar_2r.py").unlink()
    problems = check(robots(), out)
    assert any("pendulum_gravity.c (edited by hand)" in p for p in problems)
    assert any("planar_2r.py (missing)" in p for p in problems)


def test_python_byte_code_cache_is_not_a_stale_file(tmp_path):
    """Importing a generated module writes python/__pycache__/*.pyc beside it: Python's cache, not a file
    the check names, and the robot still counts as intact (not derived again)."""
    import py_compile

    out = tmp_path / "generated"
    shutil.copytree(GENERATED, out)
    module = out / "pendulum" / "python" / "pendulum.py"
    py_compile.compile(str(module), cfile=str(module.parent / "__pycache__" / "pendulum.cpython-311.pyc"))
    assert check(robots(), out) == []
    logs = []
    generate({"pendulum": robots()["pendulum"]}, out, log=logs.append)
    assert not any("deriving" in line for line in logs), logs


def test_unchanged_robots_are_not_rederived(tmp_path):
    out = tmp_path / "generated"
    shutil.copytree(GENERATED, out)
    logs: list[str] = []
    generate(robots(), out, only=["pendulum", "cartpole"], log=logs.append)
    assert any("pendulum: unchanged, kept" in line for line in logs)
    assert check(robots(), out) == []


def test_out_folder_of_other_files_is_refused_and_kept(tmp_path, capsys):
    """`--out` never deletes a folder that is not derive's; a derive folder keeps foreign entries."""
    from derive.cli import main

    foreign = tmp_path / "mine"
    foreign.mkdir()
    (foreign / "important.txt").write_text("keep me")
    assert main(["generate", "--robot", "pendulum", "--out", str(foreign)]) == 2
    assert "not a derive output folder" in capsys.readouterr().err
    assert sorted(p.name for p in foreign.iterdir()) == ["important.txt"]

    out = tmp_path / "gen"
    assert main(["generate", "--robot", "pendulum", "--out", str(out)]) == 0
    (out / "NOTES.md").write_text("notes")
    assert main(["generate", "--robot", "pendulum", "--out", str(out), "--no-cache"]) == 0
    assert (out / "NOTES.md").read_text() == "notes"
    assert oct(out.stat().st_mode & 0o777) != oct(0o700)
