"""Manipulability ellipsoids and measures (lecture section 4.3, eq. 30, figure 9).

The ellipsoid {J_t qd : |qd| <= 1} of the task Jacobian J_t (k x nv, rows as in
:mod:`derive.analysis.singularity`: the position rows with motion by default, so the
planar 2R arm has the 2 x 2 J of eq. 24) has the eigenvectors of J_t J_t^T as
axes and the square roots of its eigenvalues l_i, i.e. the singular values s_i
of J_t, as semi-axes. The measures of eq. 30:

    mu1 = sqrt(l_max / l_min) = s_max / s_min      condition number: 1 isotropic, -> inf at a singularity
    mu2 = l_max / l_min = mu1^2
    mu3 = sqrt(det(J_t J_t^T)) = s_1 s_2 ... s_k   Yoshikawa's measure, ellipsoid volume / unit ball's

The lecture writes mu3 = sqrt(l_max l_min) for its 2 x 2 J J^T; for k > 2 we use
all eigenvalues, sqrt(l_1 ... l_k) (Yoshikawa), which equals the lecture's for
k = 2. At a singularity l_min = 0: mu1 = mu2 = inf and mu3 = 0. When nv < k
(a 1-DOF pendulum's 2-D position task) that holds at every q.

Position and orientation ellipsoids come from rows 0-2 and 3-5 (with motion).

Generated code: ``<robot>_manipulability_<frame>(q[, p], mu)``, mu = [mu1, mu2, mu3]
for the default position task, for every named frame whose task can be spanned
(nv >= k). It calls ``<robot>_jacobian_<frame>`` and takes the singular values
by one-sided Jacobi rotations of the k rows (C: no malloc, only math.h; high
relative accuracy of small singular values), numpy's SVD in Python. Both algorithms are
the fixed support files templates/c/support/derive_manipulability.h (with derive_linalg.h)
and templates/python/support/manipulability.py; the templates only pass the rows.

The figure of ellipses and mu3 is :func:`derive.plot.manipulability.plot_manipulability`.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations

import casadi as ca
import numpy as np
import sympy as sp

from derive.analysis.singularity import TaskJacobian
from derive.analysis.workspace import joint_box
from derive.description.robot import Robot
from derive.errors import DeriveError


def _singular_values(J: np.ndarray) -> np.ndarray:
    """The k singular values of a (..., k, nv) stack, descending; zeros appended when nv < k."""
    J = np.asarray(J, dtype=float)
    s = np.linalg.svd(J, compute_uv=False)
    k = J.shape[-2]
    if s.shape[-1] < k:
        s = np.concatenate([s, np.zeros(s.shape[:-1] + (k - s.shape[-1],))], axis=-1)
    return s


def measures(J) -> np.ndarray:
    """[mu1, mu2, mu3] of eq. 30 (module docstring) for a k x nv J, or (..., 3) for a stack.

    Singular values at or below the rank tolerance of :func:`derive.analysis.singularity.analyse`
    (max(k, nv) eps s_max) count as 0, so a numerically singular J gives mu1 = inf, mu3 = 0.
    """
    J = np.asarray(J, dtype=float)
    s = _singular_values(J)
    s = np.where(s <= max(J.shape[-2:]) * np.finfo(float).eps * s[..., :1], 0.0, s)
    with np.errstate(divide="ignore", invalid="ignore"):
        mu1 = np.where(s[..., -1] > 0, s[..., 0] / np.where(s[..., -1] > 0, s[..., -1], 1.0), np.inf)
    return np.stack([mu1, mu1 * mu1, np.prod(s, axis=-1)], axis=-1)


def ellipsoid(J) -> tuple[np.ndarray, np.ndarray]:
    """(semi-axes sqrt(l_i) descending, axes as the columns of a k x k matrix): eigen-pairs of J J^T."""
    J = np.atleast_2d(np.asarray(J, dtype=float))
    U, _, _ = np.linalg.svd(J)
    return _singular_values(J), U


@dataclass
class ManipulabilityInfo:
    q: np.ndarray
    rows: str  # task rows, e.g. "x,y"
    mu: np.ndarray  # [mu1, mu2, mu3]
    semi_axes: np.ndarray
    axes: np.ndarray  # columns
    parts: dict  # "position" / "orientation" -> (rows, semi-axes, axes)


class Manipulability:
    """Measures and ellipsoids of one frame for a task (default: position rows with motion)."""

    def __init__(self, robot: Robot, frame: str = "tcp", task: str = "position"):
        self.robot, self.frame = robot, frame
        self.tj = TaskJacobian(robot, frame, task)
        self.parts = {}
        for part in ("position", "orientation"):
            try:
                self.parts[part] = self.tj if task == part else TaskJacobian(robot, frame, part)
            except DeriveError:  # e.g. a prismatic-only robot has no orientation part
                pass

    def at(self, q) -> ManipulabilityInfo:
        J = self.tj(q)
        semi, axes = ellipsoid(J)
        parts = {name: (tj.row_names, *ellipsoid(tj(q))) for name, tj in self.parts.items()}
        return ManipulabilityInfo(np.asarray(q, dtype=float), self.tj.row_names, measures(J), semi, axes, parts)

    def batch(self, Q) -> np.ndarray:
        """(N, 3) measures for the rows of Q."""
        Q = np.atleast_2d(Q)
        F = ca.Function("J", [self.tj.sym.q, self.tj.sym.p], [self.tj.J_sx]).map(Q.shape[0])
        flat = np.array(F(Q.T, np.tile(self.tj.p.reshape(-1, 1), (1, Q.shape[0]))))  # k x (nv N)
        J = flat.reshape(self.tj.k, Q.shape[0], self.tj.nv).transpose(1, 0, 2)
        return measures(J)


def symbolic(model, frame: str = "tcp", task: str = "position") -> dict[str, sp.Expr | sp.Matrix]:
    """Closed forms from a :class:`derive.inspect.sympy_model.SymbolicModel`: {"J", "JJt", "mu3", and for k <= 2
    "eigenvalues", "mu1", "mu2"} in the robot's symbols (eigenvalues of a 3 x 3 JJ^T are left to
    numerics: their closed form is the casus irreducibilis of the cubic)."""
    tj = TaskJacobian(model.robot, frame, task)
    J = model.jacobian(frame)[list(tj.rows), :]
    A = (J * J.T).applyfunc(sp.simplify)
    # Cauchy-Binet: det(J J^T) = sum of the squared k x k minors of J; each minor simplifies
    # far better alone (the 2R arm's is L1 L2 sin(theta2)) than the expanded determinant
    det = sum((sp.simplify(J[:, list(cols)].det()) ** 2 for cols in combinations(range(J.shape[1]), tj.k)),
              sp.Integer(0))
    out = {"J": J, "JJt": A, "mu3": sp.sqrt(det)}
    if tj.k == 1:
        lmax = lmin = A[0, 0]
    elif tj.k == 2:
        tr = sp.simplify(A.trace())
        disc = sp.sqrt(sp.simplify(tr**2 - 4 * det))
        lmax, lmin = (tr + disc) / 2, (tr - disc) / 2
    else:
        return out
    out.update(eigenvalues=(lmax, lmin), mu1=sp.sqrt(lmax / lmin), mu2=lmax / lmin)
    return out


# --------------------------------------------------------------------------- poses


MAX_POSES = 1000
"""Most poses of :func:`default_poses`: each is printed (and drawn as an ellipse); a map of mu3 over the
workspace is the figure's other panel."""


def default_poses(robot: Robot, n: int = 6) -> np.ndarray:
    """n configurations from the middle of the joint box towards 80 % of its upper corner:
    for the 2R arm from stretched (singular) to folded, as figure 9 compares. 1 <= n <= MAX_POSES."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or not 1 <= n <= MAX_POSES:
        raise DeriveError(f"robot '{robot.name}': the number of poses must be an integer in 1 .. {MAX_POSES}, got {n!r}")
    lo, hi = joint_box(robot)
    mid = (lo + hi) / 2
    return mid + np.linspace(0, 1, n)[:, None] * 0.8 * (hi - mid)
