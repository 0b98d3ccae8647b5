"""Numeric rigid-body dynamics of a fixed- or floating-base tree, written from Featherstone's textbook.

This is the independent reference the symbolic pipeline is checked against: it
uses numpy only, and reads the model through :mod:`derive.description.model` and
:mod:`derive.description.expr` (input parsing), nothing else of ``derive``.

Conventions
-----------
- Spatial vectors inside the algorithms are Featherstone's ``[angular; linear]``,
  expressed in the body frame at the body origin; the motion transform from
  frame A to frame B, whose pose in A is ``(R, r)``, is
  ``B_X_A = [[R^T, 0], [-R^T r^, R^T]]`` and forces transform with ``X^T``.
- Bodies are the moving joints, in ``robot.moving_joints`` order; body i's
  frame is the child link frame of joint i, and its entries are the
  consecutive slices ``qdofs[i]`` of q and ``dofs[i]`` of v (= qd), qdd and tau.
  Links hanging off a body through fixed joints are merged rigidly into it (their
  frames keep their own poses). With a fixed base the root link and the links
  fixed to it are the world and carry no dynamics.
- A mimic joint (``joint.mimic``: follows joint J, q_m = a q_J + b) is a body like any
  other, but its slices ``qdofs[i]`` and ``dofs[i]`` are J's, with ``scale[i]`` = a and
  ``offset[i]`` = b (1 and 0 for every other body): the body moves by
  q_i = a q[qdofs[i]] + b, qd_i = a qd[dofs[i]], qdd_i = a qdd[dofs[i]] (:meth:`NumericRobot.body_q`,
  :meth:`NumericRobot.body_rate`). Its generalized subspace is a S_i, so wherever a body's
  entries are written (tau, Jacobian columns, M, the centroidal map) they are ADDED, times a,
  into J's: tau_J += a S_i^T f_i, M = G^T M_bodies G (an explicit constraint, Featherstone's
  qd_bodies = G v with a constant G). With a mimic joint, :meth:`NumericRobot.aba` solves
  M qdd = tau - bias instead of running the articulated-body recursion, which has no
  place for a coordinate shared by two bodies.
- A floating base (``robot.floating``) is body 0, the root link (and the links fixed
  to it), moved by a free-flyer joint with Pinocchio's ``JointModelFreeFlyer``
  conventions: q[0:3] is the root origin in the world, q[3:7] the quaternion
  (x, y, z, w) turned into R by :func:`quaternion_matrix` as is (no normalisation);
  v[0:6] = [linear velocity of the root origin; angular velocity], both in the root
  frame; qdd[0:6] = dv/dt (the root's spatial acceleration, root frame) and
  tau[0:6] = [force; torque] on the root at its origin, root frame. The joints
  follow, with q index = v index + 1.
- Every joint type is one :class:`JointModel` (Featherstone, section 4.4): the
  joint transform X_J(q), the motion subspace S(q) (6 x DOF, child frame) and
  the bias c_J = Sdot qd. Multi-DOF joints are single bodies with a 6 x 2 or
  6 x 3 S here, not chains of massless bodies as on the symbolic side.
- Gravity enters as the base acceleration ``a_0 = -[0; gravity]``.
- Outputs meant for comparison (Jacobians, frame accelerations, wrenches, the
  centroidal map) use Pinocchio's ``[linear; angular]``.
- Every q-dependent quantity is computed with numpy ufuncs and plain transposes
  (no abs, no conjugation), so complex q works and complex-step derivatives
  ``f'(q) e = Im f(q + i h e) / h`` are exact to machine precision (along q_dot(q, e)
  for a floating base, whose q has a quaternion).
"""

from __future__ import annotations

from typing import Mapping

import numpy as np

from derive.description import expr
from derive.description.joints import motion_type
from derive.description.robot import Origin, Robot
from derive.errors import DeriveError

COMPLEX_STEP = 1e-30


# --------------------------------------------------------------------------- small algebra


def skew(v: np.ndarray) -> np.ndarray:
    """v^ such that v^ w = v x w."""
    return np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]], dtype=np.result_type(v, float))


def rpy_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """URDF's R = Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr, cp, sp, cy, sy = np.cos(roll), np.sin(roll), np.cos(pitch), np.sin(pitch), np.cos(yaw), np.sin(yaw)
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return rz @ ry @ rx


def rotation(axis: np.ndarray, angle) -> np.ndarray:
    """Rodrigues: exp(angle [axis]x) = 1 + sin(angle) K + (1 - cos(angle)) K^2 for a unit axis."""
    k = skew(axis)
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * (k @ k)


def quaternion_matrix(quat) -> np.ndarray:
    """R of the quaternion (x, y, z, w), Pinocchio's expression, used as is off the unit sphere too:
    [[1-2(y²+z²), 2(xy-zw), 2(xz+yw)], [2(xy+zw), 1-2(x²+z²), 2(yz-xw)], [2(xz-yw), 2(yz+xw), 1-2(x²+y²)]]."""
    x, y, z, w = quat[0], quat[1], quat[2], quat[3]
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]],
                    dtype=np.result_type(x, y, z, w, float))


def homogeneous(rot: np.ndarray, pos: np.ndarray) -> np.ndarray:
    t = np.zeros((4, 4), dtype=np.result_type(rot, pos))
    t[:3, :3], t[:3, 3], t[3, 3] = rot, pos, 1
    return t


def motion_transform(pose: np.ndarray) -> np.ndarray:
    """B_X_A = [[E, 0], [-E r^, E]], E = R^T, for the pose (R, r) of frame B in frame A."""
    e = pose[:3, :3].T
    x = np.zeros((6, 6), dtype=pose.dtype)
    x[:3, :3] = x[3:, 3:] = e
    x[3:, :3] = -e @ skew(pose[:3, 3])
    return x


def to_world(pose: np.ndarray, motion: np.ndarray) -> np.ndarray:
    """A_X_B m for the pose (R, r) of B in A: [R w; R v + r x (R w)] (m = [w; v], one per column)."""
    w = pose[:3, :3] @ motion[:3]
    return np.concatenate([w, pose[:3, :3] @ motion[3:] + np.cross(pose[:3, 3], w.T).T])


def crm(v: np.ndarray) -> np.ndarray:
    """Motion cross product v x = [[w^, 0], [v^, w^]] for v = [w; v]."""
    out = np.zeros((6, 6), dtype=v.dtype)
    out[:3, :3] = out[3:, 3:] = skew(v[:3])
    out[3:, :3] = skew(v[3:])
    return out


def crf(v: np.ndarray) -> np.ndarray:
    """Force cross product v x* = -(v x)^T."""
    return -crm(v).T


def crf_bar(f: np.ndarray) -> np.ndarray:
    """f x-bar*: the matrix with (f x-bar*) v = v x* f, i.e. [[-n^, -f^], [-f^, 0]] for f = [n; f] (skew)."""
    out = np.zeros((6, 6), dtype=f.dtype)
    out[:3, :3] = -skew(f[:3])
    out[:3, 3:] = out[3:, :3] = -skew(f[3:])
    return out


def spatial_inertia(mass: float, com: np.ndarray, inertia_com: np.ndarray) -> np.ndarray:
    """I_O = [[I_c + m c^ c^T, m c^], [m c^T, m 1]]: body inertia about the frame origin."""
    c = skew(com)
    return np.block([[inertia_com + mass * c @ c.T, mass * c], [mass * c.T, mass * np.eye(3)]])


# --------------------------------------------------------------------------- joint models

FREE_FLYER_SUBSPACE = np.block([[np.zeros((3, 3)), np.eye(3)], [np.eye(3), np.zeros((3, 3))]])
"""S of the free flyer: v = [linear; angular] (Pinocchio's order) to Featherstone's [angular; linear]."""


class JointModel:
    """One joint type: X_J(q) as the child's pose in the joint frame, S(q) and c_J(q, qd) in the child frame.

    ``v_J = S(q) qd`` is the child's spatial velocity relative to the joint frame and
    ``c_J = Sdot qd`` (Featherstone's eq. 4.43; nonzero only where S depends on q).

    - revolute ``a`` (and continuous, the same motion): T = Rot(a, q); S = [a; 0].
    - prismatic ``a``: T = Trans(a q); S = [0; a].
    - helical ``a``, pitch h: T = Rot(a, q) Trans(h a q); S = [a; h a].
    - cylindrical ``a``: T = Rot(a, q1) Trans(a q2); S = [[a, 0]; [0, a]].
    - universal ``a1``, ``a2``: T = Rot(a1, q1) Rot(a2, q2);
      S = [[Rot(a2, q2)^T a1, a2]; 0], c_J = [qd1 qd2 (Rot(a2, q2)^T a1) x a2; 0].
    - spherical, ZYX Euler (a, b, c): T = Rz(a) Ry(b) Rx(c); the body rates
      w = [[-sb, 0, 1], [cb sc, cc, 0], [cb cc, -sc, 0]] [da; db; dc] (s = sin, c = cos),
      singular where cb = 0.
    - freeflyer (a floating base): q = [p; quaternion (x, y, z, w)], T = (R(quaternion), p);
      qd = v = [linear; angular] in the child frame, S = [[0, 1]; [1, 0]] (constant).
    """

    def __init__(self, kind: str, axis: np.ndarray, axis2: np.ndarray | None = None, pitch: float = 0.0):
        self.kind, self.axis, self.axis2, self.pitch = kind, axis, axis2, pitch

    def transform(self, q) -> np.ndarray:
        a = self.axis
        if self.kind == "revolute":
            return homogeneous(rotation(a, q[0]), np.zeros(3))
        if self.kind == "prismatic":
            return homogeneous(np.eye(3), a * q[0])
        if self.kind == "helical":
            return homogeneous(rotation(a, q[0]), a * (self.pitch * q[0]))
        if self.kind == "cylindrical":
            return homogeneous(rotation(a, q[0]), a * q[1])
        if self.kind == "universal":
            return homogeneous(rotation(a, q[0]) @ rotation(self.axis2, q[1]), np.zeros(3))
        if self.kind == "freeflyer":
            return homogeneous(quaternion_matrix(q[3:7]), q[:3])
        ex, ey, ez = np.eye(3)
        return homogeneous(rotation(ez, q[0]) @ rotation(ey, q[1]) @ rotation(ex, q[2]), np.zeros(3))

    def subspace(self, q) -> np.ndarray:
        a, z = self.axis, np.zeros(3)
        if self.kind == "revolute":
            cols = [np.concatenate([a, z])]
        elif self.kind == "prismatic":
            cols = [np.concatenate([z, a])]
        elif self.kind == "helical":
            cols = [np.concatenate([a, self.pitch * a])]
        elif self.kind == "cylindrical":
            cols = [np.concatenate([a, z]), np.concatenate([z, a])]
        elif self.kind == "universal":
            cols = [np.concatenate([rotation(self.axis2, q[1]).T @ a, z]), np.concatenate([self.axis2, z])]
        elif self.kind == "freeflyer":
            return FREE_FLYER_SUBSPACE.copy()
        else:
            sb, cb, sc, cc = np.sin(q[1]), np.cos(q[1]), np.sin(q[2]), np.cos(q[2])
            w = np.array([[-sb, 0.0, 1.0], [cb * sc, cc, 0.0], [cb * cc, -sc, 0.0]])
            return np.vstack([w, np.zeros((3, 3))])
        return np.column_stack(cols)

    def subspace_rate(self, q, qd) -> np.ndarray:
        """Sdot = dS/dt along qd (6 x DOF, child frame); zero where S is constant."""
        out = np.zeros((6, len(qd)), dtype=np.result_type(q, qd, float))
        if self.kind == "universal":
            s1 = rotation(self.axis2, q[1]).T @ self.axis
            out[:3, 0] = qd[1] * np.cross(s1, self.axis2)
        elif self.kind == "spherical":
            sb, cb, sc, cc = np.sin(q[1]), np.cos(q[1]), np.sin(q[2]), np.cos(q[2])
            db, dc = qd[1], qd[2]
            out[:3, 0] = [-cb * db, -sb * sc * db + cb * cc * dc, -sb * cc * db - cb * sc * dc]
            out[:3, 1] = [0.0, -sc * dc, -cc * dc]
        return out

    def bias(self, q, qd) -> np.ndarray:
        """c_J = Sdot qd."""
        if self.kind in ("universal", "spherical"):
            return self.subspace_rate(q, qd) @ qd
        return np.zeros(6, dtype=np.result_type(q, qd, float))


# --------------------------------------------------------------------------- the robot


class NumericRobot:
    """A :class:`~derive.model.Robot` evaluated at fixed parameters, with numpy kinematics and dynamics.

    q has ``nq`` entries and v (= qd), qdd and tau ``nv`` (nq = nv + 1 with a floating base;
    see the module docstring for the free-flyer conventions). A mimic joint has no entry: it
    follows its leader's (module docstring), and every method takes and returns the reduced q, v.

    Args:
        robot: the parsed model.
        params: parameter name -> value, overriding ``robot.parameter_defaults``.
    """

    def __init__(self, robot: Robot, params: Mapping[str, float] | None = None):
        env = dict(robot.parameter_defaults)
        unknown = set(params or {}) - set(env)
        if unknown:
            raise ValueError(f"robot '{robot.name}' has no parameter(s) {', '.join(sorted(unknown))}")
        env.update({k: float(v) for k, v in (params or {}).items()})
        self.robot, self.params = robot, env

        def num(value) -> float:
            return float(expr.evaluate(value, env))

        def vec(values) -> np.ndarray:
            return np.array([num(v) for v in values], dtype=float)

        def pose(origin: Origin) -> np.ndarray:
            return homogeneous(rpy_matrix(*vec(origin.rpy)), vec(origin.xyz))

        self.gravity_vector = vec(robot.gravity)
        self.floating = robot.floating
        self.nq, self.nv = robot.nq, robot.nv
        self.joint_names = tuple(c.name for c in robot.coordinates)  # one per entry of q
        self.velocity_names = tuple(robot.velocity_names)  # one per entry of v, qdd and tau

        # Walk the tree: each link sits on a body (-1 = world) at a constant pose in that body's frame.
        self.parent: list[int] = []  # lambda(i)
        self.tree_pose: list[np.ndarray] = []  # joint frame i (before motion) in body lambda(i)
        self.joint_model: list[JointModel] = []
        self.dofs: list[slice] = []  # body i's entries of v, qdd and tau (a mimic joint's: its leader's)
        self.qdofs: list[slice] = []  # body i's entries of q (a mimic joint's: its leader's)
        self.scale: list[float] = []  # q_i = scale * q[qdofs] + offset: the mimic multiplier, else 1
        self.offset: list[float] = []  # the mimic offset, else 0
        placed = {robot.root: (-1, np.eye(4))}
        if robot.floating:  # body 0: the root link, moved by the free flyer
            self.parent.append(-1)
            self.tree_pose.append(np.eye(4))
            self.joint_model.append(JointModel("freeflyer", np.zeros(3)))
            self.dofs.append(slice(0, 6))
            self.qdofs.append(slice(0, 7))
            self.scale.append(1.0)
            self.offset.append(0.0)
            placed[robot.root] = (0, np.eye(4))
        shift = self.nq - self.nv
        # Every joint with coordinates owns the next entries of v (and of q, shifted past the quaternion);
        # a mimic joint owns none, its leader may come later in the tree's order.
        owned: dict[str, slice] = {}
        start = 6 if robot.floating else 0
        for joint in robot.joints:
            if joint.coordinates:
                owned[joint.name] = slice(start, start + joint.dof)
                start += joint.dof
        assert start == self.nv, (start, self.nv)
        for joint in robot.joints:
            body, at = placed[joint.parent]
            joint_pose = at @ pose(joint.origin)
            if joint.dof == 0:
                placed[joint.child] = (body, joint_pose)
                continue
            self.parent.append(body)
            self.tree_pose.append(joint_pose)
            self.joint_model.append(JointModel(
                motion_type(joint.type), np.array(joint.axis, dtype=float),
                None if joint.axis2 is None else np.array(joint.axis2, dtype=float),
                0.0 if joint.pitch is None else num(joint.pitch)))
            dof = owned[joint.name if joint.mimic is None else joint.mimic.joint]
            self.dofs.append(dof)
            self.qdofs.append(slice(dof.start + shift, dof.stop + shift))
            self.scale.append(1.0 if joint.mimic is None else float(joint.mimic.multiplier))
            self.offset.append(0.0 if joint.mimic is None else float(joint.mimic.offset))
            placed[joint.child] = (len(self.parent) - 1, np.eye(4))
        self.mimic = [joint.mimic is not None for joint in robot.joints if joint.dof > 0]  # per body
        if robot.floating:
            self.mimic.insert(0, False)
        self.has_mimic = any(self.mimic)
        n = self.nb = len(self.parent)
        self.support = []  # bodies from the root down to i, inclusive
        for i in range(n):
            chain, k = [], i
            while k >= 0:
                chain.append(k)
                k = self.parent[k]
            self.support.append(chain[::-1])

        # Inertias, merged per body; point masses kept per link for the potential energy and the COM.
        self.inertia = [np.zeros((6, 6)) for _ in range(n)]
        self.masses: list[tuple[int, float, np.ndarray]] = []  # (body, mass, COM in body frame) per moving link
        for link in robot.links:
            body, at = placed[link.name]
            if body < 0:  # the root and links fixed to it are world with a fixed base, as in Pinocchio
                continue
            mass = num(link.mass)
            rot = at[:3, :3] @ rpy_matrix(*vec(link.inertia_rpy))
            inertia_com = rot @ np.array([[num(x) for x in row] for row in link.inertia]) @ rot.T
            com = at[:3, :3] @ vec(link.com) + at[:3, 3]
            self.masses.append((body, mass, com))
            self.inertia[body] = self.inertia[body] + spatial_inertia(mass, com, inertia_com)
        self.total_mass = sum(mass for _, mass, _ in self.masses)  # what moves (floating: the root too)

        # Actuators per body and DOF of its joint (none for a floating base's six): armature, viscous and
        # Coulomb friction acting on the body's OWN joint rate (a mimic joint's: a qd[dofs]). In v they are
        # G^T diag(.) G (G the constant map v -> the bodies' rates): per entry of v the armature and the
        # viscous friction add up times scale^2; the Coulomb force is G^T f_c sign(G v) (:meth:`friction`).
        self.body_armature, self.body_viscous, self.body_coulomb = [], [], []
        if robot.floating:
            for values in (self.body_armature, self.body_viscous, self.body_coulomb):
                values.append(np.zeros(6))
        for joint in robot.joints:
            if joint.dof == 0:
                continue
            acts = joint.actuators
            self.body_armature.append(np.array([num(a.armature) + num(a.gear_ratio) ** 2 * num(a.motor_inertia)
                                                for a in acts]))
            self.body_viscous.append(np.array([num(a.viscous) for a in acts]))
            self.body_coulomb.append(np.array([num(a.coulomb) for a in acts]))
        self.armature, self.viscous, self.coulomb = np.zeros(self.nv), np.zeros(self.nv), np.zeros(self.nv)
        for i in range(n):  # the diagonals of G^T diag(.) G; the Coulomb coefficient of sign(v): |scale| f_c
            self.armature[self.dofs[i]] += self.scale[i] ** 2 * self.body_armature[i]
            self.viscous[self.dofs[i]] += self.scale[i] ** 2 * self.body_viscous[i]
            self.coulomb[self.dofs[i]] += abs(self.scale[i]) * self.body_coulomb[i]
        self.smoothing = robot.smoothing

        # Every placeable frame: (body, constant pose in the body frame).
        self.frames: dict[str, tuple[int, np.ndarray]] = {}
        for name in [robot.root] + [j.child for j in robot.joints]:
            self.frames[name] = placed[name]
        for frame in robot.frames:
            body, at = placed[frame.link]
            self.frames[frame.name] = (body, at @ pose(frame.origin))

    # ------------------------------------------------------------------ inputs

    def _q(self, q) -> np.ndarray:
        q = np.asarray(q)
        if q.shape != (self.nq,):
            raise ValueError(f"robot '{self.robot.name}': q must have nq = {self.nq} entries, got shape {q.shape}")
        return q

    def _v(self, v, what: str = "v") -> np.ndarray:
        v = np.asarray(v)
        if v.shape != (self.nv,):
            raise ValueError(f"robot '{self.robot.name}': {what} must have nv = {self.nv} entries, got shape {v.shape}")
        return v

    def _frame(self, name: str) -> tuple[int, np.ndarray]:
        try:
            return self.frames[self.robot.frame_name(name)]  # an alias: the frame it names
        except KeyError:
            raise ValueError(f"robot '{self.robot.name}' has no frame '{name}' (frames: {', '.join(self.frames)})") from None

    # ------------------------------------------------------------------ configurations

    def q_dot(self, q, v) -> np.ndarray:
        """dq/dt (nq) for the velocity v (nv): v itself for a fixed base.

        Floating base: the root position moves at R v_lin, the quaternion at
        0.5 quat (x) (w, 0), i.e. vector part 0.5 (q_w w + q_v x w) and scalar part -0.5 q_v . w;
        the joints at their v.
        """
        q, v = self._q(q), self._v(v)
        if not self.floating:
            return v.astype(np.result_type(q, v, float))
        out = np.zeros(self.nq, dtype=np.result_type(q, v, float))
        qv, qw, w = q[3:6], q[6], v[3:6]
        out[:3] = quaternion_matrix(q[3:7]) @ v[:3]
        out[3:6] = 0.5 * (qw * w + np.cross(qv, w))
        out[6] = -0.5 * (qv @ w)
        out[7:] = v[6:]
        return out

    def random_configuration(self, rng: np.random.Generator, angle: float = np.pi, length: float = 1.0) -> np.ndarray:
        """A random q: joints uniform in ``robot.joint_box(angle, length)``; a floating base uniform in
        [-length, length]^3 with a uniformly random unit quaternion."""
        lo, hi = self.robot.joint_box(angle, length)
        q = rng.uniform(lo, hi)
        if self.floating:
            quat = rng.normal(size=4)
            q[3:7] = quat / np.linalg.norm(quat)
        return q

    def unmoved_coordinates(self, samples: int = 3) -> list[str]:
        """The coordinates (velocity names) that move no mass or inertia: M(q)_ii at most 1e-12 of the largest
        diagonal entry at ``samples`` seeded configurations (np.random.default_rng(0)). M(q) is then singular
        and forward dynamics do not exist; the kinematics and the inverse dynamics do."""
        rng = np.random.default_rng(0)
        diag = np.min([np.diag(self.crba(self.random_configuration(rng))) for _ in range(samples)], axis=0)
        scale = max(float(np.max(np.abs(diag), initial=0.0)), 1e-300)
        return [name for name, d in zip(self.robot.velocity_names, diag) if d <= 1e-12 * scale]

    def neutral(self) -> np.ndarray:
        """q = 0 for the joints; the identity quaternion (0, 0, 0, 1) for a floating base."""
        q = np.zeros(self.nq)
        if self.floating:
            q[6] = 1.0
        return q

    # ------------------------------------------------------------------ kinematics

    def body_q(self, i: int, q) -> np.ndarray:
        """Body i's joint coordinates q_i: q[qdofs[i]], or a q[qdofs[i]] + b for a mimic joint."""
        if self.mimic[i]:
            return self.scale[i] * q[self.qdofs[i]] + self.offset[i]
        return q[self.qdofs[i]]

    def body_rate(self, i: int, v) -> np.ndarray:
        """Body i's joint rates (of qd, qdd): v[dofs[i]], or a v[dofs[i]] for a mimic joint."""
        if self.mimic[i]:
            return self.scale[i] * v[self.dofs[i]]
        return v[self.dofs[i]]

    def joint_pose(self, i: int, qi) -> np.ndarray:
        """Pose of body i in body lambda(i): T_tree_i * T_J(q_i), q_i = body_q(i, q) (see :class:`JointModel`)."""
        return self.tree_pose[i] @ self.joint_model[i].transform(qi)

    def subspace(self, i: int, q) -> np.ndarray:
        """S_i(q_i), 6 x DOF_i, body i's frame: the body's velocity per unit of its OWN joint rate."""
        return self.joint_model[i].subspace(self.body_q(i, q))

    def generalized_subspace(self, i: int, q) -> np.ndarray:
        """d v_i / d v[dofs[i]] (6 x DOF_i, body i's frame): S_i, or a S_i for a mimic joint."""
        s = self.subspace(i, q)
        return self.scale[i] * s if self.mimic[i] else s

    def body_transforms(self, q) -> list[np.ndarray]:
        """X_i = i_X_lambda(i)(q_i), the motion transform from the parent body to body i."""
        return [motion_transform(self.joint_pose(i, self.body_q(i, q))) for i in range(self.nb)]

    def body_poses(self, q) -> list[np.ndarray]:
        """World pose of every body: T_i = T_lambda(i) * T_tree_i * T_J(q_i)."""
        poses: list[np.ndarray] = []
        for i in range(self.nb):
            local = self.joint_pose(i, self.body_q(i, q))
            poses.append(local if self.parent[i] < 0 else poses[self.parent[i]] @ local)
        return poses

    def fk(self, q) -> dict[str, np.ndarray]:
        """World pose (4x4) of every name in ``robot.frame_names``: T = T_body(q) * T_body_frame."""
        poses = self.body_poses(self._q(q))
        return {name: (at.copy() if body < 0 else poses[body] @ at) for name, (body, at) in self.frames.items()}

    def frame_pose(self, q, name: str) -> np.ndarray:
        """World pose (4x4) of one frame."""
        body, at = self._frame(name)
        return at.copy() if body < 0 else self.body_poses(self._q(q))[body] @ at

    def _point_jacobian(self, q, poses, body: int, p) -> np.ndarray:
        """(6, nv) [v; w] of the point p (world) fixed to ``body``, world axes (see :meth:`jacobian`)."""
        jac = np.zeros((6, self.nv), dtype=np.result_type(q, p, float))
        if body < 0:
            return jac
        for j in self.support[body]:  # a mimic joint's column adds to its leader's
            rot, s = poses[j][:3, :3], self.generalized_subspace(j, q)
            w = rot @ s[:3]
            jac[3:, self.dofs[j]] += w
            jac[:3, self.dofs[j]] += rot @ s[3:] + np.cross(w.T, p - poses[j][:3, 3]).T
        return jac

    def jacobian(self, q, name: str) -> np.ndarray:
        """Geometric Jacobian (6, nv), ``[v; w] = J qd``, LOCAL_WORLD_ALIGNED as in Pinocchio.

        v is the velocity of the frame origin p, w the angular velocity, both in world
        axes. The columns of a supporting body j (origin o_j, rotation R_j) are its
        S_j = [s_w; s_v] turned to world axes and moved to p:
        ``[R_j s_v + (R_j s_w) x (p - o_j); R_j s_w]`` (revolute: ``[a x (p - o_j); a]``,
        prismatic: ``[a; 0]``, free flyer: ``[[R, -R (p - o)^]; [0, R]]``, as v is in the root frame);
        other columns are zero. A mimic joint's column, times its multiplier, adds to its leader's.
        """
        q = self._q(q)
        body, at = self._frame(name)
        if body < 0:
            return np.zeros((6, self.nv), dtype=np.result_type(q, float))
        poses = self.body_poses(q)
        return self._point_jacobian(q, poses, body, (poses[body] @ at)[:3, 3])

    # ------------------------------------------------------------------ dynamics

    def _base_acceleration(self, dtype, gravity: bool = True) -> np.ndarray:
        a0 = np.concatenate([np.zeros(3), -self.gravity_vector]) if gravity else np.zeros(6)
        return a0.astype(dtype)

    def _velocities(self, q, qd, xs) -> tuple[list, list, list]:
        """Body velocities v_i = X_i v_lambda + v_J, joint velocities v_J = S_i qd_i and the S_i
        (qd_i = body_rate(i, qd); S_i per unit of the body's own rate)."""
        v, vj, ss = [], [], []
        for i in range(self.nb):
            ss.append(self.subspace(i, q))
            vj.append(ss[i] @ self.body_rate(i, qd))
            v.append(vj[i] if self.parent[i] < 0 else xs[i] @ v[self.parent[i]] + vj[i])
        return v, vj, ss

    def _accelerations(self, q, qd, qdd, xs, v, vj, ss, a0) -> list:
        """Body accelerations a_i = X_i a_lambda + S_i qdd_i + c_J + v_i x S_i qd_i (a_-1 = a0)."""
        a = []
        for i in range(self.nb):
            lam = self.parent[i]
            c_j = self.joint_model[i].bias(self.body_q(i, q), self.body_rate(i, qd))
            a.append(xs[i] @ (a0 if lam < 0 else a[lam]) + ss[i] @ self.body_rate(i, qdd) + c_j + crm(v[i]) @ vj[i])
        return a

    def external_forces(self, q, wrenches: Mapping[str, np.ndarray] | None, poses=None) -> list[np.ndarray]:
        """The body-frame spatial forces [n; f] (at each body origin) of frame wrenches.

        ``wrenches`` maps a frame name (link or named frame) to [force; torque] (6) acting AT
        THE FRAME ORIGIN p, in world axes. On body i (pose R_i, o_i): f = R_i^T force,
        n = R_i^T (torque + (p - o_i) x force). A wrench on a frame fixed to the world
        (fixed base) moves nothing and is dropped.
        """
        q = self._q(q)
        dtype = np.result_type(q, float, *[np.asarray(w) for w in (wrenches or {}).values()])
        out = [np.zeros(6, dtype) for _ in range(self.nb)]
        if not wrenches:
            return out
        poses = self.body_poses(q) if poses is None else poses
        for name, wrench in wrenches.items():
            body, at = self._frame(name)
            wrench = np.asarray(wrench)
            if wrench.shape != (6,):
                raise ValueError(f"robot '{self.robot.name}': the wrench on '{name}' must have 6 entries, got shape {wrench.shape}")
            if body < 0:
                continue
            rot = poses[body][:3, :3]
            arm = rot @ at[:3, 3]  # p - o_i
            force = wrench[:3]
            out[body] = out[body] + np.concatenate([rot.T @ (wrench[3:] + np.cross(arm, force)), rot.T @ force])
        return out

    def rnea(self, q, qd, qdd, wrenches: Mapping[str, np.ndarray] | None = None, smooth: bool = False) -> np.ndarray:
        """Inverse dynamics tau = M(q) qdd + C(q, qd) qd + g(q) - sum_f J_f^T w_f (Featherstone, Table 5.1).

        Forward: v_i = X_i v_lambda + S_i qd_i, a_i = X_i a_lambda + S_i qdd_i + c_J + v_i x S_i qd_i,
        with v_0 = 0 and a_0 = -[0; gravity]. Backward: f_i = I_i a_i + v_i x* I_i v_i - f^ext_i,
        tau_i = S_i^T f_i, f_lambda += X_i^T f_i. A mimic body (qd_i = a qd_J, qdd_i = a qdd_J)
        adds a S_i^T f_i to tau_J (tau = G^T tau_bodies).

        ``wrenches`` (frame name -> [force; torque] at the frame origin, world axes; see
        :meth:`external_forces`) act on the robot; J_f is the LOCAL_WORLD_ALIGNED :meth:`jacobian`.

        Actuators add I_a qdd + :meth:`friction` (Coulomb as sign(qd), or tanh(qd / eps) if ``smooth``).
        """
        q, qd, qdd = self._q(q), self._v(qd, "qd"), self._v(qdd, "qdd")
        dtype = np.result_type(q, qd, qdd, float)
        xs = self.body_transforms(q)
        v, vj, ss = self._velocities(q, qd, xs)
        a = self._accelerations(q, qd, qdd, xs, v, vj, ss, self._base_acceleration(dtype))
        fext = self.external_forces(q, wrenches) if wrenches else None
        f = []
        for i in range(self.nb):
            f.append(self.inertia[i] @ a[i] + crf(v[i]) @ (self.inertia[i] @ v[i]))
            if fext is not None:
                f[i] = f[i] - fext[i]
        tau = np.zeros(self.nv, np.result_type(dtype, *(fext or [])))
        for i in reversed(range(self.nb)):
            tau[self.dofs[i]] += (self.scale[i] * ss[i] if self.mimic[i] else ss[i]).T @ f[i]
            if self.parent[i] >= 0:
                f[self.parent[i]] = f[self.parent[i]] + xs[i].T @ f[i]
        return tau + self.armature * qdd + self.friction(qd, smooth)

    def friction(self, qd, smooth: bool = False) -> np.ndarray:
        """Joint friction G^T (f_v r + f_c sign(r)) with r = G qd each body's own joint rate, or f_c tanh(r / eps)
        if ``smooth`` (what forward dynamics uses): f_v qd + f_c sign(qd) without mimic joints. A mimic
        joint's friction acts on its own rate r = a qd_J and adds a times its force to J's entry."""
        qd = self._v(qd, "qd")
        out = np.zeros(self.nv, dtype=np.result_type(qd, float))
        for i in range(self.nb):
            rate = self.body_rate(i, qd)
            force = self.body_viscous[i] * rate + self.body_coulomb[i] * (
                np.tanh(rate / self.smoothing) if smooth else np.sign(rate))
            out[self.dofs[i]] += self.scale[i] * force
        return out

    def gravity(self, q) -> np.ndarray:
        """Generalized gravity g(q) = rnea(q, 0, 0)."""
        zero = np.zeros(self.nv)
        return self.rnea(q, zero, zero)

    def crba(self, q) -> np.ndarray:
        """Joint-space inertia M(q) by the composite rigid body algorithm (Featherstone, Table 6.2).

        I^c_i = I_i + sum over children j of X_j^T I^c_j X_j; M_ii = S_i^T I^c_i S_i and,
        walking F = I^c_i S_i up the support (F <- X_j^T F), M_ij = M_ji^T = F^T S_j (blocks
        of DOF_i x DOF_j).

        With mimic joints S_i is the generalized subspace (a S_i for a mimic body) and the blocks
        are ADDED into the rows and columns of the bodies' coordinates: that is M = G^T M_bodies G,
        M_bodies being the CRBA of the tree with every body its own coordinate (a body pair
        i != j sharing one coordinate adds both M_ij and M_ji to that coordinate's diagonal).
        """
        q = self._q(q)
        dtype = np.result_type(q, float)
        xs = self.body_transforms(q)
        ss = [self.generalized_subspace(i, q) for i in range(self.nb)]
        ic = [inertia.astype(dtype) for inertia in self.inertia]
        for i in reversed(range(self.nb)):
            if self.parent[i] >= 0:
                ic[self.parent[i]] = ic[self.parent[i]] + xs[i].T @ ic[i] @ xs[i]
        m = np.zeros((self.nv, self.nv), dtype)
        for i in range(self.nb):
            di = self.dofs[i]
            force = ic[i] @ ss[i]
            m[di, di] += ss[i].T @ force
            j = i
            while self.parent[j] >= 0:
                force = xs[j].T @ force
                j = self.parent[j]
                block = force.T @ ss[j]
                m[di, self.dofs[j]] += block
                m[self.dofs[j], di] += block.T
        return m + np.diag(self.armature)  # the actuators' reflected inertia

    mass_matrix = crba

    def aba(self, q, qd, tau, wrenches: Mapping[str, np.ndarray] | None = None) -> np.ndarray:
        """Forward dynamics qdd = M^-1 (tau - C qd - g - friction + sum_f J_f^T w_f) by the articulated body
        algorithm (Featherstone, Table 7.1); the inverse of :meth:`rnea` with the same ``wrenches`` and
        ``smooth=True`` (the Coulomb friction as f_c tanh(qd / eps)); the armature adds to D_i.

        Pass 1: v_i, c_i = c_J + v_i x S_i qd_i, I^A_i = I_i, p^A_i = v_i x* I_i v_i - f^ext_i.
        Pass 2 (leaves to root): U_i = I^A_i S_i, D_i = S_i^T U_i, u_i = tau_i - S_i^T p^A_i;
        I^a_i = I^A_i - U_i D_i^-1 U_i^T, I^A_lambda += X_i^T I^a_i X_i,
        p^A_lambda += X_i^T (p^A_i + I^a_i c_i + U_i D_i^-1 u_i).
        Pass 3: a'_i = X_i a_lambda + c_i, qdd_i = D_i^-1 (u_i - U_i^T a'_i), a_i = a'_i + S_i qdd_i,
        a_0 = -[0; gravity].

        With mimic joints (:attr:`has_mimic`) the recursion does not apply: a coordinate shared by
        two bodies, possibly on different branches, couples subtrees that pass 2 treats as
        independent. Then qdd = M^-1 (tau - rnea(q, qd, 0, wrenches)), with :meth:`crba` and
        :meth:`rnea` (both G^T ... of the bodies), solved by LU (np.linalg.solve).
        """
        if self.has_mimic:
            return self._forward_dynamics_by_solve(q, qd, tau, wrenches)
        q, qd, tau = self._q(q), self._v(qd, "qd"), self._v(tau, "tau")
        tau = tau - self.friction(qd, smooth=True)  # the smooth friction; the armature joins D_i below
        xs = self.body_transforms(q)
        n = self.nb
        fext = self.external_forces(q, wrenches) if wrenches else None
        dtype = np.result_type(q, qd, tau, float, *(fext or []))
        v, vj, ss = self._velocities(q, qd, xs)
        c, ia, pa = [None] * n, [None] * n, [None] * n
        for i in range(n):
            dof = self.dofs[i]
            c[i] = self.joint_model[i].bias(q[self.qdofs[i]], qd[dof]) + crm(v[i]) @ vj[i]
            ia[i] = self.inertia[i].astype(dtype)
            pa[i] = crf(v[i]) @ (self.inertia[i] @ v[i])
            if fext is not None:
                pa[i] = pa[i] - fext[i]
        u_mat, d, u = [None] * n, [None] * n, [None] * n
        for i in reversed(range(n)):
            u_mat[i] = ia[i] @ ss[i]
            d[i] = ss[i].T @ u_mat[i] + np.diag(self.armature[self.dofs[i]])
            u[i] = tau[self.dofs[i]] - ss[i].T @ pa[i]
            lam = self.parent[i]
            if lam >= 0:
                d_inv_ut = np.linalg.solve(d[i], u_mat[i].T)
                i_art = ia[i] - u_mat[i] @ d_inv_ut
                p_art = pa[i] + i_art @ c[i] + u_mat[i] @ np.linalg.solve(d[i], u[i])
                ia[lam] = ia[lam] + xs[i].T @ i_art @ xs[i]
                pa[lam] = pa[lam] + xs[i].T @ p_art
        a = [None] * n
        qdd = np.zeros(self.nv, dtype)
        a0 = self._base_acceleration(dtype)
        for i in range(n):
            lam = self.parent[i]
            a_prime = xs[i] @ (a0 if lam < 0 else a[lam]) + c[i]
            qdd[self.dofs[i]] = np.linalg.solve(d[i], u[i] - u_mat[i].T @ a_prime)
            a[i] = a_prime + ss[i] @ qdd[self.dofs[i]]
        return qdd

    def _forward_dynamics_by_solve(self, q, qd, tau, wrenches=None) -> np.ndarray:
        """qdd = M(q)^-1 (tau - rnea(q, qd, 0, wrenches)): the bias (Coriolis, gravity, wrenches) by
        :meth:`rnea` at qdd = 0, M by :meth:`crba` (what :meth:`aba` does with mimic joints)."""
        q, qd, tau = self._q(q), self._v(qd, "qd"), self._v(tau, "tau")
        bias = self.rnea(q, qd, np.zeros(self.nv), wrenches, smooth=True)
        return np.linalg.solve(self.crba(q), tau - bias)

    # ------------------------------------------------------------------ the inertial-parameter regressor

    def dynamic_parameters(self) -> np.ndarray:
        """pi (10 nb + 3 per joint coordinate): per body [m, h_x, h_y, h_z, I_xx, I_xy, I_yy, I_xz, I_yz, I_zz],
        read off its spatial inertia [[I_o, h^], [h^T, m 1]] about the body origin (h = m c; Pinocchio's
        Inertia.toDynamicParameters), then per joint coordinate (a floating base's six have none) its
        [armature, viscous, coulomb]."""
        pi = []
        for inertia in self.inertia:
            i_o, h_hat = inertia[:3, :3], inertia[:3, 3:]
            pi += [inertia[5, 5], h_hat[2, 1], h_hat[0, 2], h_hat[1, 0],
                   i_o[0, 0], i_o[0, 1], i_o[1, 1], i_o[0, 2], i_o[1, 2], i_o[2, 2]]
        first = 6 if self.floating else 0
        for k in range(first, self.nv):
            pi += [self.armature[k], self.viscous[k], self.coulomb[k]]
        return np.array(pi, dtype=float)

    @staticmethod
    def unit_inertia(k: int) -> np.ndarray:
        """The spatial inertia of the parameter vector e_k (k < 10): I(pi) = sum_k pi_k unit_inertia(k)."""
        e = np.zeros(10)
        e[k] = 1.0
        h_hat = skew(e[1:4])
        i_o = np.array([[e[4], e[5], e[7]], [e[5], e[6], e[8]], [e[7], e[8], e[9]]])
        return np.block([[i_o, h_hat], [h_hat.T, e[0] * np.eye(3)]])

    def regressor(self, q, qd, qdd) -> np.ndarray:
        """Y (nv, len(pi)) with :meth:`rnea` (Coulomb as sign(qd)) = Y @ :meth:`dynamic_parameters`.

        Featherstone's linear form: body i's force I_i a_i + v_i x* I_i v_i is A_i pi_i, the 6 x 10 A_i
        having the column I(e_k) a_i + v_i x* I(e_k) v_i per parameter; A_i is then carried to the root like
        f_i in :meth:`rnea` (A <- X_j^T A), each supporting joint j taking (scale_j S_j)^T A into its rows of
        body i's ten columns (a mimic body's into its leader's). The actuator columns are qdd, qd and
        sign(qd) in their coordinate's row.
        """
        q, qd, qdd = self._q(q), self._v(qd, "qd"), self._v(qdd, "qdd")
        dtype = np.result_type(q, qd, qdd, float)
        xs = self.body_transforms(q)
        v, vj, ss = self._velocities(q, qd, xs)
        a = self._accelerations(q, qd, qdd, xs, v, vj, ss, self._base_acceleration(dtype))
        units = [self.unit_inertia(k) for k in range(10)]
        first = 6 if self.floating else 0
        y = np.zeros((self.nv, 10 * self.nb + 3 * (self.nv - first)), dtype)
        for i in range(self.nb):
            force = np.column_stack([u @ a[i] + crf(v[i]) @ (u @ v[i]) for u in units])
            j = i
            while j >= 0:
                s = self.scale[j] * ss[j] if self.mimic[j] else ss[j]
                y[self.dofs[j], 10 * i:10 * i + 10] += s.T @ force
                force = xs[j].T @ force
                j = self.parent[j]
        for k in range(first, self.nv):
            c = 10 * self.nb + 3 * (k - first)
            y[k, c:c + 3] = qdd[k], qd[k], np.sign(qd[k])
        return y

    # ------------------------------------------------------------------ frame accelerations

    def frame_acceleration(self, q, qd, qdd, name: str) -> np.ndarray:
        """[classical linear acceleration of the frame origin; angular acceleration] (6), world axes,
        without gravity (Pinocchio's getFrameClassicalAcceleration(..., LOCAL_WORLD_ALIGNED)).

        From the body's spatial velocity [w; v_o] and acceleration [dw; a_o] (body frame, a_0 = 0) and
        the frame origin r in the body frame: a_p = a_o + dw x r + w x (v_o + w x r), turned to world axes.
        """
        q, qd, qdd = self._q(q), self._v(qd, "qd"), self._v(qdd, "qdd")
        body, at = self._frame(name)
        dtype = np.result_type(q, qd, qdd, float)
        if body < 0:
            return np.zeros(6, dtype)
        xs = self.body_transforms(q)
        v, vj, ss = self._velocities(q, qd, xs)
        a = self._accelerations(q, qd, qdd, xs, v, vj, ss, self._base_acceleration(dtype, gravity=False))
        rot = self.body_poses(q)[body][:3, :3]
        r = at[:3, 3]
        w, v_o = v[body][:3], v[body][3:]
        dw, a_o = a[body][:3], a[body][3:]
        linear = a_o + np.cross(dw, r) + np.cross(w, v_o + np.cross(w, r))
        return np.concatenate([rot @ linear, rot @ dw])

    def jdot_v(self, q, qd, name: str) -> np.ndarray:
        """The bias Jdot qd of a frame: :meth:`frame_acceleration` at qdd = 0 (6, world axes)."""
        return self.frame_acceleration(q, qd, np.zeros(self.nv), name)

    # ------------------------------------------------------------------ centre of mass and centroidal momentum

    def com(self, q) -> np.ndarray:
        """Centre of mass (3, world) of the links that move: with a fixed base the root link and the
        links fixed to it are world and left out (Pinocchio's data.com[0] excludes the universe); with a
        floating base the root body counts. Mass total: :attr:`total_mass`."""
        if not self.total_mass > 0:
            raise ValueError(f"robot '{self.robot.name}': no moving mass, so no centre of mass")
        poses = self.body_poses(self._q(q))
        weighted = sum(mass * (poses[body][:3, :3] @ com + poses[body][:3, 3]) for body, mass, com in self.masses)
        return weighted / self.total_mass

    def centroidal_map(self, q) -> np.ndarray:
        """A_G (6, nv): h_G = A_G v = [linear momentum; angular momentum about the COM], world axes
        (Pinocchio's computeCentroidalMap; the same bodies as :meth:`com`).

        With world-frame body inertias I0_i = X_i^T I_i X_i (X_i = i_X_0), their composites
        I0c_j over the subtree of j and the world-frame subspaces S0_j = 0_X_j S_j, the momentum
        about the world origin is sum_j I0c_j S0_j v_j (a mimic body: a S0_j in its leader's
        columns); it is then moved to the COM G: n_G = n_0 - G x p.
        """
        q = self._q(q)
        poses = self.body_poses(q)
        dtype = np.result_type(q, float)
        ic = []
        for i in range(self.nb):
            x = motion_transform(poses[i])
            ic.append(x.T @ self.inertia[i] @ x)
        for i in reversed(range(self.nb)):
            if self.parent[i] >= 0:
                ic[self.parent[i]] = ic[self.parent[i]] + ic[i]
        momentum = np.zeros((6, self.nv), dtype)
        for j in range(self.nb):  # a mimic joint's column adds to its leader's
            momentum[:, self.dofs[j]] += ic[j] @ to_world(poses[j], self.generalized_subspace(j, q))
        g = self.com(q)
        angular = momentum[:3] - np.cross(g, momentum[3:].T).T
        return np.concatenate([momentum[3:], angular])

    def centroidal_momentum(self, q, qd) -> np.ndarray:
        """h_G = A_G(q) qd (6): [linear momentum; angular momentum about the COM], world axes."""
        return self.centroidal_map(q) @ self._v(qd, "qd")

    def com_jacobian(self, q) -> np.ndarray:
        """d com / dt = J_com v (3, nv): the linear rows of :meth:`centroidal_map` over the total mass
        (Pinocchio's jacobianCenterOfMass)."""
        return self.centroidal_map(q)[:3] / self.total_mass

    # ------------------------------------------------------------------ Coriolis and energies

    def mass_matrix_partials(self, q) -> np.ndarray:
        """dM/dq (nv, nv, nv), [k] = the derivative of M along the k-th velocity direction,
        Im M(q + i h q_dot(q, e_k)) / h by complex step (h = 1e-30); q real. For a fixed base that is
        dM/dq_k; a floating base's M does not depend on the base pose (its 6 slices are zero)."""
        q = np.asarray(self._q(q), dtype=float)
        return np.array([self.crba(q + 1j * COMPLEX_STEP * self.q_dot(q, e)).imag / COMPLEX_STEP for e in np.eye(self.nv)])

    def coriolis_matrix(self, q, qd) -> np.ndarray:
        """C(q, qd) with C qd the Coriolis and centrifugal torque and Mdot - 2C skew.

        Fixed base: Christoffel, C_ij = sum_k 1/2 (dM_ij/dq_k + dM_ik/dq_j - dM_jk/dq_i) qd_k,
        dM/dq from :meth:`mass_matrix_partials` (complex step, exact to rounding).
        Floating base (v is no time derivative of q, so Christoffel symbols of q do not apply):
        :meth:`coriolis_factorization`.
        """
        if self.floating:
            return self.coriolis_factorization(q, qd)
        dm = self.mass_matrix_partials(q)  # dm[k, i, j] = dM_ij / dq_k
        qd = np.asarray(self._v(qd, "qd"), dtype=float)
        return 0.5 * (np.einsum("kij,k->ij", dm, qd) + np.einsum("jik,k->ij", dm, qd) - np.einsum("ijk,k->ij", dm, qd))

    def coriolis_factorization(self, q, qd) -> np.ndarray:
        """C = sum_i J_i^T (I0_i Jdot_i + B_i J_i) in world-frame spatial terms (Echeandia and Wensing, 2021;
        what Pinocchio's computeCoriolisMatrix computes), for a fixed or floating base.

        J_i (6, nv): body i's world-frame Jacobian, columns S0_j = 0_X_j S_j of its support (a mimic
        body's a S0_j added to its leader's column); Jdot_i: columns v0_j x S0_j + 0_X_j Sdot_j; I0_i: world-frame inertia; v0_i = J_i qd;
        B_i = 1/2 (v0_i x* I0_i - I0_i v0_i x + (I0_i v0_i) x-bar*). Then C qd = rnea(q, qd, 0) - g
        and Mdot - 2C is skew.
        """
        q, qd = self._q(q), self._v(qd, "qd")
        dtype = np.result_type(q, qd, float)
        poses = self.body_poses(q)
        jacs: list[np.ndarray] = []  # J_i: the parent's plus S0_i in body i's columns
        jdots: list[np.ndarray] = []  # Jdot_i likewise
        vel: list[np.ndarray] = []
        for j in range(self.nb):
            lam = self.parent[j]
            s = to_world(poses[j], self.generalized_subspace(j, q))
            v0 = s @ qd[self.dofs[j]] + (vel[lam] if lam >= 0 else 0)
            vel.append(v0)
            sdot = to_world(poses[j], self.joint_model[j].subspace_rate(self.body_q(j, q), self.body_rate(j, qd)))
            if self.mimic[j]:
                sdot = self.scale[j] * sdot
            jac = jacs[lam].copy() if lam >= 0 else np.zeros((6, self.nv), dtype)
            jdot = jdots[lam].copy() if lam >= 0 else np.zeros((6, self.nv), dtype)
            jac[:, self.dofs[j]] += s  # a mimic joint's column adds to its leader's
            jdot[:, self.dofs[j]] += crm(v0) @ s + sdot
            jacs.append(jac)
            jdots.append(jdot)
        c = np.zeros((self.nv, self.nv), dtype)
        for i in range(self.nb):
            x = motion_transform(poses[i])
            inertia = x.T @ self.inertia[i] @ x
            jac, jdot = jacs[i], jdots[i]
            v0 = vel[i]
            b = 0.5 * (crf(v0) @ inertia - inertia @ crm(v0) + crf_bar(inertia @ v0))
            c = c + jac.T @ (inertia @ jdot + b @ jac)
        return c

    def kinetic_energy(self, q, qd):
        """T = 1/2 sum_i v_i^T I_i v_i over the body spatial velocities, plus the rotors' 1/2 I_a qd^2
        (= 1/2 qd^T M qd)."""
        q, qd = self._q(q), self._v(qd, "qd")
        v, _, _ = self._velocities(q, qd, self.body_transforms(q))
        return sum(0.5 * v[i] @ self.inertia[i] @ v[i] for i in range(self.nb)) + 0.5 * np.sum(self.armature * qd * qd)

    def potential_energy(self, q):
        """U = -sum_l m_l gravity . p_com_l over the links that move (world COM positions).

        Zero when every COM is at the world origin. With a fixed base the root link and links
        fixed to it are world and do not count (as in Pinocchio's computePotentialEnergy);
        a floating base's root counts.
        """
        poses = self.body_poses(self._q(q))
        energy = 0
        for body, mass, com in self.masses:
            p = poses[body][:3, :3] @ com + poses[body][:3, 3]
            energy = energy - mass * (self.gravity_vector @ p)
        return energy


def require_forward_dynamics(robot: Robot | NumericRobot, what: str) -> None:
    """A one-line DeriveError if ``robot`` has coordinates that move no mass or inertia
    (:meth:`NumericRobot.unmoved_coordinates`): M(q) is singular at every q, so the forward dynamics and
    the ODE that ``what`` needs do not exist (and `derive generate` left them out)."""
    ref = robot if isinstance(robot, NumericRobot) else NumericRobot(robot)
    names = ref.unmoved_coordinates()
    if names:
        who = f"coordinate {names[0]} moves" if len(names) == 1 else f"coordinates {', '.join(names)} move"
        where = f"{ref.robot.file}: robot '{ref.robot.name}'" if ref.robot.file else f"robot '{ref.robot.name}'"
        raise DeriveError(f"{where}: {what} needs forward dynamics, which do not exist: {who} no mass or inertia, so "
                          "M(q) is singular; give the links they move a mass or inertia")
