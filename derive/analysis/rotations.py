"""Rotations and rigid transforms of the lecture, section 2.1: numeric, sympy and CasADi.

    Rx(a) = [[1, 0, 0], [0, c, -s], [0, s, c]]       (eq. 1; Ry eq. 2, Rz eq. 3)
    H = [[R, t], [0, 1]],  H (p, 1) = (R p + t, 1)   (eq. 4-5)
    exp([w]x) = I + sin(a)/a [w]x + (1 - cos a)/a^2 [w]x^2,  a = |w|   (Rodrigues, eq. 6)

Rotation matrices are active (they rotate vectors) and right-handed. Every
function works in the algebra of its argument: floats and numpy arrays give
float numpy arrays, sympy expressions give sympy Matrices, CasADi SX gives SX
(through :mod:`derive.symbolic.spatial`, which the kinematics uses). ``log_so3`` and
``matrix_to_euler`` are numeric only.

Euler angles are intrinsic: order "ZYX" means R = Rz(a) Ry(b) Rx(c) (yaw, pitch,
roll: URDF's rpy = (c, b, a)); "XYZ" means R = Rx(a) Ry(b) Rz(c). All six
Tait-Bryan orders are accepted. At the middle angle b = +-pi/2 the first and
third axes align (gimbal lock): only a +- c is determined, ``matrix_to_euler``
then sets c = 0 and warns with :class:`GimbalLockWarning`.
"""

from __future__ import annotations

import math
import warnings

import casadi as ca
import numpy as np
import sympy as sp

from derive.symbolic import spatial
from derive.errors import DeriveError

AXES = "XYZ"


class GimbalLockWarning(RuntimeWarning):
    """Euler angles requested where the first and third rotation axes align."""


def _kind(*xs) -> str:
    if any(isinstance(x, (ca.SX, ca.MX)) for x in xs):
        return "casadi"
    if any(isinstance(x, (sp.Basic, sp.MatrixBase)) for x in xs):
        return "sympy"
    if any(isinstance(x, (list, tuple)) for x in xs):
        return _kind(*[v for x in xs if isinstance(x, (list, tuple)) for v in x])
    return "numpy"


def _elementary(axis: int, a):
    kind = _kind(a)
    if kind == "casadi":
        return (spatial.rot_x, spatial.rot_y, spatial.rot_z)[axis](a)
    if kind == "sympy":
        c, s = sp.cos(a), sp.sin(a)
    else:
        c, s = math.cos(a), math.sin(a)
    rows = {0: [[1, 0, 0], [0, c, -s], [0, s, c]],
            1: [[c, 0, s], [0, 1, 0], [-s, 0, c]],
            2: [[c, -s, 0], [s, c, 0], [0, 0, 1]]}[axis]
    return sp.Matrix(rows) if kind == "sympy" else np.array(rows, dtype=float)


def rot_x(a):
    """Rx(a), eq. 1."""
    return _elementary(0, a)


def rot_y(a):
    """Ry(a), eq. 2."""
    return _elementary(1, a)


def rot_z(a):
    """Rz(a), eq. 3."""
    return _elementary(2, a)


def homogeneous(R, t):
    """H = [[R, t], [0, 1]] (eq. 4), 4x4."""
    kind = _kind(R, t)
    if kind == "casadi":
        return spatial.homogeneous(R, t)
    if kind == "sympy":
        return sp.Matrix(sp.BlockMatrix([[sp.Matrix(R), sp.Matrix(3, 1, list(t))], [sp.zeros(1, 3), sp.ones(1, 1)]]))
    H = np.eye(4)
    H[:3, :3], H[:3, 3] = np.asarray(R, dtype=float), np.asarray(t, dtype=float).reshape(3)
    return H


def inverse_transform(H):
    """H^-1 = [[R^T, -R^T t], [0, 1]] without a general inverse (numpy or sympy)."""
    if _kind(H) == "sympy":
        H = sp.Matrix(H)
        R, t = H[:3, :3], H[:3, 3]
        return homogeneous(R.T, -R.T * t)
    H = np.asarray(H, dtype=float)
    R, t = H[:3, :3], H[:3, 3]
    return homogeneous(R.T, -R.T @ t)


def transform_point(H, p):
    """R p + t, eq. 5 (the homogeneous point (p, 1) mapped by H)."""
    if _kind(H, p) == "sympy":
        H = sp.Matrix(H)
        return H[:3, :3] * sp.Matrix(3, 1, list(p)) + H[:3, 3]
    H = np.asarray(H, dtype=float)
    return H[:3, :3] @ np.asarray(p, dtype=float) + H[:3, 3]


def skew(w):
    """[w]x with [w]x v = w x v."""
    kind = _kind(w)
    if kind == "casadi":
        return spatial.skew(w)
    x, y, z = (list(w) if kind == "sympy" else np.asarray(w, dtype=float).reshape(3))
    rows = [[0, -z, y], [z, 0, -x], [-y, x, 0]]
    return sp.Matrix(rows) if kind == "sympy" else np.array(rows, dtype=float)


def vee(S):
    """Inverse of ``skew``: w from the skew-symmetric part of S, (S - S^T)/2 = [w]x."""
    if _kind(S) == "sympy":
        S = sp.Matrix(S)
        return sp.Matrix([S[2, 1] - S[1, 2], S[0, 2] - S[2, 0], S[1, 0] - S[0, 1]]) / 2
    S = np.asarray(S, dtype=float)
    return 0.5 * np.array([S[2, 1] - S[1, 2], S[0, 2] - S[2, 0], S[1, 0] - S[0, 1]])


def axis_angle(axis, angle):
    """Rotation by ``angle`` about ``axis`` (normalised here): I + sin(a) K + (1 - cos a) K^2, K = [n]x."""
    kind = _kind(axis, angle)
    if kind == "casadi":
        return spatial.exp_so3(ca.SX(ca.DM(_unit(axis))) * angle)
    if kind == "sympy":
        n = sp.Matrix(3, 1, list(axis))
        K = skew(n / sp.sqrt(n.dot(n)))
        return sp.eye(3) + sp.sin(angle) * K + (1 - sp.cos(angle)) * K * K
    K = skew(_unit(axis))
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * (K @ K)


def _unit(axis) -> np.ndarray:
    n = np.asarray(axis, dtype=float).reshape(3)
    norm = np.linalg.norm(n)
    if norm < 1e-300:
        raise DeriveError("rotation axis: must not be the zero vector")
    return n / norm


def exp_so3(w):
    """R = exp([w]x) by Rodrigues' formula (eq. 6); a = |w| is the angle, w/a the axis.

    Numerically the coefficients sin(a)/a and (1 - cos a)/a^2 use their Taylor
    series below a = 1e-4 (relative error < 1e-17 there), so w -> 0 is exact.
    Symbolically (sympy) the closed form in a = sqrt(w . w) is returned.
    """
    kind = _kind(w)
    if kind == "casadi":
        return spatial.exp_so3(w)
    if kind == "sympy":
        w = sp.Matrix(3, 1, list(w))
        a = sp.sqrt(w.dot(w))
        K = skew(w)
        return sp.eye(3) + sp.sin(a) / a * K + (1 - sp.cos(a)) / a**2 * K * K
    w = np.asarray(w, dtype=float).reshape(3)
    a2 = float(w @ w)
    if a2 < 1e-8:
        c1, c2 = 1 - a2 / 6 + a2 * a2 / 120, 0.5 - a2 / 24 + a2 * a2 / 720
    else:
        a = math.sqrt(a2)
        c1, c2 = math.sin(a) / a, (1 - math.cos(a)) / a2
    K = skew(w)
    return np.eye(3) + c1 * K + c2 * (K @ K)


def log_so3(R) -> np.ndarray:
    """w with exp([w]x) = R and |w| in [0, pi] (the inverse of Rodrigues' formula).

    The angle is a = atan2(sin a, cos a) with sin a = |vee(R - R^T)|/2 and
    cos a = (tr R - 1)/2, accurate over the whole range (acos alone loses half the
    digits near 0 and pi). The axis comes from
    - a < 1e-4: w = vee(R) (1 + a^2/6 + 7 a^4/360), the series of a/sin a;
    - a <= pi/2: w = a / sin(a) * vee(R);
    - a > pi/2: the symmetric part, (R + R^T)/2 - cos(a) I = (1 - cos a) n n^T, read
      from its largest diagonal entry (well conditioned up to pi itself); the sign of
      n follows vee(R), which is 2 sin(a) n.
    At a = pi exactly w and -w are the same rotation: the sign is then chosen so the
    largest component of n is positive.
    """
    R = np.asarray(R, dtype=float)
    if R.shape != (3, 3):
        raise DeriveError(f"log_so3: expected a 3x3 rotation matrix, got shape {R.shape}")
    v = vee(R)
    s, c = np.linalg.norm(v), (np.trace(R) - 1) / 2
    a = math.atan2(s, c)
    if a < 1e-4:
        return v * (1 + a * a / 6 + 7 * a**4 / 360)
    if c >= 0:
        return a / s * v
    B = (R + R.T) / 2 - c * np.eye(3)
    i = int(np.argmax(np.diag(B)))
    n = B[:, i] / math.sqrt(B[i, i] * (1 - c))
    if n @ v < 0:
        n = -n
    return a * n


def exp_se3(xi):
    """H = exp of a twist xi = (v, w) (linear first, as the Jacobians): [[exp(w), V v], [0, 1]],
    V = I + (1 - cos a)/a^2 [w]x + (a - sin a)/a^3 [w]x^2 (numeric)."""
    xi = np.asarray(xi, dtype=float).reshape(6)
    v, w = xi[:3], xi[3:]
    a2 = float(w @ w)
    if a2 < 1e-8:
        c2, c3 = 0.5 - a2 / 24, 1 / 6 - a2 / 120
    else:
        a = math.sqrt(a2)
        c2, c3 = (1 - math.cos(a)) / a2, (a - math.sin(a)) / (a2 * a)
    K = skew(w)
    return homogeneous(exp_so3(w), (np.eye(3) + c2 * K + c3 * (K @ K)) @ v)


def log_se3(H) -> np.ndarray:
    """The twist (v, w) with exp_se3(v, w) = H, |w| in [0, pi] (inverse of ``exp_se3``)."""
    H = np.asarray(H, dtype=float)
    w = log_so3(H[:3, :3])
    a2 = float(w @ w)
    K = skew(w)
    if a2 < 1e-8:
        c = 1 / 12 + a2 / 720
    else:
        a = math.sqrt(a2)
        c = (1 - a * math.sin(a) / (2 * (1 - math.cos(a)))) / a2
    V_inv = np.eye(3) - 0.5 * K + c * (K @ K)
    return np.concatenate([V_inv @ H[:3, 3], w])


# --------------------------------------------------------------------------- Euler angles


def _order(order: str) -> tuple[int, int, int]:
    order = order.upper()
    if len(order) != 3 or set(order) != set(AXES):
        raise DeriveError(f"Euler order '{order}': expected three distinct axes of X, Y, Z (Tait-Bryan), e.g. ZYX or XYZ")
    return tuple(AXES.index(ch) for ch in order)


def euler_to_matrix(angles, order: str = "ZYX"):
    """R = R_i(a) R_j(b) R_k(c) for order "ijk" (intrinsic), angles (a, b, c)."""
    i, j, k = _order(order)
    a, b, c = angles
    return _elementary(i, a) @ _elementary(j, b) @ _elementary(k, c)


def matrix_to_euler(R, order: str = "ZYX", tol: float = 1e-6) -> np.ndarray:
    """(a, b, c) with R = R_i(a) R_j(b) R_k(c); b in [-pi/2, pi/2], a and c in (-pi, pi].

    With e = +1 for cyclic orders (XYZ, YZX, ZXY) and -1 otherwise:
    b = asin(e R[i,k]), a = atan2(-e R[j,k], R[k,k]), c = atan2(-e R[i,j], R[i,i]).
    When cos(b) < ``tol`` the axes of a and c align (gimbal lock): c is set to 0,
    a = atan2(e R[k,j], R[j,j]) carries the whole rotation about that axis, and a
    GimbalLockWarning is issued.
    """
    i, j, k = _order(order)
    e = 1.0 if (i, j, k) in ((0, 1, 2), (1, 2, 0), (2, 0, 1)) else -1.0
    R = np.asarray(R, dtype=float)
    sb = float(np.clip(e * R[i, k], -1.0, 1.0))
    cb = math.hypot(R[j, k], R[k, k])
    b = math.atan2(sb, cb)
    if cb < tol:
        warnings.warn(f"gimbal lock in {order.upper()} Euler angles: middle angle {b:+.9f} rad is within "
                      f"{tol:g} (cos) of +-pi/2; only a +- c of the outer angles is determined, "
                      "returning c = 0", GimbalLockWarning, stacklevel=2)
        return np.array([math.atan2(e * R[k, j], R[j, j]), b, 0.0])
    return np.array([math.atan2(-e * R[j, k], R[k, k]), b, math.atan2(-e * R[i, j], R[i, i])])


def rpy_to_matrix(roll, pitch, yaw):
    """URDF's rpy: R = Rz(yaw) Ry(pitch) Rx(roll) (= ZYX Euler angles (yaw, pitch, roll))."""
    return euler_to_matrix((yaw, pitch, roll), "ZYX")


def is_rotation(R, tol: float = 1e-9) -> bool:
    """R^T R = I and det R = +1 within ``tol``."""
    R = np.asarray(R, dtype=float)
    return R.shape == (3, 3) and np.allclose(R.T @ R, np.eye(3), atol=tol) and abs(np.linalg.det(R) - 1) < tol
