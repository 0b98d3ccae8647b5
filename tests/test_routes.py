"""Euler-Lagrange and recursive Newton-Euler give identical equations (the lecture's Examples 5 and 6).

Symbolically (sympy.simplify of the difference) for pendulum, planar_2r and cartpole,
through derive.load(name, method=...); numerically for every shipped model at 50 seeded
states to 1e-12 relative (rrprr's expanded Lagrangian C has 285 000 operations: simplify
does not finish; ur5 and panda are larger still).
"""

from __future__ import annotations

import casadi as ca
import pytest
import sympy as sp

import derive
from util import assert_close, params, robots, states, sx_model, tree_robots

QUANTITIES = ("mass_matrix", "coriolis_matrix", "gravity_vector", "inverse_dynamics")
SYMBOLIC = ("pendulum", "planar_2r", "cartpole")


def exact_zero(d: sp.Expr) -> bool:
    """d simplifies to 0, up to rounding residue (|c| < 1e-15) of float constants.

    Numeric models fold products of their constants in floating point on each route
    (cartpole: 0.1 * 9.81 * 0.5 differs in its last bit, leaving 4.7e-17 sin(theta) in tau);
    models with symbolic parameters are exact.
    """
    r = sp.simplify(d)
    return sp.simplify(r.xreplace({f: 0 for f in r.atoms(sp.Float) if abs(f) < 1e-15})) == 0


@pytest.mark.parametrize("name", SYMBOLIC)
def test_routes_agree_symbolically(name):
    lag = derive.load(name, simplify=False, method="lagrange")
    ne = derive.load(name, simplify=False, method="newton-euler")
    assert (lag.q, lag.qd, lag.qdd, lag.params) == (ne.q, ne.qd, ne.qdd, ne.params)
    for quantity in QUANTITIES:
        a, b = getattr(lag, quantity), getattr(ne, quantity)
        assert a.shape == b.shape
        bad = [(i, j) for i in range(a.rows) for j in range(a.cols) if not exact_zero(a[i, j] - b[i, j])]
        assert not bad, f"{name} {quantity}: routes differ at {bad}"


def test_pendulum_routes_give_lecture_eq18_and_eq20():
    """Eq. 18 (Euler-Lagrange) and eq. 20 (Newton-Euler): the same equation, exactly."""
    for method in ("lagrange", "newton-euler"):
        m = derive.load("pendulum", method=method)
        m_r, m_s, I_r, I_s, l, g = m.params
        phi, ddphi = m.q[0], m.qdd[0]
        eq = (m_r * (l / 2) ** 2 + m_s * l**2 + I_r + I_s) * ddphi + g * sp.sin(phi) * (l / 2 * m_r + l * m_s)
        assert sp.simplify(m.equations_of_motion[0].subs(m.tau[0], 0) - eq) == 0, method


@pytest.mark.parametrize("name", tree_robots())
def test_routes_agree_numerically(name):
    robot, model = robots()[name], sx_model(name)
    s = model.sym
    outs = [e for method in ("lagrange", "newton-euler")
            for e in (model.mass_matrix(method), model.coriolis_matrix(method), model.gravity_vector(method),
                      model.inverse_dynamics(method))]
    f = ca.Function("routes", [s.q, s.qd, s.qdd, s.p], outs)
    for q, qd, qdd in states(robot):
        values = [ca.DM(v).full() for v in f(q, qd, qdd, params(robot))]
        for k, quantity in enumerate(QUANTITIES):
            assert_close(values[k], values[k + 4], rtol=1e-12, what=f"{name} {quantity} at q = {q}")


def test_unknown_method_is_refused():
    with pytest.raises(ValueError, match="lagrange"):
        derive.load("pendulum", method="kane")
