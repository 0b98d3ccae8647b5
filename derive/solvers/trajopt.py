"""Trajectory optimisation on the derived dynamics: direct transcription in CasADi Opti + IPOPT.

    minimise    w_T T + w_E integral_0^T |u(t)|^2 dt  (+ w_A integral_0^T |qdd|^2 dt, a regulariser)
    subject to  M(q) qdd + C(q, qd) qd + g(q) = B u          (RNEA, implicit: no M^-1 in the NLP)
                (q, qd)(0) = start,  (q, qd)(T) = goal        (qdd = 0 there too when at rest)
                lower <= q <= upper,  |qd| <= velocity,  |u| <= effort      (the model's limits)
                p_frame(q(s_i T)) = waypoint_i                (the derived FK)

q, qd, qdd, tau are (nv,) in the order of Robot.coordinates (a multi-DOF joint has one entry,
with its own limits, per coordinate); u holds the torques (forces for prismatic joints) of the
actuated coordinates and B (nv x na) selects them, so passive joints (the cart-pole's pole) get
tau = 0. N uniform intervals h = T / N; every knot k = 0..N carries
(q, qd, qdd, u) and the dynamics hold at every knot. Transcriptions (``method``):

- ``trapezoidal``: q_{k+1} - q_k = h/2 (qd_k + qd_{k+1}), the same for qd with qdd; u linear in t.
- ``hermite-simpson`` (separated form): midpoints from cubic Hermite interpolation of the knots,
  with their own qdd_c and u_c and Simpson's rule; u quadratic in t.
- ``rk4``: multiple shooting, one RK4 step per interval whose four stage accelerations are
  variables held to the dynamics by RNEA; u constant over each interval.

At rest (zero velocity) a boundary state must also be held (qdd = 0): a robot too weak to hold
itself against gravity there has no solution. Every result is checked independently: the
generated forward dynamics (generated/<robot>/python/<robot>.py, LDL^T of CRBA's M, not this
NLP's graph) integrated by RK4 in fine steps under the transcription's u(t) must reproduce the
optimised knots; ``success`` comes from that check and the limits, not from IPOPT's status.
"""

from __future__ import annotations

import importlib.util
import json
import math
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Sequence

import casadi as ca
import numpy as np

from derive.errors import DeriveError
from derive.resources import CHECKOUT
from derive.description.model import Robot, load_robot

METHODS = ("trapezoidal", "hermite-simpson", "rk4")
GENERATED = CHECKOUT / "generated"
TOL = 1e-3
"""Largest |q_integrated - q_optimised| at the knots (rad or m) a successful result may have."""
LIMIT_TOL = 1e-6
"""Allowed excess over a limit, relative to max(1, |limit|): IPOPT's bound relaxation is 1e-8."""


@dataclass(frozen=True)
class Waypoint:
    """The origin of ``frame`` passes through ``position`` (world, m) at time s T, s in [0, 1]."""

    s: float
    position: tuple[float, float, float]
    frame: str = "tcp"


@dataclass
class TrajoptResult:
    """An optimised trajectory at the N + 1 knots and how it was obtained and checked.

    ``integration_error``: max over knots k of |q_sim - q_k| (rad or m), q_sim from integrating
    the generated forward dynamics under ``torque(t)`` from knot k - 1 (the transcription's
    defects); ``velocity_error`` the same for qd; ``drift`` the q error integrating open loop from
    the start (grows near unstable states). ``limit_violation``: largest excess over a limit at the
    knots (0 when held). ``stats``: solver return status, iterations, solve_time (IPOPT's
    t_wall_total, s), build_time (s), cost.
    """

    success: bool
    reason: str
    robot: str
    joints: tuple[str, ...]
    method: str
    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    tau: np.ndarray
    tau_mid: np.ndarray | None = None
    stats: dict = field(default_factory=dict)
    integration_error: float = math.inf
    velocity_error: float = math.inf
    drift: float = math.inf
    limit_violation: float = math.inf

    @property
    def duration(self) -> float:
        return float(self.t[-1]) if len(self.t) else 0.0

    def torque(self, t: float) -> np.ndarray:
        """tau(t) as the transcription defines it between knots (linear, quadratic or constant)."""
        n = len(self.t) - 1
        x = min(max(t / self.duration, 0.0), 1.0) * n
        k = min(int(x), n - 1)
        return self.interval_torque(k, x - k)

    def interval_torque(self, k: int, s: float) -> np.ndarray:
        """tau at the fraction s in [0, 1] of interval k."""
        if self.method == "rk4":
            return self.tau[k]
        if self.method == "trapezoidal":
            return (1 - s) * self.tau[k] + s * self.tau[k + 1]
        a, c, b = self.tau[k], self.tau_mid[k], self.tau[k + 1]  # Lagrange basis on s = 0, 1/2, 1
        return a * (2 * s - 1) * (s - 1) + c * 4 * s * (1 - s) + b * s * (2 * s - 1)

    def table(self) -> tuple[list[str], np.ndarray]:
        """CSV header and rows: t, q_<joint>..., qd_<joint>..., qdd_<joint>..., tau_<joint>...."""
        names = ["t"] + [f"{k}_{j}" for k in ("q", "qd", "qdd", "tau") for j in self.joints]
        return names, np.column_stack([self.t, self.q, self.qd, self.qdd, self.tau])

    def write_csv(self, path: Path) -> None:
        names, rows = self.table()
        np.savetxt(path, rows, delimiter=",", header=",".join(names), comments="", fmt="%.10g")

    def plot(self, path: Path, limits: dict | None = None) -> None:
        """Joint positions, velocities and torques over time (matplotlib, Agg) to ``path``;
        ``limits`` maps joints to effort limits, drawn dotted."""
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig, axes = plt.subplots(3, 1, sharex=True, figsize=(8, 8))
        for ax, data, label in zip(axes, (self.q, self.qd, self.tau), ("q [rad, m]", "qd [rad/s, m/s]", "tau [Nm, N]")):
            for i, j in enumerate(self.joints):
                ax.plot(self.t, data[:, i], label=j)
            ax.set_ylabel(label)
            ax.grid(True, alpha=0.3)
        colors = [line.get_color() for line in axes[2].lines]
        for color, j in zip(colors, self.joints):
            eff = (limits or {}).get(j)
            if eff is not None and np.isfinite(eff):
                for sign in (-1, 1):
                    axes[2].axhline(sign * eff, color=color, linestyle=":", linewidth=0.8)
        axes[0].legend(fontsize="small", ncol=min(len(self.joints), 4))
        axes[-1].set_xlabel("t [s]")
        axes[0].set_title(f"{self.robot}: {self.method}, N = {len(self.t) - 1}, T = {self.duration:.3f} s, "
                          f"IPOPT {self.stats.get('iterations', 0)} it, {self.stats.get('solve_time', 0):.3f} s")
        fig.tight_layout()
        fig.savefig(path, dpi=100)
        plt.close(fig)

    def summary(self) -> str:
        s = self.stats
        head = "solved" if self.success else f"FAILED: {self.reason}"
        if not len(self.t):
            return f"{self.robot}: {head}"
        return (f"{self.robot}: {head}; {self.method}, N = {len(self.t) - 1}, T = {self.duration:.3f} s, "
                f"cost {s.get('cost', math.nan):.4g}; IPOPT {s.get('return_status')}, {s.get('iterations')} iterations, "
                f"{s.get('solve_time', math.nan):.3f} s solve, {s.get('build_time', math.nan):.2f} s build; "
                f"integration error {self.integration_error:.1e} (q), {self.velocity_error:.1e} (qd), open loop {self.drift:.1e}")


def _failure(robot: Robot, method: str, reason: str) -> TrajoptResult:
    empty = np.zeros((0, robot.nv))
    return TrajoptResult(False, reason, robot.name, tuple(c.name for c in robot.coordinates), method,
                         np.zeros(0), empty, empty, empty, empty)


class TrajectoryOptimizer:
    """Transcribes and solves trajectory problems of one robot; the CasADi functions are built once."""

    def __init__(self, robot: Robot | str, p: Sequence[float] | None = None,
                 forward_dynamics: Callable | None = None, log: Callable[[str], None] = lambda s: None):
        from derive.symbolic.model import SXModel

        self.robot = load_robot(robot) if isinstance(robot, str) else robot
        self.log = log
        self.model = SXModel(self.robot)
        s = self.model.sym
        self.joints = s.joint_names
        self.p = np.array([q.default for q in self.robot.parameters] if p is None else p, dtype=float)
        if self.p.size != s.p.numel():
            raise DeriveError(f"trajopt {self.robot.name}: p has {self.p.size} values, the model {s.p.numel()} parameters")
        self.rnea = ca.Function("rnea", [s.q, s.qd, s.qdd, s.p], [self.model.newton_euler.rnea(s.qd, s.qdd)],
                                ["q", "qd", "qdd", "p"], ["tau"])
        self._fd = forward_dynamics
        self._fk: dict[str, ca.Function] = {}
        self._nlps: dict[tuple, dict] = {}

    # ---- model data ----

    def limits(self, torque_limit=None) -> dict[str, np.ndarray]:
        """lower, upper, velocity, effort per coordinate of q (inf where the model has none).

        A multi-DOF joint (spherical, universal, cylindrical) has one entry per coordinate, each
        with its own limits; ``torque_limit`` (scalar or (nv,), >= 0) overrides the effort limits.
        """
        cs = self.robot.coordinates
        val = lambda v, d: float(d if v is None else v)  # noqa: E731
        effort = np.array([val(c.limits.effort, np.inf) for c in cs])
        if torque_limit is not None:
            try:
                tl = np.asarray(torque_limit, dtype=float)
                effort = np.broadcast_to(tl, effort.shape).copy() if tl.ndim <= 1 else None
            except (TypeError, ValueError):
                effort = None
            if effort is None or np.any(np.isnan(effort)) or np.any(effort < 0):
                raise DeriveError(f"trajopt {self.robot.name}: torque_limit must be one value >= 0 or {len(cs)} "
                                  f"({', '.join(self.joints)}), got {torque_limit!r}")
        return {"lower": np.array([val(c.limits.lower, -np.inf) for c in cs]),
                "upper": np.array([val(c.limits.upper, np.inf) for c in cs]),
                "velocity": np.array([val(c.limits.velocity, np.inf) for c in cs]), "effort": effort}

    def gravity(self, q) -> np.ndarray:
        """g(q) = rnea(q, 0, 0)."""
        z = np.zeros(self.robot.nv)
        return np.array(self.rnea(q, z, z, self.p)).reshape(-1)

    def fk_position(self, frame: str) -> ca.Function:
        if frame not in self._fk:
            try:
                pos = self.model.fk(frame)[:3, 3]
            except KeyError as exc:
                raise DeriveError(f"trajopt {self.robot.name}: {exc.args[0]}") from None
            s = self.model.sym
            self._fk[frame] = ca.Function(f"fk_{frame}", [s.q, s.p], [pos])
        return self._fk[frame]

    @property
    def forward_dynamics(self) -> Callable:
        """qdd(q, qd, tau) from the generated Python module (the independent check)."""
        if self._fd is None:
            self._fd = generated_forward_dynamics(self.robot, self.p, self.log)
        return self._fd

    # ---- the problem ----

    def solve(self, start, goal, *, intervals: int = 50, method: str = "hermite-simpson", duration: float = 2.0,
              free_time: bool = False, duration_bounds: tuple[float, float] | None = None,
              time_weight: float = 0.0, effort_weight: float = 1.0, accel_weight: float = 0.0, torque_limit=None,
              passive: Sequence[str] = (), start_qd=None, goal_qd=None, waypoints: Sequence[Waypoint] = (),
              guess=None, substeps: int = 20, max_iter: int = 3000, tol: float = TOL) -> TrajoptResult:
        """Optimise a trajectory from ``start`` to ``goal`` (joint positions, (nv,)).

        Args:
            start, goal: (nv,) in the order of ``robot.coordinates`` (``self.joints``): a multi-DOF
                joint contributes one entry per coordinate (e.g. ``shoulder_z, shoulder_y, shoulder_x``).
            intervals: N (>= 2). method: one of METHODS. duration: T > 0, or its initial guess if
                ``free_time`` (then T in ``duration_bounds``, default (duration / 10, 10 duration)).
            time_weight, effort_weight: w_T, w_E of the cost (``time_weight`` needs ``free_time``).
            accel_weight: w_A of a regulariser w_A integral |qdd|^2 dt: smooths joints whose torque
                costs almost nothing (the Panda's light wrist), so N = 50 resolves their motion.
            torque_limit: overrides the model's effort limits (scalar or (nv,)).
            passive: coordinates without an actuator (tau = 0); a multi-DOF joint's name stands for
                all its coordinates.
            start_qd, goal_qd: boundary velocities (default 0: at rest, and then held, qdd = 0).
            waypoints: TCP (or other frame) positions to pass through.
            guess: None (linear interpolation in joint space on a quintic time law), an (M, nv)
                path (e.g. from a planner; resampled by arc length), or a previous TrajoptResult
                with the same N (warm start).
            substeps: RK4 steps per interval of the independent check (>= 1).
            tol: largest integration error (rad or m) of a successful result.

        Raises DeriveError (one line) for malformed requests; requests that are well formed but
        cannot be met give a result with ``success = False`` and a ``reason``.
        """
        r, nv = self.robot, self.robot.nv
        name = r.name

        def bad(what: str) -> DeriveError:
            return DeriveError(f"trajopt {name}: {what}")

        if method not in METHODS:
            raise bad(f"method must be one of {', '.join(METHODS)}, got {method!r}")
        for what, n, least in (("intervals", intervals, 2), ("substeps", substeps, 1), ("max_iter", max_iter, 1)):
            if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < least:
                raise bad(f"{what} must be an integer >= {least}, got {n!r}")
        for what, x in (("duration", duration), ("tol", tol)):
            if not _real(x) or not x > 0 or not math.isfinite(x):
                raise bad(f"{what} must be a finite number > 0, got {x!r}")
        for what, x in (("time_weight", time_weight), ("effort_weight", effort_weight), ("accel_weight", accel_weight)):
            if not _real(x) or not x >= 0 or not math.isfinite(x):
                raise bad(f"{what} must be a finite number >= 0, got {x!r}")
        if not (time_weight > 0 or effort_weight > 0):
            raise bad("time_weight and effort_weight must not both be 0")
        if time_weight and not free_time:
            raise bad("a time cost (time_weight > 0) needs free_time")
        if duration_bounds is not None:
            try:
                lo, hi = (float(x) for x in duration_bounds)
            except (TypeError, ValueError):
                lo = hi = math.nan
            if not (0 < lo <= hi < math.inf):
                raise bad(f"duration_bounds must be (lower, upper) with 0 < lower <= upper < inf, "
                          f"got {duration_bounds!r}")
            if free_time and not lo <= duration <= hi:
                raise bad(f"duration {duration:g} (the first guess of T) is outside duration_bounds [{lo:g}, {hi:g}]")
        else:
            lo, hi = duration / 10, duration * 10
        passive = (passive,) if isinstance(passive, str) else tuple(passive)
        by_joint = {j.name: [c.name for c in j.coordinates] for j in r.moving_joints}
        unknown = [j for j in passive if j not in self.joints and j not in by_joint]
        if unknown:
            raise bad(f"no joint {unknown[0]!r} to make passive (joints: {', '.join(self.joints)})")
        passive = {c for j in passive for c in (by_joint.get(j) or [j])}
        for w in waypoints:
            try:
                ok = 0.0 <= w.s <= 1.0 and len(w.position) == 3 and all(math.isfinite(float(x)) for x in w.position)
            except (TypeError, ValueError):
                ok = False
            if not ok:
                raise bad(f"a waypoint needs s in [0, 1] and 3 finite coordinates, got {w}")
            self.fk_position(w.frame)
        vec = lambda v, what: self._vector(v, what)  # noqa: E731
        start, goal = vec(start, "start"), vec(goal, "goal")
        start_qd = np.zeros(nv) if start_qd is None else vec(start_qd, "start_qd")
        goal_qd = np.zeros(nv) if goal_qd is None else vec(goal_qd, "goal_qd")
        lim = self.limits(torque_limit)
        active = [i for i, j in enumerate(self.joints) if j not in passive]
        if not active:
            raise bad("every joint is passive: nothing to actuate")
        B = np.eye(nv)[:, active]
        if isinstance(guess, TrajoptResult):
            if len(guess.t) != intervals + 1 or guess.method != method:
                raise bad("a warm start needs the same N and method")
        elif guess is not None:  # checked before the (possibly slow) transcription
            guess = _path_guess(guess, self)

        reason = self._precheck(start, goal, start_qd, goal_qd, lim, active)
        if reason:
            return _failure(r, method, reason)

        t0 = time.perf_counter()
        key = (method, intervals, (lo, hi) if free_time else None, time_weight, effort_weight, accel_weight,
               tuple(lim["effort"]), tuple(active), tuple((w.s, w.frame) for w in waypoints),
               not np.any(start_qd), not np.any(goal_qd), max_iter)
        if key not in self._nlps:  # same structure: reuse the NLP and IPOPT's derivatives, new values only
            self._nlps[key] = self._transcribe(key, lim, B)
        nlp = self._nlps[key]
        opti = nlp["opti"]
        for par, val in zip(nlp["params"], (start, goal, start_qd, goal_qd, *(w.position for w in waypoints))):
            opti.set_value(par, val)
        if not free_time:
            opti.set_value(nlp["T"], duration)
        self._set_guess(nlp, start, goal, B, guess, duration)
        self.log(f"{name}: {method}, N = {intervals}: solving")
        try:
            sol = opti.solve()
        except RuntimeError as exc:  # IPOPT did not converge: judge its last iterate all the same
            try:
                opti.stats()
            except RuntimeError:  # it never ran: a bug, not an infeasible request
                raise exc from None
            sol = opti.debug
        st = opti.stats()
        solve_time = st.get("t_wall_total", math.nan)
        build_time = time.perf_counter() - t0 - solve_time  # Opti, expansion to SX, derivatives
        v = lambda x: np.array(sol.value(x), dtype=float).reshape(x.shape)  # noqa: E731
        T = float(sol.value(nlp["T"]))
        U = v(nlp["U"])
        res = TrajoptResult(
            success=False, reason="", robot=name, joints=self.joints, method=method,
            t=np.linspace(0.0, T, intervals + 1), q=v(nlp["Q"]).T, qd=v(nlp["QD"]).T, qdd=v(nlp["QDD"]).T,
            tau=(B @ U).T, tau_mid=(B @ v(nlp["Uc"])).T if "Uc" in nlp else None,
            stats={"return_status": st["return_status"], "iterations": st["iter_count"],
                   "solve_time": solve_time, "build_time": build_time,
                   "cost": float(sol.value(opti.f))})
        self._check(res, start, goal, start_qd, goal_qd, lim, waypoints, substeps, tol)
        self.log(res.summary())
        return res

    def _vector(self, v, what: str) -> np.ndarray:
        try:
            a = np.asarray(v, dtype=float).reshape(-1)
        except (TypeError, ValueError):
            raise DeriveError(f"trajopt {self.robot.name}: {what} must be numbers, got {v!r}") from None
        if a.size != self.robot.nv:
            raise DeriveError(f"trajopt {self.robot.name}: {what} needs {self.robot.nv} values "
                              f"({', '.join(self.joints)}), got {a.size}")
        if not np.all(np.isfinite(a)):
            i = int(np.flatnonzero(~np.isfinite(a))[0])
            raise DeriveError(f"trajopt {self.robot.name}: {what} {self.joints[i]} = {a[i]:g} is not a finite number")
        return a

    def _precheck(self, start, goal, start_qd, goal_qd, lim, active) -> str:
        """The reason a request cannot be met, found before solving ('' if none is obvious)."""
        for what, x, lo, hi in (("start", start, lim["lower"], lim["upper"]), ("goal", goal, lim["lower"], lim["upper"]),
                                ("start_qd", start_qd, -lim["velocity"], lim["velocity"]),
                                ("goal_qd", goal_qd, -lim["velocity"], lim["velocity"])):
            for i, j in enumerate(self.joints):
                if not lo[i] <= x[i] <= hi[i]:
                    return f"{what} {j} = {x[i]:g} is outside the limits [{lo[i]:g}, {hi[i]:g}]"
        for what, q in (("start", start), ("goal", goal)):
            locked = self.robot.gimbal_locked(q)
            if locked:  # M is singular there: the generated forward dynamics cannot check the move
                joint = next(j for j in self.robot.joints if j.name == locked[0])
                return f"the {what} is in gimbal lock: {joint.gimbal_lock}"
        for what, q, qd in (("start", start, start_qd), ("goal", goal, goal_qd)):
            if np.any(qd):
                continue
            g = self.gravity(q)
            for i, j in enumerate(self.joints):
                cap = lim["effort"][i] if i in active else 0.0
                if abs(g[i]) > cap * (1 + LIMIT_TOL) + 1e-9:
                    kind = "passive joint" if i not in active else f"torque limit {cap:g} of"
                    return f"cannot hold the {what} at rest against gravity: {kind} {j}, needs {abs(g[i]):.4g}"
        return ""

    def _transcribe(self, key: tuple, lim: dict, B: np.ndarray) -> dict:
        """The NLP of a problem structure; start, goal, waypoints and a fixed T are parameters."""
        method, N, t_bounds, w_time, w_effort, w_accel, _, _, waypoints, rest_start, rest_goal, max_iter = key
        nv, na = B.shape
        p = ca.DM(self.p)
        u_max = lim["effort"][B.argmax(axis=0)]  # effort limits of the actuated joints
        opti = ca.Opti()
        # ---- decision variables ----
        Q = opti.variable(nv, N + 1)      # joint positions at the knots
        QD = opti.variable(nv, N + 1)     # joint velocities
        QDD = opti.variable(nv, N + 1)    # joint accelerations (implicit dynamics: no M^-1)
        U = opti.variable(na, N + 1)      # actuated torques / forces
        T = opti.variable() if t_bounds else opti.parameter()
        h = T / N
        # ---- parameters ----
        start, goal, start_qd, goal_qd = (opti.parameter(nv) for _ in range(4))
        via = [opti.parameter(3) for _ in waypoints]
        nlp = {"opti": opti, "Q": Q, "QD": QD, "QDD": QDD, "U": U, "T": T, "N": N, "method": method,
               "free_time": bool(t_bounds), "params": (start, goal, start_qd, goal_qd, *via)}
        rnea = self.rnea.map(N + 1)
        # ---- constraints ----
        opti.subject_to(rnea(Q, QD, QDD, p) == B @ U)                                 # M qdd + C qd + g = B u at the knots
        q0, q1, v0, v1, a0, a1 = Q[:, :-1], Q[:, 1:], QD[:, :-1], QD[:, 1:], QDD[:, :-1], QDD[:, 1:]
        if method == "trapezoidal":
            opti.subject_to(q1 - q0 == h / 2 * (v0 + v1))                             # trapezoidal rule for q
            opti.subject_to(v1 - v0 == h / 2 * (a0 + a1))                             # and for qd
            effort = h * (ca.sumsqr(U) - (ca.sumsqr(U[:, 0]) + ca.sumsqr(U[:, -1])) / 2)
            accel = h * (ca.sumsqr(QDD) - (ca.sumsqr(QDD[:, 0]) + ca.sumsqr(QDD[:, -1])) / 2)
        elif method == "hermite-simpson":
            Ac, Uc = opti.variable(nv, N), opti.variable(na, N)                        # midpoint qdd, u
            qc = (q0 + q1) / 2 + h / 8 * (v0 - v1)                                     # Hermite interpolation
            vc = (v0 + v1) / 2 + h / 8 * (a0 - a1)
            opti.subject_to(self.rnea.map(N)(qc, vc, Ac, p) == B @ Uc)               # dynamics at the midpoints
            opti.subject_to(q1 - q0 == h / 6 * (v0 + 4 * vc + v1))                    # Simpson's rule for q
            opti.subject_to(v1 - v0 == h / 6 * (a0 + 4 * Ac + a1))                    # and for qd
            effort = h / 6 * (ca.sumsqr(U[:, :-1]) + 4 * ca.sumsqr(Uc) + ca.sumsqr(U[:, 1:]))
            accel = h / 6 * (ca.sumsqr(QDD[:, :-1]) + 4 * ca.sumsqr(Ac) + ca.sumsqr(QDD[:, 1:]))
            nlp.update(Ac=Ac, Uc=Uc)
            self._bound(opti, Uc, -u_max, u_max)                                       # torque limits, midpoints
        else:  # rk4: stage accelerations a1 = QDD[:, k], a2..a4 as variables, u constant per interval
            A2, A3, A4 = opti.variable(nv, N), opti.variable(nv, N), opti.variable(nv, N)
            stage = self.rnea.map(N)
            tau = B @ U[:, :-1]
            opti.subject_to(stage(q0 + h / 2 * v0, v0 + h / 2 * a0, A2, p) == tau)     # stage 2
            opti.subject_to(stage(q0 + h / 2 * (v0 + h / 2 * a0), v0 + h / 2 * A2, A3, p) == tau)  # stage 3
            opti.subject_to(stage(q0 + h * (v0 + h / 2 * A2), v0 + h * A3, A4, p) == tau)  # stage 4
            opti.subject_to(q1 - q0 == h / 6 * (6 * v0 + h * (a0 + A2 + A3)))          # RK4 step for q
            opti.subject_to(v1 - v0 == h / 6 * (a0 + 2 * A2 + 2 * A3 + A4))            # and for qd
            opti.subject_to(U[:, -1] == U[:, -2])                                      # zero-order hold to T
            effort = h * ca.sumsqr(U[:, :-1])
            accel = h / 6 * (ca.sumsqr(a0) + 2 * ca.sumsqr(A2) + 2 * ca.sumsqr(A3) + ca.sumsqr(A4))
            nlp.update(A=(A2, A3, A4))
        opti.subject_to(Q[:, 0] == start)                                              # start state
        opti.subject_to(QD[:, 0] == start_qd)
        opti.subject_to(Q[:, -1] == goal)                                              # goal state
        opti.subject_to(QD[:, -1] == goal_qd)
        if rest_start:
            opti.subject_to(QDD[:, 0] == 0)                                            # held at rest
        if rest_goal:
            opti.subject_to(QDD[:, -1] == 0)
        self._bound(opti, Q, lim["lower"], lim["upper"])                               # joint limits
        self._bound(opti, QD, -lim["velocity"], lim["velocity"])                       # velocity limits
        self._bound(opti, U, -u_max, u_max)                                            # torque limits
        for (s, frame), pos in zip(waypoints, via):
            opti.subject_to(self.fk_position(frame)(Q[:, round(s * N)], p) == pos)    # TCP waypoint
        if t_bounds:
            opti.subject_to(opti.bounded(t_bounds[0], T, t_bounds[1]))                 # free final time
        opti.minimize(w_time * T + w_effort * effort + w_accel * accel)
        # expand: one SX graph for the whole NLP, 2-3x faster to evaluate than MX calling SX maps
        opti.solver("ipopt", {"expand": True, "print_time": False, "record_time": True, "detect_simple_bounds": True},
                    {"print_level": 0, "sb": "yes", "max_iter": max_iter, "linear_solver": "mumps"})
        return nlp

    @staticmethod
    def _bound(opti: ca.Opti, X, lo: np.ndarray, hi: np.ndarray) -> None:
        for i in range(X.shape[0]):
            if np.isfinite(lo[i]) and np.isfinite(hi[i]):
                opti.subject_to(opti.bounded(lo[i], X[i, :], hi[i]))
            elif np.isfinite(lo[i]):
                opti.subject_to(X[i, :] >= lo[i])
            elif np.isfinite(hi[i]):
                opti.subject_to(X[i, :] <= hi[i])

    def _set_guess(self, nlp: dict, start, goal, B, guess, duration) -> None:
        opti, N = nlp["opti"], nlp["N"]
        if isinstance(guess, TrajoptResult):  # same N and method: checked by solve
            T, q, qd, qdd, tau = guess.duration, guess.q, guess.qd, guess.qdd, guess.tau
        else:
            T = duration
            t = np.linspace(0.0, 1.0, N + 1)
            s = t**3 * (10 - 15 * t + 6 * t**2)  # quintic time law: starts and stops at rest
            q = start + np.outer(s, goal - start) if guess is None else _resample(guess, s)
            qd = np.gradient(q, T / N, axis=0)
            qdd = np.gradient(qd, T / N, axis=0)
            tau = np.array(self.rnea.map(N + 1)(q.T, qd.T, qdd.T, self.p)).T
        if nlp["free_time"]:
            opti.set_initial(nlp["T"], T)
        for key, val in (("Q", q), ("QD", qd), ("QDD", qdd), ("U", tau @ B)):
            opti.set_initial(nlp[key], val.T)
        if "Uc" in nlp:
            mid = guess.tau_mid @ B if isinstance(guess, TrajoptResult) else (tau[:-1] + tau[1:]) @ B / 2
            opti.set_initial(nlp["Uc"], mid.T)
            opti.set_initial(nlp["Ac"], (qdd[:-1] + qdd[1:]).T / 2)
        for A in nlp.get("A", ()):
            opti.set_initial(A, qdd[:-1].T)

    # ---- the independent check ----

    def _check(self, res: TrajoptResult, start, goal, start_qd, goal_qd, lim, waypoints, substeps, tol) -> None:
        sim_q, sim_qd = simulate(self.forward_dynamics, res, substeps, restart=True)
        res.integration_error = float(np.abs(sim_q - res.q).max())
        res.velocity_error = float(np.abs(sim_qd - res.qd).max())
        res.drift = float(np.abs(simulate(self.forward_dynamics, res, substeps)[0] - res.q).max())
        excess = []
        for X, lo, hi, what in ((res.q, lim["lower"], lim["upper"], "position"),
                                (res.qd, -lim["velocity"], lim["velocity"], "velocity"),
                                (res.tau, -lim["effort"], lim["effort"], "torque")):
            for i, j in enumerate(self.joints):
                scale = max(1.0, abs(lo[i]) if np.isfinite(lo[i]) else 1.0, abs(hi[i]) if np.isfinite(hi[i]) else 1.0)
                e = max(lo[i] - X[:, i].min(), X[:, i].max() - hi[i], 0.0) / scale
                excess.append((e, f"{what} limit of {j} exceeded by {e * scale:.3g}"))
        res.limit_violation, limit_msg = max(excess, key=lambda x: x[0])
        boundary = max(np.abs(res.q[0] - start).max(), np.abs(res.q[-1] - goal).max(),
                       np.abs(res.qd[0] - start_qd).max(), np.abs(res.qd[-1] - goal_qd).max())
        for w in waypoints:
            k = round(w.s * (len(res.t) - 1))
            pos = np.array(self.fk_position(w.frame)(res.q[k], self.p)).reshape(-1)
            boundary = max(boundary, float(np.abs(pos - np.asarray(w.position)).max()))
        st = res.stats
        problems = []
        if res.integration_error > tol or not np.isfinite(res.integration_error):
            problems.append(f"generated forward dynamics do not reproduce the trajectory "
                            f"(error {res.integration_error:.2g} > {tol:g})")
        if res.limit_violation > LIMIT_TOL:
            problems.append(limit_msg)
        if boundary > 1e-6:
            problems.append(f"start, goal or waypoints missed by {boundary:.2g}")
        res.success = not problems
        if problems:
            res.reason = f"IPOPT {st['return_status']} after {st['iterations']} iterations: {problems[0]}"


def solve(robot: Robot | str, start, goal, **options) -> TrajoptResult:
    """One-off ``TrajectoryOptimizer(robot).solve(start, goal, **options)``."""
    return TrajectoryOptimizer(robot).solve(start, goal, **options)


def _real(x) -> bool:
    return isinstance(x, (int, float, np.integer, np.floating)) and not isinstance(x, bool)


def _path_guess(guess, opt: TrajectoryOptimizer) -> np.ndarray:
    """A path guess as a finite (M >= 2, nv) float array, or a one-line DeriveError."""
    name, nv = opt.robot.name, opt.robot.nv
    try:
        path = np.asarray(guess, dtype=float)
    except (TypeError, ValueError):
        raise DeriveError(f"trajopt {name}: a path guess must be an (M >= 2, {nv}) array of numbers") from None
    if path.ndim != 2 or path.shape[1] != nv or len(path) < 2:
        raise DeriveError(f"trajopt {name}: a path guess must be an (M >= 2, {nv}) array, got shape {path.shape}")
    if not np.all(np.isfinite(path)):
        row = int(np.argwhere(~np.isfinite(path))[0, 0])
        raise DeriveError(f"trajopt {name}: a path guess must be finite, row {row} is not")
    return path


def _resample(path: np.ndarray, s: np.ndarray) -> np.ndarray:
    """An (M, nv) path at the path fractions s (by arc length in joint space)."""
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))])
    u = arc / arc[-1] if arc[-1] > 0 else np.linspace(0.0, 1.0, len(path))
    return np.column_stack([np.interp(s, u, path[:, i]) for i in range(path.shape[1])])


def simulate(forward_dynamics: Callable, res: TrajoptResult, substeps: int = 20,
             restart: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """Integrate qdd = forward_dynamics(q, qd, tau) under res.torque(t); q and qd at the knots.

    Classical RK4 with ``substeps`` steps per interval. Open loop from the start state, or with
    ``restart`` from every optimised knot over its own interval (the transcription's defects,
    free of the growth of errors near unstable states such as the upright pendulum).
    """
    n = len(res.t) - 1
    h = res.duration / n / substeps
    q, qd = res.q[0], res.qd[0]
    out_q, out_qd = [q], [qd]
    for k in range(n):
        if restart:
            q, qd = res.q[k], res.qd[k]
        for m in range(substeps):
            u0, um, u1 = (res.interval_torque(k, (m + c) / substeps) for c in (0.0, 0.5, 1.0))
            k1v, k1a = qd, forward_dynamics(q, qd, u0)
            k2v = qd + h / 2 * k1a
            k2a = forward_dynamics(q + h / 2 * k1v, k2v, um)
            k3v = qd + h / 2 * k2a
            k3a = forward_dynamics(q + h / 2 * k2v, k3v, um)
            k4v = qd + h * k3a
            k4a = forward_dynamics(q + h * k3v, k4v, u1)
            q = q + h / 6 * (k1v + 2 * k2v + 2 * k3v + k4v)
            qd = qd + h / 6 * (k1a + 2 * k2a + 2 * k3a + k4a)
        out_q.append(q)
        out_qd.append(qd)
    return np.array(out_q), np.array(out_qd)


def generated_forward_dynamics(robot: Robot, p: np.ndarray, log: Callable[[str], None] = lambda s: None,
                               root: Path = GENERATED) -> Callable:
    """forward_dynamics(q, qd, tau) of the robot's generated Python module.

    <root>/<robot>/python/<robot>.py when <root>/MANIFEST.json says it was generated from this
    very model; otherwise (a model not in generated/, or edited since) the Python is generated
    into a temporary folder first.
    """
    from derive.codegen.generate import generate, model_hash

    name = robot.name
    try:
        current = json.loads((root / "MANIFEST.json").read_text())["robots"][name]["model_hash"] == model_hash(robot)
    except (OSError, ValueError, KeyError):
        current = False
    path = root / name / "python" / f"{name}.py"
    if current and path.is_file():
        module = _import(path, name)
    else:
        log(f"{name}: {root / name} is missing or stale: generating it into a temporary folder for the check")
        with tempfile.TemporaryDirectory() as tmp:
            generate({name: robot}, Path(tmp) / "gen", log=lambda s: None)
            module = _import(Path(tmp) / "gen" / name / "python" / f"{name}.py", name)
    fd = module.forward_dynamics
    if module.PARAMETERS:
        return lambda q, qd, tau: fd(q, qd, tau, p)
    return fd


def _import(path: Path, name: str):
    spec = importlib.util.spec_from_file_location(f"derive_generated_{name}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
