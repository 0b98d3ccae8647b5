"""Loop closures checked when a model is read: phi(q) = 0 at the reference, the rank of K, the chart.

phi(q) stacks the residuals of the robot's loops (:class:`derive.description.robot.Loop`) and
K = dphi/dq (rows x nq). The closed chain's coordinates are the tree's q = (y, z): y independent,
z dependent, the closure z = gamma(y) solving phi(y, z) = 0; K_z (K's z columns, restricted to the kept
rows) must be invertible there (a chart).

This module evaluates the poses with its own small numpy forward kinematics (the description stage
imports neither the symbolic side nor the reference); every operation is complex-safe, so
K e_k = Im phi(q + i h e_k) / h exactly (complex step, h = 1e-30). The symbolic side
(:mod:`derive.symbolic.closure`) and the numeric reference (:mod:`derive.reference.closure`) compute
the same phi independently; the tests compare all three.

How the model is closed and its chart chosen (:func:`close`):
1. q0 = models.yaml's ``reference`` (coordinates not named start at 0).
2. rank r of K from its singular values (relative tolerance :data:`RANK_TOL`) after a Gauss-Newton
   solve of phi = 0 over all of q from q0 (minimum-norm steps): only to choose the chart.
3. Without ``independent``: z = r columns of K picked greedily by largest pivot (Gram-Schmidt with
   column pivoting), an actuated coordinate (one with an ``actuator`` or an ``effort`` limit) weighted
   down 1000-fold so it stays independent where it can; equal pivots go to the later coordinate.
4. The kept rows: r rows of K_z picked the same way (over-constrained loops such as a hinge on a planar
   four-bar give redundant rows).
5. y held at q0, z solved by Newton on the kept rows from q0: the reference configuration. Every row
   of phi must then be <= :data:`CLOSED_TOL` (else the loops cannot close there, or are inconsistent).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from derive.description import expr
from derive.description.joints import motion_type
from derive.description.robot import Loop, Robot

RANK_TOL = 1e-9
"""A singular value of K below this times the largest counts as zero."""
CHART_TOL = 1e-8
"""K_z is a chart where its smallest singular value is above this times its largest."""
CLOSED_TOL = 1e-10
"""Largest |phi_i| (m, or the sine of an angle) of a closed configuration."""
NEWTON_STEPS = 50
COMPLEX_STEP = 1e-30


# --------------------------------------------------------------------------- poses (complex-safe)


def _rotation(axis, angle) -> np.ndarray:
    a = np.asarray(axis, dtype=float)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * (k @ k)


def _rpy(r, p, y) -> np.ndarray:
    return _rotation((0, 0, 1), y) @ _rotation((0, 1, 0), p) @ _rotation((1, 0, 0), r)


class Poses:
    """World poses (R, p) of every link and named frame of a fixed-base robot at q (numbers, complex-safe)."""

    def __init__(self, robot: Robot, params: dict | None = None):
        self.robot = robot
        self.env = dict(robot.parameter_defaults) | dict(params or {})
        self.index = {c.name: i for i, c in enumerate(robot.coordinates)}
        # the constant parts, evaluated once: each joint's and frame's origin, a helical joint's pitch
        self.joint_origins = [self._origin(j.origin) for j in robot.joints]
        self.frame_origins = [self._origin(f.origin) for f in robot.frames]
        self.pitch = {j.name: self.num(j.pitch) for j in robot.joints if j.pitch is not None}

    def num(self, v) -> float:
        return float(expr.evaluate(v, self.env))

    def _origin(self, origin) -> tuple[np.ndarray, np.ndarray]:
        return _rpy(*(self.num(x) for x in origin.rpy)), np.array([self.num(x) for x in origin.xyz])

    def _motion(self, joint, q) -> tuple[np.ndarray, np.ndarray]:
        """The joint's own motion (R, p) in its joint frame."""
        kind = motion_type(joint.type)
        if joint.mimic is not None:
            values = [joint.mimic.multiplier * q[self.index[joint.mimic.joint]] + joint.mimic.offset]
        else:
            values = [q[self.index[c.name]] for c in joint.coordinates]
        axis = np.asarray(joint.axis, dtype=float)
        zero = np.zeros(3)
        if kind == "revolute":
            return _rotation(axis, values[0]), zero
        if kind == "prismatic":
            return np.eye(3), axis * values[0]
        if kind == "helical":
            return _rotation(axis, values[0]), axis * (self.pitch[joint.name] * values[0])
        if kind == "cylindrical":
            return _rotation(axis, values[0]), axis * values[1]
        if kind == "universal":
            return _rotation(axis, values[0]) @ _rotation(joint.axis2, values[1]), zero
        if kind == "spherical":
            return _rotation((0, 0, 1), values[0]) @ _rotation((0, 1, 0), values[1]) @ _rotation((1, 0, 0), values[2]), zero
        return np.eye(3), zero  # fixed

    def __call__(self, q) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        robot = self.robot
        out = {robot.root: (np.eye(3), np.zeros(3))}
        for joint, (Ro, po) in zip(robot.joints, self.joint_origins):
            R, p = out[joint.parent]
            Rm, pm = self._motion(joint, q)
            R_joint, p_joint = R @ Ro, R @ po + p
            out[joint.child] = (R_joint @ Rm, R_joint @ pm + p_joint)
        for frame, (Ro, po) in zip(robot.frames, self.frame_origins):
            R, p = out[frame.link]
            out[frame.name] = (R @ Ro, R @ po + p)
            for alias in frame.aliases:
                out[alias] = out[frame.name]
        return out


def loop_residual(loop: Loop, pa: tuple, pb: tuple, length: float | None = None):
    """phi of one loop from the poses (R_a, p_a), (R_b, p_b) (the equations of :class:`Loop`)."""
    (Ra, a), (Rb, b) = pa, pb
    d = a - b
    ex, ey, ez = np.eye(3)
    if loop.kind == "point":
        return d
    if loop.kind == "distance":
        return np.array([(d @ d - length * length) / (2 * length)])
    if loop.kind == "weld":
        return np.concatenate([d, [(Ra @ ey) @ (Rb @ ez), (Ra @ ez) @ (Rb @ ex), (Ra @ ex) @ (Rb @ ey)]])
    n = np.asarray(loop.axis, dtype=float)
    u, v = (np.asarray(x) for x in loop.basis)
    if loop.kind == "hinge":
        return np.concatenate([d, [(Ra @ u) @ (Rb @ n), (Ra @ v) @ (Rb @ n)]])
    rows = [(Ra @ u) @ d, (Ra @ v) @ d] + ([(Ra @ u) @ (Rb @ v)] if loop.rotation else [])
    return np.array(rows)


def loop_flipped(loop: Loop, pa: tuple, pb: tuple) -> bool:
    """The orientation rows vanish but the frames are turned half a turn against each other."""
    (Ra, _), (Rb, _) = pa, pb
    if loop.kind == "hinge":
        n = np.asarray(loop.axis, dtype=float)
        return float(np.real((Ra @ n) @ (Rb @ n))) < 0
    if loop.kind == "weld":
        return float(np.real(np.trace(Ra.T @ Rb))) < 1.5  # 1 + 2 cos(angle): 3 when equal, <= -1 for half a turn
    if loop.kind == "planar" and loop.rotation:
        u = np.asarray(loop.basis[0])
        return float(np.real((Ra @ u) @ (Rb @ u))) < 0
    return False


# --------------------------------------------------------------------------- phi, K, Newton


class Closure:
    """phi(q) and K(q) of a robot's loops, numerically (the description's own check)."""

    def __init__(self, robot: Robot, params: dict | None = None):
        self.robot = robot
        self.poses = Poses(robot, params)
        self.lengths = [None if lp.length is None else self.poses.num(lp.length) for lp in robot.loops]
        self.nq = robot.nq

    def loop_rows(self) -> list[slice]:
        out, start = [], 0
        for lp in self.robot.loops:
            out.append(slice(start, start + lp.rows))
            start += lp.rows
        return out

    def phi(self, q) -> np.ndarray:
        poses = self.poses(q)
        return np.concatenate([loop_residual(lp, poses[lp.a], poses[lp.b], length)
                               for lp, length in zip(self.robot.loops, self.lengths)])

    def jacobian(self, q) -> np.ndarray:
        """K = dphi/dq by complex step (exact to rounding)."""
        q = np.asarray(q, dtype=float)
        cols = [self.phi(q + 1j * COMPLEX_STEP * e).imag / COMPLEX_STEP for e in np.eye(self.nq)]
        return np.array(cols).T

    def flipped(self, q) -> list[int]:
        poses = self.poses(q)
        return [i for i, lp in enumerate(self.robot.loops) if loop_flipped(lp, poses[lp.a], poses[lp.b])]

    def gauss_newton(self, q0, free: list[int], rows: list[int] | None = None) -> np.ndarray:
        """phi = 0 by Newton steps on q[free] (minimum-norm least squares on ``rows`` of phi)."""
        q = np.array(q0, dtype=float)
        rows = list(range(sum(lp.rows for lp in self.robot.loops))) if rows is None else rows
        for _ in range(NEWTON_STEPS):
            r = self.phi(q)[rows]
            if np.max(np.abs(r), initial=0.0) <= 1e-14:
                break
            step = np.linalg.lstsq(self.jacobian(q)[np.ix_(rows, free)], r, rcond=None)[0]
            q[free] -= step
            if np.max(np.abs(step)) <= 1e-15:
                break
        return q


def rank(K: np.ndarray) -> int:
    """Numerical rank: singular values above RANK_TOL times the largest."""
    if K.size == 0:
        return 0
    s = np.linalg.svd(K, compute_uv=False)
    return int(np.sum(s > RANK_TOL * max(s[0], 1e-300)))


def pivot_columns(A: np.ndarray, count: int, weight: np.ndarray | None = None) -> list[int]:
    """``count`` columns of A by Gram-Schmidt with column pivoting: each time the column whose part outside
    the span of those chosen is longest (times ``weight``); within 1e-9 of the longest, the later column."""
    A = np.array(A, dtype=float)
    weight = np.ones(A.shape[1]) if weight is None else weight
    chosen: list[int] = []
    for _ in range(count):
        norms = np.linalg.norm(A, axis=0) * weight
        norms[chosen] = -1.0
        best = float(np.max(norms))
        k = max(i for i in range(A.shape[1]) if norms[i] >= best * (1 - 1e-9))
        chosen.append(k)
        length = np.linalg.norm(A[:, k])
        if length > 0:  # a zero column (A's rank below count) takes nothing out of the others
            unit = A[:, k] / length
            A = A - np.outer(unit, unit @ A)
    return sorted(chosen)


def actuated(robot: Robot) -> list[bool]:
    """Per coordinate: its joint has an ``actuator`` mapping or an ``effort`` limit."""
    joints = {j.name: j for j in robot.joints}
    return [joints[c.joint].actuator is not None or c.limits.effort is not None for c in robot.coordinates]


@dataclass(frozen=True)
class Closed:
    """What :func:`close` finds: the chart, the kept rows and the closed reference configuration."""

    independent: tuple[str, ...]
    chosen: bool  # y chosen by pivoting
    rows: tuple[int, ...]  # kept rows of phi
    rank: int
    q: tuple[float, ...]  # closed reference configuration
    residual: float  # max |phi_i| there
    chart_sigma: float  # smallest singular value of K_z (kept rows) over its largest
    redundant: int | None  # a loop adding no rank to the others, if any
    flipped: tuple[int, ...]  # loops closed half a turn wrong


def close(robot: Robot, independent: tuple[str, ...] | None, reference: dict[str, float]) -> Closed:
    """Close the robot's loops from its reference values and choose the chart (module docstring)."""
    cl = Closure(robot)
    names = [c.name for c in robot.coordinates]
    q0 = np.array([float(reference.get(n, 0.0)) for n in names])
    n = len(names)
    q1 = cl.gauss_newton(q0, list(range(n)))
    K1 = cl.jacobian(q1)
    r = rank(K1)
    if independent is None:
        weight = np.where(actuated(robot), 1e-3, 1.0)
        z = pivot_columns(K1, r, weight)
        y_names = tuple(names[i] for i in range(n) if i not in z)
        chosen = True
    else:
        y_names = tuple(nm for nm in names if nm in independent)
        z = [i for i in range(n) if names[i] not in independent]
        chosen = False
    z_ok = len(z) == r
    rows = pivot_columns(K1[:, z].T, min(r, len(z))) if z else []
    q = cl.gauss_newton(q0, z, rows) if z_ok and z else q1
    K = cl.jacobian(q)
    phi = cl.phi(q)
    sigma = 0.0
    if z_ok and z:
        s = np.linalg.svd(K[np.ix_(rows, z)], compute_uv=False)
        sigma = float(s[-1] / max(s[0], 1e-300))
    redundant = None
    slices = cl.loop_rows()
    full = rank(K)
    for i, sl in enumerate(slices):
        others = np.delete(K, np.arange(sl.start, sl.stop), axis=0)
        if rank(others) == full:
            redundant = i
            break
    return Closed(y_names, chosen, tuple(rows), r, tuple(float(x) for x in q), float(np.max(np.abs(phi))), sigma,
                  redundant, tuple(cl.flipped(q)))


def reference_configuration(robot: Robot) -> np.ndarray:
    """The closed reference configuration q (nq) of a robot with loops (stored when it was read)."""
    return np.array(robot.reference_q, dtype=float)


def closure_note(robot: Robot) -> str:
    """One line: how many loop rows, the rank, the independent coordinates and how they were chosen."""
    y = ", ".join(robot.independent or ())
    how = ("chosen by pivoting on K at the reference configuration (largest pivots dependent, actuated "
           "coordinates kept independent where possible)" if robot.independent_chosen else "given in the model")
    rows = sum(lp.rows for lp in robot.loops)
    kept = len(robot.loop_rows or ())
    return (f"{len(robot.loops)} loop(s), {rows} closure rows, rank {kept}"
            + (f" ({rows - kept} redundant)" if kept < rows else "")
            + f"; independent y = ({y}) {how}; dependent z = ({', '.join(robot.dependent)})"
            + (f"; motor <-> joint maps to outputs ({', '.join(robot.outputs)})" if robot.outputs else ""))
