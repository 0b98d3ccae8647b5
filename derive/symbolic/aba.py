"""Forward dynamics by the articulated-body algorithm (Featherstone, RBDA Table 7.1), in body frames.

The composite-rigid-body route (M by CRBA, then LDL^T) costs O(n^2) for M and O(n^3) for the
factorisation: on a 40-joint chain 92k operations after CSE. The ABA's three passes cost O(n):
per body a 6x6 articulated inertia, moved into the parent's frame by a rotation and a shift of
its 3x3 blocks, which is why it loses on short arms (the Panda: about 3x the operations of CRBA
plus LDL^T) and wins on long chains. Fixed bases without mimic joints (:func:`supported`).

Spatial vectors here are [angular; linear] in body coordinates about the body origin; a body's
spatial inertia is [[I_o, h x], [-h x, m 1]] (h = m c, I_o about the origin). The actuators'
armature adds to each joint's articulated inertia D_i, their friction to the joint's bias.
"""

from __future__ import annotations

import casadi as ca

from derive.symbolic import derivatives
from derive.symbolic.spatial import skew


supported = derivatives.supported
"""Whether :func:`forward_dynamics` handles the robot of a NewtonEuler: a fixed base, no mimic joints
(the same robots as the analytic derivatives)."""


class _Articulated:
    """A symmetric 6x6 spatial inertia as 3x3 blocks [[A, B], [B^T, C]] ([angular; linear])."""

    def __init__(self, A: ca.SX, B: ca.SX, C: ca.SX):
        self.A, self.B, self.C = A, B, C

    def apply(self, x: ca.SX) -> ca.SX:
        w, v = x[0:3], x[3:6]
        return ca.vertcat(self.A @ w + self.B @ v, self.B.T @ w + self.C @ v)

    def minus_outer(self, U: ca.SX, inv_d: ca.SX) -> "_Articulated":
        """This - U U^T / D."""
        Uw, Uv = U[0:3], U[3:6]
        return _Articulated(self.A - (Uw * inv_d) @ Uw.T, self.B - (Uw * inv_d) @ Uv.T, self.C - (Uv * inv_d) @ Uv.T)

    def to_parent(self, Q: ca.SX, p: ca.SX) -> "_Articulated":
        """The inertia in the parent's frame: axes turned by Q (child to parent), then about the
        parent's origin, the child's origin sitting at p (parent coordinates)."""
        A, B, C = Q @ self.A @ Q.T, Q @ self.B @ Q.T, Q @ self.C @ Q.T
        P = skew(p)
        BP = B @ P
        return _Articulated(_symmetric(A - BP - BP.T - P @ C @ P), B + P @ C, C)

    def __add__(self, other: "_Articulated") -> "_Articulated":
        return _Articulated(self.A + other.A, self.B + other.B, self.C + other.C)


def _symmetric(S: ca.SX) -> ca.SX:
    """S with its lower triangle copied from the upper one (the same numbers, computed once)."""
    out = ca.SX(3, 3)
    for r in range(3):
        for c in range(3):
            out[r, c] = S[min(r, c), max(r, c)]
    return out


def _cross_motion(a: ca.SX, b: ca.SX) -> ca.SX:
    """a x b for motion vectors [w; v]."""
    return ca.vertcat(ca.cross(a[0:3], b[0:3]), ca.cross(a[0:3], b[3:6]) + ca.cross(a[3:6], b[0:3]))


def _cross_force(a: ca.SX, f: ca.SX) -> ca.SX:
    """a x* f for a motion a = [w; v] and a force f = [n; f]."""
    return ca.vertcat(ca.cross(a[0:3], f[0:3]) + ca.cross(a[3:6], f[3:6]), ca.cross(a[0:3], f[3:6]))


def forward_dynamics(ne, tau: ca.SX) -> ca.SX:
    """qdd(q, qd, tau) of the robot of ``ne`` (its actuators included: armature, smooth friction)."""
    if not supported(ne):
        raise ValueError("the articulated-body algorithm here needs a fixed base without mimic joints")
    bodies, sym = ne.bodies, ne.sym
    n, qd = len(bodies), sym.qd
    drive = ne.drive
    friction = drive.torque(qd, ca.SX.zeros(n, 1), smooth=True) if drive.active else None
    S, Q, p, v, c, IA, pA = [None] * n, [None] * n, [None] * n, [None] * n, [None] * n, [None] * n, [None] * n
    for i, b in enumerate(bodies):
        s_w, s_v = ne.motion_axes(i)
        S[i] = ca.vertcat(s_w, s_v)
        Q[i], p[i] = ne.placement(i)  # child axes -> parent axes; the child's origin in the parent
        if b.parent >= 0:
            v_p = v[b.parent]
            w = Q[i].T @ v_p[0:3]
            v[i] = ca.vertcat(w, Q[i].T @ (v_p[3:6] + ca.cross(v_p[0:3], p[i]))) + S[i] * qd[i]
            c[i] = _cross_motion(v[i], S[i] * qd[i])
        else:  # the world does not move
            v[i], c[i] = S[i] * qd[i], ca.SX.zeros(6, 1)
        h = b.h
        IA[i] = _Articulated(b.I_o, skew(h), b.m * ca.SX.eye(3))
        pA[i] = _cross_force(v[i], IA[i].apply(v[i]))
    U, D, u = [None] * n, [None] * n, [None] * n
    for i in reversed(range(n)):
        b = bodies[i]
        U[i] = IA[i].apply(S[i])
        D[i] = ca.dot(S[i], U[i]) + drive.armature[i]  # a float 0.0 without an actuator: nothing added
        u[i] = tau[i] - ca.dot(S[i], pA[i]) - (friction[i] if friction is not None else 0)
        if b.parent < 0:
            continue
        inv_d = 1 / D[i]
        Ia = IA[i].minus_outer(U[i], inv_d)
        pa = pA[i] + Ia.apply(c[i]) + U[i] * (u[i] * inv_d)
        P = Ia.to_parent(Q[i], p[i])
        IA[b.parent] = IA[b.parent] + P
        n_c, f_c = Q[i] @ pa[0:3], Q[i] @ pa[3:6]
        pA[b.parent] = pA[b.parent] + ca.vertcat(n_c + ca.cross(p[i], f_c), f_c)
    a, qdd = [None] * n, [None] * n
    a_root = ca.vertcat(ca.SX.zeros(3, 1), -ne.gravity)
    for i, b in enumerate(bodies):
        a_p = a[b.parent] if b.parent >= 0 else a_root
        a_in = ca.vertcat(Q[i].T @ a_p[0:3], Q[i].T @ (a_p[3:6] + ca.cross(a_p[0:3], p[i]))) + c[i]
        qdd[i] = (u[i] - ca.dot(U[i], a_in)) / D[i]
        a[i] = a_in + S[i] * qdd[i]
    return ca.vertcat(*qdd)
