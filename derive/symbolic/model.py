"""The derived model in CasADi SX: every quantity of the product card, by either route.

``SXModel(robot)`` holds the symbols, the kinematics and both dynamics routes
(Lagrangian and recursive Newton-Euler); code generation, the solvers and the sympy
view all start from it.
"""

from __future__ import annotations

from functools import cached_property

import casadi as ca

from derive.description.robot import Robot
from derive.symbolic.dynamics import Lagrangian, NewtonEuler
from derive.symbolic.kinematics import Kinematics, configuration_rate
from derive.symbolic.ode import forward_dynamics
from derive.symbolic.symbols import make_symbols
from derive.symbolic.whole_body import WholeBody


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
        """qdd(q, qd, tau) by LDL^T of M; never a symbolic inverse. ``extra_torque`` is added to tau
        (e.g. the joint torques sum J^T w of external wrenches)."""
        if method == "newton-euler":
            bias = self.newton_euler.bias
        else:
            r = self.lagrangian
            bias = r.coriolis_matrix @ self.sym.qd + r.gravity_vector
        tau = self.sym.tau if extra_torque is None else self.sym.tau + extra_torque
        return forward_dynamics(self.mass_matrix(method), bias, tau, self.newton_euler.dof_parents)

    def ode_rhs(self, method: str = "newton-euler") -> ca.SX:
        """f(x, u) = [dq/dt; qdd] with x = [q; qd], u = tau (dq/dt = qd for a fixed base)."""
        return ca.vertcat(self.configuration_rate, self.forward_dynamics(method))

    def ode_jac_x(self, method: str = "newton-euler") -> ca.SX:
        return ca.jacobian(self.ode_rhs(method), self.sym.x)

    def ode_jac_u(self, method: str = "newton-euler") -> ca.SX:
        return ca.jacobian(self.ode_rhs(method), self.sym.tau)
