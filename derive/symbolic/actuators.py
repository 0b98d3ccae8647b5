"""Actuators and friction: the reflected rotor inertia on M's diagonal and the joint friction torque.

Per entry of v (a floating base's six have none): armature I_a = armature + gear_ratio^2
motor_inertia, viscous f_v and Coulomb f_c friction (:class:`derive.description.robot.Actuator`):

    M(q) -> M(q) + diag(I_a),   tau_f(qd) = f_v qd + f_c sign(qd).

Inverse dynamics uses sign(qd) (the torque a measured motion needs); forward dynamics, the ODE,
its Jacobians, simulation and trajectory optimisation use the smooth f_c tanh(qd / eps) (eps =
``Robot.smoothing``), so f(x, u) stays differentiable. A robot without actuators gets exactly the
expressions of ideal joints (nothing is added), so its generated code does not change.

A mimic joint (q_m = a q_J + b, no entry of its own) may have an actuator too: its terms act on its
own motion qd_m = a qd_J and reach the coordinates through the constant mimic map G (qd_tree = G qd),
as everything else of it does: diag(I_a) and diag(f_v) of the tree's joints become G^T diag G, i.e.
a^2 I_a and a^2 f_v added to J's diagonal entries, and its Coulomb force G^T f_c sign(G qd) the term
a f_c sign(a qd_J) (smooth: a f_c tanh(a qd_J / eps), eps on the mimic joint's own rate) of J.
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
        self.armature = zero + [self.reflected(a) for a in acts]
        self.viscous = zero + [value(a.viscous) if a.viscous != 0.0 else 0.0 for a in acts]
        self.coulomb = zero + [value(a.coulomb) if a.coulomb != 0.0 else 0.0 for a in acts]
        # the mimic joints' own actuators, through G (module docstring)
        column = {c.name: nb + i for i, c in enumerate(robot.joint_coordinates)}
        self.mimic_coulomb: list[tuple[int, float, ca.SX | float]] = []  # (entry k, a, f_c): a f_c sign(a qd_k)
        for joint, a in robot.mimic_actuators:
            k, scale = column[joint.mimic.joint], float(joint.mimic.multiplier)
            self.armature[k] = self._plus(self.armature[k], scale * scale, self.reflected(a))
            self.viscous[k] = self._plus(self.viscous[k], scale * scale, value(a.viscous) if a.viscous != 0.0 else 0.0)
            if a.coulomb != 0.0:
                self.mimic_coulomb.append((k, scale, value(a.coulomb)))

    def reflected(self, a) -> ca.SX | float:
        """I_a = armature + gear_ratio^2 motor_inertia of one Actuator (a float 0.0 if both are 0)."""
        value = self.sym.value
        if (a.armature, a.motor_inertia) == (0.0, 0.0):
            return 0.0
        return value(a.armature) + value(a.gear_ratio) ** 2 * value(a.motor_inertia)

    @staticmethod
    def _plus(x, scale: float, y):
        """x + scale * y, keeping an exact float 0.0 where nothing is added."""
        if isinstance(y, float) and y == 0.0 or scale == 0.0:
            return x
        if isinstance(x, float) and x == 0.0:
            return scale * y
        return x + scale * y

    @staticmethod
    def _any(values) -> bool:
        return any(not (isinstance(v, float) and v == 0.0) for v in values)

    @property
    def active(self) -> bool:
        return self._any(self.armature + self.viscous + self.coulomb + [c for _, _, c in self.mimic_coulomb])

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
            for m, scale, fc_m in self.mimic_coulomb:  # G^T f_c sign(G qd): the mimic joint's own rate a qd_k
                if m == k and not (isinstance(fc_m, float) and fc_m == 0.0):
                    rate = scale * qd[k]
                    term += scale * fc_m * (ca.tanh(rate / eps) if smooth else ca.sign(rate))
            out[k] = term
        return out
