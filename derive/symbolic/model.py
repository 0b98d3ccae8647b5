"""The derived model in CasADi SX: every quantity of the product card, by either route.

``SXModel(robot)`` holds the symbols, the kinematics and both dynamics routes
(Lagrangian and recursive Newton-Euler); code generation, the solvers and the sympy
view all start from it.
"""

from __future__ import annotations

from functools import cached_property

import casadi as ca

from derive.description.robot import Robot
from derive.symbolic import aba
from derive.symbolic.dynamics import Lagrangian, NewtonEuler, graph_cost
from derive.symbolic.kinematics import Kinematics, configuration_rate
from derive.symbolic.ode import forward_dynamics
from derive.symbolic.symbols import make_symbols
from derive.symbolic.whole_body import WholeBody


ABA_FROM_NV = 8
"""Fewest velocities for which the articulated-body algorithm is a candidate for forward dynamics
(below it CRBA and LDL^T always had fewer operations)."""

ABA_COMPARE_MAX_NV = 12
"""Up to this many velocities both forward dynamics are built and the cheaper kept; above it the ABA."""


class SXModel:
    """The derived model in CasADi SX: every quantity of the product card."""

    def __init__(self, robot: Robot):
        self.robot = robot
        self.sym = make_symbols(robot)
        self.kinematics = Kinematics(robot, self.sym)
        self.newton_euler = NewtonEuler(robot, self.sym)

    @cached_property
    def lagrangian(self) -> Lagrangian:
        """The Lagrangian route (fixed-base robots only)."""
        return Lagrangian(self.robot, self.sym, self.kinematics)

    @cached_property
    def whole_body(self) -> WholeBody:
        """Centre of mass, centroidal map, frame accelerations, external wrenches."""
        return WholeBody(self.kinematics, self.newton_euler, self.sym)

    @cached_property
    def configuration_rate(self) -> ca.SX:
        """dq/dt (nq) as a function of q and v = qd: qd itself for a fixed base."""
        return configuration_rate(self.robot, self.sym)

    def route(self, method: str):
        if method == "lagrange":
            return self.lagrangian
        if method == "newton-euler":
            return self.newton_euler
        raise ValueError(f"method must be 'lagrange' or 'newton-euler', got {method!r}")

    def fk(self, frame: str) -> ca.SX:
        return self.kinematics.fk(frame)

    def jacobian(self, frame: str) -> ca.SX:
        return self.kinematics.jacobian(frame)

    def analytic_jacobian(self, frame: str) -> ca.SX:
        return self.kinematics.analytic_jacobian(frame)

    def mass_matrix(self, method: str = "lagrange") -> ca.SX:
        return self.route(method).mass_matrix

    def coriolis_matrix(self, method: str = "lagrange") -> ca.SX:
        return self.route(method).coriolis_matrix

    def gravity_vector(self, method: str = "lagrange") -> ca.SX:
        return self.route(method).gravity_vector

    def inverse_dynamics(self, method: str = "lagrange") -> ca.SX:
        return self.route(method).inverse_dynamics()

    def forward_dynamics(self, method: str = "newton-euler", extra_torque: ca.SX | None = None) -> ca.SX:
        """qdd(q, qd, tau) by LDL^T of M, never a symbolic inverse, or (Newton-Euler route, where it
        gives fewer operations: :attr:`articulated`) by the articulated-body algorithm. ``extra_torque``
        is added to tau (e.g. the joint torques sum J^T w of external wrenches)."""
        tau = self.sym.tau if extra_torque is None else self.sym.tau + extra_torque
        if method == "newton-euler" and self.articulated:
            return aba.forward_dynamics(self.newton_euler, tau)
        return self._forward_dynamics_by_ldl(method, tau)

    def _forward_dynamics_by_ldl(self, method: str, tau: ca.SX) -> ca.SX:
        """M^-1 (tau - bias) of the route ``method`` by LDL^T of M (LTDL along a branched tree)."""
        if method == "newton-euler":
            bias = self.newton_euler.bias
        else:
            r = self.lagrangian
            bias = r.coriolis_matrix @ self.sym.qd + r.gravity_vector
        return forward_dynamics(self.mass_matrix(method), bias, tau, self.newton_euler.dof_parents)

    @cached_property
    def articulated(self) -> bool:
        """Whether the Newton-Euler route's forward dynamics is the articulated-body algorithm
        (:mod:`derive.symbolic.aba`, O(n)) rather than CRBA and LDL^T (O(n^3)): above
        :data:`ABA_COMPARE_MAX_NV` velocities wherever it applies (a 40-joint chain: 25 117 operations
        against 92 230), from :data:`ABA_FROM_NV` the one with fewer operations after CSE (the Panda's,
        7: 1 815 against 1 527; a 12-joint chain's 6 801 against 8 648)."""
        ne = self.newton_euler
        if not aba.supported(ne) or self.sym.nv < ABA_FROM_NV:
            return False
        if self.sym.nv > ABA_COMPARE_MAX_NV:
            return True
        s = self.sym
        by_ldl = self._forward_dynamics_by_ldl("newton-euler", s.tau)
        return graph_cost(aba.forward_dynamics(ne, s.tau), s.q, s.qd, s.tau) < graph_cost(by_ldl, s.q, s.qd, s.tau)

    @property
    def forward_dynamics_algorithm(self) -> str:
        """How the Newton-Euler route's forward dynamics are computed (manifest.json's ``algorithm``)."""
        if self.articulated:
            return "articulated-body algorithm"
        return "CRBA, then LDL^T" if self.newton_euler.dof_parents is None else "CRBA, then LTDL along the tree"

    def ode_rhs(self, method: str = "newton-euler") -> ca.SX:
        """f(x, u) = [dq/dt; qdd] with x = [q; qd], u = tau (dq/dt = qd for a fixed base)."""
        return ca.vertcat(self.configuration_rate, self.forward_dynamics(method))

    def ode_jac_x(self, method: str = "newton-euler") -> ca.SX:
        return ca.jacobian(self.ode_rhs(method), self.sym.x)

    def ode_jac_u(self, method: str = "newton-euler") -> ca.SX:
        return ca.jacobian(self.ode_rhs(method), self.sym.tau)
