"""Forward kinematics and Jacobians of every frame, as CasADi SX expressions.

FK composes, along the tree, each joint's constant origin with its motion
(the lecture's eq. 11: H = H_1 H_2 ... H_n). A joint of several DOF moves as
a chain of 1-DOF elementary motions, one per coordinate (:func:`joint_motions`:
cylindrical = turn, slide; universal = turn, turn; spherical ZYX = turns about
z, y, x), as if massless bodies sat between them. Geometric Jacobians use the
lecture's eq. 26-27 per coordinate instead of differentiating FK:
    revolute j:  [a_j x (p - o_j); a_j],   prismatic j: [a_j; 0],
    helical j (pitch h_j):  [a_j x (p - o_j) + h_j a_j; a_j],
with a_j the motion's axis and o_j its origin in world coordinates, and p
the frame origin: Pinocchio's LOCAL_WORLD_ALIGNED Jacobian ([linear; angular]).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import casadi as ca

from derive.description.joints import motion_type
from derive.description.robot import Joint, Robot, Value
from derive.symbolic.spatial import axis_angle, homogeneous, rpy, skew
from derive.symbolic.symbols import Symbols


@dataclass(frozen=True)
class Motion:
    """One elementary 1-DOF motion, for coordinate ``coordinate``, of the frame it starts from.

    revolute: turn by q about ``axis``; prismatic: slide by q along it; helical:
    both, the slide being ``pitch`` * q. ``axis`` is a unit vector of the starting
    frame (which a turn about it leaves unchanged).
    """

    coordinate: str
    kind: str  # revolute | prismatic | helical
    axis: tuple
    pitch: Value | None = None
    mimic: str | None = None  # the mimic joint making this motion: it moves by scale * q + offset
    scale: float = 1.0
    offset: float = 0.0

    @property
    def key(self) -> str:
        """Unique per motion: the coordinate, or ``mimic:<joint>`` for a mimic joint's motion."""
        return self.coordinate if self.mimic is None else f"mimic:{self.mimic}"

    def value(self, q: ca.SX) -> ca.SX:
        """The motion's angle or length for the coordinate's value ``q``."""
        return q if self.mimic is None else self.scale * q + self.offset


_X, _Y, _Z = (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)


def joint_motions(joint: Joint) -> tuple[Motion, ...]:
    """The joint's motion as elementary motions in q order: the joint transform is their product.

    revolute and continuous: Rot(axis, q);
    cylindrical: Rot(axis, q_rot) Trans(axis q_trans); universal: Rot(axis, q_1) Rot(axis2, q_2);
    spherical: Rz(q_z) Ry(q_y) Rx(q_x) (ZYX Euler angles); fixed: none.
    """
    kind = motion_type(joint.type)  # a continuous joint turns as a revolute one
    if joint.mimic is not None:
        return (Motion(joint.mimic.joint, kind, joint.axis, joint.pitch, joint.name, joint.mimic.multiplier,
                       joint.mimic.offset),)
    names = [c.name for c in joint.coordinates]
    if kind in ("revolute", "prismatic", "helical"):
        return (Motion(names[0], kind, joint.axis, joint.pitch),)
    kinds = {"cylindrical": (("revolute", joint.axis), ("prismatic", joint.axis)),
             "universal": (("revolute", joint.axis), ("revolute", joint.axis2)),
             "spherical": (("revolute", _Z), ("revolute", _Y), ("revolute", _X))}.get(joint.type, ())
    return tuple(Motion(n, kind, axis) for n, (kind, axis) in zip(names, kinds))


@dataclass(frozen=True)
class Pose:
    """World pose of a frame: rotation R (3x3) and origin p (3x1)."""

    R: ca.SX
    p: ca.SX

    @property
    def matrix(self) -> ca.SX:
        return homogeneous(self.R, self.p)


def quaternion_matrix(x, y, z, w) -> ca.SX:
    """The rotation of a unit quaternion (x, y, z, w), written as Eigen's ``toRotationMatrix``
    (and Pinocchio's free-flyer) writes it; the same expression off the unit sphere."""
    return ca.SX(ca.blockcat([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]))


def configuration_rate(robot: Robot, sym: Symbols, v: ca.SX | None = None) -> ca.SX:
    """dq/dt (nq) for the velocity ``v`` (default ``sym.qd``): v itself for a fixed base; with a
    floating base, R v_lin for the position and 1/2 quat (x) (w, 0) for the quaternion
    (x, y, z, w): vector part 1/2 (q_w w + q_v x w), scalar part -1/2 q_v . w."""
    v = sym.qd if v is None else v
    if not robot.floating:
        return v
    q = sym.q
    qv, qw = q[3:6], q[6]
    R = quaternion_matrix(q[3], q[4], q[5], q[6])
    w = v[3:6]
    return ca.vertcat(R @ v[0:3], 0.5 * (qw * w + ca.cross(qv, w)), -0.5 * ca.dot(qv, w), v[6:])


BASE = "base"  # the key of a floating base in Kinematics.ancestors lists (its 6 velocity columns)


class Kinematics:
    """world_T_<frame> and Jacobians for every link and named frame of a robot.

    With a floating base the root link sits at q[0:3] with the rotation of the quaternion
    q[3:7] (:func:`quaternion_matrix`), and every frame's Jacobian has the base's 6 columns:
    [R, -[p - p_b]x R; 0, R] for the base velocity [v; w] given in the root frame.
    """

    def __init__(self, robot: Robot, sym: Symbols):
        self.robot, self.sym = robot, sym
        index = {c.name: i for i, c in enumerate(robot.coordinates)}
        self.vindex = {n: i for i, n in enumerate(robot.velocity_names)}  # coordinate -> column of J, entry of v
        if robot.floating:
            q = sym.q
            root = Pose(quaternion_matrix(q[3], q[4], q[5], q[6]), q[0:3])
        else:
            root = Pose(ca.SX.eye(3), ca.SX.zeros(3, 1))
        poses: dict[str, Pose] = {robot.root: root}
        ancestors: dict[str, tuple[str, ...]] = {robot.root: (BASE,) if robot.floating else ()}  # what moves a link
        self.motions: dict[str, Motion] = {}
        self.joint_axis: dict[str, ca.SX] = {}  # per coordinate: world axis a_j and origin o_j
        self.joint_origin: dict[str, ca.SX] = {}
        for j in robot.joints:
            parent = poses[j.parent]
            R_o = rpy(*(sym.value(v) for v in j.origin.rpy))
            p_o = ca.vertcat(*(sym.value(v) for v in j.origin.xyz))
            R_j = parent.R @ R_o
            p_j = parent.p + parent.R @ p_o
            motions = joint_motions(j)
            for m in motions:
                qi = m.value(sym.q[index[m.coordinate]])
                a = self.joint_axis[m.key] = R_j @ ca.SX(ca.DM(list(m.axis)))
                self.joint_origin[m.key] = p_j
                self.motions[m.key] = m
                if m.kind == "prismatic":
                    p_j = p_j + a * qi
                else:
                    R_j = R_j @ axis_angle(m.axis, qi)
                if m.kind == "helical":
                    p_j = p_j + a * (sym.value(m.pitch) * qi)
            poses[j.child] = Pose(R_j, p_j)
            ancestors[j.child] = ancestors[j.parent] + tuple(m.key for m in motions)
        for f in robot.frames:
            link = poses[f.link]
            R_o = rpy(*(sym.value(v) for v in f.origin.rpy))
            p_o = ca.vertcat(*(sym.value(v) for v in f.origin.xyz))
            poses[f.name] = Pose(link.R @ R_o, link.p + link.R @ p_o)
            ancestors[f.name] = ancestors[f.link]
        for alias, name in robot.frame_aliases.items():  # the same pose under another name (the URDF's own)
            poses[alias], ancestors[alias] = poses[name], ancestors[name]
        self.poses = poses
        self.ancestors = ancestors
        self.index = index
        self.mimicked = {j.mimic.joint for j in robot.joints if j.mimic is not None}  # columns summing motions

    def pose(self, frame: str) -> Pose:
        if frame not in self.poses:
            raise KeyError(f"robot '{self.robot.name}' has no frame '{frame}' (frames: {', '.join(self.poses)})")
        return self.poses[frame]

    def fk(self, frame: str) -> ca.SX:
        """world_T_frame, the 4x4 homogeneous transform of ``frame`` (eq. 4, 11)."""
        return self.pose(frame).matrix

    def jacobian(self, frame: str) -> ca.SX:
        """6 x nv geometric Jacobian [linear; angular] of ``frame``, LOCAL_WORLD_ALIGNED (eq. 26-27)."""
        pose = self.pose(frame)
        return self.point_jacobian(frame, pose.p)

    def point_jacobian(self, frame: str, point: ca.SX) -> ca.SX:
        """6 x nv Jacobian [linear; angular] of a point (world coordinates) moving with ``frame``."""
        J = ca.SX.zeros(6, self.sym.nv)
        for name in self.ancestors[frame]:
            if name == BASE:
                R = self.poses[self.robot.root].R
                J[0:3, 0:3] = R
                J[0:3, 3:6] = -skew(point - self.poses[self.robot.root].p) @ R
                J[3:6, 3:6] = R
                continue
            m, a = self.motions[name], self.joint_axis[name]
            i = self.vindex[m.coordinate]
            if m.kind == "prismatic":
                column = ca.vertcat(a, ca.SX.zeros(3, 1))
            else:
                linear = ca.cross(a, point - self.joint_origin[name])
                if m.kind == "helical":
                    linear += self.sym.value(m.pitch) * a
                column = ca.vertcat(linear, a)
            if m.coordinate in self.mimicked:  # d(motion)/dq = scale: the coordinate's motions add up
                J[:, i] += m.scale * column
            elif m.kind == "prismatic":
                J[0:3, i] = a
            else:
                J[0:3, i] = column[0:3]
                J[3:6, i] = a
        return J

    def moving_rows(self, frame: str) -> tuple[int, ...]:
        """Rows of ``frame``'s Jacobian that are not identically zero for every q (structurally, in SX):
        a planar arm's z and roll/pitch rows are dropped."""
        J = self.jacobian(frame)
        return tuple(i for i in range(6) if not all(ca.SX(J[i, c]).is_zero() for c in range(J.shape[1])))

    def analytic_jacobian(self, frame: str) -> ca.SX:
        """3 x nv d(position of frame)/dq, the lecture's eq. 22-24."""
        return ca.jacobian(self.pose(frame).p, self.sym.q)

    @cached_property
    def frames(self) -> tuple[str, ...]:
        return tuple(self.poses)
