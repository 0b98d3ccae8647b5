"""Inverse kinematics: find q within the joint limits with world_T_frame(q) = target.

The residual is the lecture's pose error in the world frame (section 2.5.2),

    e(q) = [p_target - p(q);  log(R_target R(q)^T)]          (6,)  [m; rad]

with log the SO(3) log map (Rodrigues, :func:`derive.symbolic.spatial.log_so3`), so that
de/dq = -J(q) with J the geometric Jacobian, LOCAL_WORLD_ALIGNED. Weights w (6,)
select and scale its rows: E(q) = 1/2 sum_i w_i e_i^2; a position-only target has
w = [1, 1, 1, 0, 0, 0].

Solvers, all on CasADi functions built from the derived FK and Jacobian:

- ``"lm"``: Levenberg-Marquardt. Each step solves (J^T W J + lambda I) dq = J^T W e
  (lambda = 0 is the lecture's eq. 15 in its least-squares form) by LDL^T; joints
  the step pushes past a limit are held at that limit and the others re-solved
  (one active-set pass); the step is accepted if E decreases (lambda / 10), else
  lambda * 10. An attempt that stalls (lambda > 1e5, or 30 iterations without
  success) restarts from q drawn uniformly within the limits (seeded generator).
- ``"opti"``: CasADi Opti + IPOPT, min E(q) + rest_weight/2 |q - q_rest|^2 within
  the limits, from q0 then from random restarts.
- ``"auto"`` (default): LM; if it fails, IPOPT from the best q found.

Given a rest posture, a converged solution is then moved towards it (null-space
preference of a redundant arm) by IPOPT: min |q - q_rest|^2 subject to e_i(q) = 0
for the weighted rows and the limits; the move is kept if it still meets the
tolerances and is nearer the rest posture.

Time: ``timeout`` caps the wall time of a solve (LM stops early enough to leave one
IPOPT solve, itself capped at OPTI_WALL_TIME); building the CasADi functions, once
per robot and frame in a process, is not counted.

The angles of continuous joints (unbounded) are returned wrapped to (-pi, pi] (the same
pose); with a rest posture each is first taken to its turn nearest the rest angle.

``success`` is decided here, never by a solver's status: position error (the norm
of the weighted position rows) < tol_position, rotation error < tol_rotation and q
within the limits. A failed solve returns the q with the smallest E found.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from functools import lru_cache

import casadi as ca
import numpy as np
from numpy.random import default_rng

from derive.errors import DeriveError
from derive.description.joints import wrap_angle
from derive.description.model import Robot, load_robot
from derive.symbolic.ode import ldlt_solve
from derive.symbolic.ik import (ATTEMPT, LAMBDA0, LAMBDA_MIN, LAMBDA_STALL, TOL_POSITION, TOL_ROTATION, joint_ranges,
                                pose_error)
from derive.symbolic.model import SXModel

BLOCK = 6             # LM iterations per CasADi call
OPTI_WALL_TIME = 0.02  # s, cap of one IPOPT solve; in method "auto" LM leaves that much of the timeout


@dataclass(frozen=True)
class IkResult:
    """q (nv,), whether it meets the tolerances within the limits, its residual, and the work done."""

    q: np.ndarray
    success: bool
    position_error: float   # m, norm of the weighted position rows of e
    rotation_error: float   # rad, norm of the weighted rotation rows of e
    iterations: int         # LM iterations plus IPOPT iterations
    restarts: int


class IkProblem:
    """The CasADi functions of one robot frame's IK, built once (see :func:`problem`)."""

    def __init__(self, robot: Robot, frame: str):
        model = SXModel(robot)
        if frame not in model.kinematics.frames:
            raise DeriveError(f"robot '{robot.name}': no frame '{frame}' (frames: {', '.join(model.kinematics.frames)})")
        if not model.kinematics.ancestors[frame]:
            raise DeriveError(f"robot '{robot.name}': frame '{frame}' does not move with any joint")
        self.robot, self.frame = robot, frame
        s = model.sym
        self.n = n = s.nv
        self.p_default = np.array([par.default for par in robot.parameters], dtype=float)
        self.lower, self.upper, self.sample_lower, self.sample_upper = joint_ranges(robot)
        q, p = s.q, s.p
        T_target, w = ca.SX.sym("T", 4, 4), ca.SX.sym("w", 6)
        fk, jac = model.fk(frame), model.jacobian(frame)
        fkj = ca.Function("fkj", [q, p], [fk, jac])
        lo, hi = ca.DM(self.lower), ca.DM(self.upper)

        def error(qq):
            T, J = fkj(qq, p)
            e = pose_error(T, T_target)
            return e, J, 0.5 * ca.dot(w * e, e)

        # ---- one Levenberg-Marquardt iteration ----
        lam = ca.SX.sym("lam")
        e, J, E = error(q)
        A = J.T @ (J * ca.repmat(w, 1, n)) + lam * ca.SX.eye(n)
        g = J.T @ (w * e)
        q_step = q + ldlt_solve(A, g)
        held = ca.logic_or(q_step < lo, q_step > hi)                 # joints pushed past a limit
        free = 1 - held
        d_held = held * (ca.fmin(ca.fmax(q_step, lo), hi) - q)       # their step: onto the limit
        A_free = A * (free @ free.T) + ca.diag(held)                 # held rows and columns -> identity
        g_free = free * (g - A @ d_held) + d_held
        q_trial = ca.fmin(ca.fmax(q + ldlt_solve(A_free, g_free), lo), hi)
        _, _, E_trial = error(q_trial)
        accept = E_trial < E
        step = ca.Function("lm_step", [q, lam, T_target, w, p],
                           [ca.if_else(accept, q_trial, q),
                            ca.if_else(accept, ca.fmax(lam / 10, LAMBDA_MIN), ca.fmin(lam * 10, 1e10))])

        # ---- BLOCK iterations per call, packed into one vector in and one out: a CasADi call from
        # Python costs ~10 us per argument, more than an iteration ----
        qk, lk = q, lam
        for _ in range(BLOCK):
            qk, lk = step(qk, lk, T_target, w, p)
        e_end, _, E_end = error(qk)
        context = ca.vertcat(ca.vec(T_target), w, p)
        self.lm_block = ca.Function("lm_block", [ca.vertcat(q, lam), context], [ca.vertcat(qk, lk, E_end, e_end)])
        self.residual = ca.Function("residual", [q, context], [ca.vertcat(E, e)])
        # the first evaluation of a CasADi function allocates its work memory (~10 ms): do it here
        self.lm_block(np.zeros(n + 1), np.zeros(context.numel()))
        self._error, self._sym = error, (q, p, T_target, w)
        self._opti: dict[tuple, ca.Function] = {}

    # ---- IPOPT formulations (built on first use: IPOPT set-up costs tens of ms) ----
    def opti(self, kind: str, rows: tuple[bool, ...] = ()) -> ca.Function:
        """f(q_init, q_rest, T, w, p, rest_weight) -> q, by CasADi Opti + IPOPT.

        ``"fit"``: min E(q) + rest_weight/2 |q - q_rest|^2 within the limits.
        ``"rest"``: min 1/2 |q - q_rest|^2 subject to e_i(q) = 0 for the ``rows`` i (those
        of weight > 0) and the limits: the solution nearest the rest posture, along the
        self-motion of a redundant arm.
        """
        key = (kind, rows)
        if key in self._opti:
            return self._opti[key]
        n = self.n
        opti = ca.Opti()
        # ---- decision variables ----
        q = opti.variable(n)
        # ---- parameters ----
        q_rest, rest_weight = opti.parameter(n), opti.parameter()
        T_target, w, p = opti.parameter(4, 4), opti.parameter(6), opti.parameter(self.p_default.size)
        q_s, p_s, T_s, w_s = self._sym
        e, E = ca.Function("error", [q_s, p_s, T_s, w_s], list(self._error(q_s))[::2])(q, p, T_target, w)
        # ---- objective ----
        if kind == "fit":
            opti.minimize(E + 0.5 * rest_weight * ca.sumsqr(q - q_rest))
        else:
            opti.minimize(0.5 * ca.sumsqr(q - q_rest))
        # ---- constraints ----
        for i in (i for i, r in enumerate(rows) if r and kind == "rest"):
            opti.subject_to(e[i] == 0)                                  # the pose is held
        for i in range(n):
            if np.isfinite(self.lower[i]):
                opti.subject_to(q[i] >= self.lower[i])                  # joint limit
            if np.isfinite(self.upper[i]):
                opti.subject_to(q[i] <= self.upper[i])                  # joint limit
        opti.solver("ipopt", {"print_time": False, "error_on_fail": False},
                    {"print_level": 0, "sb": "yes", "max_iter": 100, "tol": 1e-12, "max_wall_time": OPTI_WALL_TIME})
        # a decision variable among the inputs is its initial guess
        f = opti.to_function(f"ik_{kind}", [q, q_rest, T_target, w, p, rest_weight], [q])
        self._opti[key] = f
        return f

    @staticmethod
    def opti_iterations(f: ca.Function) -> int:
        """IPOPT iterations of the last call of an :meth:`opti` function (1 if not reported)."""
        try:
            return int(f.stats().get("iter_count", 1))
        except RuntimeError:
            return 1


@lru_cache(maxsize=32)
def problem(robot: Robot, frame: str = "tcp") -> IkProblem:
    """The IK functions of ``robot``'s ``frame``, built once per process."""
    robot.require_fixed_base("inverse kinematics")
    return IkProblem(robot, frame)


def _target(target, weights, frame_robot: str) -> tuple[np.ndarray, np.ndarray]:
    """(T (4, 4), w (6,)) from a 4x4 pose or a position (3,), checked."""
    t = np.asarray(target, dtype=float)
    if t.shape == (3,):
        T, w = np.eye(4), np.array([1.0, 1, 1, 0, 0, 0])
        T[:3, 3] = t
    elif t.shape == (4, 4):
        T, w = t, np.ones(6)
        R = T[:3, :3]
        if np.isfinite(R).all() and (np.abs(R @ R.T - np.eye(3)).max() > 1e-6 or np.linalg.det(R) < 0):
            raise DeriveError(f"robot '{frame_robot}': target rotation is not a rotation matrix (R R^T != I)")
    else:
        raise DeriveError(f"robot '{frame_robot}': target must be a 4x4 pose or a position (3,), got shape {t.shape}")
    if weights is not None:
        w = np.asarray(weights, dtype=float).reshape(-1)
        if w.shape != (6,) or (w < 0).any() or not w.any():
            raise DeriveError(f"robot '{frame_robot}': weights must be 6 non-negative numbers, not all zero")
    if not (np.isfinite(T).all() and np.isfinite(w).all()):
        raise DeriveError(f"robot '{frame_robot}': target and weights must be finite")
    return T, w


@lru_cache(maxsize=32)
def _named_robot(name: str) -> Robot:
    return load_robot(name)


def _robot(model) -> Robot:
    if isinstance(model, Robot):
        return model
    if isinstance(model, str):
        return _named_robot(model)
    if hasattr(model, "robot"):  # SymbolicModel, SXModel
        return model.robot
    raise DeriveError(f"solve_ik: model must be a robot name, a Robot or a derived model, got {type(model).__name__}")


def solve_ik(model, target, q0=None, frame: str = "tcp", *, weights=None, method: str = "auto",
             rest=None, rest_weight: float = 0.0, tol_position: float = TOL_POSITION,
             tol_rotation: float = TOL_ROTATION, max_iterations: int = 20000, timeout: float = 0.1,
             seed: int = 0, p=None) -> IkResult:
    """q within the limits with world_T_frame(q) = target, as far as the tolerances.

    Args:
        model: robot name, :class:`~derive.model.Robot`, ``derive.load(...)`` or an SXModel.
        target: world_T_frame (4, 4), or a position (3,) for position-only IK.
        q0: start (default: the middle of the limits); clipped into the limits.
        weights: (6,) row weights of e = [dp; dtheta] (default ones, or [1, 1, 1, 0, 0, 0]
            for a position); rows of weight 0 are neither solved for nor checked.
        method: ``"auto"``, ``"lm"`` or ``"opti"`` (see the module docstring).
        rest, rest_weight: a rest posture (nv,). With ``"opti"`` or after a failed LM,
            rest_weight/2 |q - rest|^2 joins the objective; after a successful solve q is
            moved towards ``rest`` within the tolerances (null space of a redundant arm).
        max_iterations, timeout: caps on LM iterations and on wall time (s); the solver
            stops at whichever comes first and returns the best q found.
        seed: of the generator drawing restarts.
        p: robot parameters (default: the model's defaults).
    """
    robot = _robot(model)
    prob = problem(robot, frame)
    start = time.perf_counter()   # the timeout covers solving, not building the functions (once)
    n = prob.n
    T, w = _target(target, weights, robot.name)
    pv = prob.p_default if p is None else np.asarray(p, dtype=float).reshape(-1)
    if pv.shape != prob.p_default.shape:
        raise DeriveError(f"robot '{robot.name}': p must have {prob.p_default.size} elements, got {pv.size}")
    if method not in ("auto", "lm", "opti"):
        raise DeriveError(f"solve_ik: method must be 'auto', 'lm' or 'opti', got {method!r}")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise DeriveError(f"robot '{robot.name}': seed must be an integer >= 0, got {seed!r}")
    if isinstance(max_iterations, bool) or not isinstance(max_iterations, (int, np.integer)) or max_iterations < 1:
        raise DeriveError(f"robot '{robot.name}': max_iterations must be an integer >= 1, got {max_iterations!r}")
    for what, x in (("timeout", timeout), ("tol_position", tol_position), ("tol_rotation", tol_rotation)):
        if not (isinstance(x, (int, float, np.integer, np.floating)) and np.isfinite(x) and x > 0):
            raise DeriveError(f"robot '{robot.name}': {what} must be a finite number > 0, got {x!r}")
    if not (isinstance(rest_weight, (int, float, np.integer, np.floating)) and np.isfinite(rest_weight) and rest_weight >= 0):
        raise DeriveError(f"robot '{robot.name}': rest_weight must be a finite number >= 0, got {rest_weight!r}")
    lo, hi = prob.lower, prob.upper
    mid = np.where(np.isfinite(lo) & np.isfinite(hi), 0.5 * (np.where(np.isfinite(lo), lo, 0.0) + np.where(np.isfinite(hi), hi, 0.0)), np.clip(0.0, lo, hi))
    q = mid if q0 is None else np.asarray(q0, dtype=float).reshape(-1)
    if q.shape != (n,) or not np.isfinite(q).all():
        raise DeriveError(f"robot '{robot.name}': q0 must be {n} finite numbers")
    q_rest = mid if rest is None else np.asarray(rest, dtype=float).reshape(-1)
    if q_rest.shape != (n,) or not np.isfinite(q_rest).all():
        raise DeriveError(f"robot '{robot.name}': rest must be {n} finite numbers")
    q = np.clip(q, lo, hi)
    rng = default_rng(seed)
    context = ca.DM(np.concatenate([T.T.reshape(-1), w, pv]))   # vec() is column-major
    checked = (w[:3] > 0, w[3:] > 0)

    def errors(e: np.ndarray) -> tuple[float, float]:
        """(position error, rotation error): norms of the weighted rows of e."""
        return float(np.linalg.norm(e[:3][checked[0]])), float(np.linalg.norm(e[3:][checked[1]]))

    def ok(errs: tuple[float, float]) -> bool:
        return errs[0] < tol_position and errs[1] < tol_rotation

    def out_of_time(spare: float = 0.0) -> bool:
        return time.perf_counter() - start > timeout - spare

    def opti(kind: str, rows: tuple[bool, ...] = ()) -> ca.Function:
        nonlocal start
        t = time.perf_counter()
        f = prob.opti(kind, rows)
        start += time.perf_counter() - t   # building (once per process) is not solving
        return f

    best = (np.inf, q, errors(np.full(6, np.inf)))   # (E, q, errors)
    iterations = restarts = 0
    if method in ("auto", "lm"):
        lam, attempt = LAMBDA0, 0
        while True:
            out = prob.lm_block(np.append(q, lam), context).full().reshape(-1)
            q, lam, E, errs = out[:n], out[n], out[n + 1], errors(out[n + 2:])
            iterations += BLOCK
            attempt += BLOCK
            if E < best[0]:
                best = (E, q, errs)
            if ok(errs) or iterations >= max_iterations or out_of_time(OPTI_WALL_TIME if method == "auto" else 0.0):
                break
            if attempt >= ATTEMPT or lam > LAMBDA_STALL:
                q = rng.uniform(prob.sample_lower, prob.sample_upper)
                lam, attempt = LAMBDA0, 0
                restarts += 1
    if method == "opti" or (method == "auto" and not ok(best[2]) and not out_of_time()):
        fit, q = opti("fit"), best[1]
        while True:
            q = np.clip(fit(q, q_rest, T, w, pv, rest_weight).full().reshape(-1), lo, hi)
            iterations += prob.opti_iterations(fit)
            out = prob.residual(q, context).full().reshape(-1)
            if out[0] < best[0]:
                best = (out[0], q, errors(out[1:]))
            if ok(best[2]) or method != "opti" or out_of_time() or iterations >= max_iterations:
                break
            q = rng.uniform(prob.sample_lower, prob.sample_upper)
            restarts += 1
    E, q, errs = best
    turns = list(robot.continuous_indices)
    if ok(errs) and rest is not None:
        if turns:  # each continuous joint's turn nearest the rest posture: the same pose, less to move
            q = q.copy()
            q[turns] = q_rest[turns] + wrap_angle(q[turns] - q_rest[turns])
        towards_rest = opti("rest", tuple(bool(x) for x in w > 0))
        moved = np.clip(towards_rest(q, q_rest, T, w, pv, rest_weight).full().reshape(-1), lo, hi)
        iterations += prob.opti_iterations(towards_rest)
        moved_errs = errors(prob.residual(moved, context).full().reshape(-1)[1:])
        if ok(moved_errs) and np.sum((moved - q_rest) ** 2) < np.sum((q - q_rest) ** 2):
            q, errs = moved, moved_errs
    q = robot.wrap(q)  # continuous joints to (-pi, pi]: the same pose (they have no limits to leave)
    within = bool(np.all(q >= lo) and np.all(q <= hi))
    return IkResult(q=q, success=ok(errs) and within, position_error=errs[0], rotation_error=errs[1],
                    iterations=iterations, restarts=restarts)
