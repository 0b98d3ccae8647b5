"""The symbolic model (Lagrangian and recursive routes) against the numpy reference.

For every shipped model at 50 seeded random states, relative tolerance 1e-9.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from derive.reference import NumericRobot
from util import assert_close, params, robots, states, sx_model

ROBOTS = sorted(robots())


@pytest.fixture(scope="module", params=ROBOTS)
def case(request):
    name = request.param
    robot = robots()[name]
    model = sx_model(name)
    s = model.sym
    lag, ne = model.lagrangian, model.newton_euler
    f = ca.Function("dyn", [s.q, s.qd, s.qdd, s.p], [
        lag.mass_matrix, lag.coriolis_matrix, lag.gravity_vector, lag.inverse_dynamics(),
        ne.mass_matrix, ne.coriolis_matrix, ne.gravity_vector, ne.inverse_dynamics(),
        ca.jtimes(lag.mass_matrix, s.q, s.qd),
    ])
    return robot, model, f, NumericRobot(robot)


def _eval(f, q, qd, qdd, p):
    return [np.atleast_2d(np.array(o)) for o in f(q, qd, qdd, p)]


def test_inverse_dynamics_matches_rnea(case):
    robot, _, f, ref = case
    for q, qd, qdd in states(robot):
        out = _eval(f, q, qd, qdd, params(robot))
        expected = ref.rnea(q, qd, qdd)
        assert_close(out[3].ravel(), expected, what=f"{robot.name} Lagrangian tau")
        assert_close(out[7].ravel(), expected, what=f"{robot.name} Newton-Euler tau")


def test_mass_matrix_matches_crba_and_is_spd(case):
    robot, _, f, ref = case
    for q, qd, qdd in states(robot):
        M, M_ne = _eval(f, q, qd, qdd, params(robot))[0], _eval(f, q, qd, qdd, params(robot))[4]
        crba = ref.crba(q)
        assert_close(M, crba, what=f"{robot.name} M (Lagrange)")
        assert_close(M_ne, crba, what=f"{robot.name} M (CRBA)")
        assert_close(M, M.T, rtol=1e-14, what="M symmetric")
        assert np.linalg.eigvalsh(M).min() > 0, f"{robot.name}: M not positive definite at q = {q}"


def test_gravity_equals_rnea_without_motion(case):
    robot, _, f, ref = case
    zero = np.zeros(robot.nv)
    for q, qd, qdd in states(robot):
        out = _eval(f, q, qd, qdd, params(robot))
        expected = ref.rnea(q, zero, zero)
        assert_close(out[2].ravel(), expected, what=f"{robot.name} g = dU/dq")
        assert_close(out[6].ravel(), expected, what=f"{robot.name} g (RNEA)")


def test_coriolis_is_christoffel_and_mdot_minus_2c_is_skew(case):
    robot, _, f, ref = case
    for q, qd, qdd in states(robot):
        out = _eval(f, q, qd, qdd, params(robot))
        C, Mdot = out[1], out[8]
        zero = np.zeros(robot.nv)
        C_ref, Cqd_ref = ref.coriolis_matrix(q, qd), ref.rnea(q, qd, zero) - ref.rnea(q, zero, zero)
        # C's own size is |dM/dq| |qd| ~ |M| |qd|; where C is 0 identically (the Delta's tree: each arm on
        # a fixed axis, the plate on three prismatic joints: M constant) both sides are rounding of that size
        natural = np.abs(out[0]).max() * max(np.abs(qd).max(), 1.0)
        if np.abs(C_ref).max() <= 1e-14 * natural and np.abs(Cqd_ref).max() <= 1e-14 * natural:
            assert max(np.abs(C).max(), np.abs(out[5]).max()) <= 1e-14 * natural, f"{robot.name}: C is not 0"
        else:
            assert_close(C, C_ref, what=f"{robot.name} C")
            assert_close(out[5], C, what=f"{robot.name} C (CRBA route)")
            assert_close(C @ qd, Cqd_ref, what=f"{robot.name} C qd")
        N = Mdot - 2 * C
        # relative to the size of Mdot ~ |M| |qd| (N itself is 0 for one joint)
        scale = max(np.abs(Mdot).max(), 2 * np.abs(C).max(), np.abs(out[0]).max() * np.abs(qd).max())
        assert np.abs(N + N.T).max() <= 1e-9 * scale, f"{robot.name}: Mdot - 2C not skew-symmetric"


def test_jacobians_match_derivative_of_fk(case):
    """Geometric and analytic Jacobians against complex-step derivatives of the reference FK."""
    robot, model, _, ref = case
    s = model.sym
    frames = [fr.name for fr in robot.frames] + [robot.moving_joints[-1].child]
    fns = {fr: ca.Function("k", [s.q, s.p], [model.fk(fr), model.jacobian(fr), model.analytic_jacobian(fr)])
           for fr in frames}
    h = 1e-30
    for q, _, _ in states(robot):
        for fr, fn in fns.items():
            T, J, Ja = (np.array(o) for o in fn(q, params(robot)))
            assert_close(T, ref.frame_pose(q, fr), what=f"{robot.name} fk {fr}")
            R = T[:3, :3]
            dp, w = np.zeros((3, robot.nv)), np.zeros((3, robot.nv))
            for k in range(robot.nv):
                Tc = ref.frame_pose(q + 1j * h * np.eye(robot.nv)[k], fr)
                dp[:, k] = Tc[:3, 3].imag / h
                W = (Tc[:3, :3].imag / h) @ R.T  # [w]x = Rdot R^T
                w[:, k] = [W[2, 1], W[0, 2], W[1, 0]]
            assert_close(J[:3], dp, what=f"{robot.name} J linear {fr}")
            assert_close(J[3:], w, what=f"{robot.name} J angular {fr}")
            assert_close(Ja, dp, what=f"{robot.name} analytic J {fr}")
