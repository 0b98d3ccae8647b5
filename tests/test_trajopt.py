"""Trajectory optimisation on the derived dynamics: swing-ups and rest-to-rest moves solve, hold
their limits, and are reproduced by integrating the generated forward dynamics (RK4, fine
steps); impossible requests fail with a one-line reason; the CLI writes CSV and PNG.

The generated Python used for the independent check is generated into a temporary folder.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest

from derive.cli import main
from derive.errors import DeriveError
from derive.generate import generate
from derive.trajopt import LIMIT_TOL, TrajectoryOptimizer, Waypoint, _import, generated_forward_dynamics
from derive.trajopt_examples import PANDA_GOAL, PANDA_READY, point_to_point_duration, swing_up, velocity_reversals
from util import robots

ROBOTS = ("cartpole", "pendulum", "planar_2r", "panda")


@pytest.fixture(scope="module")
def gen(tmp_path_factory):
    out = tmp_path_factory.mktemp("trajopt") / "gen"
    generate(robots(), out, only=ROBOTS, use_cache=False, log=lambda s: None)
    return out


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
                accel_weight=1.0, substeps=10)
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
    module = _import(gen / "planar_2r" / "python" / "planar_2r.py", "planar_2r")
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


def test_cli_failure_is_one_line(tmp_path, capsys):
    rc = main(["trajopt", "panda", "--from", ",".join(map(str, PANDA_READY)), "--to", ",".join(map(str, PANDA_GOAL)),
               "--torque-limit", "5", "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and "against gravity" in err
    assert not any(tmp_path.iterdir())
