"""Forward kinematics and Jacobians of every frame, as CasADi SX expressions.

FK composes, along the tree, each joint's constant origin with its motion
(the lecture's eq. 11: H = H_1 H_2 ... H_n). Geometric Jacobians use the
lecture's eq. 26-27 per joint instead of differentiating FK:
    revolute j:  [a_j x (p - o_j); a_j],   prismatic j: [a_j; 0],
with a_j the joint axis and o_j the joint origin in world coordinates, and p
the frame origin: Pinocchio's LOCAL_WORLD_ALIGNED Jacobian ([linear; angular]).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import casadi as ca

from .model import Robot
from .spatial import axis_angle, homogeneous, rpy
from .symbols import Symbols


@dataclass(frozen=True)
class Pose:
    """World pose of a frame: rotation R (3x3) and origin p (3x1)."""

    R: ca.SX
    p: ca.SX

    @property
    def matrix(self) -> ca.SX:
        return homogeneous(self.R, self.p)


class Kinematics:
    """world_T_<frame> and Jacobians for every link and named frame of a robot."""

    def __init__(self, robot: Robot, sym: Symbols):
        self.robot, self.sym = robot, sym
        index = {j.name: i for i, j in enumerate(robot.moving_joints)}
        poses: dict[str, Pose] = {robot.root: Pose(ca.SX.eye(3), ca.SX.zeros(3, 1))}
        ancestors: dict[str, tuple[str, ...]] = {robot.root: ()}  # moving joints above a link
        self.joint_axis: dict[str, ca.SX] = {}
        self.joint_origin: dict[str, ca.SX] = {}
        for j in robot.joints:
            parent = poses[j.parent]
            R_o = rpy(*(sym.value(v) for v in j.origin.rpy))
            p_o = ca.vertcat(*(sym.value(v) for v in j.origin.xyz))
            R_j = parent.R @ R_o
            p_j = parent.p + parent.R @ p_o
            axis = ca.SX(ca.DM(list(j.axis)))
            if j.type == "fixed":
                poses[j.child] = Pose(R_j, p_j)
                ancestors[j.child] = ancestors[j.parent]
                continue
            qi = sym.q[index[j.name]]
            self.joint_axis[j.name] = R_j @ axis
            self.joint_origin[j.name] = p_j
            if j.type == "revolute":
                poses[j.child] = Pose(R_j @ axis_angle(j.axis, qi), p_j)
            else:  # prismatic
                poses[j.child] = Pose(R_j, p_j + self.joint_axis[j.name] * qi)
            ancestors[j.child] = ancestors[j.parent] + (j.name,)
        for f in robot.frames:
            link = poses[f.link]
            R_o = rpy(*(sym.value(v) for v in f.origin.rpy))
            p_o = ca.vertcat(*(sym.value(v) for v in f.origin.xyz))
            poses[f.name] = Pose(link.R @ R_o, link.p + link.R @ p_o)
            ancestors[f.name] = ancestors[f.link]
        self.poses = poses
        self.ancestors = ancestors
        self.index = index

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
        J = ca.SX.zeros(6, self.sym.nv)
        types = {j.name: j.type for j in self.robot.moving_joints}
        for name in self.ancestors[frame]:
            i, a = self.index[name], self.joint_axis[name]
            if types[name] == "revolute":
                J[0:3, i] = ca.cross(a, pose.p - self.joint_origin[name])
                J[3:6, i] = a
            else:
                J[0:3, i] = a
        return J

    def analytic_jacobian(self, frame: str) -> ca.SX:
        """3 x nv d(position of frame)/dq, the lecture's eq. 22-24."""
        return ca.jacobian(self.pose(frame).p, self.sym.q)

    @cached_property
    def frames(self) -> tuple[str, ...]:
        return tuple(self.poses)
