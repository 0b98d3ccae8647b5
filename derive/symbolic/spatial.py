"""Rotations and homogeneous transforms in CasADi SX (symbolic) with exact constants.

Constant angles exact to rounding (within EXACT = 1e-14 rad of a multiple of pi/2,
:mod:`derive.description.angles`) are taken as that multiple, so their cosine and sine are
exactly 0 and +-1: the file's 1.5707963267948966 (cos = 6e-17) means pi/2, and keeping the
residue would cost arithmetic in every generated function. That moves no result by more than
1e-14 relative. An angle farther off is what the model says and is kept: ur5's URDF writes
1.57079632679 (pi/2 - 4.9e-12), the Kinova Gen3's 1.5708 (pi/2 + 3.7e-6); making those exact is
the import's decision (``derive import-urdf --snap-angles TOL``, recorded in the entry's
``source``), never a silent one (a 1e-11 rule here once moved Sawyer's gravity by 6.7e-11 from
its URDF). The decision is taken on the angle, never on the value of its cosine.
"""

from __future__ import annotations

import math

import casadi as ca

from derive.description.angles import EXACT, quarter

_QUARTERS = ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0))  # (cos, sin) of k pi/2, k mod 4


def _cs(angle):
    """(cos, sin) of an angle: exact for a numeric multiple of pi/2 (within EXACT), SX otherwise."""
    if isinstance(angle, (int, float)):
        k = quarter(angle, EXACT)
        if k is not None:
            return _QUARTERS[k % 4]
        return math.cos(angle), math.sin(angle)
    return ca.cos(angle), ca.sin(angle)


def rot_x(a) -> ca.SX:
    """Rx(a) of the lecture's eq. 1."""
    c, s = _cs(a)
    return ca.SX(ca.blockcat([[1, 0, 0], [0, c, -s], [0, s, c]]))


def rot_y(a) -> ca.SX:
    """Ry(a) of eq. 2."""
    c, s = _cs(a)
    return ca.SX(ca.blockcat([[c, 0, s], [0, 1, 0], [-s, 0, c]]))


def rot_z(a) -> ca.SX:
    """Rz(a) of eq. 3."""
    c, s = _cs(a)
    return ca.SX(ca.blockcat([[c, -s, 0], [s, c, 0], [0, 0, 1]]))


def rpy(r, p, y) -> ca.SX:
    """URDF roll-pitch-yaw: R = Rz(y) Ry(p) Rx(r). Numeric angles give constants (exact for multiples of pi/2)."""
    if all(isinstance(v, (int, float)) for v in (r, p, y)):
        m = rot_z(y) @ rot_y(p) @ rot_x(r)
        return ca.SX(ca.DM([[float(ca.DM(m[i, k])) for k in range(3)] for i in range(3)]))
    return rot_z(y) @ rot_y(p) @ rot_x(r)


def axis_angle(axis: tuple[float, float, float], angle) -> ca.SX:
    """Rotation about a unit ``axis`` by ``angle`` (Rodrigues, eq. 6), exact for the x, y, z axes."""
    if tuple(axis) == (1.0, 0.0, 0.0):
        return rot_x(angle)
    if tuple(axis) == (0.0, 1.0, 0.0):
        return rot_y(angle)
    if tuple(axis) == (0.0, 0.0, 1.0):
        return rot_z(angle)
    if tuple(axis) == (-1.0, 0.0, 0.0):
        return rot_x(-angle)
    if tuple(axis) == (0.0, -1.0, 0.0):
        return rot_y(-angle)
    if tuple(axis) == (0.0, 0.0, -1.0):
        return rot_z(-angle)
    c, s = _cs(angle)
    k = skew(ca.SX(ca.DM(list(axis))))
    return ca.SX.eye(3) + s * k + (1 - c) * (k @ k)


def skew(v) -> ca.SX:
    """[v]x with [v]x w = v x w."""
    return ca.SX(ca.blockcat([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]]))


def homogeneous(rotation, translation) -> ca.SX:
    """H = [[R, t], [0, 1]] of eq. 4."""
    return ca.SX(ca.blockcat([[rotation, ca.reshape(ca.SX(translation), 3, 1)], [ca.SX(1, 3), ca.SX(1)]]))


def exp_so3(w) -> ca.SX:
    """Rodrigues' formula (eq. 6) for a rotation vector w = a * n, |n| = 1, a = |w|:

        exp([w]x) = I + sin(a)/a [w]x + (1 - cos(a))/a^2 [w]x^2.

    (The summary prints (1 - cos a)/a; with [w]x = a [n]x the factor of [w]x^2 is 1/a^2.)
    Below a^2 = 1e-8 the coefficients switch to their Taylor series, so the expression
    stays finite and differentiable at w = 0 (CasADi evaluates both branches).
    """
    w = ca.reshape(ca.SX(w), 3, 1)
    a2 = ca.dot(w, w)
    a = ca.sqrt(a2)
    small = a2 < 1e-8
    safe = ca.if_else(small, 1, a)
    c1 = ca.if_else(small, 1 - a2 / 6, ca.sin(safe) / safe)
    c2 = ca.if_else(small, 0.5 - a2 / 24, (1 - ca.cos(safe)) / (safe * safe))
    k = skew(w)
    return ca.SX.eye(3) + c1 * k + c2 * (k @ k)


def log_so3(R) -> ca.SX:
    """The inverse of :func:`exp_so3`: the rotation vector w = a * n, a in [0, pi], with exp([w]x) = R.

    With v = vee(R - R^T) / 2 = sin(a) n and cos(a) = (tr R - 1) / 2, a = atan2(|v|, cos a)
    and w = a / |v| * v. Below |v| = 1e-9 that ratio is replaced: near a = 0 by w = v
    (error O(a^3)); near a = pi by pi times the unit column of (R + I) / 2 = n n^T with
    the largest diagonal (the sign of n is immaterial there). CasADi evaluates every
    branch, so none divides by zero.
    """
    R = ca.SX(R)
    v = 0.5 * ca.vertcat(R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1])
    c = 0.5 * (R[0, 0] + R[1, 1] + R[2, 2] - 1)
    # |v| with a finite derivative at v = 0 (norm_2's is NaN there, and 0 * NaN poisons even a
    # zero-weighted residual): the square root only ever sees 1 in the small branch
    s2 = ca.dot(v, v)
    small = s2 < 1e-18
    s = ca.if_else(small, 0, ca.sqrt(ca.if_else(small, 1, s2)))
    a = ca.atan2(s, c)
    general = a / ca.if_else(small, 1, s) * v
    B = 0.5 * (R + ca.SX.eye(3))
    k0 = ca.logic_and(B[0, 0] >= B[1, 1], B[0, 0] >= B[2, 2])
    k1 = ca.logic_and(ca.logic_not(k0), B[1, 1] >= B[2, 2])
    col = ca.if_else(k0, B[:, 0], ca.if_else(k1, B[:, 1], B[:, 2]))
    half_turn = ca.pi * col / ca.sqrt(ca.fmax(ca.if_else(k0, B[0, 0], ca.if_else(k1, B[1, 1], B[2, 2])), 1e-300))
    return ca.if_else(small, ca.if_else(c > 0, v, half_turn), general)
