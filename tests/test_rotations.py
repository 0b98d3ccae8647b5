"""Rotations (lecture eq. 1-6), Euler angles, SE(3) exp/log and the inertia tools."""

from __future__ import annotations

import math
import warnings

import casadi as ca
import numpy as np
import pytest
import sympy as sp

from derive.analysis import rotations as rot
from derive.errors import DeriveError
from derive.description.inertia import check_inertia, inertia_about_com, inertia_problem, principal_moments, rotate_inertia, steiner
from derive.description.model import inertia_problem as model_inertia_problem

RNG_SEED = 0


def random_unit(rng, n=1):
    v = rng.normal(size=(n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def test_elementary_rotations_match_lecture_eq1_to_3():
    a = sp.Symbol("alpha")
    c, s = sp.cos(a), sp.sin(a)
    assert rot.rot_x(a) == sp.Matrix([[1, 0, 0], [0, c, -s], [0, s, c]])
    assert rot.rot_y(a) == sp.Matrix([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    assert rot.rot_z(a) == sp.Matrix([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    for f in (rot.rot_x, rot.rot_y, rot.rot_z):
        num = f(0.3)
        assert np.allclose(num, np.array(f(a).subs(a, 0.3), dtype=float), atol=1e-15)
        x = ca.SX.sym("x")
        assert np.allclose(np.array(ca.Function("f", [x], [f(x)])(0.3)), num, atol=1e-15)
        assert rot.is_rotation(num)


def test_homogeneous_transform_maps_points_as_eq5():
    rng = np.random.default_rng(RNG_SEED)
    R, t, p = rot.exp_so3(rng.normal(size=3)), rng.normal(size=3), rng.normal(size=3)
    H = rot.homogeneous(R, t)
    assert np.allclose(H @ np.append(p, 1), np.append(R @ p + t, 1), atol=1e-14)
    assert np.allclose(rot.transform_point(H, p), R @ p + t, atol=1e-14)
    assert np.allclose(rot.inverse_transform(H) @ H, np.eye(4), atol=1e-14)
    a, x = sp.symbols("a x")
    Hs = rot.homogeneous(rot.rot_z(a), [x, 0, 0])
    assert sp.simplify(rot.inverse_transform(Hs) * Hs - sp.eye(4)) == sp.zeros(4, 4)


def test_rodrigues_matches_matrix_exponential_and_axis_rotations():
    """Eq. 6 with the 1/a^2 factor equals expm([w]x); about x it is Rx (eq. 1)."""
    from scipy.linalg import expm

    rng = np.random.default_rng(RNG_SEED)
    for w in rng.normal(size=(20, 3)) * 2:
        assert np.allclose(rot.exp_so3(w), expm(rot.skew(w)), atol=1e-13)
    assert np.allclose(rot.exp_so3([0.7, 0, 0]), rot.rot_x(0.7), atol=1e-15)
    a = sp.Symbol("a", positive=True)
    assert sp.simplify(rot.exp_so3([0, 0, a]) - rot.rot_z(a)) == sp.zeros(3, 3)
    w = ca.SX.sym("w", 3)
    f = ca.Function("exp", [w], [rot.exp_so3(w)])
    for v in ([0.3, -0.2, 1.1], [1e-6, 2e-6, 0.0], [0.0, 0.0, 0.0]):
        assert np.allclose(np.array(f(v)), rot.exp_so3(v), atol=1e-15)


@pytest.mark.parametrize("angle_kind", ["random", "near_zero", "near_pi"])
def test_log_inverts_exp_for_random_rotations(angle_kind):
    """log(exp(w)) == w for |w| < pi, including |w| within 1e-9 of pi and near 0; exp(log(R)) == R."""
    rng = np.random.default_rng(RNG_SEED)
    axes = random_unit(rng, 200)
    if angle_kind == "random":
        angles = rng.uniform(0, np.pi, 200)
    elif angle_kind == "near_zero":
        angles = 10.0 ** rng.uniform(-14, -2, 200)
    else:
        angles = np.pi - 10.0 ** rng.uniform(-17, -9, 200)  # [pi - 1e-9, pi], some exactly the double pi
    worst_w = worst_R = 0.0
    for n, a in zip(axes, angles):
        w = a * n
        R = rot.exp_so3(w)
        assert rot.is_rotation(R, tol=1e-14)
        back = rot.log_so3(R)
        # sin(a) below ~1e-13 is at the rounding level of R's entries: w and -w are then
        # numerically the same rotation (exactly so at pi), and either may come back
        err = np.abs(back - w).max() if np.pi - a > 1e-13 else min(np.abs(back - w).max(), np.abs(back + w).max())
        worst_w = max(worst_w, err)
        worst_R = max(worst_R, np.abs(rot.exp_so3(back) - R).max())
    assert worst_w < 1e-14, worst_w
    assert worst_R < 1e-15, worst_R


def test_log_at_exactly_pi_returns_one_of_the_two_equal_vectors():
    rng = np.random.default_rng(RNG_SEED)
    for n in random_unit(rng, 50):
        R = rot.exp_so3(np.pi * n)
        w = rot.log_so3(R)
        assert min(np.abs(w - np.pi * n).max(), np.abs(w + np.pi * n).max()) < 1e-14
        assert np.abs(rot.exp_so3(w) - R).max() < 1e-15
    # just past pi, the shorter equivalent vector comes back
    n = random_unit(rng)[0]
    w = rot.log_so3(rot.exp_so3((np.pi + 1e-9) * n))
    assert np.allclose(w, -(np.pi - 1e-9) * n, atol=1e-14)


def test_log_rejects_non_3x3():
    with pytest.raises(DeriveError, match="3x3"):
        rot.log_so3(np.eye(4))


def test_se3_exp_log_round_trip():
    rng = np.random.default_rng(RNG_SEED)
    for xi in rng.normal(size=(50, 6)):
        xi[3:] *= rng.uniform(0, np.pi) / np.linalg.norm(xi[3:])  # |w| < pi: log's range
        H = rot.exp_se3(xi)
        assert np.allclose(rot.log_se3(H), xi, atol=1e-12)
    # a pure rotation about an axis through the origin leaves the origin fixed
    assert np.allclose(rot.exp_se3([0, 0, 0, 0, 0, 1.0])[:3, 3], 0)


@pytest.mark.parametrize("order", ["ZYX", "XYZ", "YXZ", "ZXY", "XZY", "YZX"])
def test_euler_angles_round_trip(order):
    rng = np.random.default_rng(RNG_SEED)
    with warnings.catch_warnings():
        warnings.simplefilter("error", rot.GimbalLockWarning)
        for _ in range(100):
            ang = np.array([rng.uniform(-np.pi, np.pi), rng.uniform(-1.5, 1.5), rng.uniform(-np.pi, np.pi)])
            R = rot.euler_to_matrix(ang, order)
            assert np.allclose(rot.matrix_to_euler(R, order), ang, atol=1e-12)


def test_zyx_euler_angles_are_urdf_rpy():
    r, p, y = 0.1, -0.4, 2.0
    R = rot.rpy_to_matrix(r, p, y)
    assert np.allclose(R, rot.rot_z(y) @ rot.rot_y(p) @ rot.rot_x(r))
    assert np.allclose(rot.matrix_to_euler(R, "ZYX"), [y, p, r])
    a, b, c = sp.symbols("a b c")
    assert rot.euler_to_matrix((a, b, c), "XYZ") == rot.rot_x(a) * rot.rot_y(b) * rot.rot_z(c)


@pytest.mark.parametrize("order", ["ZYX", "XYZ"])
def test_gimbal_lock_warns_and_still_reconstructs_the_rotation(order):
    for b in (np.pi / 2, -np.pi / 2, np.pi / 2 - 1e-8):
        R = rot.euler_to_matrix((0.3, b, -0.8), order)
        with pytest.warns(rot.GimbalLockWarning, match="gimbal lock"):
            ang = rot.matrix_to_euler(R, order)
        assert ang[2] == 0.0
        assert np.abs(rot.euler_to_matrix(ang, order) - R).max() < 1e-7


def test_euler_order_is_validated():
    with pytest.raises(DeriveError, match="three distinct axes"):
        rot.euler_to_matrix((0, 0, 0), "ZYZ")


# --------------------------------------------------------------------------- inertia


def test_steiner_scalar_form_is_lecture_eq8():
    I_s, m_s, l1, l2 = sp.symbols("I_s m_s l_1 l_2", positive=True)
    assert steiner(I_s, m_s, l1) == I_s + m_s * l1**2
    # Example 1: angular momentum I1 w1 = I2 w2 -> w2 = w1 (I_s + m l1^2) / (I_s + m l2^2)
    assert steiner(0.1, 2.0, 0.5) == pytest.approx(0.6)


def test_steiner_tensor_form_matches_point_mass_sum():
    """A rigid cloud of point masses: inertia about O equals Steiner from its COM."""
    rng = np.random.default_rng(RNG_SEED)
    pts, ms = rng.normal(size=(30, 3)), rng.uniform(0.1, 1.0, 30)

    def about(origin):
        r = pts - origin
        return sum(m * ((v @ v) * np.eye(3) - np.outer(v, v)) for m, v in zip(ms, r))

    com = ms @ pts / ms.sum()
    I_c = about(com)
    O = rng.normal(size=3)
    assert np.allclose(steiner(I_c, ms.sum(), com - O), about(O), atol=1e-12)
    assert np.allclose(inertia_about_com(about(O), ms.sum(), com - O), I_c, atol=1e-12)
    # rod of length l about its end: m l^2 / 12 + m (l/2)^2 = m l^2 / 3 (the pendulum's rod)
    m, l = sp.symbols("m l", positive=True)
    I_end = steiner(sp.diag(m * l**2 / 12, m * l**2 / 12, 0), m, [0, 0, l / 2])
    assert sp.simplify(I_end[0, 0] - m * l**2 / 3) == 0


def test_rotated_inertia_keeps_principal_moments_and_matches_rotated_body():
    rng = np.random.default_rng(RNG_SEED)
    pts, ms = rng.normal(size=(20, 3)), rng.uniform(0.1, 1.0, 20)
    inertia = lambda p: sum(m * ((v @ v) * np.eye(3) - np.outer(v, v)) for m, v in zip(ms, p))  # noqa: E731
    R = rot.exp_so3(rng.normal(size=3))
    assert np.allclose(rotate_inertia(R, inertia(pts)), inertia(pts @ R.T), atol=1e-12)
    assert np.allclose(principal_moments(rotate_inertia(R, inertia(pts)))[0], principal_moments(inertia(pts))[0])
    a = sp.Symbol("a")
    Is = rotate_inertia(rot.rot_z(a), sp.diag(1, 2, 3))
    assert sp.simplify(Is.trace()) == 6


def test_inertia_validity_check():
    assert inertia_problem(np.diag([1.0, 2.0, 2.5])) is None
    assert inertia_problem(np.zeros((3, 3))) is None  # point mass
    assert inertia_problem(np.diag([0.0, 1.0, 1.0])) is None  # thin rod
    assert "positive definite" in inertia_problem(np.diag([0.0, 1.0, 1.0]), strict=True)
    assert "triangle" in inertia_problem(np.diag([1.0, 1.0, 3.0]))
    assert "semi-definite" in inertia_problem(np.diag([-1.0, 2.0, 2.0]))
    assert "symmetric" in inertia_problem([[1, 0.5, 0], [0, 1, 0], [0, 0, 1]])
    assert "mass" in inertia_problem(np.eye(3), mass=-1.0)
    assert "massless" in inertia_problem(np.eye(3), mass=0.0)
    with pytest.raises(DeriveError, match="link3: breaks the triangle"):
        check_inertia(np.diag([1.0, 1.0, 3.0]), what="link3")


def test_inertia_check_scales_with_the_tensor():
    """Tiny bodies (1e-10 kg m^2) that are not physical are caught: the tolerance is relative
    to the trace, not absolute; model validation uses this same check."""
    for bad, why in ((np.diag([1e-10, 1e-10, 3e-10]), "triangle"), (np.diag([-5e-10, 1e-10, 1e-10]), "semi-definite")):
        assert why in inertia_problem(bad)
        assert model_inertia_problem is inertia_problem
    # and a large physical one is not rejected by rounding
    good = steiner(np.diag([1e3, 1e3, 2e3]), 1e4, [1e-9, 0, 0])
    assert inertia_problem(good) is None


def test_symbolic_point_mass_pendulum_inertia():
    """Lecture Example 5: rod (COM at l/2) and sphere (at l) about the pivot, eq. 16."""
    m_r, m_s, I_r, I_s, l = sp.symbols("m_r m_s I_r I_s l", positive=True)
    total = steiner(I_r, m_r, l / 2) + steiner(I_s, m_s, l)
    assert sp.expand(total - (m_r * (l / 2) ** 2 + m_s * l**2 + I_r + I_s)) == 0
    assert math.isclose(float(total.subs({m_r: 1, m_s: 2, I_r: 0, I_s: 0, l: 1})), 2.25)
