"""Numeric reference of a closed chain (numpy only): closures, the projection G and the KKT system.

Independent of the symbolic side (:mod:`derive.symbolic.closure`): it uses the tree's
:class:`derive.reference.rnea.NumericRobot` (Featherstone's algorithms) and the loop definitions of
:class:`derive.description.robot.Loop`.

Tree coordinates q = (y, z) in the tree's order (y = ``robot.independent``, z = ``robot.dependent``);
phi(q) stacks the loops' residuals, K = dphi/dq their Jacobian (here from the frames' geometric
Jacobians, not by differentiating phi) and only the kept rows ``robot.loop_rows`` enter K_z (a
redundant row of an over-constrained loop adds nothing). With K qd = 0 and K qdd + Kdot qd = 0:

    qd = G yd,   G = [I; -K_z^-1 K_y] (rows in q's order),
    qdd = G ydd + Gdot yd,   Gdot yd = [0; -K_z^-1 Kdot qd],
    M_y = G^T M G,   h_y = G^T (C qd + g + M Gdot yd) = G^T rnea(q, qd, Gdot yd),
    tau_y = G^T rnea(q, qd, G ydd + Gdot yd) (inverse dynamics),   ydd = M_y^-1 (tau_y - h_y),

and the tree's KKT system with the actuation tau = S^T tau_y on y (S selects y):

    [M  K^T] [ qdd  ]   [ tau - h   ]
    [K   0 ] [-lambda] = [-Kdot qd ],   i.e. M qdd + h = tau + K^T lambda,

lambda being the loops' constraint forces (in phi's units: N for position rows).
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from derive.description import expr
from derive.description.robot import Robot
from derive.reference.rnea import COMPLEX_STEP, NumericRobot

NEWTON_STEPS = 30


class ClosedChainReference:
    """The closed chain of ``robot`` (which has loops) at fixed parameters, in numpy."""

    def __init__(self, robot: Robot, params: Mapping[str, float] | None = None):
        if not robot.loops:
            raise ValueError(f"robot '{robot.name}' has no loops")
        self.robot = robot
        self.tree = NumericRobot(robot, params)
        names = [c.name for c in robot.coordinates]
        self.n = len(names)
        self.y = [names.index(c) for c in robot.independent]
        self.z = [names.index(c) for c in robot.dependent]
        self.rows = list(robot.loop_rows)
        self.lengths = [None if lp.length is None else float(expr.evaluate(lp.length, self.tree.params))
                        for lp in robot.loops]
        self.q_ref = np.array(robot.reference_q, dtype=float)

    # ------------------------------------------------------------------ closures

    def phi(self, q) -> np.ndarray:
        """The stacked loop residuals (the equations of :class:`derive.description.robot.Loop`)."""
        out = []
        for lp, length in zip(self.robot.loops, self.lengths):
            Ta, Tb = self.tree.frame_pose(q, lp.a), self.tree.frame_pose(q, lp.b)
            Ra, Rb, d = Ta[:3, :3], Tb[:3, :3], Ta[:3, 3] - Tb[:3, 3]
            if lp.kind == "point":
                out.append(d)
            elif lp.kind == "distance":
                out.append(np.array([(d @ d - length ** 2) / (2 * length)]))
            elif lp.kind == "weld":
                out.append(np.array([Ra[:, i] @ Rb[:, j] for i, j in ((1, 2), (2, 0), (0, 1))]))
                out[-1] = np.concatenate([d, out[-1]])
            else:
                n = np.array(lp.axis, dtype=float)
                u, v = (np.array(x) for x in lp.basis)
                if lp.kind == "hinge":
                    out.append(np.concatenate([d, [(Ra @ u) @ (Rb @ n), (Ra @ v) @ (Rb @ n)]]))
                else:
                    out.append(np.array([(Ra @ u) @ d, (Ra @ v) @ d] + ([(Ra @ u) @ (Rb @ v)] if lp.rotation else [])))
        return np.concatenate(out)

    def constraint_jacobian(self, q) -> np.ndarray:
        """K(q) (rows x nq) from the frames' LOCAL_WORLD_ALIGNED Jacobians [v; w]: with A = R_a a', B = R_b b'
        d/dt (A . B) = (A x B) . (w_a - w_b), d/dt (A . d) = (A x d) . w_a + A . (v_a - v_b)."""
        out = []
        for lp, length in zip(self.robot.loops, self.lengths):
            Ta, Tb = self.tree.frame_pose(q, lp.a), self.tree.frame_pose(q, lp.b)
            Ja, Jb = self.tree.jacobian(q, lp.a), self.tree.jacobian(q, lp.b)
            Ra, Rb, d = Ta[:3, :3], Tb[:3, :3], Ta[:3, 3] - Tb[:3, 3]
            Jd, Jw = Ja[:3] - Jb[:3], Ja[3:] - Jb[3:]

            def turn(A, B):
                return np.cross(A, B) @ Jw

            if lp.kind == "point":
                out.append(Jd)
            elif lp.kind == "distance":
                out.append((d @ Jd / length)[None, :])
            elif lp.kind == "weld":
                out.append(np.vstack([Jd] + [turn(Ra[:, i], Rb[:, j]) for i, j in ((1, 2), (2, 0), (0, 1))]))
            else:
                n = np.array(lp.axis, dtype=float)
                u, v = (np.array(x) for x in lp.basis)
                if lp.kind == "hinge":
                    out.append(np.vstack([Jd, turn(Ra @ u, Rb @ n), turn(Ra @ v, Rb @ n)]))
                else:
                    rows = [np.cross(Ra @ w, d) @ Ja[3:] + (Ra @ w) @ Jd for w in (u, v)]
                    if lp.rotation:
                        rows.append(turn(Ra @ u, Rb @ v))
                    out.append(np.vstack(rows))
        return np.vstack(out)

    def kdot_qd(self, q, qd) -> np.ndarray:
        """Kdot qd = (dK/dq qd) qd by complex step along qd (K is analytic in q)."""
        q, qd = np.asarray(q, dtype=float), np.asarray(qd, dtype=float)
        return self.constraint_jacobian(q + 1j * COMPLEX_STEP * qd).imag @ qd / COMPLEX_STEP

    def closure(self, y, z0=None) -> tuple[np.ndarray, float]:
        """(q, max |phi|): z = gamma(y) by Newton on the kept rows from z0 (default the reference's z)."""
        q = self.q_ref.copy() if z0 is None else self.assemble(y, z0)
        q[self.y] = y
        for _ in range(NEWTON_STEPS):
            r = self.phi(q)[self.rows]
            if np.max(np.abs(r)) <= 1e-15:
                break
            q[self.z] -= np.linalg.solve(self.constraint_jacobian(q)[np.ix_(self.rows, self.z)], r)
        return q, float(np.max(np.abs(self.phi(q))))

    def closure_from_outputs(self, o, w0=None) -> tuple[np.ndarray, float]:
        """(q, max |phi|): the loops closed with models.yaml's ``outputs`` held at o, by Newton on the kept rows
        over the other coordinates w from w0 (default the reference's): the joint -> motor position map."""
        names = [c.name for c in self.robot.coordinates]
        oi = [names.index(c) for c in self.robot.outputs]
        w = [i for i in range(self.n) if i not in oi]
        q = self.q_ref.copy()
        if w0 is not None:
            q[w] = w0
        q[oi] = o
        for _ in range(NEWTON_STEPS):
            r = self.phi(q)[self.rows]
            if np.max(np.abs(r)) <= 1e-15:
                break
            q[w] -= np.linalg.solve(self.constraint_jacobian(q)[np.ix_(self.rows, w)], r)
        return q, float(np.max(np.abs(self.phi(q))))

    def output_jacobian(self, q) -> np.ndarray:
        """J = d o / d y (ny x ny): ``outputs``' rows of G, od = J yd."""
        names = [c.name for c in self.robot.coordinates]
        return self.projection(q)[[names.index(c) for c in self.robot.outputs]]

    def assemble(self, y, z) -> np.ndarray:
        q = np.zeros(self.n)
        q[self.y], q[self.z] = y, z
        return q

    # ------------------------------------------------------------------ projection

    def projection(self, q) -> np.ndarray:
        """G (nq x ny): qd = G yd."""
        K = self.constraint_jacobian(q)[self.rows]
        G = np.zeros((self.n, len(self.y)))
        G[self.y] = np.eye(len(self.y))
        G[self.z] = -np.linalg.solve(K[:, self.z], K[:, self.y])
        return G

    def gdot_yd(self, q, qd) -> np.ndarray:
        """Gdot yd = [0; -K_z^-1 Kdot qd] for qd = G yd."""
        K = self.constraint_jacobian(q)[self.rows]
        out = np.zeros(self.n)
        out[self.z] = -np.linalg.solve(K[:, self.z], self.kdot_qd(q, qd)[self.rows])
        return out

    # ------------------------------------------------------------------ reduced dynamics (q closed, qd = G yd)

    def mass_matrix(self, q) -> np.ndarray:
        """M_y = G^T M G."""
        G = self.projection(q)
        return G.T @ self.tree.crba(q) @ G

    def bias(self, q, yd) -> np.ndarray:
        """h_y = G^T rnea(q, qd, Gdot yd) = G^T (C qd + g + M Gdot yd), qd = G yd."""
        G = self.projection(q)
        qd = G @ yd
        return G.T @ self.tree.rnea(q, qd, self.gdot_yd(q, qd))

    def inverse_dynamics(self, q, yd, ydd) -> np.ndarray:
        """tau_y = G^T rnea(q, G yd, G ydd + Gdot yd)."""
        G = self.projection(q)
        qd = G @ yd
        return G.T @ self.tree.rnea(q, qd, G @ ydd + self.gdot_yd(q, qd))

    def regressor(self, q, yd, ydd) -> np.ndarray:
        """Y_y = G^T Y(q, G yd, G ydd + Gdot yd) (ny x n_pi) of the tree's regressor (Featherstone's linear
        form, :meth:`NumericRobot.regressor`): inverse_dynamics = Y_y @ the tree's dynamic parameters."""
        G = self.projection(q)
        qd = G @ yd
        return G.T @ self.tree.regressor(q, qd, G @ ydd + self.gdot_yd(q, qd))

    def forward_dynamics(self, q, yd, tau_y) -> np.ndarray:
        """ydd = M_y^-1 (tau_y - h_y)."""
        return np.linalg.solve(self.mass_matrix(q), tau_y - self.bias(q, yd))

    # ------------------------------------------------------------------ the tree's KKT system

    def actuation(self, tau_y) -> np.ndarray:
        """The tree torque S^T tau_y (tau_y on y, 0 on z)."""
        tau = np.zeros(self.n)
        tau[self.y] = tau_y
        return tau

    def kkt_forward_dynamics(self, q, qd, tau) -> tuple[np.ndarray, np.ndarray]:
        """(qdd, lambda) of [M K^T; K 0] [qdd; -lambda] = [tau - h; -Kdot qd] (kept rows of K)."""
        K = self.constraint_jacobian(q)[self.rows]
        M = self.tree.crba(q)
        h = self.tree.rnea(q, qd, np.zeros(self.n))
        r = len(self.rows)
        A = np.block([[M, K.T], [K, np.zeros((r, r))]])
        sol = np.linalg.solve(A, np.concatenate([tau - h, -self.kdot_qd(q, qd)[self.rows]]))
        return sol[:self.n], -sol[self.n:]

    def kkt_inverse_dynamics(self, q, qd, qdd) -> tuple[np.ndarray, np.ndarray]:
        """(tau_y, lambda) with M qdd + h = S^T tau_y + K^T lambda (qdd consistent with the loops)."""
        K = self.constraint_jacobian(q)[self.rows]
        S = np.zeros((self.n, len(self.y)))
        S[self.y, np.arange(len(self.y))] = 1.0
        sol = np.linalg.solve(np.hstack([S, K.T]), self.tree.rnea(q, qd, qdd))
        return sol[:len(self.y)], sol[len(self.y):]

    # ------------------------------------------------------------------ energy and simulation

    def energy(self, q, qd) -> float:
        return float(self.tree.kinetic_energy(q, qd) + self.tree.potential_energy(q))

    def rk4(self, y0, yd0, dt: float, steps: int, tau_y=None):
        """RK4 of x = (y, yd), xdot = (yd, FD_y) with q = gamma(y) at every stage (Newton from the last z).

        Returns (q (steps + 1, nq), qd (steps + 1, nq)), the closed tree configurations and rates.
        """
        ny = len(self.y)
        tau_y = np.zeros(ny) if tau_y is None else tau_y
        z = self.q_ref[self.z].copy()

        def f(x):
            nonlocal z
            q, _ = self.closure(x[:ny], z)
            z = q[self.z]
            return np.concatenate([x[ny:], self.forward_dynamics(q, x[ny:], tau_y)])

        x = np.concatenate([y0, yd0])
        qs, qds = [], []
        for k in range(steps + 1):
            q, _ = self.closure(x[:ny], z)
            qs.append(q)
            qds.append(self.projection(q) @ x[ny:])
            if k == steps:
                break
            k1 = f(x)
            k2 = f(x + dt / 2 * k1)
            k3 = f(x + dt / 2 * k2)
            k4 = f(x + dt * k3)
            x = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
        return np.array(qs), np.array(qds)
