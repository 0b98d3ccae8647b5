"""The inertial-parameter regressor: inverse dynamics as tau = Y(q, qd, qdd) pi, linear in pi.

pi holds, per moving body in the order of Pinocchio's joints (a floating base's root body first,
then the child link of each moving joint, the links fixed to it merged in), its 10 standard
parameters in Pinocchio's order (``pinocchio.Inertia.toDynamicParameters()``)

    [m, m c_x, m c_y, m c_z, I_xx, I_xy, I_yy, I_xz, I_yz, I_zz]

(first moment m c and inertia about the BODY ORIGIN, body axes), followed per joint coordinate
(a floating base's six have none) by its actuator parameters [I_a, f_v, f_c]: the reflected rotor
inertia armature + gear_ratio^2 motor_inertia, the viscous and the Coulomb friction coefficients
(columns qdd_k, qd_k and sign(qd_k)). A multi-DOF joint is one body: the massless bodies between
its elementary motions have no parameters. A mimic joint's body is a body like any other; its
columns enter its leader's row times the multiplier (tau = G^T tau_bodies). A mimic joint's own
actuator (multiplier a) has no parameters of its own: it adds a^2 I_a, a^2 f_v and |a| f_c to its
leader's (a f_c sign(a qd) = |a| f_c sign(qd)), the values that inverse dynamics needs.

Y is derived from a linear-in-parameters Newton-Euler recursion, not by differentiating inverse
dynamics: body i's wrench at its origin is linear in its parameters,

    f_i = m a_i + dw_i x h + w_i x (w_i x h),  t_i = I_o dw_i + w_i x (I_o w_i) + h x a_i  (h = m c),

i.e. [f_i; t_i] = A_i(w_i, dw_i, a_i) pi_i with a 6 x 10 A_i, and a joint k supporting body i feels
s_k^T [f_i; t_i] moved to joint k, which is (X_ik s_k) . [f_i; t_i]: the joint's motion axis carried
DOWN into body i's frame. So each body gets its ancestors' axes (one motion transform per pair) and
Y[k, body i] = (X_ik s_k)^T A_i, an inner product per column.
"""

from __future__ import annotations

from functools import cached_property

import casadi as ca
import numpy as np

from derive.description.robot import Robot
from derive.symbolic.dynamics import NewtonEuler
from derive.symbolic.symbols import make_symbols

INERTIAL = ("m", "mx", "my", "mz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz")
"""The 10 standard parameters of a body, Pinocchio's order: mass, first moment m c, inertia about the origin."""
ACTUATOR = ("Ia", "fv", "fc")
"""The 3 parameters of a joint coordinate's actuator: armature (reflected inertia), viscous and Coulomb friction."""
_E = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
_SYM = ((0, 0), (0, 1), (1, 1), (0, 2), (1, 2), (2, 2))  # I_xx, I_xy, I_yy, I_xz, I_yz, I_zz


def body_links(robot: Robot) -> tuple[str, ...]:
    """The links naming the parameterised bodies, in pi's order: the root link for a floating base,
    then the child link of every moving joint in tree order (Pinocchio's joints)."""
    return ((robot.root,) if robot.floating else ()) + tuple(j.child for j in robot.moving_joints)


def parameter_names(robot: Robot) -> tuple[str, ...]:
    """The names of pi's entries: ``m_<link>``, ``mx_<link>``, ..., ``Izz_<link>`` per body, then
    ``Ia_<coordinate>``, ``fv_<coordinate>``, ``fc_<coordinate>`` per joint coordinate."""
    body = tuple(f"{k}_{link}" for link in body_links(robot) for k in INERTIAL)
    return body + tuple(f"{k}_{c.name}" for c in robot.joint_coordinates for k in ACTUATOR)


def _body_parameters(m, h, I) -> list:
    return [m, h[0], h[1], h[2]] + [I[r, c] for r, c in _SYM]


class Regressor:
    """Y(q, qd, qdd) of one robot, in CasADi SX, from the body kinematics of a :class:`NewtonEuler`."""

    def __init__(self, ne: NewtonEuler):
        self.ne, self.robot, self.sym = ne, ne.robot, ne.sym
        children = {j.child for j in self.robot.moving_joints}
        # body index (of ne.bodies) of each parameterised body, -1 a floating root: the last elementary
        # motion of each joint carries its child link (the ones before it are massless)
        self.bodies = ([-1] if ne.floating else []) + [i for i, b in enumerate(ne.bodies) if b.name in children]
        named = [self.robot.root if i < 0 else ne.bodies[i].name for i in self.bodies]
        assert named == list(body_links(self.robot)), (named, body_links(self.robot))
        self.names = parameter_names(self.robot)

    @property
    def size(self) -> int:
        """n_pi: 10 per body plus 3 per joint coordinate."""
        return len(self.names)

    @cached_property
    def parameters(self) -> ca.SX:
        """pi (n_pi) as SX: the model's values, constants or expressions of the parameters p."""
        out = []
        for i in self.bodies:
            m, h, I = self.ne.root_mass if i < 0 else (self.ne.bodies[i].m, self.ne.bodies[i].h, self.ne.bodies[i].I_o)
            out += _body_parameters(m, h, I)
        value = self.sym.value
        acting = {c.name: [c.actuator] for c in self.robot.joint_coordinates}
        scale = {c.name: [1.0] for c in self.robot.joint_coordinates}
        for joint, a in self.robot.mimic_actuators:  # a mimic joint's own actuator, through G
            acting[joint.mimic.joint].append(a)
            scale[joint.mimic.joint].append(float(joint.mimic.multiplier))
        for c in self.robot.joint_coordinates:
            terms = [[value(a.armature) + value(a.gear_ratio) ** 2 * value(a.motor_inertia), value(a.viscous),
                      value(a.coulomb)] for a in acting[c.name]]
            own = terms[0]
            for s, (ia, fv, fc) in zip(scale[c.name][1:], terms[1:]):
                own = [own[0] + s * s * ia, own[1] + s * s * fv, own[2] + abs(s) * fc]
            out += own
        return ca.vertcat(*[ca.SX(v) for v in out])

    def parameter_vector(self, params: dict | None = None) -> list[float]:
        """The robot's parameters p (defaults, updated by ``params``: name -> value) as numbers, in p's order."""
        unknown = set(params or {}) - set(self.robot.parameter_defaults)
        if unknown:
            raise ValueError(f"robot '{self.robot.name}' has no parameter(s) {', '.join(sorted(unknown))}")
        env = dict(self.robot.parameter_defaults) | {k: float(v) for k, v in (params or {}).items()}
        return [env[n] for n in self.sym.parameter_names]

    def values(self, params: dict | None = None) -> np.ndarray:
        """pi (n_pi) as numbers at the robot's parameters (defaults, or ``params``: name -> value)."""
        f = ca.Function("pi", [self.sym.p], [self.parameters])
        return np.array(f(self.parameter_vector(params)), dtype=float).reshape(-1)

    def _offset(self, i: int, qj: ca.SX) -> ca.SX:
        """Body i's origin in its parent body (what the joint's motion leaves it at)."""
        b = self.ne.bodies[i]
        if b.kind == "revolute":
            return b.p
        angle = b.motion.value(qj[self.ne.index[i]])
        slide = angle if b.kind == "prismatic" else b.pitch * angle
        return b.p + (b.E @ ca.SX(ca.DM(list(b.axis)))) * slide

    def _axis(self, i: int) -> tuple[ca.SX, ca.SX]:
        """Body i's motion per unit rate of its own motion: (angular, linear), body axes."""
        b = self.ne.bodies[i]
        s = ca.SX(ca.DM(list(b.axis)))
        zero = ca.SX.zeros(3, 1)
        if b.kind == "helical":
            return s, b.pitch * s
        return (s, zero) if b.kind == "revolute" else (zero, s)

    def _down(self, i: int, p: ca.SX, axis: tuple[ca.SX, ca.SX]) -> tuple[ca.SX, ca.SX]:
        """A motion (angular, linear at the parent's origin, parent axes) seen in body i: at its origin, its axes."""
        s_w, s_v = axis
        return self.ne.to_child(i, s_w), self.ne.to_child(i, s_v + ca.cross(s_w, p))

    @staticmethod
    def _wrenches(w: ca.SX, dw: ca.SX, a: ca.SX) -> list[tuple[ca.SX, ca.SX]]:
        """A_i as 10 columns (f, t): the body's wrench at its origin per unit of each parameter."""
        zero = ca.SX.zeros(3, 1)
        cols = [(a, zero)]  # m
        for e in _E:  # m c along x, y, z
            e = ca.SX(ca.DM(e))
            cols.append((ca.cross(dw, e) + ca.cross(w, ca.cross(w, e)), ca.cross(e, a)))
        for r, c in _SYM:  # a unit entry of the symmetric inertia about the origin
            E = ca.SX(3, 3)
            E[r, c] = E[c, r] = 1.0
            cols.append((zero, E @ dw + ca.cross(w, E @ w)))
        return cols

    @cached_property
    def matrix(self) -> ca.SX:
        """Y (nv x n_pi): tau = Y pi is :meth:`NewtonEuler.inverse_dynamics` (Coulomb as sign(qd))."""
        ne, s = self.ne, self.sym
        nb, nv = ne.nb, s.nv
        qj = s.q[7:] if ne.floating else s.q
        w0, dw0, a0 = ne.root_motion(s.qd, s.qdd)
        qd, qdd = ne.body_rates(s.qd[nb:]), ne.body_rates(s.qdd[nb:])
        zero = ca.SX.zeros(3, 1)
        # the free flyer's six motions: tau[0:3] the force, tau[3:6] the torque on the root, root axes
        base = [(zero, ca.SX(ca.DM(e))) for e in _E] + [(ca.SX(ca.DM(e)), zero) for e in _E]
        Y = ca.SX(nv, self.size)
        column = {b: 10 * k for k, b in enumerate(self.bodies)}

        def fill(body: int, axes: list, w, dw, a) -> None:
            """Y's rows of the given axes [(row, scale, (s_w, s_v))] for body's columns."""
            if body not in column:
                return
            for k, (f, t) in enumerate(self._wrenches(w, dw, a)):
                for row, scale, (s_w, s_v) in axes:
                    Y[row, column[body] + k] += scale * (ca.dot(s_w, t) + ca.dot(s_v, f))

        if ne.floating:
            fill(-1, [(r, 1, ax) for r, ax in enumerate(base)], w0, dw0, a0)
        state = {-1: (w0, dw0, a0, [(r, 1, ax) for r, ax in enumerate(base)] if ne.floating else [])}
        for i, b in enumerate(ne.bodies):
            w_p, dw_p, a_p, axes_p = state[b.parent]
            p = self._offset(i, qj)
            s_w, s_v = self._axis(i)
            w_in = ne.to_child(i, w_p)
            w = w_in + s_w * qd[i]
            dw = ne.to_child(i, dw_p) + s_w * qdd[i] + ca.cross(w_in, s_w * qd[i])
            a_lin = a_p + ca.cross(dw_p, p) + ca.cross(w_p, ca.cross(w_p, p))
            a = ne.to_child(i, a_lin) + s_v * qdd[i] + 2 * ca.cross(w, s_v * qd[i])
            axes = [(row, scale, self._down(i, p, ax)) for row, scale, ax in axes_p]
            axes.append((nb + ne.index[i], ne.scale[i], (s_w, s_v)))
            state[i] = (w, dw, a, axes)
            fill(i, axes, w, dw, a)
        first = 10 * len(self.bodies)
        for k in range(len(self.robot.joint_coordinates)):
            row, col = nb + k, first + 3 * k
            Y[row, col], Y[row, col + 1], Y[row, col + 2] = s.qdd[row], s.qd[row], ca.sign(s.qd[row])
        return Y


def parameter_values(robot: Robot, params: dict | None = None) -> np.ndarray:
    """pi (n_pi) at the parameters' defaults (or ``params``: name -> value), in :func:`parameter_names`' order."""
    return Regressor(NewtonEuler(robot, make_symbols(robot))).values(params)
