"""Continuous joints: unbounded revolutes whose reported angles are wrapped to (-pi, pi].

A planar 2R arm whose shoulder is continuous (and whose elbow is a bounded revolute): it parses
with velocity and effort limits only, moves as a revolute (symbolic, numpy reference, Pinocchio,
generated C and Python agree), and IK from a start several turns away returns the shoulder in
(-pi, pi] in C, Python, the solver and the CLI, as the CSVs of simulate and trajopt write it;
URDF's continuous imports as continuous; position limits on one are a one-line error.
"""

from __future__ import annotations

import csv
import ctypes
import json
import math

import casadi as ca
import numpy as np
import pytest

from derive.analysis.grubler import mechanism_from_robot
from derive.analysis.workspace import sample_configurations
from derive.bench.ik import ik_sources
from derive.cli import main
from derive.codegen.generate import generate
from derive.description.joints import wrap_angle
from derive.description.model import parse_models
from derive.description.robot import ModelError
from derive.description.urdf import import_urdf
from derive.reference import NumericRobot
from derive.solvers.ik import solve_ik
from derive.solvers.simulate import simulate, write_csv
from derive.symbolic.model import SXModel
from pin_model import PinRobot
from util import assert_close, build_library, load_module

MODELS = """
robots:
  spinner:
    gravity: [0.5, -0.3, -9.81]
    links:
      - {name: base}
      - {name: l1, mass: 1.0, com: [0.5, 0.02, 0.01], inertia: [0.01, 0.08, 0.08]}
      - {name: l2, mass: 0.7, com: [0.4, 0, -0.02], inertia: [0.01, 0.05, 0.05]}
    joints:
      - {name: turn, type: continuous, parent: base, child: l1, axis: [0, 0, 1], limits: {velocity: 3, effort: 20}}
      - {name: elbow, type: revolute, parent: l1, child: l2, origin: {xyz: [1, 0, 0]}, axis: [0, 0, 1],
         limits: {lower: -2.5, upper: 2.5}}
    frames:
      - {name: tcp, link: l2, xyz: [0.8, 0, 0]}
"""
ROBOT = parse_models(MODELS)["spinner"]
STRICT = ["cc", "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O1", "-fPIC"]
Q_TRUE = np.array([2.0, 1.0])   # the target's configuration
Q_FAR = np.array([40.0, 1.2])   # a start 6 turns away (40 - 12 pi = 2.30)


def in_range(a) -> bool:
    return bool(np.all((np.asarray(a) > -math.pi) & (np.asarray(a) <= math.pi)))


@pytest.fixture(scope="module")
def gen(tmp_path_factory):
    out = tmp_path_factory.mktemp("continuous") / "generated"
    generate({"spinner": ROBOT}, out, use_cache=False, log=lambda s: None)
    return out


@pytest.fixture(scope="module")
def py(gen):
    module = load_module(gen / "spinner" / "python" / "spinner.py", "generated_spinner")
    return module


def target() -> np.ndarray:
    return NumericRobot(ROBOT).frame_pose(Q_TRUE, "tcp")


# ---------------------------------------------------------------- the description


def test_continuous_joint_parses_as_an_unbounded_revolute():
    turn, elbow = ROBOT.coordinates
    assert (ROBOT.joints[0].type, ROBOT.joints[0].dof, turn.unit, turn.continuous, elbow.continuous) == (
        "continuous", 1, "rad", True, False)
    assert (turn.limits.lower, turn.limits.upper, turn.limits.velocity, turn.limits.effort) == (None, None, 3.0, 20.0)
    assert ROBOT.joint_box() == ((-math.pi, -2.5), (math.pi, 2.5))
    assert ROBOT.continuous_indices == (0,)
    # a mimic joint following the turn at half its rate, or as a rack: q and q + 2 pi differ, nothing is wrapped
    for jtype, multiplier, wrapped in (("revolute", 0.5, ()), ("prismatic", 1.0, ()), ("revolute", -2.0, (0,))):
        follower = parse_models(MODELS.replace("type: revolute, parent: l1", f"type: {jtype}, parent: l1").replace(
            "limits: {lower: -2.5, upper: 2.5}", f"mimic: {{joint: turn, multiplier: {multiplier}}}"))["spinner"]
        assert follower.continuous_indices == wrapped, (jtype, multiplier)
    assert mechanism_from_robot(ROBOT).dof == 2
    np.testing.assert_array_equal(ROBOT.wrap([[22.4, 22.4], [-math.pi, -math.pi]]), [[22.4 - 8 * math.pi, 22.4],
                                                                                     [math.pi, -math.pi]])


def test_wrap_angle_is_exact_and_in_the_half_open_range():
    a = np.array([0.0, -0.0, 1.0, math.pi, -math.pi, 3 * math.pi, -3 * math.pi, 2 * math.pi, 22.4, -52.3, 39.1,
                  -19.9, 1e6, -1e6, 7.0 * math.pi / 2])
    w = wrap_angle(a)
    assert in_range(w)
    # IEEE remainder is exact too: the same bits, but -pi (a tie) where wrap_angle gives pi
    expected = np.array([math.remainder(x, 2 * math.pi) for x in a])
    expected[expected == -math.pi] = math.pi
    np.testing.assert_array_equal(w, expected)
    assert wrap_angle(math.pi) == math.pi and wrap_angle(-math.pi) == math.pi


@pytest.mark.parametrize("limits, field", [("{lower: -1, upper: 1}", "lower"), ("{upper: 1, velocity: 2}", "upper")])
def test_position_limits_on_a_continuous_joint_are_a_one_line_error(tmp_path, capsys, limits, field):
    path = tmp_path / "bad.yaml"
    path.write_text(MODELS.replace("limits: {velocity: 3, effort: 20}", f"limits: {limits}"))
    assert main(["--models", str(path), "info", "spinner"]) == 2
    err = capsys.readouterr().err
    assert err == (f"derive: error: {path}: robot 'spinner': joints[0].limits.{field}: a continuous joint has no "
                   "position limits (velocity and effort may be given): drop it, or make the joint revolute\n")


def test_dh_rows_and_urdf_joints_may_be_continuous(tmp_path):
    dh = parse_models("""
robots:
  dh_arm:
    dh:
      convention: standard
      rows:
        - {joint: q1, type: continuous, a: 0.5, link: l1, mass: 1, com: [-0.25, 0, 0], inertia: [0.01, 0.02, 0.02]}
        - {joint: q2, type: revolute, a: 0.4, link: l2, mass: 1, com: [-0.2, 0, 0], inertia: [0.01, 0.02, 0.02],
           limits: {lower: -2, upper: 2}}
""")["dh_arm"]
    assert [(c.name, c.type) for c in dh.coordinates] == [("q1", "continuous"), ("q2", "revolute")]
    with pytest.raises(ModelError, match=r"dh.rows\[0\].limits.lower: a continuous joint has no position limits"):
        parse_models("robots: {a: {dh: {convention: standard, rows: [{joint: q1, type: continuous, a: 0.5, link: l1, "
                     "mass: 1, inertia: [0.01, 0.02, 0.02], limits: {lower: -1}}]}}}")
    urdf = tmp_path / "wheel.urdf"
    urdf.write_text("""<robot name="wheel">
  <link name="base"/>
  <link name="hub"><inertial><mass value="1"/><origin xyz="0 0 0.1"/>
    <inertia ixx="0.01" iyy="0.01" izz="0.02" ixy="0" ixz="0" iyz="0"/></inertial></link>
  <joint name="spin" type="continuous"><parent link="base"/><child link="hub"/><axis xyz="0 0 1"/>
    <limit lower="-1" upper="1" effort="5" velocity="10"/></joint>
</robot>""")
    entry = import_urdf(urdf)
    assert entry["joints"][0]["type"] == "continuous"
    assert entry["joints"][0]["limits"] == {"velocity": 10.0, "effort": 5.0}  # URDF ignores a continuous lower/upper
    wheel = parse_models(json.dumps({"robots": {"wheel": entry}}))["wheel"]
    assert [c.continuous for c in wheel.coordinates] == [True]


# ---------------------------------------------------------------- dynamics: a revolute's


def test_symbolic_reference_pinocchio_and_generated_code_agree(gen, py, tmp_path):
    model, ref, pin = SXModel(ROBOT), NumericRobot(ROBOT), PinRobot(ROBOT)  # pin: one angle, as revolute
    s = model.sym
    f = ca.Function("f", [s.q, s.qd, s.qdd], [model.mass_matrix(), model.inverse_dynamics()])
    names = ["spinner_mass_matrix", "spinner_inverse_dynamics"]
    lib = ctypes.CDLL(str(build_library(STRICT, [gen / "spinner" / "c" / f"{n}.c" for n in names],
                                        tmp_path / "libspinner.so")))
    ptr = ctypes.POINTER(ctypes.c_double)

    def call(name, shape, *args):
        out = np.zeros(shape)
        getattr(lib, name)(*[np.ascontiguousarray(a, dtype=float).ctypes.data_as(ptr) for a in args],
                           out.ctypes.data_as(ptr))
        return out

    rng = np.random.default_rng(0)
    for _ in range(10):
        q = np.array([rng.uniform(-20, 20), rng.uniform(-2.5, 2.5)])   # any angle, several turns out
        qd, qdd = rng.normal(size=2), rng.normal(size=2)
        M, tau = ref.crba(q), ref.rnea(q, qd, qdd)
        M_sx, tau_sx = (np.array(x).reshape(-1) for x in f(q, qd, qdd))
        for got, expected, what in [(M_sx, M, "symbolic M"), (tau_sx, tau, "symbolic ID"),
                                    (pin.crba(q), M, "Pinocchio M"), (pin.rnea(q, qd, qdd), tau, "Pinocchio ID"),
                                    (call(names[0], (2, 2), q), M, "C M"), (call(names[1], 2, q, qd, qdd), tau, "C ID"),
                                    (py.mass_matrix(q), M, "Python M"), (py.inverse_dynamics(q, qd, qdd), tau, "Python ID")]:
            assert_close(np.reshape(got, np.shape(expected)), expected, what=what)
        # q and q + 2 pi are one configuration
        assert_close(ref.crba(q + [2 * math.pi, 0]), M, rtol=1e-12, what="M periodic")


def test_manifest_names_the_continuous_joints(gen):
    manifest = json.loads((gen / "spinner" / "manifest.json").read_text())
    assert manifest["continuous"] == ["turn"]
    assert [j["type"] for j in manifest["joints"]] == ["continuous", "revolute"]
    assert manifest["conventions"]["continuous_joints"].startswith("continuous joints (turn): unbounded revolute")


# ---------------------------------------------------------------- outputs wrapped


def test_ik_from_turns_away_returns_wrapped_angles_in_c_python_solver_and_cli(gen, py, tmp_path, capsys):
    T = target()
    lib = {}
    for extra in ((), ("-DDERIVE_FLOAT",)):
        built = build_library(STRICT + list(extra), ik_sources(gen / "spinner" / "c", "spinner"),
                              tmp_path / f"libik{len(extra)}.so")
        lib[extra] = ctypes.CDLL(str(built)).spinner_ik_tcp
        lib[extra].restype = ctypes.c_int

    def c_ik(extra=()):
        real = np.float32 if extra else np.float64
        ptr = ctypes.POINTER(ctypes.c_float if extra else ctypes.c_double)
        q, residual = np.zeros(2, real), np.zeros(2, real)
        args = [np.ascontiguousarray(a, dtype=real) for a in (T, Q_FAR)]
        status = lib[extra](*[a.ctypes.data_as(ptr) for a in args], None, q.ctypes.data_as(ptr),
                            residual.ctypes.data_as(ptr))
        return q.astype(float), status

    q_c, status_c = c_ik()
    q_py, _, status_py = py.ik_tcp(T, Q_FAR)
    assert status_c == status_py == 0
    np.testing.assert_allclose(q_c, Q_TRUE, atol=1e-5)          # not 2 + 12 pi
    np.testing.assert_allclose(q_py, q_c, rtol=0, atol=1e-9)    # the same iterate
    q_f, status_f = c_ik(("-DDERIVE_FLOAT",))
    assert status_f == 0 and in_range(np.float32(q_f[0])) and abs(q_f[0] - 2.0) < 1e-3
    # the Python batch path wraps each state too
    q_batch, _, status_batch = py.ik_tcp(np.stack([T, T]), np.stack([Q_FAR, Q_FAR + [-60.0, 0.0]]))
    assert (status_batch == 0).all() and in_range(q_batch[:, 0]) and np.allclose(q_batch, Q_TRUE, atol=1e-5)
    # the solver, with and without a rest posture several turns away
    for rest in (None, [-30.0, 1.0]):
        result = solve_ik(ROBOT, T, q0=Q_FAR, rest=rest, method="lm")
        assert result.success and in_range(result.q[0]) and np.allclose(result.q, Q_TRUE, atol=1e-5), rest
    # the CLI: the printed angle is the wrapped one, and says so
    path = tmp_path / "models.yaml"
    path.write_text(MODELS)
    yaw = float(Q_TRUE.sum())
    assert main(["--models", str(path), "ik", "spinner", "--xyz", *map(str, T[:3, 3]), "--rpy", "0", "0", str(yaw),
                 "--q0", "40", "1.2"]) == 0
    out = capsys.readouterr().out
    line = next(x for x in out.splitlines() if x.strip().startswith("turn "))
    assert line.endswith("(continuous: wrapped to (-pi, pi])") and abs(float(line.split("=")[1].split()[0]) - 2.0) < 1e-5


def test_simulate_integrates_the_winding_angle_and_writes_it_wrapped(gen, tmp_path):
    traj = simulate(ROBOT, [3.0, 0.0], [8.0, 0.0], t_end=0.5, dt=1e-3, generated=gen)
    assert traj.continuous == (0,) and traj.q[-1, 0] > 2 * math.pi     # the state winds past pi, then 2 pi
    assert traj.energy_drift < 1e-8                                      # the work needs the turns
    rows = list(csv.reader(write_csv(traj, tmp_path / "sim.csv").open()))
    assert rows[0][:3] == ["t", "q_turn", "q_elbow"]
    turn = np.array([float(r[1]) for r in rows[1:]])
    elbow = np.array([float(r[2]) for r in rows[1:]])
    assert in_range(turn)
    np.testing.assert_array_equal(turn, wrap_angle(traj.q[:, 0]))
    np.testing.assert_array_equal(elbow, traj.q[:, 1])                  # a revolute joint: as integrated


def test_trajopt_keeps_the_optimised_angle_and_writes_it_wrapped(gen):
    from derive.solvers.simulate import load_generated
    from derive.solvers.trajopt import TrajectoryOptimizer
    mod = load_generated("spinner", gen)
    opt = TrajectoryOptimizer(ROBOT, forward_dynamics=lambda q, qd, tau: mod.forward_dynamics(q, qd, tau))
    assert list(opt.limits()["lower"]) == [-math.inf, -2.5]             # no position bound on the turn
    res = opt.solve(np.array([2.8, 0.0]), np.array([3.6, 0.0]), intervals=20, duration=1.0,
                    accel_weight=1.0)
    assert res.success, res.reason
    assert res.q[-1, 0] == pytest.approx(3.6, abs=1e-6)                  # through pi, not the long way round
    names, rows = res.table()
    column = rows[:, names.index("q_turn")]
    assert in_range(column) and column[-1] == pytest.approx(3.6 - 2 * math.pi, abs=1e-6)
    np.testing.assert_array_equal(rows[:, names.index("q_elbow")], res.q[:, 1])
    # that CSV's wrapped path is a guess again: its jump of 2 pi is taken out
    again = opt.solve(np.array([2.8, 0.0]), np.array([3.6, 0.0]), intervals=20, duration=1.0, accel_weight=1.0,
                      guess=rows[:, 1:3])
    assert again.success and again.q[-1, 0] == pytest.approx(3.6, abs=1e-6) and np.all(np.diff(again.q[:, 0]) > -1e-6)


def test_workspace_samples_each_turn_once():
    grid = sample_configurations(ROBOT, 16, "grid")
    assert sorted(set(grid[:, 0])) == pytest.approx(list(np.linspace(-math.pi, math.pi, 5)[1:]))   # (-pi, pi]
    assert sorted(set(grid[:, 1])) == pytest.approx(list(np.linspace(-2.5, 2.5, 4)))              # limits included
    assert in_range(sample_configurations(ROBOT, 1000, "random", seed=1)[:, 0])
