"""A closed chain in reduced coordinates, in CasADi SX: closures, G(q), Gdot yd, M_y, h_y, ID_y, FD_y, lambda.

The tree's coordinates q = (y, z) (``robot.independent``, ``robot.dependent``, in q's order), the
loops' residual phi(q) (the equations of :class:`derive.description.robot.Loop`) and K = dphi/dq;
K_y, K_z are K's y and z columns on the kept rows ``robot.loop_rows`` (K_z square and invertible on
the chart). From K qd = 0 and K qdd + Kdot qd = 0 (Featherstone, RBDA 8.5, the projection method that
mimic joints use with a constant G):

    qd = G yd,                G = [I; -K_z^-1 K_y]                  (rows in q's order)
    qdd = G ydd + Gdot yd,    Gdot yd = [0; -K_z^-1 Kdot qd]
    M_y = G^T M G,            h_y = G^T rnea(q, qd, Gdot yd) = G^T (C qd + g + M Gdot yd)
    tau_y = G^T rnea(q, G yd, G ydd + Gdot yd),        ydd = M_y^-1 (tau_y - h_y)
    lambda = K_z^-T [rnea(q, qd, qdd)]_z   (M qdd + h = S^T tau_y + K^T lambda, actuation on y only)

Every function takes the closed tree configuration q (nq) and the y rates; :meth:`ClosedChainModel.closure`
gives q from y by a fixed count of Newton steps on the kept rows (with a status and the residual).
Parameters p come last, as in every generated function.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import casadi as ca

from derive.description.robot import Robot
from derive.symbolic.closed_form import closed_form_closure
from derive.symbolic.model import SXModel
from derive.symbolic.ode import ldlt_solve

NEWTON_STEPS = 8
"""Newton steps of the closure solve: quadratic convergence from the previous z takes a well-placed
start (the last step's z, at control rates) to rounding in 3 to 4; 8 leaves margin."""
CLOSED_TOL = 1e-12
"""status = 1 where max |phi| <= this after the Newton steps."""
ASSEMBLED_TOL = 1e-6
"""The generated closure's status: 1 where max |phi| <= this. Looser than CLOSED_TOL so that a float
build (rounding ~1e-7 of the lengths) reports an assembled mechanism as one; the residual itself is
returned (~1e-16 in double) for a caller that wants more."""


class ClosedChainModel:
    """The reduced model of a robot with loops, as SX expressions and casadi Functions."""

    def __init__(self, robot: Robot, model: SXModel | None = None):
        if not robot.loops:
            raise ValueError(f"robot '{robot.name}' has no loops")
        self.robot = robot
        self.model = model or SXModel(robot)
        self.sym = s = self.model.sym
        names = list(s.joint_names)
        self.y = [names.index(c) for c in robot.independent]
        self.z = [names.index(c) for c in robot.dependent]
        self.rows = list(robot.loop_rows)
        self.ny, self.nq = len(self.y), len(names)
        self.yd = ca.vertcat(*[ca.SX.sym(f"d{names[i]}") for i in self.y])
        self.ydd = ca.vertcat(*[ca.SX.sym(f"dd{names[i]}") for i in self.y])
        self.tau_y = ca.vertcat(*[ca.SX.sym(f"tau_{names[i]}") for i in self.y])

    # ---- constraints ----
    @cached_property
    def phi(self) -> ca.SX:
        """The stacked loop residuals phi(q)."""
        s, kin = self.sym, self.model.kinematics
        out = []
        for lp in self.robot.loops:
            A, B = kin.pose(lp.a), kin.pose(lp.b)
            d = A.p - B.p
            if lp.kind == "point":
                out.append(d)  # 3 rows: the origins coincide
            elif lp.kind == "distance":
                L = s.value(lp.length)
                out.append((ca.dot(d, d) - L * L) / (2 * L))  # 1 row: a rod of length L
            elif lp.kind == "weld":
                out += [d] + [ca.dot(A.R[:, i], B.R[:, j]) for i, j in ((1, 2), (2, 0), (0, 1))]  # 6 rows
            else:
                n = ca.DM(list(lp.axis))
                u, v = (ca.DM(list(x)) for x in lp.basis)
                if lp.kind == "hinge":  # 5 rows: the origins coincide, the axes align
                    out += [d, ca.dot(A.R @ u, B.R @ n), ca.dot(A.R @ v, B.R @ n)]
                else:  # planar: 2 rows (the origins coincide in the plane), 3 with the turn about n
                    out += [ca.dot(A.R @ u, d), ca.dot(A.R @ v, d)]
                    if lp.rotation:
                        out.append(ca.dot(A.R @ u, B.R @ v))
        return ca.vertcat(*out)

    @cached_property
    def constraint_jacobian(self) -> ca.SX:
        """K(q) = dphi/dq (all rows)."""
        return ca.jacobian(self.phi, self.sym.q)

    @cached_property
    def kdot_qd_tree(self) -> ca.SX:
        """Kdot qd = d(K qd)/dq qd (all rows) for the tree's qd symbols, independent of q."""
        qd = self.sym.qd
        return ca.jacobian(self.constraint_jacobian @ qd, self.sym.q) @ qd

    def kdot_qd(self, qd: ca.SX) -> ca.SX:
        """Kdot qd at the rates ``qd`` (an expression, e.g. G yd: substituted after differentiating)."""
        return ca.substitute(self.kdot_qd_tree, self.sym.qd, qd)

    @cached_property
    def k_y(self) -> ca.SX:
        return self.constraint_jacobian[self.rows, self.y]

    @cached_property
    def k_z(self) -> ca.SX:
        return self.constraint_jacobian[self.rows, self.z]

    # ---- closure solve ----
    def newton_step(self) -> ca.Function:
        """q -> q with z - K_z^-1 phi_rows (y untouched)."""
        s = self.sym
        q_new = ca.SX(s.q)
        q_new[self.z] = s.q[self.z] - ca.solve(self.k_z, self.phi[self.rows])
        return ca.Function("newton_step", [s.q, s.p], [q_new])

    def closure(self, steps: int = NEWTON_STEPS) -> ca.Function:
        """(y, z0, p) -> (q, status, residual): z = gamma(y) by ``steps`` Newton steps from z0; status 1 where
        max |phi| <= CLOSED_TOL, residual = max |phi| (all rows)."""
        s = self.sym
        y = ca.SX.sym("y", self.ny)
        z0 = ca.SX.sym("z0", len(self.z))
        q = ca.SX.zeros(self.nq, 1)
        q[self.y], q[self.z] = y, z0
        step = self.newton_step()
        for _ in range(steps):
            q = step(q, s.p)
        phi = ca.Function("phi", [s.q, s.p], [self.phi])(q, s.p)
        residual = ca.mmax(ca.fabs(phi))
        return ca.Function("closure", [y, z0, s.p], [q, ca.if_else(residual <= CLOSED_TOL, 1, 0), residual],
                           ["y", "z0", "p"], ["q", "status", "residual"])

    # ---- projection ----
    @cached_property
    def projection(self) -> ca.SX:
        """G(q) (nq x ny): qd = G yd."""
        G = ca.SX.zeros(self.nq, self.ny)
        G[self.y, :] = ca.SX.eye(self.ny)
        G[self.z, :] = -ca.solve(self.k_z, self.k_y)
        return G

    @cached_property
    def qd(self) -> ca.SX:
        """qd = G yd."""
        return self.projection @ self.yd

    @cached_property
    def gdot_yd(self) -> ca.SX:
        """Gdot yd = [0; -K_z^-1 Kdot qd] with qd = G yd."""
        out = ca.SX.zeros(self.nq, 1)
        out[self.z] = -ca.solve(self.k_z, self.kdot_qd(self.qd)[self.rows])
        return out

    def tree_torque(self, qdd: ca.SX) -> ca.SX:
        """The tree's rnea(q, G yd, qdd) (with the actuators' armature and friction, if any)."""
        ne = self.model.newton_euler
        tau = ne.rnea(self.qd, qdd)
        drive = ne.drive.torque(self.qd, qdd, False)
        return tau if drive is None else tau + drive

    # ---- reduced dynamics ----
    @cached_property
    def mass_matrix(self) -> ca.SX:
        """M_y = G^T M G (ny x ny)."""
        G = self.projection
        return G.T @ self.model.mass_matrix("newton-euler") @ G

    @cached_property
    def bias(self) -> ca.SX:
        """h_y = G^T rnea(q, qd, Gdot yd)."""
        return self.projection.T @ self.tree_torque(self.gdot_yd)

    @cached_property
    def inverse_dynamics(self) -> ca.SX:
        """tau_y = G^T rnea(q, G yd, G ydd + Gdot yd)."""
        return self.projection.T @ self.tree_torque(self.projection @ self.ydd + self.gdot_yd)

    @cached_property
    def forward_dynamics(self) -> ca.SX:
        """ydd = M_y^-1 (tau_y - h_y), by LDL^T of M_y."""
        return ldlt_solve(self.mass_matrix, self.tau_y - self.bias)

    def constraint_forces(self, ydd: ca.SX) -> ca.SX:
        """lambda = K_z^-T [rnea(q, qd, G ydd + Gdot yd)]_z (kept rows): M qdd + h = S^T tau_y + K^T lambda."""
        tau = self.tree_torque(self.projection @ ydd + self.gdot_yd)
        return ca.solve(self.k_z.T, tau[self.z])

    # ---- functions ----
    def functions(self) -> dict[str, ca.Function]:
        """casadi Functions of the closed chain; q is the closed tree configuration, p the parameters."""
        s = self.sym
        q, p, yd, ydd, tau = s.q, s.p, self.yd, self.ydd, self.tau_y
        qd_tree = s.qd
        fd = self.forward_dynamics
        return {
            "phi": ca.Function("phi", [q, p], [self.phi], ["q", "p"], ["phi"]),
            "constraint_jacobian": ca.Function("constraint_jacobian", [q, p], [self.constraint_jacobian], ["q", "p"],
                                               ["K"]),
            "kdot_qd": ca.Function("kdot_qd", [q, qd_tree, p], [self.kdot_qd_tree], ["q", "qd", "p"], ["kdot_qd"]),
            "closure": self.closure(),
            "projection": ca.Function("projection", [q, p], [self.projection], ["q", "p"], ["G"]),
            "gdot_yd": ca.Function("gdot_yd", [q, yd, p], [self.gdot_yd], ["q", "yd", "p"], ["gdot_yd"]),
            "mass_matrix": ca.Function("mass_matrix", [q, p], [self.mass_matrix], ["q", "p"], ["M_y"]),
            "bias": ca.Function("bias", [q, yd, p], [self.bias], ["q", "yd", "p"], ["h_y"]),
            "inverse_dynamics": ca.Function("inverse_dynamics", [q, yd, ydd, p], [self.inverse_dynamics],
                                            ["q", "yd", "ydd", "p"], ["tau_y"]),
            "forward_dynamics": ca.Function("forward_dynamics", [q, yd, tau, p], [fd], ["q", "yd", "tau_y", "p"],
                                            ["ydd"]),
            "constraint_forces": ca.Function("constraint_forces", [q, yd, tau, p], [self.constraint_forces(fd)],
                                             ["q", "yd", "tau_y", "p"], ["lambda"]),
            "constraint_forces_id": ca.Function("constraint_forces_id", [q, yd, ydd, p], [self.constraint_forces(ydd)],
                                                ["q", "yd", "ydd", "p"], ["lambda"]),
        }

    # ---- the model in y: q = gamma(y) put in ----
    def in_y(self, closed_form: bool = True) -> "ReducedChain":
        """The reduced model as expressions of y (not of q): q = gamma(y) by the closed form of
        :func:`~derive.symbolic.closed_form.closed_form_closure` where one exists (and ``closed_form``),
        else by :data:`NEWTON_STEPS` Newton steps from the reference configuration's z (rounded to 1e-3:
        the solved reference's last bits may differ between machines, the generated code must not)."""
        s = self.sym
        y = ca.SX.sym("y", self.ny)
        found = closed_form_closure(self.model, y) if closed_form else None
        if found is not None:
            gamma, method = found
            q_out, z0 = gamma, None
        else:
            z0 = ca.SX.sym("z0", len(self.z))
            start = ca.DM([round(float(self.robot.reference_q[i]), 3) for i in self.z])
            q_out = ca.SX.zeros(self.nq, 1)
            q_out[self.y], q_out[self.z] = y, z0
            step = self.newton_step()
            for _ in range(NEWTON_STEPS):
                q_out = step(q_out, s.p)
            gamma = ca.substitute(q_out, z0, start)
            method = f"Newton: {NEWTON_STEPS} steps on the kept rows"
        phi = ca.substitute(self.phi, s.q, q_out)
        residual = ca.mmax(ca.fabs(phi))
        # 1 where residual <= ASSEMBLED_TOL, else 0 (a NaN residual too: fmin(NaN, 1) = 1); no comparison op needed
        status = 0.5 * (1 + ca.sign(ASSEMBLED_TOL - ca.fmin(residual, 1)))

        def put(e: ca.SX) -> ca.SX:
            return ca.substitute(e, s.q, gamma)

        fd = put(self.forward_dynamics)
        return ReducedChain(y=y, z0=z0, q=q_out, status=status, residual=residual, gamma=gamma, method=method,
                            projection=put(self.projection), gdot_yd=put(self.gdot_yd),
                            mass_matrix=put(self.mass_matrix), bias=put(self.bias),
                            inverse_dynamics=put(self.inverse_dynamics), forward_dynamics=fd,
                            constraint_forces=put(self.constraint_forces(self.forward_dynamics)))


@dataclass(frozen=True)
class ReducedChain:
    """The reduced model of :meth:`ClosedChainModel.in_y`: expressions of y, the rates' symbols
    (``ClosedChainModel.yd``, ``ydd``, ``tau_y``) and p. ``q``, ``status``, ``residual``: the closure's
    outputs (of y, and of z0 for the Newton solve); ``gamma``: q = gamma(y) put into the others."""

    y: ca.SX
    z0: ca.SX | None  # the Newton solve's starting z (None for a closed form)
    q: ca.SX
    status: ca.SX
    residual: ca.SX
    gamma: ca.SX
    method: str
    projection: ca.SX
    gdot_yd: ca.SX
    mass_matrix: ca.SX
    bias: ca.SX
    inverse_dynamics: ca.SX
    forward_dynamics: ca.SX
    constraint_forces: ca.SX
