"""Forward dynamics and the first-order reduced ODE (the lecture's section 3.2).

qdd = M(q)^-1 (tau - C(q, qd) qd - g(q)) is computed by an unrolled LDL^T
factorisation and two triangular solves: M is never inverted symbolically (the
PyDy blow-up), and the same operations appear in the generated C.

x = [q; qd], u = tau:  x' = f(x, u) = [qd; qdd(q, qd, u)], with df/dx and df/du
by algorithmic differentiation of that graph.
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


def ode_rhs(q: ca.SX, qd: ca.SX, qdd: ca.SX) -> ca.SX:
    """x' = [qd; qdd]."""
    return ca.vertcat(qd, qdd)
