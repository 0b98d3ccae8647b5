"""Singularities and redundancy (lecture sections 2.4 and 4.1-4.2).

At a configuration q the task Jacobian J_t (k x nv: the chosen rows of the
geometric Jacobian, [linear; angular], LOCAL_WORLD_ALIGNED) has the SVD
J_t = U diag(s) V^T. Its rank r counts the singular values above
``tol = max(k, nv) * eps * s_max`` (numpy's rule); the null space, the joint
velocities that do not move the task (J_t qd = 0), is spanned by the last
nv - r columns of V; the last k - r columns of U are the task directions the
arm cannot move in. q is singular when r < min(k, nv).

Task rows: "position" (default) is rows 0-2 of J, "orientation" rows 3-5,
"full" all six; rows that are identically zero for every q (a planar arm's z
and roll/pitch rows, found structurally in the CasADi expression) are dropped,
so the planar 2R arm's position task is its 2 x 2 (x, y) Jacobian of eq. 24.
Explicit rows can be named: "x,y,wz" (x y z wx wy wz).

Redundancy: a robot is kinematically redundant for a task of dimension k when
nv > k (a null space of dimension >= nv - k everywhere), and intrinsically
redundant when nv exceeds the dimension of its operational space (all rows of
J that are not identically zero).

The search for singular configurations minimises det(J_t J_t^T) (or det(J_t^T J_t)
when nv < k), a smooth function that vanishes exactly there, from random
starts by a trust-region Newton method with gradient and Hessian from CasADi's
AD; angular coordinates are free
(angles are wrapped to (-pi, pi] afterwards), prismatic ones stay in their limits.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import casadi as ca
import numpy as np

from derive.analysis.workspace import joint_box, sample_configurations
from derive.description import expr
from derive.description.robot import Robot
from derive.errors import DeriveError
from derive.symbolic.kinematics import Kinematics
from derive.symbolic.symbols import make_symbols

ROW_NAMES = ("x", "y", "z", "wx", "wy", "wz")
MAX_STARTS = 10_000
"""Most random starts of :func:`find_singularities`: each is a Newton search of milliseconds to a second."""
TASKS = {"position": (0, 1, 2), "orientation": (3, 4, 5), "full": (0, 1, 2, 3, 4, 5)}


def parse_task(robot: Robot, task: str) -> tuple[tuple[int, ...], bool]:
    """(candidate rows, drop rows that are identically zero?) of a task name or a row list."""
    if task in TASKS:
        return TASKS[task], True
    names = [t.strip() for t in task.split(",") if t.strip()]
    bad = [n for n in names if n not in ROW_NAMES]
    if bad or not names or len(set(names)) != len(names):
        raise DeriveError(f"robot '{robot.name}': task '{task}': expected position, orientation, full, "
                          f"or distinct rows of {', '.join(ROW_NAMES)} separated by commas")
    return tuple(ROW_NAMES.index(n) for n in names), False


class TaskJacobian:
    """J_t(q): the task rows of the geometric Jacobian of ``frame``, numeric and symbolic (SX)."""

    def __init__(self, robot: Robot, frame: str = "tcp", task: str = "position", kinematics=None):
        robot.require_fixed_base("the singularity and manipulability analysis")
        self.robot, self.frame, self.task = robot, frame, task
        kin = kinematics or Kinematics(robot, make_symbols(robot))  # reuse an SXModel's when given
        self.sym = kin.sym
        if frame not in kin.poses:
            raise DeriveError(f"robot '{robot.name}': no frame '{frame}' (frames: {', '.join(kin.poses)})")
        J = kin.jacobian(frame)
        self.moving_rows = kin.moving_rows(frame)
        rows, drop = parse_task(robot, task)
        self.rows = tuple(r for r in rows if r in self.moving_rows) if drop else rows
        if not self.rows:
            raise DeriveError(f"robot '{robot.name}': frame '{frame}' never moves along the {task} rows")
        self.J_sx = J[list(self.rows), :]
        self.p = np.array([p.default for p in robot.parameters])
        self._f = ca.Function("J", [self.sym.q, self.sym.p], [self.J_sx])

    @property
    def k(self) -> int:
        """Task dimension."""
        return len(self.rows)

    @property
    def nv(self) -> int:
        return self.robot.nv

    @property
    def row_names(self) -> str:
        return ",".join(ROW_NAMES[r] for r in self.rows)

    def __call__(self, q) -> np.ndarray:
        q = np.asarray(q, dtype=float).reshape(-1)
        if q.shape[0] != self.nv:
            raise DeriveError(f"robot '{self.robot.name}': q must have {self.nv} entries, got {q.shape[0]}")
        if not np.all(np.isfinite(q)):
            raise DeriveError(f"robot '{self.robot.name}': q must be finite, got {q.tolist()}")
        return np.array(self._f(q, self.p))

    @cached_property
    def gram_det(self) -> ca.Function:
        """q -> (det(J_t J_t^T), gradient, Hessian): det of the smaller Gram matrix (J_t^T J_t if nv < k)."""
        J = self.J_sx
        d = ca.det(J @ J.T if self.k <= self.nv else J.T @ J)
        H, g = ca.hessian(d, self.sym.q)
        return ca.Function("gram_det", [self.sym.q, self.sym.p], [d, g, H])


@dataclass
class SingularityInfo:
    """Rank analysis of J_t at one configuration (see the module docstring)."""

    q: np.ndarray
    singular_values: np.ndarray  # descending, min(k, nv) of them
    rank: int
    null_space: np.ndarray  # nv x (nv - rank), orthonormal columns
    lost_directions: np.ndarray  # k x (k - rank): task directions the frame cannot move in
    tol: float

    @property
    def singular(self) -> bool:
        return self.rank < len(self.singular_values)


def analyse(J: np.ndarray, q=None, tol: float | None = None) -> SingularityInfo:
    """Rank, singular values, null-space basis and lost task directions of a k x nv matrix."""
    J = np.atleast_2d(np.asarray(J, dtype=float))
    U, s, Vt = np.linalg.svd(J)
    tol = max(J.shape) * np.finfo(float).eps * (s[0] if s.size else 0.0) if tol is None else tol
    rank = int((s > tol).sum())
    return SingularityInfo(np.asarray(q, dtype=float) if q is not None else None, s, rank, Vt[rank:].T, U[:, rank:], tol)


def redundancy(tj: TaskJacobian) -> str:
    """One line per kind of redundancy (see the module docstring)."""
    n, k, ops = tj.nv, tj.k, len(tj.moving_rows)
    kin = (f"kinematically redundant for the {k}-D task ({tj.row_names}): nv = {n} > {k}, "
           f"a null space of dimension >= {n - k} everywhere" if n > k else
           f"not kinematically redundant for the {k}-D task ({tj.row_names}): nv = {n} <= {k}"
           + (f" (nv < k: J_t has rank <= {n} < {k}, the task can never be spanned)" if n < k else ""))
    op = ",".join(ROW_NAMES[r] for r in tj.moving_rows)
    intr = (f"intrinsically redundant: nv = {n} > {ops}, the dimension of its operational space ({op})" if n > ops else
            f"not intrinsically redundant: nv = {n} <= {ops}, the dimension of its operational space ({op})")
    return kin + "\n" + intr


@dataclass
class SingularConfiguration:
    q: np.ndarray
    singular_values: np.ndarray
    within_limits: bool


def free_coordinates(tj: TaskJacobian, samples: int = 4, seed: int = 0) -> tuple[int, ...]:
    """Coordinates the singular values do not depend on (e.g. a base joint about the gravity-free
    vertical axis): changing them alone never makes or breaks a singularity."""
    rng = np.random.default_rng(seed)
    Q = sample_configurations(tj.robot, samples, "random", seed)
    free = []
    for i in range(tj.nv):
        changed = False
        for q in Q:
            q2 = q.copy()
            q2[i] += rng.uniform(0.3, 1.0)
            s1, s2 = (np.linalg.svd(tj(x), compute_uv=False) for x in (q, q2))
            changed |= np.abs(s1 - s2).max() > 1e-9 * max(s1.max(), 1e-300)
        if not changed:
            free.append(i)
    return tuple(free)


def find_singularities(tj: TaskJacobian, starts: int = 24, seed: int = 0, rtol: float = 1e-7,
                       progress=None) -> tuple[list[SingularConfiguration], tuple[int, ...]]:
    """Distinct singular configurations reached by minimising det(Gram(J_t)) from random starts.

    A minimum counts as singular when s_min / s_max < ``rtol``. Coordinates the singular
    values do not depend on (``free_coordinates``) are set to 0 in the results, and
    configurations equal up to wrapped angles (within 1e-3) are reported once.
    Returns (configurations sorted by q, the free coordinates).
    """
    from scipy.optimize import Bounds, minimize

    if isinstance(starts, bool) or not isinstance(starts, (int, np.integer)) or not 1 <= starts <= MAX_STARTS:
        raise DeriveError(f"robot '{tj.robot.name}': the number of starts must be an integer in 1 .. {MAX_STARTS} "
                          f"(each is a Newton search), got {starts!r}")
    lo, hi = joint_box(tj.robot)
    angle = np.array([c.unit == "rad" for c in tj.robot.coordinates])
    bounds = None if angle.all() else Bounds(np.where(angle, -np.inf, lo), np.where(angle, np.inf, hi))
    free = free_coordinates(tj)
    found: list[SingularConfiguration] = []
    for n, q0 in enumerate(sample_configurations(tj.robot, starts, "random", seed), 1):
        scale = float(tj.gram_det(q0, tj.p)[0]) or 1.0

        def f(q):
            d, g, _ = tj.gram_det(q, tj.p)
            return float(d) / scale, np.array(g).reshape(-1) / scale

        def hess(q):
            return np.array(tj.gram_det(q, tj.p)[2]) / scale

        # a trust region with the exact Hessian stays in the start's basin; quasi-Newton first
        # steps tend to jump over it (from theta2 = 1.44 the 2R arm's L-BFGS lands near pi)
        res = minimize(f, q0, jac=True, hess=hess, method="trust-constr", bounds=bounds,
                       options={"gtol": 1e-14, "xtol": 1e-14, "maxiter": 300})
        q = np.where(angle, (res.x + np.pi) % (2 * np.pi) - np.pi, res.x)
        q[np.isclose(q, -np.pi, atol=1e-9) & angle] = np.pi  # (-pi, pi]
        q[list(free)] = 0.0
        q[np.abs(q) < 1e-9] = 0.0  # the minimiser's last digits are noise
        s = np.linalg.svd(tj(q), compute_uv=False)
        if progress:
            progress(n, starts, q, s)
        if s[-1] >= rtol * s[0]:
            continue
        if any(_same(q, c.q, angle) for c in found):
            continue
        found.append(SingularConfiguration(q, s, bool(np.all((q >= lo - 1e-12) & (q <= hi + 1e-12)))))
    found.sort(key=lambda c: tuple(np.round(c.q, 6)))
    return found, free


def _same(a: np.ndarray, b: np.ndarray, angle: np.ndarray, tol: float = 1e-3) -> bool:
    d = a - b
    d = np.where(angle, (d + np.pi) % (2 * np.pi) - np.pi, d)
    return bool(np.abs(d).max() < tol)


# --------------------------------------------------------------------------- input


def eval_number(text: str) -> float:
    """A number, allowing 'pi' and simple fractions of it ('pi/2', '-3*pi/4')."""
    try:
        return float(expr.evaluate(text.strip(), {}, pi=math.pi))
    except Exception:  # noqa: BLE001  (any parse error means: not a number)
        raise ValueError(text) from None
