"""The Python API for inspection: ``m = derive.load("pendulum"); m.mass_matrix``.

Quantities are derived in CasADi SX (fast, with algorithmic differentiation)
and returned as sympy Matrices in the robot's own symbols (joint names for q,
``d<joint>`` for qd, parameter names for p). Small models (nv <= 2 by default)
are simplified with ``sympy.simplify``; ask for ``simplify=False`` to get the
raw expressions of larger ones, which can be long. The SX forms are under
``m.sx``.
"""

from __future__ import annotations

from functools import cached_property
from pathlib import Path

import casadi as ca
import sympy as sp

from .dynamics import Lagrangian, NewtonEuler
from .kinematics import Kinematics
from .model import Robot, load_robot
from .ode import forward_dynamics
from .symbols import make_symbols
from .tosympy import to_sympy


class SXModel:
    """The derived model in CasADi SX: every quantity of the product card."""

    def __init__(self, robot: Robot):
        self.robot = robot
        self.sym = make_symbols(robot)
        self.kinematics = Kinematics(robot, self.sym)
        self.lagrangian = Lagrangian(robot, self.sym, self.kinematics)
        self.newton_euler = NewtonEuler(robot, self.sym)

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

    def forward_dynamics(self, method: str = "newton-euler") -> ca.SX:
        """qdd(q, qd, tau) by LDL^T of M; never a symbolic inverse."""
        if method == "newton-euler":
            bias = self.newton_euler.bias
        else:
            r = self.lagrangian
            bias = r.coriolis_matrix @ self.sym.qd + r.gravity_vector
        return forward_dynamics(self.mass_matrix(method), bias, self.sym.tau)

    def ode_rhs(self, method: str = "newton-euler") -> ca.SX:
        """f(x, u) = [qd; qdd] with x = [q; qd], u = tau."""
        return ca.vertcat(self.sym.qd, self.forward_dynamics(method))

    def ode_jac_x(self, method: str = "newton-euler") -> ca.SX:
        return ca.jacobian(self.ode_rhs(method), self.sym.x)

    def ode_jac_u(self, method: str = "newton-euler") -> ca.SX:
        return ca.jacobian(self.ode_rhs(method), self.sym.tau)


class SymbolicModel:
    """A robot's model as sympy objects, for inspection and papers.

    ``method`` picks the route M, C, g and the inverse dynamics come from:
    "lagrange" (Euler-Lagrange, the lecture's Example 5) or "newton-euler"
    (recursive Newton-Euler and CRBA, Example 6); tests prove them identical.
    """

    def __init__(self, robot: Robot, simplify: bool | None = None, method: str = "lagrange"):
        self.robot = robot
        self.sx = SXModel(robot)
        self.sx.route(method)  # validates the name
        self.method = method
        self.simplify = robot.nv <= 2 if simplify is None else simplify
        s = self.sx.sym
        self.q = sp.Matrix([sp.Symbol(n) for n in s.joint_names])
        self.qd = sp.Matrix([sp.Symbol(f"d{n}") for n in s.joint_names])
        self.qdd = sp.Matrix([sp.Symbol(f"dd{n}") for n in s.joint_names])
        self.tau = sp.Matrix([sp.Symbol(f"tau_{n}") for n in s.joint_names])
        self.params = sp.Matrix([sp.Symbol(n) for n in s.parameter_names])

    def _sympy(self, e: ca.SX) -> sp.Matrix:
        s = self.sx.sym
        pairs = [(s.q, list(self.q)), (s.qd, list(self.qd)), (s.qdd, list(self.qdd)), (s.tau, list(self.tau)),
                 (s.p, list(self.params))]
        (m,) = to_sympy([e], [(x, syms) for x, syms in pairs if x.numel()])
        if self.simplify:
            m = m.applyfunc(lambda v: sp.simplify(sp.trigsimp(v)))
        return m

    @property
    def nv(self) -> int:
        return self.robot.nv

    @property
    def frames(self) -> tuple[str, ...]:
        return self.sx.kinematics.frames

    def fk(self, frame: str = "tcp") -> sp.Matrix:
        """world_T_frame (4x4)."""
        return self._sympy(self.sx.fk(frame))

    def jacobian(self, frame: str = "tcp") -> sp.Matrix:
        """Geometric Jacobian (6 x nv), [linear; angular], LOCAL_WORLD_ALIGNED."""
        return self._sympy(self.sx.jacobian(frame))

    def analytic_jacobian(self, frame: str = "tcp") -> sp.Matrix:
        """d(position of frame)/dq (3 x nv)."""
        return self._sympy(self.sx.analytic_jacobian(frame))

    @cached_property
    def kinetic_energy(self) -> sp.Expr:
        return self._sympy(self.sx.lagrangian.kinetic_energy)[0, 0]

    @cached_property
    def potential_energy(self) -> sp.Expr:
        return self._sympy(self.sx.lagrangian.potential_energy)[0, 0]

    @cached_property
    def mass_matrix(self) -> sp.Matrix:
        """M(q) = d2T/dqd2."""
        return self._sympy(self.sx.mass_matrix(self.method))

    @cached_property
    def coriolis_matrix(self) -> sp.Matrix:
        """C(q, qd) from Christoffel symbols."""
        return self._sympy(self.sx.coriolis_matrix(self.method))

    @cached_property
    def gravity_vector(self) -> sp.Matrix:
        """g(q) = dU/dq."""
        return self._sympy(self.sx.gravity_vector(self.method))

    @cached_property
    def inverse_dynamics(self) -> sp.Matrix:
        """tau = M qdd + C qd + g."""
        return self._sympy(self.sx.inverse_dynamics(self.method))

    @cached_property
    def equations_of_motion(self) -> sp.Matrix:
        """M qdd + C qd + g - tau (= 0)."""
        return self.inverse_dynamics - self.tau

    def forward_dynamics(self) -> sp.Matrix:
        """qdd(q, qd, tau), LDL^T solve (unsimplified for nv > 2); always the recursive route, the leanest."""
        return self._sympy(self.sx.forward_dynamics())


def load(name: str, models: str | Path | None = None, simplify: bool | None = None,
         method: str = "lagrange") -> SymbolicModel:
    """Load robot ``name`` from models.yaml (default: the project's) and derive its model
    by ``method`` ("lagrange" or "newton-euler")."""
    return SymbolicModel(load_robot(name, models), simplify=simplify, method=method)
