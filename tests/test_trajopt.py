"""Trajectory optimisation on the derived dynamics: swing-ups and rest-to-rest moves solve, hold
their limits, and are reproduced by integrating the generated forward dynamics (RK4, fine
steps); impossible requests fail with a one-line reason; the CLI writes CSV and PNG.

The generated Python used for the independent check is generated into a temporary folder.
"""

from __future__ import annotations

import math
import re

import casadi as ca
import numpy as np
import pytest

from derive.cli import main
from derive.errors import DeriveError
from derive.codegen.generate import generate
from derive.description.model import load_models, parse_models
from derive.solvers.simulate import load_generated
from derive.solvers.trajopt import LIMIT_TOL, TrajectoryOptimizer, Waypoint, generated_forward_dynamics
from derive.solvers.trajopt_examples import PANDA_GOAL, PANDA_READY, point_to_point_duration, swing_up, velocity_reversals
from util import robots

ROBOTS = ("cartpole", "pendulum", "planar_2r", "panda")


@pytest.fixture(scope="module")
def gen(generated_copy):
    return generated_copy("trajopt")  # the committed generated/ (conftest.py): ROBOTS used here


@pytest.fixture(scope="module")
def opt(gen):
    cache = {}

    def make(name: str) -> TrajectoryOptimizer:
        if name not in cache:
            robot = robots()[name]
            p = np.array([x.default for x in robot.parameters])
            cache[name] = TrajectoryOptimizer(robot, forward_dynamics=generated_forward_dynamics(robot, p, root=gen))
        return cache[name]

    return make


def assert_limits_held(o: TrajectoryOptimizer, r, torque_limit=None) -> None:
    lim = o.limits(torque_limit)
    for X, lo, hi in ((r.q, lim["lower"], lim["upper"]), (r.qd, -lim["velocity"], lim["velocity"]),
                      (r.tau, -lim["effort"], lim["effort"])):
        slack = LIMIT_TOL * np.maximum(1.0, np.where(np.isfinite(hi), np.abs(hi), 1.0))
        assert np.all(X >= lo - slack) and np.all(X <= hi + slack)


def test_cartpole_swing_up_is_reproduced_by_generated_forward_dynamics(opt):
    o = opt("cartpole")
    r = swing_up(o)
    assert r.success, r.reason
    assert len(r.t) == 101 and r.t[-1] == pytest.approx(2.0)
    assert r.integration_error < 1e-3 and r.drift < 1e-3  # per interval and open loop from the start
    np.testing.assert_allclose(r.q[0], [0, 0], atol=1e-9)
    np.testing.assert_allclose(r.q[-1], [0, math.pi], atol=1e-9)  # pole up, cart back at 0
    np.testing.assert_allclose(r.qd[[0, -1]], 0, atol=1e-9)
    assert np.all(r.tau[:, 1] == 0)  # the pole is passive
    assert_limits_held(o, r)
    assert np.abs(r.tau[:, 0]).max() > 10  # the 20 N force bound matters


def test_cartpole_dynamics_hold_in_the_nlp(opt):
    """The knots satisfy M qdd + C qd + g = tau, checked with the generated Python (not the NLP graph)."""
    o = opt("cartpole")
    r = swing_up(o, intervals=40)
    for q, qd, qdd, tau in zip(r.q, r.qd, r.qdd, r.tau):
        np.testing.assert_allclose(o.forward_dynamics(q, qd, tau), qdd, atol=1e-6)


def test_pendulum_swing_up_below_mgl_needs_several_pumps(opt):
    o = opt("pendulum")
    mgl = abs(o.gravity([math.pi / 2])[0])
    assert mgl == pytest.approx(9.81 * (1.0 / 2 + 2.0) * 1.0)  # g l (m_r / 2 + m_s)
    r = swing_up(o)
    limit = 0.25 * mgl
    assert r.success, r.reason
    assert r.integration_error < 1e-3 and r.drift < 1e-3
    assert velocity_reversals(r.qd[:, 0]) >= 3  # several pumps before it goes over the top
    assert np.abs(r.tau).max() <= limit * (1 + LIMIT_TOL)
    assert np.abs(r.tau).max() >= 0.99 * limit  # the limit is active (bang-like pumping)
    assert r.q[-1, 0] == pytest.approx(math.pi, abs=1e-9)
    assert 1.0 < r.duration < 60.0  # free final time, inside its bounds


@pytest.mark.parametrize("method", ["trapezoidal", "rk4"])
def test_other_transcriptions_solve_the_cartpole(opt, method):
    o = opt("cartpole")
    r = swing_up(o, method=method)
    assert r.success, r.reason
    assert r.integration_error < 1e-3
    assert_limits_held(o, r)
    if method == "rk4":  # zero-order hold over the last interval
        np.testing.assert_array_equal(r.torque(r.duration - 1e-9), r.tau[-2])


def test_panda_rest_to_rest_holds_every_limit(opt):
    o = opt("panda")
    r = o.solve(PANDA_READY, PANDA_GOAL, intervals=50, duration=point_to_point_duration(o, PANDA_READY, PANDA_GOAL),
                accel_weight=1.0)  # the default check: RK4, 20 steps per interval, as the README says
    assert r.success, r.reason
    assert r.integration_error < 1e-3
    assert_limits_held(o, r)
    np.testing.assert_allclose(r.qd[[0, -1]], 0, atol=1e-9)
    np.testing.assert_allclose(r.qdd[[0, -1]], 0, atol=1e-9)  # held at rest at both ends
    assert np.abs(r.qd).max() / 2.175 > 0.9  # the velocity limits shape the move


def test_too_weak_to_hold_against_gravity_fails_with_reason(opt):
    r = opt("panda").solve(PANDA_READY, PANDA_GOAL, torque_limit=5.0)
    assert not r.success
    assert "gravity" in r.reason and "panda_joint" in r.reason and "\n" not in r.reason


def test_goal_outside_limits_fails_with_reason(opt):
    goal = list(PANDA_GOAL)
    goal[3] = 0.5  # panda_joint4 lives in [-3.07, -0.07]
    r = opt("panda").solve(PANDA_READY, goal)
    assert not r.success
    assert r.reason == "goal panda_joint4 = 0.5 is outside the limits [-3.0718, -0.0698]"


def test_solver_infeasible_swing_up_fails_with_reason(opt):
    r = swing_up(opt("cartpole"), torque_limit=[1.0, 0.0], duration=1.0, intervals=30, max_iter=200)
    assert not r.success
    assert r.reason.startswith("IPOPT ") and "\n" not in r.reason
    assert r.stats["return_status"] != "Solve_Succeeded"


def test_waypoint_goes_through_the_derived_fk(opt, gen):
    o = opt("planar_2r")
    module = load_generated("planar_2r", gen)
    via = module.fk_tcp([0.3, 1.2])[:3, 3]  # reachable, computed by the generated FK
    r = o.solve([0.0, 0.0], [1.0, 0.5], intervals=40, duration=2.0, waypoints=[Waypoint(0.5, tuple(via))])
    assert r.success, r.reason
    np.testing.assert_allclose(module.fk_tcp(r.q[20])[:3, 3], via, atol=1e-6)


def test_path_guess_and_warm_start(opt):
    o = opt("planar_2r")
    path = np.array([[0.0, 0.0], [0.2, 0.8], [0.6, 1.0], [1.0, 0.5]])  # e.g. a planner's waypoints
    r = o.solve(path[0], path[-1], intervals=40, duration=2.0, guess=path)
    assert r.success, r.reason
    again = o.solve(path[0], path[-1], intervals=40, duration=2.0, guess=r)
    assert again.success and again.stats["iterations"] < r.stats["iterations"]
    assert again.stats["cost"] == pytest.approx(r.stats["cost"], rel=1e-6)
    with pytest.raises(DeriveError, match=r"\(M >= 2, 2\)"):
        o.solve(path[0], path[-1], guess=np.zeros((5, 3)))


def test_implicit_dynamics_have_no_mass_matrix_inverse(opt):
    """The NLP's dynamics are RNEA: linear in qdd, so no division by anything that depends on q."""
    o = opt("panda")
    s = o.model.sym
    tau = o.rnea(s.q, s.qd, s.qdd, s.p)
    assert ca.depends_on(tau, s.qdd) and not ca.depends_on(ca.jacobian(tau, s.qdd), s.qdd)
    assert not ca.depends_on(ca.jacobian(tau, s.qdd), s.qd)  # M(q) only


def test_bad_input_is_one_line(opt):
    o = opt("cartpole")
    with pytest.raises(DeriveError, match="method must be one of"):
        o.solve([0, 0], [0, 1], method="euler")
    with pytest.raises(DeriveError, match="start needs 2 values"):
        o.solve([0], [0, 1])
    with pytest.raises(DeriveError, match="no joint 'pole'"):
        o.solve([0, 0], [0, 1], passive=("pole",))
    with pytest.raises(DeriveError, match="no frame 'hand'"):
        o.solve([0, 0], [0, 1], waypoints=[Waypoint(0.5, (0, 0, 0), "hand")])


def test_cli_writes_csv_and_png(tmp_path, capsys):
    import matplotlib.image

    assert main(["trajopt", "cartpole", "--swing-up", "--intervals", "60", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert f"wrote {tmp_path / 'trajectory.csv'}" in out and "velocity reversals" in out
    lines = (tmp_path / "trajectory.csv").read_text().splitlines()
    assert lines[0] == "t,q_s,q_theta,qd_s,qd_theta,qdd_s,qdd_theta,tau_s,tau_theta"
    data = np.loadtxt(tmp_path / "trajectory.csv", delimiter=",", skiprows=1)
    assert data.shape == (61, 9) and data[-1, 2] == pytest.approx(math.pi)
    image = matplotlib.image.imread(tmp_path / "trajectory.png")
    assert image.ndim == 3 and image.shape[0] > 100 and image.std() > 0


def test_cli_infeasible_request_exits_1_with_one_line(tmp_path, capsys):
    """Well formed but infeasible: exit 1 (ran, no solution), not 2 (bad input); one line on stderr, nothing written."""
    rc = main(["trajopt", "panda", "--from", ",".join(map(str, PANDA_READY)), "--to", ",".join(map(str, PANDA_GOAL)),
               "--torque-limit", "5", "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert rc == 1 and err.count("\n") == 1 and "against gravity" in err
    assert err.startswith("derive: trajopt panda: no solution: ") and not err.startswith("derive: error")
    assert not any(tmp_path.iterdir())


# ---- multi-DOF joints: one entry of q (and its own limits) per coordinate ----

BALL_ARM = """
robots:
  ball_arm:
    gravity: [0, 0, -9.81]
    links:
      - {name: base}
      - {name: upper, mass: 1.0, com: [0, 0, 0.2], inertia: [0.02, 0.02, 0.004]}
      - {name: fore, mass: 0.5, com: [0, 0, 0.15], inertia: [0.006, 0.006, 0.001]}
    joints:
      - {name: shoulder, type: spherical, parent: base, child: upper,
         limits: [{lower: -3, upper: 3, velocity: 3, effort: 30}, {lower: -Y, upper: Y, velocity: 3, effort: 25},
                  {lower: -3, upper: 3, velocity: 3, effort: 30}]}
      - {name: elbow, type: universal, parent: upper, child: fore, origin: {xyz: [0, 0, 0.4]},
         axis: [0, 1, 0], axis2: [1, 0, 0],
         limits: [{lower: -2, upper: 2, velocity: 4, effort: 10}, {lower: -1.5, upper: 1.5, velocity: 4, effort: 8}]}
    frames:
      - {name: tcp, link: fore, xyz: [0, 0, 0.3]}
"""
"""A spherical shoulder (ZYX, |shoulder_y| <= Y keeps it away from gimbal lock) and a universal elbow."""

BALL_GOAL = [0.8, 0.5, -0.4, 0.6, -0.5]


def ball_arm(y_limit: float = 1.2):
    return parse_models(BALL_ARM.replace("Y", str(y_limit)))["ball_arm"]


def test_limits_are_per_coordinate_of_multi_dof_joints():
    o = TrajectoryOptimizer(load_models("examples/joint_types.yaml")["joint_types"])
    lim = o.limits()
    assert o.joints[:5] == ("shoulder_z", "shoulder_y", "shoulder_x", "elbow_1", "elbow_2")
    assert all(len(v) == o.robot.nv == 10 for v in lim.values())
    np.testing.assert_array_equal(lim["lower"][:3], [-3.1, -1.4, -3.1])  # the spherical joint's three limits
    np.testing.assert_array_equal(lim["upper"][7:9], [3.1, 0.3])  # cylindrical: column_rot, column_trans
    assert np.all(np.isinf(lim["effort"]))
    np.testing.assert_array_equal(o.limits(torque_limit=2.0)["effort"], np.full(10, 2.0))


def test_multi_dof_rest_to_rest_is_reproduced_by_generated_forward_dynamics(tmp_path):
    robot = ball_arm()
    generate({"ball_arm": robot}, tmp_path / "gen", use_cache=False, log=lambda s: None)
    fd = generated_forward_dynamics(robot, np.zeros(0), root=tmp_path / "gen")  # not generated/: tmp only
    o = TrajectoryOptimizer(robot, forward_dynamics=fd)
    lim = o.limits()
    np.testing.assert_array_equal(lim["effort"], [30, 25, 30, 10, 8])
    np.testing.assert_array_equal(lim["lower"], [-3, -1.2, -3, -2, -1.5])
    r = o.solve(np.zeros(5), BALL_GOAL, intervals=30, duration=1.5, accel_weight=1.0)
    assert r.success, r.reason
    assert r.joints == ("shoulder_z", "shoulder_y", "shoulder_x", "elbow_1", "elbow_2")
    assert r.q.shape == r.tau.shape == (31, 5)
    assert r.integration_error < 1e-3  # the generated Python (LDL^T of CRBA's M) reproduces every knot
    np.testing.assert_allclose(r.q[[0, -1]], [np.zeros(5), BALL_GOAL], atol=1e-9)
    np.testing.assert_allclose(r.qd[[0, -1]], 0, atol=1e-9)
    np.testing.assert_allclose(r.qdd[[0, -1]], 0, atol=1e-9)  # held at rest at both ends
    assert_limits_held(o, r)
    for q, qd, qdd, tau in zip(r.q, r.qd, r.qdd, r.tau):  # the knots satisfy the dynamics
        np.testing.assert_allclose(o.forward_dynamics(q, qd, tau), qdd, atol=1e-6)
    assert np.all(np.abs(np.cos(r.q[:, 1])) > 0.3)  # nowhere near gimbal lock
    # a multi-DOF joint's name makes all its coordinates passive: a limp elbow cannot hold the goal
    limp = o.solve(np.zeros(5), BALL_GOAL, intervals=30, duration=1.5, passive=("elbow",))
    assert not limp.success and "passive joint elbow_" in limp.reason and limp.joints == r.joints


def test_start_in_gimbal_lock_fails_with_reason():
    o = TrajectoryOptimizer(ball_arm(y_limit=2.0))
    r = o.solve([0, math.pi / 2, 0, 0, 0], BALL_GOAL)
    assert not r.success and "gimbal lock" in r.reason and "shoulder" in r.reason and "\n" not in r.reason


# ---- malformed requests: one line on stderr, exit status 2, no traceback ----

@pytest.fixture(scope="module")
def guess_files(tmp_path_factory):
    d = tmp_path_factory.mktemp("guesses")
    (d / "path.yaml").write_text("path:\n  - [0, 0]\n  - [1, 1]\n")
    (d / "empty.csv").write_text("")
    (d / "pickled.npy").write_bytes(b"not an array")
    (d / "nan.csv").write_text("0,0\nnan,0.5\n1,1\n")
    (d / "wide.csv").write_text("0,0,0\n1,1,1\n")
    return d


@pytest.mark.parametrize("args, message", [
    (["--duration", "0"], "duration must be a finite number > 0, got 0.0"),
    (["--duration", "-1"], "duration must be a finite number > 0, got -1.0"),
    (["--duration", "inf"], "duration must be a finite number > 0"),
    (["--intervals", "0"], "intervals must be an integer >= 2, got 0"),
    (["--intervals", "-5"], "intervals must be an integer >= 2, got -5"),
    (["--time-weight", "-1", "--free-time"], "time_weight must be a finite number >= 0, got -1.0"),
    (["--time-weight", "1"], "a time cost (time_weight > 0) needs free_time"),
    (["--accel-weight", "-1"], "accel_weight must be a finite number >= 0"),
    (["--substeps", "0"], "substeps must be an integer >= 1"),
    (["--torque-limit", "-1"], "torque_limit must be one value >= 0 or 2"),
    (["--torque-limit", "1,2,3"], "torque_limit must be one value >= 0 or 2"),
    (["--passive", "theta1,theta2"], "every joint is passive"),
    (["--from", "nan,0"], "--from theta1 = nan is not a finite number"),
    (["--to", "1,inf"], "--to theta2 = inf is not a finite number"),
    (["--from", "0,x"], "--from: 'x' is not a number"),
    (["--guess", "{d}/path.yaml"], "path.yaml: not a .npy array or a CSV of numbers"),
    (["--guess", "{d}/empty.csv"], "empty.csv: not a .npy array or a CSV of numbers"),
    (["--guess", "{d}/pickled.npy"], "pickled.npy: not a .npy array or a CSV of numbers"),
    (["--guess", "{d}/nan.csv"], "a path guess must be finite, row 1 is not"),
    (["--guess", "{d}/wide.csv"], "a path guess must be an (M >= 2, 2) array, got shape (2, 3)"),
])
def test_cli_rejects_malformed_requests_in_one_line(args, message, guess_files, tmp_path, capsys):
    base = {"--from": "0,0", "--to": "1,1"}
    base.update({a: None for a in args if a in base})
    argv = ["trajopt", "planar_2r"] + [x for k, v in base.items() if v for x in (k, v)]
    argv += [a.format(d=guess_files) for a in args] + ["--out", str(tmp_path / "out")]
    rc = main(argv)
    captured = capsys.readouterr()
    assert rc == 2, captured
    assert captured.err.count("\n") == 1 and "Traceback" not in captured.err + captured.out
    assert captured.err.startswith("derive: error: trajopt") and message in captured.err
    assert captured.out == ""  # nothing was solved, so nothing misleading was printed first
    assert not (tmp_path / "out").exists()


def test_api_rejects_malformed_requests(opt):
    o = opt("planar_2r")
    free = {"free_time": True}
    for kwargs, message in (({"duration": 0.0}, "duration must be"), ({"intervals": 2.5}, "intervals must be an integer"),
                            ({"duration_bounds": (2.0, 1.0), **free}, "duration_bounds"),
                            ({"duration": 20.0, "duration_bounds": (1.0, 5.0), **free}, "outside duration_bounds"),
                            ({"effort_weight": 0.0}, "must not both be 0"), ({"tol": -1.0}, "tol must be"),
                            ({"torque_limit": [1.0, float("nan")]}, "torque_limit"),
                            ({"start_qd": [0.0, float("nan")]}, "start_qd theta2 = nan"),
                            ({"waypoints": [Waypoint(0.5, (0.1, float("nan"), 0.0))]}, "3 finite coordinates")):
        with pytest.raises(DeriveError, match=re.escape(message)):
            o.solve([0, 0], [1, 1], **kwargs)
