"""Actuators and friction: the reflected rotor inertia on M's diagonal and the joint friction torque.

Per entry of v (a floating base's six have none): armature I_a = armature + gear_ratio^2
motor_inertia, viscous f_v and Coulomb f_c friction (:class:`derive.description.robot.Actuator`):

    M(q) -> M(q) + diag(I_a),   tau_f(qd) = f_v qd + f_c sign(qd).

Inverse dynamics uses sign(qd) (the torque a measured motion needs); forward dynamics, the ODE,
its Jacobians, simulation and trajectory optimisation use the smooth f_c tanh(qd / eps) (eps =
``Robot.smoothing``), so f(x, u) stays differentiable. A robot without actuators gets exactly the
expressions of ideal joints (nothing is added), so its generated code does not change.
"""

from __future__ import annotations

import casadi as ca

from derive.description.robot import Robot
from derive.symbolic.symbols import Symbols


class Drive:
    """The actuator terms of one robot, as SX (floats where constant)."""

    def __init__(self, robot: Robot, sym: Symbols):
        self.robot, self.sym = robot, sym
        nb = sym.nv - len(robot.joint_coordinates)
        zero = [0.0] * nb
        acts = [c.actuator for c in robot.joint_coordinates]
        value = sym.value
        self.armature = zero + [value(a.armature) + value(a.gear_ratio) ** 2 * value(a.motor_inertia)
                                if (a.armature, a.motor_inertia) != (0.0, 0.0) else 0.0 for a in acts]
        self.viscous = zero + [value(a.viscous) if a.viscous != 0.0 else 0.0 for a in acts]
        self.coulomb = zero + [value(a.coulomb) if a.coulomb != 0.0 else 0.0 for a in acts]

    @staticmethod
    def _any(values) -> bool:
        return any(not (isinstance(v, float) and v == 0.0) for v in values)

    @property
    def active(self) -> bool:
        return self._any(self.armature + self.viscous + self.coulomb)

    def mass(self, M: ca.SX) -> ca.SX:
        """M + diag(I_a) (M itself without armature)."""
        if not self._any(self.armature):
            return M
        M = ca.SX(M)
        for k, a in enumerate(self.armature):
            if not (isinstance(a, float) and a == 0.0):
                M[k, k] = M[k, k] + a
        return M

    def torque(self, qd: ca.SX, qdd: ca.SX, smooth: bool) -> ca.SX | None:
        """I_a qdd + f_v qd + f_c sign(qd) (tanh(qd / eps) if ``smooth``); None without actuators."""
        if not self.active:
            return None
        eps = self.robot.smoothing
        out = ca.SX.zeros(self.sym.nv, 1)
        for k in range(self.sym.nv):
            a, fv, fc = self.armature[k], self.viscous[k], self.coulomb[k]
            term = ca.SX(0)
            if not (isinstance(a, float) and a == 0.0):
                term += a * qdd[k]
            if not (isinstance(fv, float) and fv == 0.0):
                term += fv * qd[k]
            if not (isinstance(fc, float) and fc == 0.0):
                term += fc * (ca.tanh(qd[k] / eps) if smooth else ca.sign(qd[k]))
            out[k] = term
        return out
