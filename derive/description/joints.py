"""The joint-type registry: every joint type derive models, its degrees of freedom and coordinates.

A new joint type is one entry in :data:`JOINT_TYPES` (and, if it has several coordinates,
:data:`COORDINATE_SUFFIXES`), its motion in :func:`derive.symbolic.kinematics.joint_motions`,
and the same motion in the independent reference (:mod:`derive.reference.rnea`); a type that
moves as another one (continuous = revolute) is one entry in :data:`MOVES_AS` instead.
"""

from __future__ import annotations

import math

import numpy as np

JOINT_TYPES = {"revolute": 1, "continuous": 1, "prismatic": 1, "helical": 1, "cylindrical": 2, "universal": 2,
               "spherical": 3, "fixed": 0}
"""Joint type -> degrees of freedom (the lecture's Table 1; a rigid body has 6, so constraints = 6 - DOF).

- revolute: angle q about ``axis``; prismatic: length q along ``axis``;
- continuous: a revolute joint without position limits (URDF's ``continuous``): q and q + 2 pi
  are the same configuration, and what derive reports of q (IK, simulate, trajopt) is wrapped
  to (-pi, pi] (:func:`wrap_angle`);
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

MOVES_AS = {"continuous": "revolute"}
"""Joint type -> the type whose motion it has (all that differs is what its position means)."""


def motion_type(jtype: str) -> str:
    """The joint type whose motion (transform, motion subspace) ``jtype`` has: revolute for continuous."""
    return MOVES_AS.get(jtype, jtype)


def wrap_angle(a):
    """a (rad, a float or an array) wrapped to (-pi, pi], with pi the double nearest it: the same turn.

    fmod is exact, and so is the one shift by 2 pi after it (Sterbenz's lemma: the operands are
    within a factor 2), so the result is a - 2 pi k exactly rounded to the nearest double; the
    generated C (ik.c.jinja) computes the same bits.
    """
    r = np.fmod(a, 2.0 * math.pi)
    return np.where(r > math.pi, r - 2.0 * math.pi, np.where(r <= -math.pi, r + 2.0 * math.pi, r))
