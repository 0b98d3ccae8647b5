"""Order reduction and linearisation (the lecture's section 3.2, Example 7)."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
import sympy as sp

import derive
from derive.inspect.linearize import first_order, linearize, linearize_numeric
from util import assert_close, params, random_q, robots, sx_model


def test_pendulum_order_reduction_matches_lecture_example7():
    """a phi'' + b phi = 0 (eq. 21) and z' = [z1, -b/a z0], exactly."""
    m = derive.load("pendulum")
    m_r, m_s, I_r, I_s, l, g = m.params
    phi, ddphi = m.q[0], m.qdd[0]
    a = m_r * (l / 2) ** 2 + m_s * l**2 + I_r + I_s
    b = g * (l / 2 * m_r + l * m_s)
    lin = linearize(m, [0])
    assert sp.simplify(lin.M[0, 0] - a) == 0
    assert sp.simplify(lin.K[0, 0] - b) == 0
    assert lin.D == sp.zeros(1, 1) and lin.u0 == sp.zeros(1, 1)
    z0, z1 = sp.symbols("z0 z1")
    reduced = lin.A * sp.Matrix([z0, z1])
    assert sp.simplify(reduced - sp.Matrix([z1, -b / a * z0])) == sp.zeros(2, 1)
    assert sp.simplify(lin.B - sp.Matrix([0, 1 / a])) == sp.zeros(2, 1)
    # the lecture's route: sin(phi) ~ phi in eq. 18 gives the same a and b
    small = m.equations_of_motion[0].subs({m.tau[0]: 0, sp.sin(phi): phi})
    assert sp.simplify(small - (a * ddphi + b * phi)) == 0


def test_first_order_form_is_q_qd_and_forward_dynamics():
    m = derive.load("pendulum")
    x, u, f = first_order(m)
    assert x == sp.Matrix([m.q[0], m.qd[0]]) and u == m.tau
    a = m.mass_matrix[0, 0]
    assert f[0] == m.qd[0]
    assert sp.simplify(f[1] - (m.tau[0] - m.gravity_vector[0]) / a) == 0


@pytest.fixture(scope="module")
def planar_2r():
    return derive.load("planar_2r", method="newton-euler")


def test_planar_2r_exact_linearisation_matches_numeric(planar_2r):
    """Away from equilibrium (qd0, tau0 nonzero): exact A, B at the defaults == the AD ones."""
    m = planar_2r
    q0, qd0, tau0 = [sp.Rational(1, 3), sp.Rational(-2, 5)], [sp.Rational(1, 2), 1], [1, -sp.Rational(1, 4)]
    exact = linearize(m, q0, qd0, tau0)
    num = linearize_numeric(m.sx, [float(v) for v in q0], [float(v) for v in qd0], [float(v) for v in tau0])
    at = dict(zip(m.params, params(m.robot)))
    for name in ("M", "D", "K", "A", "B"):
        assert_close(np.array(getattr(exact, name).subs(at).evalf(), dtype=float), getattr(num, name), rtol=1e-12,
                     what=name)


def test_planar_2r_upright_is_unstable(planar_2r):
    """About q = (pi/2, 0) (arm straight up) A has a positive real eigenvalue; hanging down it has none."""
    m = planar_2r
    at = dict(zip(m.params, params(m.robot)))
    up = np.array(linearize(m, [sp.pi / 2, 0]).A.subs(at).evalf(), dtype=float)
    down = np.array(linearize(m, [-sp.pi / 2, 0]).A.subs(at).evalf(), dtype=float)
    assert np.linalg.eigvals(up).real.max() > 1
    assert np.abs(np.linalg.eigvals(down).real).max() < 1e-9


@pytest.mark.parametrize("name", sorted(robots()))
def test_numeric_linearisation_matches_ode_jacobians(name):
    """A, B from the implicit-function form == d f/dx, d f/du by AD of the LDL^T forward dynamics."""
    robot, model = robots()[name], sx_model(name)
    s = model.sym
    jac = ca.Function("ode_jacobians", [s.q, s.qd, s.tau, s.p], [model.ode_jac_x(), model.ode_jac_u()])
    rng = np.random.default_rng(0)
    for _ in range(5):
        q0, qd0, tau0 = random_q(robot, rng), rng.normal(size=robot.nv), rng.normal(size=robot.nv)
        for point in ((q0, None, None), (q0, qd0, tau0)):
            lin = linearize_numeric(model, *point)
            qd, tau = lin.x0[robot.nv:], lin.u0
            A, B = (np.array(v) for v in jac(q0, qd, tau, params(robot)))
            assert_close(lin.A, A, rtol=1e-9, what=f"{name} A")
            assert_close(lin.B, B, rtol=1e-9, what=f"{name} B")
        equilibrium = linearize_numeric(model, q0)
        assert np.abs(equilibrium.D).max() < 1e-12 * max(1.0, np.abs(equilibrium.K).max()), "D = 0 at rest"
