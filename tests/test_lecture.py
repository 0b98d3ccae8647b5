"""The lecture's worked examples (../shared/robotics1-summary.md), reproduced exactly."""

from __future__ import annotations

import sympy as sp

import derive
from derive.description.model import parse_models


def test_pendulum_matches_lecture_eq18():
    """[m_r (l/2)^2 + m_s l^2 + I_r + I_s] phi'' + g sin(phi) (l/2 m_r + l m_s) = 0."""
    m = derive.load("pendulum")
    m_r, m_s, I_r, I_s, l, g = m.params
    phi, ddphi = m.q[0], m.qdd[0]
    eq18 = (m_r * (l / 2) ** 2 + m_s * l**2 + I_r + I_s) * ddphi + g * sp.sin(phi) * (l / 2 * m_r + l * m_s)
    lhs = m.equations_of_motion[0].subs(m.tau[0], 0)
    assert sp.simplify(lhs - eq18) == 0
    assert sp.simplify(m.mass_matrix[0, 0] - (m_r * (l / 2) ** 2 + m_s * l**2 + I_r + I_s)) == 0
    assert m.coriolis_matrix == sp.zeros(1, 1)


def test_pendulum_energies_match_lecture_eq16():
    m = derive.load("pendulum")
    m_r, m_s, I_r, I_s, l, g = m.params
    phi, dphi = m.q[0], m.qd[0]
    T = sp.Rational(1, 2) * (m_r * (l / 2 * dphi) ** 2 + m_s * l**2 * dphi**2) + sp.Rational(1, 2) * (I_r + I_s) * dphi**2
    U = g * (1 - sp.cos(phi)) * (l / 2 * m_r + l * m_s)
    assert sp.simplify(m.kinetic_energy - T) == 0
    # our U is zero at the pivot height; the lecture's at the rest position: they differ by a constant
    assert sp.simplify(sp.diff(m.potential_energy - U, phi)) == 0


def test_planar_2r_jacobian_matches_lecture_eq24():
    m = derive.load("planar_2r")
    L1, L2 = m.params[0], m.params[1]
    t1, t2 = m.q
    eq24 = sp.Matrix([[-L1 * sp.sin(t1) - L2 * sp.sin(t1 + t2), -L2 * sp.sin(t1 + t2)],
                      [L1 * sp.cos(t1) + L2 * sp.cos(t1 + t2), L2 * sp.cos(t1 + t2)]])
    J = m.analytic_jacobian("tcp")
    assert sp.simplify(J[:2, :] - eq24) == sp.zeros(2, 2)
    assert J[2, :] == sp.zeros(1, 2)
    fk = m.fk("tcp")  # eq. 23
    assert sp.simplify(fk[0, 3] - (L1 * sp.cos(t1) + L2 * sp.cos(t1 + t2))) == 0
    assert sp.simplify(fk[1, 3] - (L1 * sp.sin(t1) + L2 * sp.sin(t1 + t2))) == 0


def test_planar_2r_geometric_jacobian_matches_lecture_eq29():
    """Eq. 29's nonzero rows: x, y linear rows equal eq. 24 and the z angular row is [1, 1].

    (The summary's eq. 29 prints L_2 cos(theta_1) in row 2; eq. 24 and eq. 28 give L_1, which we follow.)
    """
    m = derive.load("planar_2r")
    L1, L2 = m.params[0], m.params[1]
    t1, t2 = m.q
    J = m.jacobian("tcp")
    expected = sp.Matrix([
        [-L1 * sp.sin(t1) - L2 * sp.sin(t1 + t2), -L2 * sp.sin(t1 + t2)],
        [L1 * sp.cos(t1) + L2 * sp.cos(t1 + t2), L2 * sp.cos(t1 + t2)],
        [0, 0], [0, 0], [0, 0], [1, 1]])
    assert sp.simplify(J - expected) == sp.zeros(6, 2)


def test_planar_2r_dh_frames_match_lecture_eq25_and_eq28():
    m = derive.load("planar_2r")
    L1 = m.params[0]
    t1 = m.q[0]
    T1 = m.fk("link1")  # eq. 25 with i = 1: frame 1 of the standard DH table
    expected = sp.Matrix([[sp.cos(t1), -sp.sin(t1), 0, L1 * sp.cos(t1)], [sp.sin(t1), sp.cos(t1), 0, L1 * sp.sin(t1)],
                          [0, 0, 1, 0], [0, 0, 0, 1]])
    assert sp.simplify(T1 - expected) == sp.zeros(4, 4)


def test_rrprr_tcp_matches_lecture_eq11_eq12():
    """TCP_s = H^s_{x,1} H^1_{y,2} H^2_{x,3} H^3_{y,b} TCP_b with the transforms of eq. 12."""
    m = derive.load("rrprr", simplify=False)
    L1, L2, L_tcp = m.params
    t1, t2, t3, t4, t5 = m.q

    def H(R, t=(0, 0, 0)):
        return sp.Matrix(sp.BlockMatrix([[R, sp.Matrix(t)], [sp.zeros(1, 3), sp.ones(1, 1)]]))

    Rx = lambda a: sp.Matrix([[1, 0, 0], [0, sp.cos(a), -sp.sin(a)], [0, sp.sin(a), sp.cos(a)]])  # eq. 1
    Ry = lambda a: sp.Matrix([[sp.cos(a), 0, sp.sin(a)], [0, 1, 0], [-sp.sin(a), 0, sp.cos(a)]])  # eq. 2
    H_s1 = H(Rx(t1))
    H_12 = H(Ry(t3), (0, L1 + t2, 0))
    H_23 = H(Rx(t4))
    H_3b = H(Ry(t5), (0, L2, 0))
    tcp_b = H(sp.eye(3), (0, L_tcp, 0))
    expected = H_s1 * H_12 * H_23 * H_3b * tcp_b
    assert sp.simplify(sp.expand(m.fk("tcp") - expected)) == sp.zeros(4, 4)


def test_dh_conventions_agree_on_the_same_arm():
    """A 3-joint arm written as standard and as modified DH has the same tool pose."""
    text = """
robots:
  std:
    dh:
      convention: standard
      rows:
        - {joint: q1, type: revolute, a: 0.3, alpha: 1.5707963267948966, d: 0.4, link: a1}
        - {joint: q2, type: prismatic, a: 0.2, alpha: 0.3, theta: 0.5, link: a2}
        - {joint: q3, type: revolute, a: 0.1, alpha: 0, d: 0.05, link: a3}
    frames: [{name: tcp, link: a3}]
  mod:
    dh:
      convention: modified
      rows:
        - {joint: q1, type: revolute, a: 0, alpha: 0, d: 0.4, link: a1}
        - {joint: q2, type: prismatic, a: 0.3, alpha: 1.5707963267948966, theta: 0.5, link: a2}
        - {joint: q3, type: revolute, a: 0.2, alpha: 0.3, d: 0.05, link: a3}
    frames: [{name: tcp, link: a3, xyz: [0.1, 0, 0]}]
"""
    import casadi as ca
    import numpy as np

    robots = parse_models(text)
    fns = []
    for name in ("std", "mod"):
        model = derive.SXModel(robots[name])
        fns.append(ca.Function(name, [model.sym.q], [model.fk("tcp")[:3, 3]]))
    rng = np.random.default_rng(0)
    for _ in range(20):
        q = rng.uniform(-1, 1, 3)
        np.testing.assert_allclose(np.array(fns[0](q)), np.array(fns[1](q)), rtol=0, atol=1e-12)
