"""Forward dynamics and the first-order reduced ODE (the lecture's section 3.2).

qdd = M(q)^-1 (tau - C(q, qd) qd - g(q)) is computed by an unrolled LDL^T
factorisation and two triangular solves: M is never inverted symbolically (the
PyDy blow-up), and the same operations appear in the generated C.

x = [q; qd], u = tau:  x' = f(x, u) = [qd; qdd(q, qd, u)], with df/dx and df/du
from the implicit-function theorem on the inverse dynamics (:func:`ode_jacobians`).
The same order reduction in sympy and the linearisation about an operating point
are in :mod:`derive.inspect.linearize`.
"""

from __future__ import annotations

import casadi as ca


def ldlt_solve(M: ca.SX, b: ca.SX) -> ca.SX:
    """Solve M x = b for symmetric positive definite M by unrolled LDL^T (no pivoting).

    M = L D L^T with unit lower-triangular L; x = L^-T D^-1 L^-1 b.
    """
    n = M.shape[0]
    L = [[None] * n for _ in range(n)]
    D = [None] * n
    for j in range(n):
        D[j] = M[j, j] - sum((L[j][k] * L[j][k] * D[k] for k in range(j)), ca.SX(0))
        inv = 1 / D[j]
        for i in range(j + 1, n):
            L[i][j] = (M[i, j] - sum((L[i][k] * L[j][k] * D[k] for k in range(j)), ca.SX(0))) * inv
    y = [None] * n
    for i in range(n):
        y[i] = b[i] - sum((L[i][k] * y[k] for k in range(i)), ca.SX(0))
    z = [y[i] / D[i] for i in range(n)]
    x = [None] * n
    for i in reversed(range(n)):
        x[i] = z[i] - sum((L[k][i] * x[k] for k in range(i + 1, n)), ca.SX(0))
    return ca.vertcat(*x)


def forward_dynamics(M: ca.SX, bias: ca.SX, tau: ca.SX) -> ca.SX:
    """qdd = M^-1 (tau - bias), bias = C qd + g, by LDL^T."""
    return ldlt_solve(M, tau - bias)


def ode_jacobians(M: ca.SX, tau_id: ca.SX, q: ca.SX, qd: ca.SX, qdd: ca.SX, qdd_fd: ca.SX,
                  q_rate: ca.SX | None = None) -> tuple[ca.SX, ca.SX]:
    """A = df/dx and B = df/du of f = [qd; qdd(q, qd, u)] without differentiating the solve.

    From ID(q, qd, qdd(q, qd, u)) = u (implicit function theorem):
        dqdd/dx = -M^-1 dID/dx |_{qdd = FD},   dqdd/du = M^-1,
    so A = [[0, I], [-M^-1 dID/dq, -M^-1 dID/dqd]] and B = [[0], [M^-1]], each column
    by the same unrolled LDL^T (CSE shares the factorisation). ``tau_id`` is ID as an
    expression of q, qd and the symbol ``qdd``; ``qdd_fd`` the forward dynamics. ``q_rate`` is
    dq/dt as a function of q and qd when that is not qd itself (a floating base's quaternion):
    the top rows of A are then its Jacobian.
    """
    n, nq = qd.numel(), q.numel()
    x = ca.vertcat(q, qd)
    dID = ca.substitute(ca.jacobian(tau_id, x), qdd, qdd_fd)
    eye = ca.SX.eye(n)
    top = ca.horzcat(ca.SX.zeros(n, n), eye) if q_rate is None else ca.jacobian(q_rate, x)
    A = ca.vertcat(top, ca.horzcat(*[-ldlt_solve(M, dID[:, k]) for k in range(nq + n)]))
    B = ca.vertcat(ca.SX.zeros(nq, n), ca.horzcat(*[ldlt_solve(M, eye[:, k]) for k in range(n)]))
    return A, B


def ode_rhs(q: ca.SX, qd: ca.SX, qdd: ca.SX) -> ca.SX:
    """x' = [qd; qdd]."""
    return ca.vertcat(qd, qdd)
