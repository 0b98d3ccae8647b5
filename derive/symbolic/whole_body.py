"""Whole-body quantities: centre of mass, centroidal momentum, frame accelerations, external wrenches.

Conventions (Pinocchio's, so results compare one to one):

- the centre of mass is that of the moving bodies: a fixed base's root link is the world
  and does not count (``pinocchio.centerOfMass``); a floating base's root link does;
- ``com_jacobian`` (3 x nv) maps v to the CoM velocity in world coordinates
  (``jacobianCenterOfMass``); ``centroidal_map`` (6 x nv) maps v to the momentum
  [linear; angular] about the CoM in world axes (``computeCentroidalMap``'s A_G);
- a frame's classical acceleration is [d/dt of the world velocity of its origin;
  angular acceleration], world-aligned (``getFrameClassicalAcceleration`` with
  LOCAL_WORLD_ALIGNED), without gravity; ``jdot_qd`` is the same at qdd = 0, the
  bias J'(q, qd) qd of every task-space controller;
- an external wrench w_f = [force; torque] acts at frame f's origin, in world-aligned
  axes; inverse dynamics with wrenches is tau = ID(q, qd, qdd) - sum_f J_f^T w_f.

Every quantity is built from body-origin Jacobians (each column is an axis and a cross
product of :class:`derive.symbolic.kinematics.Kinematics`), so CSE shares them with FK.
"""

from __future__ import annotations

from functools import cached_property

import casadi as ca

from derive.symbolic.kinematics import Kinematics, configuration_rate
from derive.symbolic.dynamics import NewtonEuler
from derive.symbolic.spatial import rpy, skew
from derive.symbolic.symbols import Symbols


class WholeBody:
    """Centroidal and task-space quantities of one robot (see the module docstring)."""

    def __init__(self, kin: Kinematics, ne: NewtonEuler, sym: Symbols):
        self.kin, self.ne, self.sym = kin, ne, sym
        self.robot = kin.robot
        self._jdot: dict[str, ca.SX] = {}  # per frame

    @cached_property
    def _named_frames(self) -> dict:
        return {f.name: f for f in self.robot.frames}

    @cached_property
    def _rate(self) -> ca.SX:
        return configuration_rate(self.robot, self.sym)

    @cached_property
    def _bodies(self) -> list[tuple[str, ca.SX, ca.SX, ca.SX]]:
        """(frame, m, h, I_o) of every body with mass: body-frame first moment and inertia about its origin."""
        out = []
        if self.robot.floating:
            out.append((self.robot.root, *self.ne.root_mass))
        for b in self.ne.bodies:
            if b.name in self.kin.poses and not (ca.SX(b.m).is_zero() and ca.SX(b.h).is_zero()):
                out.append((b.name, b.m, b.h, b.I_o))
        return out

    @property
    def bodies(self) -> list[tuple[str, ca.SX, ca.SX, ca.SX]]:
        """(frame, m, h, I_o) of every body with mass (the floating root included): first moment and inertia
        about its origin, in its frame's axes."""
        return self._bodies

    @cached_property
    def mass(self) -> ca.SX:
        """Total mass of the moving bodies."""
        return sum((m for _, m, _, _ in self._bodies), ca.SX(0))

    @cached_property
    def com(self) -> ca.SX:
        """Centre of mass (3x1, world)."""
        first = ca.SX.zeros(3, 1)
        for frame, m, h, _ in self._bodies:
            pose = self.kin.pose(frame)
            first += m * pose.p + pose.R @ h
        return first / self.mass

    def _momentum_rows(self, frame: str, m, h) -> tuple[ca.SX, ca.SX, ca.SX]:
        """(J of the body origin, world first moment h_w, m J_c): m J_c maps v to the body's linear momentum."""
        J = self.kin.jacobian(frame)
        h_w = self.kin.pose(frame).R @ h
        return J, h_w, m * J[0:3, :] - skew(h_w) @ J[3:6, :]

    @cached_property
    def com_jacobian(self) -> ca.SX:
        """d(com)/dt = J_com v (3 x nv)."""
        total = ca.SX.zeros(3, self.sym.nv)
        for frame, m, h, _ in self._bodies:
            total += self._momentum_rows(frame, m, h)[2]
        return total / self.mass

    @cached_property
    def centroidal_map(self) -> ca.SX:
        """A_G (6 x nv): [linear; angular] momentum about the CoM, world axes, = A_G v."""
        c = self.com
        linear = ca.SX.zeros(3, self.sym.nv)
        angular = ca.SX.zeros(3, self.sym.nv)
        for frame, m, h, I_o in self._bodies:
            J, h_w, P = self._momentum_rows(frame, m, h)
            pose = self.kin.pose(frame)
            # about the body origin: R I_o R^T w + h_w x v_o; moved to the CoM: + (p_o - c) x P
            angular += pose.R @ I_o @ pose.R.T @ J[3:6, :] + skew(h_w) @ J[0:3, :] + skew(pose.p - c) @ P
            linear += P
        return ca.vertcat(linear, angular)

    def placement_in_body(self, frame: str) -> tuple[int, ca.SX, ca.SX]:
        """(body, R_bf, r): the RNEA body the frame moves with (-1 the root), the frame's rotation and
        origin in that body's coordinates."""
        if frame in self._named_frames:  # a named frame on a link
            f = self._named_frames[frame]
            body, R_bl, p_bl = self.ne.where[f.link]
            R_bf = R_bl @ rpy(*(self.sym.value(v) for v in f.origin.rpy))
            return body, R_bf, p_bl + R_bl @ ca.vertcat(*(self.sym.value(v) for v in f.origin.xyz))
        return self.ne.where[frame]

    def _classical_acceleration(self, frame: str, qdd: ca.SX) -> ca.SX:
        """[linear; angular] classical acceleration (6x1) of the frame's origin, world-aligned, without
        gravity, from the RNEA's forward pass without gravity (that of ``rnea(split=True)``, which
        bundles share): its body's a + dw x r + w x (w x r), rotated into the world."""
        body, R_bf, r = self.placement_in_body(frame)
        w, dw, a = (x[body] for x in self.ne.forward(self.sym.qd, qdd, gravity=False))
        R_wb = self.kin.pose(frame).R @ R_bf.T
        linear = R_wb @ (a + ca.cross(dw, r) + ca.cross(w, ca.cross(w, r)))
        return ca.vertcat(linear, R_wb @ dw)

    def jdot_qd(self, frame: str) -> ca.SX:
        """J'(q, qd) qd (6x1): the frame's classical acceleration at qdd = 0, world-aligned."""
        if frame not in self._jdot:
            self._jdot[frame] = self._classical_acceleration(frame, ca.SX.zeros(self.sym.nv, 1))
        return self._jdot[frame]

    def frame_acceleration(self, frame: str, qdd: ca.SX | None = None) -> ca.SX:
        """[classical linear; angular] acceleration (6x1) of the frame for (q, qd, qdd), world-aligned;
        ``qdd``: the accelerations (default the symbol qdd)."""
        return self._classical_acceleration(frame, self.sym.qdd if qdd is None else qdd)

    def wrench_torques(self, wrenches: ca.SX) -> ca.SX:
        """sum_f J_f^T w_f (nv x 1) for ``wrenches`` stacked [w_f; ...] in :attr:`Robot.wrench_frames` order."""
        tau = ca.SX.zeros(self.sym.nv, 1)
        for k, frame in enumerate(self.robot.wrench_frames):
            tau += self.kin.jacobian(frame).T @ wrenches[6 * k:6 * k + 6]
        return tau

    @cached_property
    def coriolis_matrix(self) -> ca.SX:
        """C(q, qd) with Mdot - 2C skew-symmetric and C qd = the velocity terms of inverse dynamics, for any
        base (Pinocchio's computeCoriolisMatrix; the Christoffel symbols need qd = dq/dt, which a floating
        base's quaternion breaks). In spatial world coordinates at the world origin ([w; v]), per body:

            C = sum_i J_i^T (I_i Jdot_i + B_i J_i),  B_i = 1/2 (v_i x* I_i - I_i v_i x + (I_i v_i) xbar*),

        with J_i the body's spatial world Jacobian, v_i = J_i qd, I_i its spatial inertia at the origin,
        Jdot_i = dJ_i/dq dq/dt and (f xbar*) m = m x* f.
        """
        nv = self.sym.nv
        rate = self._rate
        C = ca.SX.zeros(nv, nv)
        for frame, m, h, I_o in self._bodies:
            pose = self.kin.pose(frame)
            J = self.kin.jacobian(frame)
            J0 = ca.vertcat(J[3:6, :], J[0:3, :] + skew(pose.p) @ J[3:6, :])  # [w; v at the world origin]
            Jdot = ca.reshape(ca.jtimes(ca.vec(J0), self.sym.q, rate), 6, nv)
            h_w = pose.R @ h
            I_p = ca.blockcat([[pose.R @ I_o @ pose.R.T, skew(h_w)], [skew(h_w).T, m * ca.SX.eye(3)]])
            X = ca.blockcat([[ca.SX.eye(3), ca.SX.zeros(3, 3)], [-skew(pose.p), ca.SX.eye(3)]])
            I0 = X.T @ I_p @ X
            v = J0 @ self.sym.qd
            f = I0 @ v
            B = 0.5 * (crf(v) @ I0 - I0 @ crm(v) + ca.blockcat([[-skew(f[0:3]), -skew(f[3:6])],
                                                               [-skew(f[3:6]), ca.SX.zeros(3, 3)]]))
            C += J0.T @ (I0 @ Jdot + B @ J0)
        return C


def crm(v: ca.SX) -> ca.SX:
    """Motion cross product v x = [[w x, 0], [u x, w x]] for v = [w; u]."""
    return ca.blockcat([[skew(v[0:3]), ca.SX.zeros(3, 3)], [skew(v[3:6]), skew(v[0:3])]])


def crf(v: ca.SX) -> ca.SX:
    """Force cross product v x* = -(v x)^T."""
    return -crm(v).T
