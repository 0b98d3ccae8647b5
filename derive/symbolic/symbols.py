"""Robot -> the symbols of its model, in one fixed order.

q (nq, 1) and qd, qdd, tau (nv, 1) are CasADi SX column vectors named after the
coordinates of the joints (a floating base adds Robot.BASE_POSITION to q and
BASE_VELOCITY to the others) (``phi``, ``dphi``, ``ddphi``, ``tau_phi``; a
multi-DOF joint ``ball`` gives ``ball_z``, ``ball_y``, ``ball_x``, see
:data:`derive.description.model.COORDINATE_SUFFIXES`); p holds the robot's parameters in
file order. Every derivation takes its symbols from here, so the order of
inputs in generated code is the order of joints and parameters in models.yaml.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca

from derive.description import expr
from derive.description.robot import Robot, Value


@dataclass(frozen=True)
class Symbols:
    q: ca.SX
    qd: ca.SX
    qdd: ca.SX
    tau: ca.SX
    p: ca.SX
    joint_names: tuple[str, ...]  # one per entry of q: Robot.coordinates' names
    parameter_names: tuple[str, ...]

    velocity_names: tuple[str, ...] = ()  # one per entry of qd, qdd, tau: Robot.velocity_names

    @property
    def nv(self) -> int:
        return self.qd.numel()

    @property
    def nq(self) -> int:
        return self.q.numel()

    @property
    def x(self) -> ca.SX:
        """The state of the first-order ODE, x = [q; qd]."""
        return ca.vertcat(self.q, self.qd)

    def value(self, v: Value) -> ca.SX | float:
        """A model value (number or parameter expression) as a float or an SX expression."""
        if not isinstance(v, str):
            return float(v)
        env = {name: self.p[i] for i, name in enumerate(self.parameter_names)}
        return expr.evaluate(v, env, {"sin": ca.sin, "cos": ca.cos, "tan": ca.tan, "sqrt": ca.sqrt,
                                      "atan2": ca.atan2}, pi=math.pi)


def make_symbols(robot: Robot) -> Symbols:
    names = tuple(c.name for c in robot.coordinates)
    velocities = robot.velocity_names

    def vec(fmt: str, entries: tuple[str, ...]) -> ca.SX:
        return ca.vertcat(*[ca.SX.sym(fmt.format(n)) for n in entries]) if entries else ca.SX(0, 1)

    params = tuple(p.name for p in robot.parameters)
    p = ca.vertcat(*[ca.SX.sym(n) for n in params]) if params else ca.SX(0, 1)
    return Symbols(q=vec("{}", names), qd=vec("d{}", velocities), qdd=vec("dd{}", velocities),
                   tau=vec("tau_{}", velocities), p=p, joint_names=names, parameter_names=params,
                   velocity_names=velocities)
