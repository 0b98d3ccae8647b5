"""Equations of motion M(q) qdd + C(q, qd) qd + g(q) = tau, in CasADi SX.

Two routes to the same equations (the lecture's section 3, Examples 5 and 6):

- ``Lagrangian``: T(q, qd) and U(q) from the link poses; M = d2T/dqd2,
  g = dU/dq, C from the Christoffel symbols of M so that Mdot - 2C is
  skew-symmetric. This is the model researchers inspect.
- ``NewtonEuler``: recursive Newton-Euler (forward recursion of velocities and
  accelerations, backward recursion of forces; the lecture's section 4) and the
  composite-rigid-body algorithm for M, in body frames. The expression graphs
  share link velocities and composite inertias, so CSE keeps that sharing and
  the generated code is several times leaner than the expanded Lagrangian.

Both take the same Symbols; tests check they agree. Rigidly attached links
(fixed joints) are merged into their moving ancestor's body. A joint of several
DOF (cylindrical, universal, spherical) becomes a chain of 1-DOF elementary
motions (:func:`derive.symbolic.kinematics.joint_motions`) joined by massless bodies, so
both recursions only ever see revolute, prismatic and helical bodies.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import casadi as ca

from derive.symbolic import derivatives
from derive.symbolic.actuators import Drive
from derive.symbolic.kinematics import Kinematics, Motion, joint_motions, quaternion_matrix
from derive.description.robot import Robot
from derive.symbolic.spatial import axis_angle, rpy, skew
from derive.symbolic.symbols import Symbols


def _vec(sym: Symbols, values) -> ca.SX:
    return ca.vertcat(*(sym.value(v) for v in values))


def link_mass_properties(robot: Robot, sym: Symbols, link_name: str):
    """(m, com, I_c) of a link in its own frame: inertia about the COM in link axes."""
    link = robot.link(link_name)
    R_in = rpy(*(sym.value(v) for v in link.inertia_rpy))
    I = ca.SX(3, 3)
    for r in range(3):
        for c in range(3):
            I[r, c] = sym.value(link.inertia[r][c])
    return sym.value(link.mass), _vec(sym, link.com), R_in @ I @ R_in.T


CHRISTOFFEL_MAX_NV = 12
"""Up to this many coordinates the Coriolis matrix is built both ways (see NewtonEuler.coriolis_matrix)."""


def graph_cost(e: ca.SX, *inputs: ca.SX) -> int:
    """Instructions of ``e`` after CSE (inputs, constants and outputs included: a comparison, not a count)."""
    return ca.Function("cost", list(inputs), [ca.cse(ca.densify(e))], {"allow_free": True}).n_instructions()


def christoffel_coriolis(M: ca.SX, q: ca.SX, qd: ca.SX) -> ca.SX:
    """C_ij = sum_k 1/2 (dM_ij/dq_k + dM_ik/dq_j - dM_jk/dq_i) qd_k (Christoffel symbols of the first kind)."""
    n = q.numel()
    dM = [ca.jacobian(M[:, k], q) for k in range(n)]  # dM[k][i, l] = dM_ik / dq_l
    C = ca.SX(n, n)
    for i in range(n):
        for j in range(n):
            C[i, j] = sum(0.5 * (dM[j][i, k] + dM[k][i, j] - dM[k][j, i]) * qd[k] for k in range(n))
    return C


class Lagrangian:
    """Euler-Lagrange route: L = T - U, d/dt dL/dqd - dL/dq = tau."""

    def __init__(self, robot: Robot, sym: Symbols, kin: Kinematics | None = None):
        robot.require_fixed_base("the Lagrangian route (T and U as functions of q and dq/dt)")
        self.robot, self.sym = robot, sym
        self.kin = kin or Kinematics(robot, sym)

    @cached_property
    def kinetic_energy(self) -> ca.SX:
        """T = sum_i 1/2 m_i v_ci . v_ci + 1/2 w_i . (R_i I_i R_i^T) w_i, world frame."""
        T = ca.SX(0)
        for link in self.robot.links:
            m, com, I_c = link_mass_properties(self.robot, self.sym, link.name)
            pose = self.kin.pose(link.name)
            p_c = pose.p + pose.R @ com
            v_c = ca.jtimes(p_c, self.sym.q, self.sym.qd)
            w = self.kin.jacobian(link.name)[3:6, :] @ self.sym.qd
            T += 0.5 * m * ca.dot(v_c, v_c) + 0.5 * ca.dot(w, pose.R @ I_c @ pose.R.T @ w)
        return T

    @cached_property
    def potential_energy(self) -> ca.SX:
        """U = -sum_i m_i g . p_ci (zero with every COM at the world origin)."""
        g = _vec(self.sym, self.robot.gravity)
        U = ca.SX(0)
        for link in self.robot.links:
            m, com, _ = link_mass_properties(self.robot, self.sym, link.name)
            pose = self.kin.pose(link.name)
            U -= m * ca.dot(g, pose.p + pose.R @ com)
        return U

    @cached_property
    def mass_matrix(self) -> ca.SX:
        """M(q) = d2T/dqd2 (plus the actuators' armature), symmetric positive definite (nv x nv)."""
        return Drive(self.robot, self.sym).mass(ca.hessian(self.kinetic_energy, self.sym.qd)[0])

    @cached_property
    def gravity_vector(self) -> ca.SX:
        """g(q) = dU/dq (nv x 1); equals rnea(q, 0, 0)."""
        return ca.gradient(self.potential_energy, self.sym.q)

    @cached_property
    def coriolis_matrix(self) -> ca.SX:
        """C(q, qd) from the Christoffel symbols of M; Mdot - 2C is skew-symmetric."""
        return christoffel_coriolis(self.mass_matrix, self.sym.q, self.sym.qd)

    def inverse_dynamics(self, qdd: ca.SX | None = None) -> ca.SX:
        """tau = M(q) qdd + C(q, qd) qd + g(q)."""
        qdd = self.sym.qdd if qdd is None else qdd
        tau = self.mass_matrix @ qdd + self.coriolis_matrix @ self.sym.qd + self.gravity_vector
        friction = Drive(self.robot, self.sym).torque(self.sym.qd, ca.SX.zeros(self.sym.nv, 1), smooth=False)
        return tau if friction is None else tau + friction


@dataclass(frozen=True)
class Body:
    """A moving body (links merged over fixed joints) in its own frame.

    The joint places the body in its parent body: constant rotation E and
    offset p (parent coordinates), then the motion about/along ``axis``
    (a helical one slides ``pitch`` * q while it turns by q).
    Mass properties about the body origin: mass m, first moment h = m c,
    inertia I_o. The bodies between the elementary motions of a multi-DOF joint
    are massless, with E = 1 and p = 0.
    """

    name: str
    parent: int  # -1: the root (world)
    joint: str  # the coordinate it moves by
    kind: str  # revolute | prismatic | helical
    axis: tuple
    E: ca.SX
    p: ca.SX
    m: ca.SX
    h: ca.SX
    I_o: ca.SX
    pitch: ca.SX | float | None = None
    motion: Motion | None = None  # its elementary motion: a mimic joint's moves by scale * q[joint] + offset


def build_bodies(robot: Robot, sym: Symbols) -> tuple[list[Body], tuple, dict]:
    """Merge fixed joints; returns the moving bodies (in q order), the root's mass properties and
    where each link sits: link -> (body index, -1 the root; rotation and offset in that body's frame)."""
    # link -> (body index, rotation and offset of the link in that body's frame)
    where: dict[str, tuple[int, ca.SX, ca.SX]] = {robot.root: (-1, ca.SX.eye(3), ca.SX.zeros(3, 1))}
    bodies: list[dict] = []
    for j in robot.joints:
        b, R_bl, p_bl = where[j.parent]
        R_o = R_bl @ rpy(*(sym.value(v) for v in j.origin.rpy))
        p_o = p_bl + R_bl @ _vec(sym, j.origin.xyz)
        if j.type == "fixed":
            where[j.child] = (b, R_o, p_o)
            continue
        motions = joint_motions(j)
        for k, mo in enumerate(motions):
            name = j.child if k == len(motions) - 1 else f"{j.child}[{mo.coordinate}]"
            body = dict(name=name, parent=b, joint=mo.coordinate, kind=mo.kind, axis=mo.axis, E=R_o, p=p_o, motion=mo)
            bodies.append(body | ({"pitch": sym.value(mo.pitch)} if mo.kind == "helical" else {}))
            b, R_o, p_o = len(bodies) - 1, ca.SX.eye(3), ca.SX.zeros(3, 1)
        where[j.child] = (b, R_o, p_o)
    mass = {i: [ca.SX(0), ca.SX.zeros(3, 1), ca.SX.zeros(3, 3)] for i in range(-1, len(bodies))}
    for link in robot.links:
        b, R_bl, p_bl = where[link.name]
        m, com, I_c = link_mass_properties(robot, sym, link.name)
        c = p_bl + R_bl @ com
        acc = mass[b]
        acc[0] += m
        acc[1] += m * c
        acc[2] += R_bl @ I_c @ R_bl.T - m * (skew(c) @ skew(c))
    out = [Body(**d, m=mass[i][0], h=mass[i][1], I_o=mass[i][2]) for i, d in enumerate(bodies)]
    return out, tuple(mass[-1]), where


class NewtonEuler:
    """Recursive route: RNEA for inverse dynamics, CRBA for M, in body frames.

    With a floating base the root link is one more body, moved by the free flyer: its
    velocity [v; w] (root frame) is qd[0:6], its acceleration d[v; w]/dt is qdd[0:6] (so
    the classical acceleration of its origin is dv/dt + w x v), and tau[0:6] is the wrench
    [force; torque] on it at its origin, in its frame. Gravity enters as the root's
    acceleration -g, in root coordinates R^T g for a floating base.
    """

    def __init__(self, robot: Robot, sym: Symbols):
        self.robot, self.sym = robot, sym
        self.bodies, root, self.where = build_bodies(robot, sym)
        self.floating = robot.floating
        self.root_mass = root  # (m, h, I_o) of the root link: a body only with a floating base
        self.nb = 6 if robot.floating else 0  # entries of v before the joints'
        qj = sym.q[7:] if robot.floating else sym.q  # the joints' entries of q
        # body -> its coordinate's entry among the joints' (a mimic body shares its joint's entry)
        column = {c.name: i for i, c in enumerate(robot.joint_coordinates)}
        self.index = [column[b.joint] for b in self.bodies]
        self.scale = [b.motion.scale for b in self.bodies]
        self.mimic = any(b.motion.mimic for b in self.bodies)
        angle = [b.motion.value(qj[k]) for b, k in zip(self.bodies, self.index)]
        self.gravity = _vec(sym, robot.gravity)
        self._rot = [axis_angle(b.axis, angle[i]) if b.kind != "prismatic" else None for i, b in enumerate(self.bodies)]
        self._p = [b.p if b.kind == "revolute" else
                   b.p + (b.E @ ca.SX(ca.DM(list(b.axis)))) * (angle[i] if b.kind == "prismatic" else b.pitch * angle[i])
                   for i, b in enumerate(self.bodies)]
        if robot.floating:
            q = sym.q
            self.base_rotation = quaternion_matrix(q[3], q[4], q[5], q[6])
        self.drive = Drive(robot, sym)

    def to_child(self, i: int, v: ca.SX) -> ca.SX:
        """Parent-body coordinates -> body i coordinates (rotation only)."""
        v = self.bodies[i].E.T @ v
        return self._rot[i].T @ v if self._rot[i] is not None else v

    def to_parent(self, i: int, v: ca.SX) -> ca.SX:
        v = self._rot[i] @ v if self._rot[i] is not None else v
        return self.bodies[i].E @ v

    def placement(self, i: int) -> tuple[ca.SX, ca.SX]:
        """(Q, p) of body i: the rotation from its axes to its parent's (E, then the joint's turn) and
        its origin in the parent's coordinates (with a prismatic or helical joint's slide)."""
        return (self.bodies[i].E if self._rot[i] is None else self.bodies[i].E @ self._rot[i]), self._p[i]

    def motion_axes(self, i: int) -> tuple[ca.SX, ca.SX]:
        """(s_w, s_v): joint motion subspace as angular and linear parts, body coordinates."""
        b = self.bodies[i]
        s = ca.SX(ca.DM(list(b.axis)))
        zero = ca.SX.zeros(3, 1)
        if b.kind == "helical":
            return s, b.pitch * s
        return (s, zero) if b.kind == "revolute" else (zero, s)

    @cached_property
    def dof_parents(self) -> tuple[int, ...] | None:
        """For each entry of v, the entry of its parent motion (-1 at the root), for the LTDL of M along a
        branched tree or floating base; None for an unbranched fixed-base chain (LDL^T costs the same and
        keeps its code) and with mimic joints (a coordinate moving two branches couples them in M)."""
        n, nb = len(self.bodies), self.nb
        chain = all(b.parent == i - 1 for i, b in enumerate(self.bodies))
        if self.mimic or (chain and not self.floating):
            return None
        base = tuple(range(-1, nb - 1))  # the free flyer's six, as a chain
        return base + tuple(nb + b.parent if b.parent >= 0 else nb - 1 for b in self.bodies[:n])

    def body_rates(self, v: ca.SX) -> list:
        """The joints' rates (or accelerations) ``v`` per body: scale * v[joint] (G v)."""
        if not self.mimic:
            return v
        return [s * v[k] if s != 1 else v[k] for s, k in zip(self.scale, self.index)]

    def root_motion(self, qd: ca.SX, qdd: ca.SX, gravity: bool = True) -> tuple[ca.SX, ca.SX, ca.SX]:
        """(w, dw, a) of the root, root coordinates: a is the classical acceleration of its origin
        minus gravity (zero velocity and acceleration -g for a fixed base)."""
        zero = ca.SX.zeros(3, 1)
        if not self.floating:
            return zero, zero, -self.root_gravity if gravity else zero
        w = qd[3:6]
        a = qdd[0:3] + ca.cross(w, qd[0:3])
        return w, qdd[3:6], a - self.root_gravity if gravity else a

    @cached_property
    def root_gravity(self) -> ca.SX:
        """g in root coordinates: the world's for a fixed base, R^T g for a floating one."""
        return self.base_rotation.T @ self.gravity if self.floating else self.gravity

    def forward(self, qd: ca.SX, qdd: ca.SX, gravity: bool = True) -> tuple[list, list, list]:
        """The RNEA's forward pass: per body its angular velocity w, angular acceleration dw and the
        classical acceleration a of its origin minus gravity (only if ``gravity``), body coordinates;
        index -1 (the last entry) is the root's."""
        n, nb = len(self.bodies), self.nb
        w, dw, a = [None] * (n + 1), [None] * (n + 1), [None] * (n + 1)
        w[-1], dw[-1], a[-1] = self.root_motion(qd, qdd, gravity)
        qd, qdd = self.body_rates(qd[nb:]), self.body_rates(qdd[nb:])
        for i, b in enumerate(self.bodies):
            s_w, s_v = self.motion_axes(i)
            w_p, dw_p, a_p = w[b.parent], dw[b.parent], a[b.parent]
            p = self._p[i]
            w_in = self.to_child(i, w_p)
            w[i] = w_in + s_w * qd[i]
            dw[i] = self.to_child(i, dw_p) + s_w * qdd[i] + ca.cross(w_in, s_w * qd[i])
            a_lin = a_p + ca.cross(dw_p, p) + ca.cross(w_p, ca.cross(w_p, p))
            a[i] = self.to_child(i, a_lin) + s_v * qdd[i] + 2 * ca.cross(w[i], s_v * qd[i])
        return w, dw, a

    @cached_property
    def gravity_accelerations(self) -> list:
        """-g in each body's coordinates (index -1: the root's): what ``forward`` with gravity adds to a."""
        n = len(self.bodies)
        g = [None] * (n + 1)
        g[-1] = -self.root_gravity
        for i, b in enumerate(self.bodies):
            g[i] = self.to_child(i, g[b.parent])
        return g

    def world_to_body(self, i: int, v: ca.SX) -> ca.SX:
        """The world-aligned vector ``v`` in body i's coordinates (i = -1: the root's)."""
        if i == -1:
            return self.base_rotation.T @ v if self.floating else v
        return self.to_child(i, self.world_to_body(self.bodies[i].parent, v))

    def rnea(self, qd: ca.SX, qdd: ca.SX, gravity: bool = True, split: bool = False,
             external: list | None = None) -> ca.SX:
        """tau = RNEA(q, qd, qdd): M qdd + C qd + g (g only if ``gravity``). With ``split`` the forward
        pass runs without gravity and -g is added per body (:attr:`gravity_accelerations`): a few more
        operations, but the pass is then the one frame accelerations use (bundles share it).
        ``external``: (body, force, torque) wrenches on bodies (-1 the root), body coordinates, the torque
        about the body's origin: tau is then M qdd + C qd + g - sum J^T w, the backward pass carrying them."""
        n, nb = len(self.bodies), self.nb
        if split and gravity:
            w, dw, a = self.forward(qd, qdd, gravity=False)
            a = [a_i + g_i for a_i, g_i in zip(a, self.gravity_accelerations)]
        else:
            w, dw, a = self.forward(qd, qdd, gravity)
        w_0, dw_0, a_0 = w[-1], dw[-1], a[-1]
        f, t = [None] * n, [None] * n
        for i, b in enumerate(self.bodies):
            f[i] = b.m * a[i] + ca.cross(dw[i], b.h) + ca.cross(w[i], ca.cross(w[i], b.h))
            t[i] = b.I_o @ dw[i] + ca.cross(w[i], b.I_o @ w[i]) + ca.cross(b.h, a[i])
        tau = ca.SX.zeros(self.sym.nv, 1)
        f_0 = t_0 = ca.SX.zeros(3, 1)
        if self.floating:
            m, h, I = self.root_mass
            f_0 = m * a_0 + ca.cross(dw_0, h) + ca.cross(w_0, ca.cross(w_0, h))
            t_0 = I @ dw_0 + ca.cross(w_0, I @ w_0) + ca.cross(h, a_0)
        for i, force, torque in external or ():
            if i >= 0:
                f[i], t[i] = f[i] - force, t[i] - torque
            else:  # on the root: moves nothing unless it floats
                f_0, t_0 = f_0 - force, t_0 - torque
        for i in reversed(range(n)):
            b = self.bodies[i]
            s_w, s_v = self.motion_axes(i)
            if self.mimic:  # tau = G^T tau_bodies
                tau[nb + self.index[i]] += self.scale[i] * (ca.dot(s_w, t[i]) + ca.dot(s_v, f[i]))
            else:
                tau[nb + i] = ca.dot(s_w, t[i]) + ca.dot(s_v, f[i])
            if b.parent >= 0:
                f_p = self.to_parent(i, f[i])
                f[b.parent] = f[b.parent] + f_p
                t[b.parent] = t[b.parent] + self.to_parent(i, t[i]) + ca.cross(self._p[i], f_p)
            elif self.floating:
                f_p = self.to_parent(i, f[i])
                f_0, t_0 = f_0 + f_p, t_0 + self.to_parent(i, t[i]) + ca.cross(self._p[i], f_p)
        if self.floating:
            tau[0:3], tau[3:6] = f_0, t_0
        return tau

    @cached_property
    def mass_matrix(self) -> ca.SX:
        """M(q) (with the actuators' armature on its diagonal, :mod:`derive.symbolic.actuators`)."""
        return self.drive.mass(self.rigid_mass_matrix)

    @cached_property
    def rigid_mass_matrix(self) -> ca.SX:
        """M(q) of the rigid bodies by the composite-rigid-body algorithm (Featherstone, Table 6.2)."""
        n, nb = len(self.bodies), self.nb
        comp = [[b.m, b.h, b.I_o] for b in self.bodies]
        root = list(self.root_mass)  # the floating root's composite
        for i in reversed(range(n)):
            b = self.bodies[i]
            if b.parent < 0 and not self.floating:
                continue
            m, h, I = comp[i]
            p = self._p[i]
            h_p = self.to_parent(i, h)
            # rotate I into parent axes: R I R^T with R = E Rz(q)
            RI = ca.horzcat(*[self.to_parent(i, I[:, k]) for k in range(3)])
            I_rot = ca.horzcat(*[self.to_parent(i, RI[k, :].T) for k in range(3)])
            I_full = I_rot - skew(p) @ skew(h_p) - skew(h_p) @ skew(p) - m * (skew(p) @ skew(p))
            # symmetric by construction: only the upper triangle is computed
            I_p = ca.SX(3, 3)
            for r in range(3):
                for c in range(3):
                    I_p[r, c] = I_full[min(r, c), max(r, c)]
            par = comp[b.parent] if b.parent >= 0 else root
            par[0] = par[0] + m
            par[1] = par[1] + h_p + m * p
            par[2] = par[2] + I_p
        M = ca.SX(nb + n, nb + n)  # over the bodies' motions; G^T M G at the end for mimic joints
        if self.floating:
            m, h, I = root  # momentum [m v + w x h; I w + h x v] of the whole robot for the base velocity [v; w]
            M[0:3, 0:3] = m * ca.SX.eye(3)
            M[0:3, 3:6] = -skew(h)
            M[3:6, 0:3] = skew(h)
            M[3:6, 3:6] = I
        for i in range(n):
            m, h, I = comp[i]
            s_w, s_v = self.motion_axes(i)
            # spatial momentum of composite i for a unit rate of joint i, about its origin
            f = ca.cross(s_w, h) + m * s_v
            t = I @ s_w + ca.cross(h, s_v)
            M[nb + i, nb + i] = ca.dot(s_w, t) + ca.dot(s_v, f)
            j = i
            while self.bodies[j].parent >= 0:
                f_p = self.to_parent(j, f)
                t = self.to_parent(j, t) + ca.cross(self._p[j], f_p)
                f = f_p
                j = self.bodies[j].parent
                sj_w, sj_v = self.motion_axes(j)
                M[nb + i, nb + j] = M[nb + j, nb + i] = ca.dot(sj_w, t) + ca.dot(sj_v, f)
            if self.floating:
                f_p = self.to_parent(j, f)
                t = self.to_parent(j, t) + ca.cross(self._p[j], f_p)
                M[0:3, nb + i] = f_p
                M[3:6, nb + i] = t
                M[nb + i, 0:3] = f_p.T
                M[nb + i, 3:6] = t.T
        if self.mimic:
            G = ca.DM(nb + n, self.sym.nv)
            for k in range(nb):
                G[k, k] = 1
            for i in range(n):
                G[nb + i, nb + self.index[i]] = self.scale[i]
            M = G.T @ M @ G
        return M

    @cached_property
    def gravity_vector(self) -> ca.SX:
        zeros = ca.SX.zeros(self.sym.nv, 1)
        return self.rnea(zeros, zeros)

    @cached_property
    def coriolis_matrix(self) -> ca.SX:
        """The Christoffel-symbol C(q, qd), by the cheapest of three exact forms: the symbols of M
        (:func:`christoffel_coriolis`, O(n^3) terms); 1/2 d(C qd)/dqd of the Newton-Euler velocity
        terms rnea(q, qd, 0) without gravity (C qd = sum_jk c_ijk qd_j qd_k with c_ijk = c_ikj, so its
        derivative is 2 C) by automatic differentiation, which grows as n^2 and wins from about 8
        generic joints; or the same derivative from the tree's structure
        (:mod:`derive.symbolic.derivatives`: O(n) per body plus a dot product per ancestor pair; fixed
        bases without mimic joints), the cheapest on long chains. Up to :data:`CHRISTOFFEL_MAX_NV`
        coordinates all are built and the one with fewer operations after CSE is kept; above, the
        structural form where it applies, else automatic differentiation."""
        self.robot.require_fixed_base("the Coriolis matrix from Christoffel symbols")
        q, qd = self.sym.q, self.sym.qd
        zeros = ca.SX.zeros(self.sym.nv, 1)
        small = self.sym.nv <= CHRISTOFFEL_MAX_NV
        candidates = []  # (C, how); on equal cost the last one wins
        if derivatives.worth_trying(self):
            C = 0.5 * derivatives.inverse_dynamics_derivatives(self, zeros, actuators=False)[1]
            candidates.append((C, "1/2 d(C qd)/dqd by the analytic RNEA derivatives"))
        if small or not candidates:
            C = 0.5 * ca.jacobian(self.rnea(qd, zeros, gravity=False), qd)
            candidates.append((C, "1/2 d(C qd)/dqd by automatic differentiation of the RNEA"))
        if small:
            candidates.append((christoffel_coriolis(self.mass_matrix, q, qd), "Christoffel symbols of M"))
        C, self.coriolis_algorithm = min(reversed(candidates), key=lambda c: graph_cost(c[0], q, qd))
        return C

    def inverse_dynamics(self, qdd: ca.SX | None = None, smooth: bool = False, split: bool = False,
                         external: list | None = None) -> ca.SX:
        """RNEA plus the actuators' armature and friction (Coulomb as sign(qd), tanh(qd / eps) if ``smooth``);
        ``split``: gravity added per body after a gravity-free forward pass; ``external``: wrenches on
        bodies (see :meth:`rnea`)."""
        qdd = self.sym.qdd if qdd is None else qdd
        tau = self.rnea(self.sym.qd, qdd, split=split, external=external)
        drive = self.drive.torque(self.sym.qd, qdd, smooth)
        return tau if drive is None else tau + drive

    @cached_property
    def bias(self) -> ca.SX:
        """C(q, qd) qd + g(q) = rnea(q, qd, 0), plus the smooth friction: what forward dynamics subtracts."""
        zero = ca.SX.zeros(self.sym.nv, 1)
        tau = self.rnea(self.sym.qd, zero)
        drive = self.drive.torque(self.sym.qd, zero, smooth=True)
        return tau if drive is None else tau + drive
