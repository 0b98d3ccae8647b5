"""Rotations and homogeneous transforms in CasADi SX (symbolic) with exact constants.

Constant rotations (numeric rpy) are evaluated in floating point and entries
within 1e-15 of 0 or +-1 are snapped: cos(pi/2) = 6.1e-17 is rounding noise of
the URDF's decimal pi/2, and keeping it would cost arithmetic in every
generated function while changing results by less than one ulp of the link
lengths involved.
"""

from __future__ import annotations

import math

import casadi as ca

SNAP = 1e-15


def _snap(x: float) -> float:
    for target in (0.0, 1.0, -1.0):
        if abs(x - target) < SNAP:
            return target
    return x


def _cs(angle):
    if isinstance(angle, (int, float)):
        return _snap(math.cos(angle)), _snap(math.sin(angle))
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
    """URDF roll-pitch-yaw: R = Rz(y) Ry(p) Rx(r). Numeric angles give snapped constants."""
    if all(isinstance(v, (int, float)) for v in (r, p, y)):
        m = rot_z(y) @ rot_y(p) @ rot_x(r)
        return ca.SX(ca.DM([[_snap(float(ca.DM(m[i, k]))) for k in range(3)] for i in range(3)]))
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
