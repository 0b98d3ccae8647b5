"""Forward dynamics and the first-order reduced ODE (the lecture's section 3.2).

qdd = M(q)^-1 (tau - C(q, qd) qd - g(q)) is computed by an unrolled LDL^T
factorisation and two triangular solves (for a branched tree or a floating base, the
LTDL factorisation along the tree, which creates no fill-in): M is never inverted
symbolically (the PyDy blow-up), and the same operations appear in the generated C.

x = [q; qd], u = tau:  x' = f(x, u) = [qd; qdd(q, qd, u)], with df/dx and df/du
from the implicit-function theorem on the inverse dynamics (:func:`ode_jacobians`).
The same order reduction in sympy and the linearisation about an operating point
are in :mod:`derive.inspect.linearize`.
"""

from __future__ import annotations

from typing import Callable

import casadi as ca

from derive.symbolic import derivatives


def ldlt_factor(M: ca.SX) -> tuple[list[list], list]:
    """M = L D L^T for symmetric positive definite M (no pivoting): (L, D), L unit lower-triangular
    as rows of scalars (None above the diagonal), D the diagonal."""
    n = M.shape[0]
    L = [[None] * n for _ in range(n)]
    D = [None] * n
    for j in range(n):
        D[j] = M[j, j] - sum((L[j][k] * L[j][k] * D[k] for k in range(j)), ca.SX(0))
        inv = 1 / D[j]
        for i in range(j + 1, n):
            L[i][j] = (M[i, j] - sum((L[i][k] * L[j][k] * D[k] for k in range(j)), ca.SX(0))) * inv
    return L, D


def ldlt_substitute(L: list[list], D: list, b: ca.SX) -> ca.SX:
    """x = L^-T D^-1 L^-1 b from :func:`ldlt_factor`'s (L, D); ``b`` may have several columns, solved
    together row by row (each row one CasADi operation: the same scalar expressions as column by
    column, built without a Python operation per entry)."""
    n = len(D)
    y = [None] * n
    for i in range(n):
        y[i] = b[i, :] - sum((L[i][k] * y[k] for k in range(i)), ca.SX(0))
    z = [y[i] / D[i] for i in range(n)]
    x = [None] * n
    for i in reversed(range(n)):
        x[i] = z[i] - sum((L[k][i] * x[k] for k in range(i + 1, n)), ca.SX(0))
    return ca.vertcat(*x)


def ldlt_solve(M: ca.SX, b: ca.SX) -> ca.SX:
    """Solve M x = b for symmetric positive definite M by unrolled LDL^T (no pivoting).

    M = L D L^T with unit lower-triangular L; x = L^-T D^-1 L^-1 b.
    """
    return ldlt_substitute(*ldlt_factor(M), b)


def ltdl_factor(M: ca.SX, parents: tuple[int, ...]) -> dict:
    """M = L^T D L for the mass matrix of a branched tree (Featherstone's LTDL, RBDA section 6.5):
    {(k, i): entry} for i an ancestor of k (L's, unit diagonal) or k itself (D's); ``parents[k]`` is
    the index of k's parent coordinate, -1 at the root.

    Eliminating from the leaves up creates no fill-in, so the cost follows the tree, O(n d^2)
    for depth d, where LDL^T from the root fills the whole matrix (a floating base couples every
    coordinate to the base's six).
    """
    n = M.shape[0]
    H = {(k, i): M[k, i] for k in range(n) for i in _ancestors(k, parents, inclusive=True)}
    for k in reversed(range(n)):
        i = parents[k]
        while i != -1:
            a = H[k, i] / H[k, k]
            j = i
            while j != -1:
                H[i, j] = H[i, j] - a * H[k, j]
                j = parents[j]
            H[k, i] = a
            i = parents[i]
    return H


def ltdl_substitute(H: dict, b: ca.SX, parents: tuple[int, ...]) -> ca.SX:
    """x = M^-1 b from :func:`ltdl_factor`'s factor; ``b`` may have several columns (row by row, as
    :func:`ldlt_substitute`)."""
    n = len(parents)
    y = [b[k, :] for k in range(n)]
    for k in reversed(range(n)):  # L^T y = b, leaves first
        for i in _ancestors(k, parents):
            y[i] = y[i] - H[k, i] * y[k]
    x = [y[k] / H[k, k] for k in range(n)]
    for k in range(n):  # L x = z, root first
        for i in _ancestors(k, parents):
            x[k] = x[k] - H[k, i] * x[i]
    return ca.vertcat(*x)


def _ancestors(k: int, parents: tuple[int, ...], inclusive: bool = False) -> list[int]:
    out = [k] if inclusive else []
    i = parents[k]
    while i != -1:
        out.append(i)
        i = parents[i]
    return out


def solver(M: ca.SX, parents: tuple[int, ...] | None = None) -> Callable[[ca.SX], ca.SX]:
    """B -> M^-1 B with M factored once (LTDL along the tree where ``parents`` is given, LDL^T
    otherwise), B one or more right-hand sides as columns: they share the factor's expressions
    instead of rebuilding them, which cost O(n^3) scalar operations in Python per solve (a 20-joint
    chain's ODE Jacobians: 61 solves, 11 s), and are solved row by row for all columns at once."""
    if parents is None:
        L, D = ldlt_factor(M)
        return lambda b: ldlt_substitute(L, D, b)
    H = ltdl_factor(M, parents)
    return lambda b: ltdl_substitute(H, b, parents)


def solve(M: ca.SX, b: ca.SX, parents: tuple[int, ...] | None = None) -> ca.SX:
    """M^-1 b: LTDL along the tree where ``parents`` is given (a branched tree), LDL^T otherwise."""
    return solver(M, parents)(b)


def forward_dynamics(M: ca.SX, bias: ca.SX, tau: ca.SX, parents: tuple[int, ...] | None = None) -> ca.SX:
    """qdd = M^-1 (tau - bias), bias = C qd + g, by LDL^T (or LTDL along a branched tree)."""
    return solve(M, tau - bias, parents)


def ode_jacobians(M: ca.SX, dID: ca.SX, q: ca.SX, qd: ca.SX, q_rate: ca.SX | None = None,
                  parents: tuple[int, ...] | None = None) -> tuple[ca.SX, ca.SX]:
    """A = df/dx and B = df/du of f = [qd; qdd(q, qd, u)] without differentiating the solve.

    From ID(q, qd, qdd(q, qd, u)) = u (implicit function theorem):
        dqdd/dx = -M^-1 dID/dx |_{qdd = FD},   dqdd/du = M^-1,
    so A = [[0, I], [-M^-1 dID/dq, -M^-1 dID/dqd]] and B = [[0], [M^-1]], all columns by the
    same unrolled LDL^T (or LTDL). ``dID`` is dID/dx (nv x (nq + nv)) at qdd = the forward dynamics
    (:func:`inverse_dynamics_jacobian`). ``q_rate`` is dq/dt as a function of q and qd when that is
    not qd itself (a floating base's quaternion): the top rows of A are then its Jacobian.
    """
    n, nq = qd.numel(), q.numel()
    x = ca.vertcat(q, qd)
    eye = ca.SX.eye(n)
    top = ca.horzcat(ca.SX.zeros(n, n), eye) if q_rate is None else ca.jacobian(q_rate, x)
    inverse = solver(M, parents)
    A = ca.vertcat(top, -inverse(dID))
    B = ca.vertcat(ca.SX.zeros(nq, n), inverse(eye))
    return A, B


def inverse_dynamics_jacobian(ne, mode: str, qdd_fd: ca.SX) -> ca.SX:
    """dID/dx (nv x (nq + nv)) of ``ne.inverse_dynamics(smooth=True)`` at qdd = ``qdd_fd``, by ``mode``:
    "reverse" or "forward" automatic differentiation (:data:`AD_MODES`), or "analytic", from the
    tree's structure (:mod:`derive.symbolic.derivatives`: fixed bases without mimic joints)."""
    s = ne.sym
    if mode == "analytic":
        return ca.horzcat(*derivatives.inverse_dynamics_derivatives(ne, qdd_fd))
    dID = ca.jacobian(ne.inverse_dynamics(smooth=True), ca.vertcat(s.q, s.qd), AD_MODES[mode])
    return ca.substitute(dID, s.qdd, qdd_fd)


AD_MODES = {"reverse": {"allow_forward": False}, "forward": {"allow_reverse": False}}
"""CasADi jacobian options of each AD mode of dID/dx. Reverse mode takes one sweep per output (nv),
forward mode one per input (nq + nv). On a chain reverse gives fewer operations (Panda's A: 8 473
instead of 9 981); on a short arm (UR5) or a branched floating base forward can (solo12), by a few
per cent. Both grow about 20x the RNEA's size on long chains, where the analytic form does not."""


def ode_rhs(q: ca.SX, qd: ca.SX, qdd: ca.SX) -> ca.SX:
    """x' = [qd; qdd]."""
    return ca.vertcat(qd, qdd)
