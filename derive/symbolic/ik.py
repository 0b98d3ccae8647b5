"""The inverse-kinematics problem shared by the solver and the generated code.

The residual is the lecture's pose error in the world frame (section 2.5.2),

    e(q) = [p_target - p(q);  log(R_target R(q)^T)]          (6,)  [m; rad]

with log the SO(3) log map, so that de/dq = -J(q) with J the geometric Jacobian,
LOCAL_WORLD_ALIGNED. A solve succeeds when the weighted position rows are below
TOL_POSITION and the rotation rows below TOL_ROTATION, with q within the limits.
The Levenberg-Marquardt settings are the same in :mod:`derive.solvers.ik` and in
the generated ``<robot>_ik_<frame>``.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from derive.description.robot import Robot
from derive.symbolic.spatial import log_so3

TOL_POSITION = 1e-5   # m
TOL_ROTATION = 1e-4   # rad
LAMBDA0, LAMBDA_MIN, LAMBDA_STALL = 1e-2, 1e-9, 1e5
ATTEMPT = 30          # LM iterations before a restart


def pose_error(T: ca.SX, T_target: ca.SX) -> ca.SX:
    """e = [p_target - p; log(R_target R^T)] (6,), world frame; de/dq = -J for the world-aligned Jacobian."""
    R, p = T[:3, :3], T[:3, 3]
    return ca.vertcat(T_target[:3, 3] - p, log_so3(T_target[:3, :3] @ R.T))


def joint_ranges(robot: Robot) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(lower, upper) limits per entry of q (+-inf where missing) and the box restarts draw
    from: the limits, or [-pi, pi] rad / [-1, 1] m where one is missing."""
    lo, hi = robot.joint_box(np.inf, np.inf)
    slo, shi = robot.joint_box()
    return np.array(lo), np.array(hi), np.array(slo), np.array(shi)
