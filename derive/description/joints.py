"""The joint-type registry: every joint type derive models, its degrees of freedom and coordinates.

A new joint type is one entry in :data:`JOINT_TYPES` (and, if it has several coordinates,
:data:`COORDINATE_SUFFIXES`), its motion in :func:`derive.symbolic.kinematics.joint_motions`,
and the same motion in the independent reference (:mod:`derive.reference.rnea`).
"""

from __future__ import annotations

JOINT_TYPES = {"revolute": 1, "prismatic": 1, "helical": 1, "cylindrical": 2, "universal": 2, "spherical": 3,
               "fixed": 0}
"""Joint type -> degrees of freedom (the lecture's Table 1; a rigid body has 6, so constraints = 6 - DOF).

- revolute: angle q about ``axis``; prismatic: length q along ``axis``;
- helical: angle q about ``axis`` and length ``pitch`` * q along it (pitch in m/rad,
  negative for a left-handed screw);
- cylindrical: angle ``<joint>_rot`` about ``axis``, then length ``<joint>_trans`` along it;
- universal: angle ``<joint>_1`` about ``axis``, then ``<joint>_2`` about ``axis2``
  (perpendicular to ``axis``, given in the joint frame, carried along by the first turn):
  R = Rot(axis, q1) Rot(axis2, q2);
- spherical: ZYX Euler angles of the joint frame, R = Rz(<joint>_z) Ry(<joint>_y) Rx(<joint>_x);
  gimbal lock at cos(<joint>_y) = 0 (see :attr:`Joint.gimbal_lock`).
"""

COORDINATE_SUFFIXES = {"cylindrical": ("rot", "trans"), "universal": ("1", "2"), "spherical": ("z", "y", "x")}
"""Multi-DOF joint type -> suffixes of its coordinates' names ``<joint>_<suffix>``, in q order."""
