"""Analytical partial derivatives of the inverse dynamics, d tau / dq and d tau / dqd.

Automatic differentiation of the body-frame RNEA differentiates every downstream transform once
per direction, so its expression grows about 20x the RNEA's own (a 20-joint chain: 92k operations
after CSE, reverse mode). Here the derivatives come from the structure of the tree instead (the
idea of Carpentier and Mansard, "Analytical derivatives of rigid body dynamics algorithms", RSS
2018; derived afresh below), which costs O(n) per body plus two 6-vector dot products per
ancestor-descendant pair.

Everything is in world coordinates at the world origin, motion vectors [v; w] (v the velocity of
the body point at the world origin) and forces [f; n]. Joint k has the world motion axis S_k,
body i the velocity v_i = v_p + S_i qd_i, acceleration a_i = a_p + S_i qdd_i + v_i x S_i qd_i
(a_root = [-g; 0] brings in gravity), the force f_i = I_i a_i + v_i x* I_i v_i, the subtree force
F_i = f_i + sum of the children's, and tau_i = S_i . F_i.

Moving q_k turns the subtree of k rigidly about S_k. Turning the whole world rigidly changes no
torque (the equations are covariant), so the derivative is minus the effect of turning only what
enters the subtree from outside: its parent's velocity and acceleration (nu_k = -S_k x v_p,
alpha_k = -S_k x a_p). Adding dv to the parent's velocity and da to its acceleration changes the
subtree's accelerations by da + dv x (v_i - v_p), so a subtree force F_j (j in the subtree of k,
or any j below k for the part of F_j beyond k) changes by I^C (da - dv x v_p) + B'^C dv with the
composite inertia I^C, B'^C dv = sum_i [I_i (dv x v_i) + v_i x* I_i dv] + dv x* h^C and the
composite momentum h^C = sum_i I_i v_i. With u_j = I^C_j S_j and b_j = B^C_j S_j - S_j x* h^C_j
(B_i = (v_i x*) I_i - I_i (v_i x)), for an ancestor (or itself) k of j:

    d tau_j / dq_k  = u_j . beta_k + b_j . nu_k,        beta_k = alpha_k - nu_k x v_p(k)
    d tau_j / dqd_k = u_j . (2 v_p(k) x S_k) + b_j . S_k

and for a descendant k of j, through F_k alone (S_j does not move):

    d tau_j / dq_k  = S_j . (S_k x* F_k + I^C_k beta_k + B'^C_k nu_k)
    d tau_j / dqd_k = S_j . (I^C_k (2 v_p(k) x S_k) + B'^C_k S_k)

(qd_k adds S_k to the velocities beyond it, and v_p(k) x S_k to the accelerations). Both forms
agree at k = j. The actuators' terms (armature, friction) are added by differentiating them
directly (a diagonal). Fixed bases without mimic joints only (:func:`supported`); the rest keeps
automatic differentiation.
"""

from __future__ import annotations

import casadi as ca

from derive.symbolic.spatial import skew


WORTH_FROM_NV = 8
"""Fewest velocities for which the analytic form is worth building as a candidate: below, automatic
differentiation always gave fewer operations (Panda, 7: dID/dx 6 291 against 6 025 by reverse AD;
UR5, 6: 4 583 against 2 513), from 12 on chains the analytic form wins (12: 16 251 against 32 289)."""


def supported(ne) -> bool:
    """Whether :func:`inverse_dynamics_derivatives` handles the robot of ``ne`` (a
    :class:`~derive.symbolic.dynamics.NewtonEuler`, which uses this module and so is not imported
    here): a fixed base, no mimic joints."""
    return not ne.floating and not ne.mimic


def worth_trying(ne) -> bool:
    """Supported, and with at least :data:`WORTH_FROM_NV` velocities."""
    return supported(ne) and ne.sym.nv >= WORTH_FROM_NV


def motion_cross(m: ca.SX, x: ca.SX) -> ca.SX:
    """m x x for motion vectors [v; w]."""
    v, w = m[0:3], m[3:6]
    return ca.vertcat(ca.cross(w, x[0:3]) + ca.cross(v, x[3:6]), ca.cross(w, x[3:6]))


def force_cross(m: ca.SX, f: ca.SX) -> ca.SX:
    """m x* f for a motion m = [v; w] and a force f = [f; n]."""
    v, w = m[0:3], m[3:6]
    return ca.vertcat(ca.cross(w, f[0:3]), ca.cross(w, f[3:6]) + ca.cross(v, f[0:3]))


class Inertia:
    """A spatial inertia about the world origin: mass m, first moment h = m c, rotational inertia I."""

    def __init__(self, m, h: ca.SX, I: ca.SX):
        self.m, self.h, self.I = m, h, I

    def __add__(self, other: "Inertia") -> "Inertia":
        return Inertia(self.m + other.m, self.h + other.h, self.I + other.I)

    def apply(self, x: ca.SX) -> ca.SX:
        """The momentum [m v - h x w; I w + h x v] of the motion x = [v; w]."""
        v, w = x[0:3], x[3:6]
        return ca.vertcat(self.m * v - ca.cross(self.h, w), self.I @ w + ca.cross(self.h, v))

    def matrix(self) -> ca.SX:
        return ca.blockcat([[self.m * ca.SX.eye(3), -skew(self.h)], [skew(self.h), self.I]])


def _motion_cross_matrix(m: ca.SX) -> ca.SX:
    v, w = skew(m[0:3]), skew(m[3:6])
    return ca.blockcat([[w, v], [ca.SX.zeros(3, 3), w]])


def _force_cross_matrix(m: ca.SX) -> ca.SX:
    v, w = skew(m[0:3]), skew(m[3:6])
    return ca.blockcat([[w, ca.SX.zeros(3, 3)], [v, w]])


def inverse_dynamics_derivatives(ne, qdd: ca.SX, smooth: bool = True,
                                 actuators: bool = True) -> tuple[ca.SX, ca.SX]:
    """(d tau / dq, d tau / dqd) of ``ne.inverse_dynamics(qdd, smooth)`` at the accelerations ``qdd``
    (a symbol or an expression, e.g. the forward dynamics), each nv x nv; without the actuators'
    terms if not ``actuators`` (the rigid bodies' RNEA alone: d tau / dqd is then 2 C(q, qd), C the
    Christoffel-symbol Coriolis matrix, whatever qdd and gravity)."""
    if not supported(ne):
        raise ValueError("analytical inverse-dynamics derivatives need a fixed base without mimic joints")
    bodies, sym = ne.bodies, ne.sym
    n, qd = len(bodies), sym.qd
    R, o, S, I = [None] * n, [None] * n, [None] * n, [None] * n
    v, a, f = [None] * n, [None] * n, [None] * n
    zero = ca.SX.zeros(6, 1)
    a_root = ca.vertcat(-ne.gravity, ca.SX.zeros(3, 1))
    for i, b in enumerate(bodies):
        R_p, o_p = (R[b.parent], o[b.parent]) if b.parent >= 0 else (ca.SX.eye(3), ca.SX.zeros(3, 1))
        Q, p = ne.placement(i)
        o[i] = o_p + R_p @ p
        R[i] = R_p @ Q
        s_w, s_v = ne.motion_axes(i)
        w = R[i] @ s_w
        S[i] = ca.vertcat(R[i] @ s_v + ca.cross(o[i], w), w)
        h = R[i] @ b.h
        I[i] = Inertia(b.m, b.m * o[i] + h,
                       R[i] @ b.I_o @ R[i].T - skew(o[i]) @ skew(h) - skew(h) @ skew(o[i]) - b.m * (skew(o[i]) @ skew(o[i])))
        v_p, a_p = (v[b.parent], a[b.parent]) if b.parent >= 0 else (zero, a_root)
        v[i] = v_p + S[i] * qd[i]
        a[i] = a_p + S[i] * qdd[i] + motion_cross(v_p, S[i]) * qd[i]
        f[i] = I[i].apply(a[i]) + force_cross(v[i], I[i].apply(v[i]))
    # composites over each subtree: inertia, momentum, force, and B = sum (v x*) I - I (v x)
    IC, hC, FC, BC = list(I), [I[i].apply(v[i]) for i in range(n)], list(f), [None] * n
    for i in range(n):
        Im = I[i].matrix()
        BC[i] = _force_cross_matrix(v[i]) @ Im - Im @ _motion_cross_matrix(v[i])
    for i in reversed(range(n)):
        p = bodies[i].parent
        if p >= 0:
            IC[p], hC[p], FC[p], BC[p] = IC[p] + IC[i], hC[p] + hC[i], FC[p] + FC[i], BC[p] + BC[i]

    def b_prime(k: int, x: ca.SX) -> ca.SX:
        return BC[k] @ x + force_cross(x, hC[k])

    u = [IC[j].apply(S[j]) for j in range(n)]
    bvec = [BC[j] @ S[j] - force_cross(S[j], hC[j]) for j in range(n)]
    nu, beta, beta_d, y, z = [None] * n, [None] * n, [None] * n, [None] * n, [None] * n
    for k, b in enumerate(bodies):
        v_p, a_p = (v[b.parent], a[b.parent]) if b.parent >= 0 else (zero, a_root)
        nu[k] = -motion_cross(S[k], v_p)
        beta[k] = -motion_cross(S[k], a_p) - motion_cross(nu[k], v_p)
        beta_d[k] = 2 * motion_cross(v_p, S[k])
        y[k] = force_cross(S[k], FC[k]) + IC[k].apply(beta[k]) + b_prime(k, nu[k])
        z[k] = IC[k].apply(beta_d[k]) + b_prime(k, S[k])
    dq, dqd = ca.SX(n, n), ca.SX(n, n)
    for j in range(n):
        k = j
        while k >= 0:  # k an ancestor of j, or j itself
            dq[j, k] = ca.dot(u[j], beta[k]) + ca.dot(bvec[j], nu[k])
            dqd[j, k] = ca.dot(u[j], beta_d[k]) + ca.dot(bvec[j], S[k])
            if k != j:  # j is a descendant of k: the row of k
                dq[k, j] = ca.dot(S[k], y[j])
                dqd[k, j] = ca.dot(S[k], z[j])
            k = bodies[k].parent
    drive = ne.drive.torque(qd, sym.qdd, smooth) if actuators else None  # its qd-derivative: a diagonal
    if drive is not None:
        dqd += ca.jacobian(drive, qd)
    return dq, dqd
