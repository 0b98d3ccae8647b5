"""Order reduction and linearisation in sympy (the lecture's section 3.2 and Example 7).

x = [q; qd], u = tau:  x' = f(x, u) = [qd; qdd(q, qd, u)]. :func:`first_order` gives f
in the robot's own symbols; :func:`linearize` (exact) and :func:`linearize_numeric`
(any size) linearise it about an operating point: the small-angle pendulum
a phi'' + b phi = 0 becomes z' = [z1, -b/a z0].
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca
import numpy as np
import sympy as sp


def first_order(m) -> tuple[sp.Matrix, sp.Matrix, sp.Matrix]:
    """(x, u, f) of x' = f(x, u) for a SymbolicModel: x = [q; qd], u = tau, f = [qd; qdd(q, qd, tau)]."""
    return m.q.col_join(m.qd), m.tau, m.qd.col_join(m.forward_dynamics())


# ---- linearisation about an operating point ----

@dataclass(frozen=True)
class Linearization:
    """M0 dqdd + D0 dqd + K0 dq = dtau and dx' = A dx + B du about (x0, u0).

    K0 = d tau_id/dq and D0 = d tau_id/dqd at (q0, qd0, qdd0), with
    tau_id(q, qd, qdd) = M qdd + C qd + g and qdd0 = fd(q0, qd0, tau0); then
    A = [[0, I], [-M0^-1 K0, -M0^-1 D0]] and B = [[0], [M0^-1]], x = [q; qd], u = tau.
    sympy Matrices from :func:`linearize`, numpy arrays from :func:`linearize_numeric`.
    """

    M: object
    D: object
    K: object
    A: object
    B: object
    x0: object
    u0: object


def linearize(m, q0, qd0=None, tau0=None) -> Linearization:
    """Exact (sympy) linearisation of a SymbolicModel ``m`` about q0, qd0 (default 0), tau0.

    tau0 defaults to the holding torque g(q0), so (q0, 0, g(q0)) is an equilibrium
    (qdd0 = 0); values may be numbers or sympy expressions (e.g. in the parameters).
    Solves with M0 (LU), never a symbolic inverse; meant for small models.
    """
    n = m.nv
    q0 = sp.Matrix(n, 1, list(q0))
    qd0 = sp.zeros(n, 1) if qd0 is None else sp.Matrix(n, 1, list(qd0))
    at_q = dict(zip(m.q, q0))
    at_x = {**at_q, **dict(zip(m.qd, qd0))}
    M0 = m.mass_matrix.xreplace(at_q)
    bias0 = (m.coriolis_matrix * m.qd + m.gravity_vector).xreplace(at_x)
    tau0 = m.gravity_vector.xreplace(at_q) if tau0 is None else sp.Matrix(n, 1, list(tau0))
    qdd0 = M0.LUsolve(tau0 - bias0).applyfunc(_tidy)
    point = {**at_x, **dict(zip(m.qdd, qdd0))}
    tau_id = m.inverse_dynamics
    K0 = tau_id.jacobian(m.q).xreplace(point).applyfunc(_tidy)
    D0 = tau_id.jacobian(m.qd).xreplace(point).applyfunc(_tidy)
    A = sp.Matrix.vstack(sp.zeros(n).row_join(sp.eye(n)), (-M0.LUsolve(K0)).row_join(-M0.LUsolve(D0)))
    B = sp.zeros(n).col_join(M0.LUsolve(sp.eye(n)))
    return Linearization(M0, D0, K0, A.applyfunc(_tidy), B.applyfunc(_tidy), q0.col_join(qd0), tau0)


def _tidy(e: sp.Expr) -> sp.Expr:
    # exact and fast: entries are rational in the parameters once q0 is fixed (sp.simplify is 20x slower)
    return sp.factor(sp.cancel(e))


def linearize_numeric(sx, q0, qd0=None, tau0=None, p=None) -> Linearization:
    """Linearisation of an SXModel ``sx`` at numbers (any size), by algorithmic differentiation.

    Same conventions as :func:`linearize`; p defaults to the model's parameter defaults.
    """
    s = sx.sym
    n = s.nv
    q0 = np.asarray(q0, dtype=float).reshape(n)
    qd0 = np.zeros(n) if qd0 is None else np.asarray(qd0, dtype=float).reshape(n)
    p = np.array([par.default for par in sx.robot.parameters]) if p is None else np.asarray(p, dtype=float)
    tau_id = sx.inverse_dynamics("newton-euler")
    f = ca.Function("lin", [s.q, s.qd, s.qdd, s.p], [sx.mass_matrix("newton-euler"), sx.gravity_vector("newton-euler"),
                                                     tau_id, ca.jacobian(tau_id, s.q), ca.jacobian(tau_id, s.qd)])
    zero = np.zeros(n)
    M0, g0, bias0, _, _ = (np.array(v) for v in f(q0, qd0, zero, p))
    tau0 = g0.reshape(n) if tau0 is None else np.asarray(tau0, dtype=float).reshape(n)
    qdd0 = np.linalg.solve(M0, tau0 - bias0.reshape(n))
    _, _, _, K0, D0 = (np.array(v) for v in f(q0, qd0, qdd0, p))
    A = np.block([[np.zeros((n, n)), np.eye(n)], [-np.linalg.solve(M0, K0), -np.linalg.solve(M0, D0)]])
    B = np.vstack([np.zeros((n, n)), np.linalg.solve(M0, np.eye(n))])
    return Linearization(M0, D0, K0, A, B, np.concatenate([q0, qd0]), tau0)
