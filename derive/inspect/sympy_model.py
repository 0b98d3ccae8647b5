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

from derive.description.model import Robot, load_robot
from derive.inspect.tosympy import to_sympy
from derive.codegen.checks import check_mass_matrix, unmoved_reason
from derive.errors import DeriveError
from derive.symbolic.model import SXModel


class SymbolicModel:
    """A robot's model as sympy objects, for inspection and papers.

    ``method`` picks the route M, C, g and the inverse dynamics come from:
    "lagrange" (Euler-Lagrange, the lecture's Example 5) or "newton-euler"
    (recursive Newton-Euler and CRBA, Example 6); tests prove them identical.
    """

    def __init__(self, robot: Robot, simplify: bool | None = None, method: str = "lagrange"):
        robot.require_fixed_base("the sympy model")
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
        """qdd(q, qd, tau), LDL^T solve (unsimplified for nv > 2); always the recursive route, the leanest.
        A DeriveError where coordinates move no mass (M(q) singular: no forward dynamics)."""
        unmoved = check_mass_matrix(self.sx, strict=False)
        if unmoved:
            where = f"{self.robot.file}: robot '{self.robot.name}'" if self.robot.file else f"robot '{self.robot.name}'"
            raise DeriveError(f"{where}: no forward dynamics: {unmoved_reason(unmoved)}")
        return self._sympy(self.sx.forward_dynamics())


def load(name: str, models: str | Path | None = None, simplify: bool | None = None,
         method: str = "lagrange") -> SymbolicModel:
    """Load robot ``name`` from models.yaml (default: the project's) and derive its model
    by ``method`` ("lagrange" or "newton-euler")."""
    return SymbolicModel(load_robot(name, models), simplify=simplify, method=method)
