"""Excitation trajectories for identification: ``derive excite ROBOT``.

Each coordinate follows a finite Fourier series of base frequency w_f = 2 pi / T (Swevers et al.),

    q_j(t) = q0_j + sum_{l=1..L} a_jl / (w_f l) sin(w_f l t) - b_jl / (w_f l) cos(w_f l t),

periodic, so the controller can repeat it and average. The coefficients minimise the condition
number of the stacked base regressor W = [Y_b(q(t_k), qd(t_k), qdd(t_k))]_k over the samples of one
period, subject to the position, velocity and acceleration limits (linear in the coefficients) and
the effort limits (through inverse dynamics) at every sample, each kept 5 % inside. The gradient of
log cond(W) is exact: W's Jacobian with respect to the coefficients comes from CasADi (a mapped SX
function of the trajectory), and d sigma_i = u_i^T dW v_i. SciPy's SLSQP solves the constrained
problem; the start is a random Fourier trajectory using half of every limit, whose condition number
is reported next to the optimised one.
"""

from __future__ import annotations

import io
import math
from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import numpy as np

from derive.errors import DeriveError
from derive.filesystem import write_atomically
from derive.symbolic.base_parameters import dependencies_text, near_dependencies


@dataclass
class Excitation:
    """The optimised trajectory sampled at ``t``, its condition number, and a random one's for comparison."""

    robot: str
    joints: tuple[str, ...]
    period: float
    harmonics: int
    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    tau: np.ndarray
    condition: float
    random_condition: float
    iterations: int
    limits_ok: bool
    worst_limit: float  # max over samples of |value| / limit, per kind (<= 1 within limits)
    dependencies: str = ""  # the smallest singular values of W_b and their base-parameter combinations

    def table(self) -> tuple[list[str], np.ndarray]:
        names = ["t"] + [f"{k}_{j}" for k in ("q", "qd", "qdd", "tau") for j in self.joints]
        return names, np.column_stack([self.t, self.q, self.qd, self.qdd, self.tau])

    def csv(self) -> str:
        """The trajectory as CSV text: a header (t, q_<c>..., qd_<c>..., qdd_<c>..., tau_<c>...), one sample a line."""
        names, rows = self.table()
        text = io.StringIO()
        np.savetxt(text, rows, delimiter=",", header=",".join(names), comments="", fmt="%.12g")
        return text.getvalue()

    def write_csv(self, path: str | Path) -> Path:
        """Write :meth:`csv` to ``path`` atomically (the old file stays whole on any failure); returns it."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        return write_atomically(path, self.csv(), "excitation CSV")

    def summary(self) -> str:
        return (f"{self.robot}: excitation of period {self.period:g} s, {self.harmonics} harmonics, "
                f"{len(self.t)} samples: cond(W_b) = {self.condition:.4g} (a random Fourier trajectory within the "
                f"same limits: {self.random_condition:.4g}); {self.iterations} SLSQP iterations; within every limit: "
                f"{'yes' if self.limits_ok else 'NO'} (worst use {self.worst_limit:.3f})"
                + (f"\n{self.dependencies}" if self.dependencies else ""))


def fourier_basis(t: np.ndarray, period: float, harmonics: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(P, V, A): q = P theta_j, qd = V theta_j, qdd = A theta_j for one coordinate's theta_j = [q0, a_1..L, b_1..L]."""
    wf = 2 * math.pi / period
    n = len(t)
    P, V, A = np.zeros((n, 1 + 2 * harmonics)), np.zeros((n, 1 + 2 * harmonics)), np.zeros((n, 1 + 2 * harmonics))
    P[:, 0] = 1.0
    for l in range(1, harmonics + 1):
        w = wf * l
        s, c = np.sin(w * t), np.cos(w * t)
        P[:, l], P[:, harmonics + l] = s / w, -c / w
        V[:, l], V[:, harmonics + l] = c, s
        A[:, l], A[:, harmonics + l] = -w * s, w * c
    return P, V, A


def excite(robot, Yb: ca.SX, q: ca.SX, qd: ca.SX, qdd: ca.SX, tau_id: ca.SX | None = None, period: float = 10.0,
           harmonics: int = 5, samples: int = 100, seed: int = 0, max_iterations: int = 200,
           log=lambda s: None, names: tuple[str, ...] = ()) -> Excitation:
    """Optimise the Fourier coefficients (see the module docstring). ``Yb`` and ``tau_id`` are SX of q, qd, qdd.

    ``names``: the base parameters (Yb's columns); with them the result reports the near-dependencies of the
    optimised W_b (its smallest singular values and their combinations).
    """
    from scipy.optimize import minimize  # deferred: only excite needs it

    robot.require_fixed_base("derive excite")
    coords = robot.coordinates
    n = len(coords)
    lo, hi = robot.joint_box()
    lo, hi = np.array(lo), np.array(hi)
    vmax = np.array([c.limits.velocity if c.limits.velocity else math.inf for c in coords])
    emax = np.array([c.limits.effort if c.limits.effort else math.inf for c in coords])
    amax = np.where(np.isfinite(vmax), 2.0 * vmax, math.inf)  # no acceleration limits in URDF: 2 x velocity per s
    t = np.linspace(0.0, period, samples, endpoint=False)
    P, V, A = fourier_basis(t, period, harmonics)
    m = 1 + 2 * harmonics
    theta = ca.SX.sym("theta", n * m)
    th = ca.reshape(theta, m, n)  # column j: coordinate j's coefficients
    Qs, Vs, As = ca.DM(P) @ th, ca.DM(V) @ th, ca.DM(A) @ th  # samples x n
    f_yb = ca.Function("yb", [q, qd, qdd], [Yb])
    r = Yb.shape[1]
    fmap = f_yb.map(samples)
    W = fmap(Qs.T, Vs.T, As.T)  # nv x (r samples)
    Wst = ca.vertcat(*[W[:, k * r:(k + 1) * r] for k in range(samples)])  # (samples nv) x r
    fW = ca.Function("W", [theta], [Wst])
    # d sigma_i = u_i^T dW v_i: the gradient of log(sigma_1 / sigma_r) is that of the scalar
    # u_1^T W v_1 / sigma_1 - u_r^T W v_r / sigma_r with the singular pairs held fixed (reverse mode)
    U = ca.SX.sym("U", Wst.shape[0], 2)
    Vv = ca.SX.sym("V", r, 2)
    wts = ca.SX.sym("w", 2)
    scalar = wts[0] * ca.dot(U[:, 0], Wst @ Vv[:, 0]) - wts[1] * ca.dot(U[:, 1], Wst @ Vv[:, 1])
    fgrad = ca.Function("g", [theta, U, Vv, wts], [ca.gradient(scalar, theta)])
    ftau = None
    if tau_id is not None and np.isfinite(emax).any():
        tmap = ca.Function("tau", [q, qd, qdd], [tau_id]).map(samples)
        T = tmap(Qs.T, Vs.T, As.T)
        ftau = ca.Function("T", [theta], [ca.vec(T), ca.jacobian(ca.vec(T), theta)])

    def cond_and_grad(x):
        Wv = np.array(fW(x))
        Us, s, Vt = np.linalg.svd(Wv, full_matrices=False)
        if s[-1] <= 0:
            return 1e6, np.zeros_like(x)
        g = fgrad(x, np.column_stack([Us[:, 0], Us[:, -1]]), np.column_stack([Vt[0], Vt[-1]]), [1 / s[0], 1 / s[-1]])
        return float(np.log(s[0] / s[-1])), np.array(g).ravel()

    # linear limits at every sample: lo <= P th <= hi, |V th| <= vmax, |A th| <= amax
    G, h = [], []
    for j in range(n):
        sel = np.zeros((m, n * m))
        sel[:, j * m:(j + 1) * m] = np.eye(m)
        for B, bound_lo, bound_hi in ((P, lo[j], hi[j]), (V, -vmax[j], vmax[j]), (A, -amax[j], amax[j])):
            if np.isfinite(bound_hi):
                G.append(-(B @ sel))
                h.append(np.full(samples, bound_hi))
            if np.isfinite(bound_lo):
                G.append(B @ sel)
                h.append(np.full(samples, -bound_lo))
    Gm, hv = np.vstack(G), np.concatenate(h)
    margin = 0.95  # stay 5 % inside every limit
    cons = [{"type": "ineq", "fun": lambda x: (Gm @ x) + margin * hv, "jac": lambda x: Gm}]
    if ftau is not None:
        big = np.tile(emax, samples)
        finite = np.isfinite(big)

        def torque(x):
            T, _ = ftau(x)
            T = np.array(T).ravel()[finite]
            return np.concatenate([margin * big[finite] - T, margin * big[finite] + T])

        def torque_jac(x):
            _, J = ftau(x)
            J = np.array(J)[finite]
            return np.vstack([-J, J])

        cons.append({"type": "ineq", "fun": torque, "jac": torque_jac})
    rng = np.random.default_rng(seed)
    x0 = random_coefficients(rng, n, m, harmonics, period, lo, hi, vmax, amax, P, V, A)
    random_condition = math.exp(cond_and_grad(x0)[0])
    log(f"excite {robot.name}: {n} coordinates x {m} coefficients, {samples} samples of {period:g} s; "
        f"random start cond = {random_condition:.4g}")
    res = minimize(cond_and_grad, x0, jac=True, method="SLSQP", constraints=cons,
                   options={"maxiter": max_iterations, "ftol": 1e-8})
    x = res.x
    th_x = x.reshape(n, m).T
    qs, qds, qdds = P @ th_x, V @ th_x, A @ th_x
    taus = np.zeros_like(qs)
    if tau_id is not None:
        taus = np.array(ca.Function("tau", [q, qd, qdd], [tau_id]).map(samples)(qs.T, qds.T, qdds.T)).T
    use = [np.max(np.abs(qs - (lo + hi) / 2) / ((hi - lo) / 2)) if np.all(np.isfinite(hi - lo)) else 0.0,
           np.max(np.abs(qds) / vmax), np.max(np.abs(qdds) / amax), np.max(np.abs(taus) / emax)]
    worst = float(np.nanmax([u for u in use if np.isfinite(u)] or [0.0]))
    within = bool(np.all(qs >= lo - 1e-9) and np.all(qs <= hi + 1e-9) and np.all(np.abs(qds) <= vmax + 1e-9)
                  and np.all(np.abs(qdds) <= amax + 1e-9) and np.all(np.abs(taus) <= emax + 1e-9))
    cond = math.exp(cond_and_grad(x)[0])
    deps = dependencies_text(near_dependencies(np.array(fW(x)), names)) if names else ""
    return Excitation(robot.name, tuple(c.name for c in coords), period, harmonics, t, qs, qds, qdds, taus, cond,
                      random_condition, int(res.nit), within, worst, deps)


def random_coefficients(rng, n, m, harmonics, period, lo, hi, vmax, amax, P, V, A) -> np.ndarray:
    """Random Fourier coefficients scaled to use at most half of every limit (the optimiser's start and the
    comparison: a random trajectory of the same length within the same limits)."""
    x = np.zeros((m, n))
    for j in range(n):
        c = rng.normal(size=m)
        c[0] = 0.0
        centre = 0.5 * (lo[j] + hi[j]) if np.isfinite(lo[j] + hi[j]) else 0.0
        scale = []
        for B, bound in ((P, 0.5 * (hi[j] - lo[j])), (V, vmax[j]), (A, amax[j])):
            peak = np.max(np.abs(B[:, 1:] @ c[1:]))
            if np.isfinite(bound) and peak > 0:
                scale.append(bound / peak)
        c *= 0.5 * min(scale) if scale else 0.5
        c[0] = centre
        x[:, j] = c
    return x.T.reshape(-1)


MAX_SEED = 2**63 - 1
MAX_ITERATIONS = 100_000
PERIOD_RANGE = (0.01, 3600.0)  # s: a controller repeats the period; beyond an hour is not an excitation


def check_options(robot: str, period: float, harmonics: int, samples: int, seed: int = 0,
                  max_iterations: int = 200) -> None:
    """One-line DeriveError for an option of ``derive excite`` out of its range."""
    if not (math.isfinite(period) and PERIOD_RANGE[0] <= period <= PERIOD_RANGE[1]):
        raise DeriveError(f"excite {robot}: --period must be {PERIOD_RANGE[0]:g} to {PERIOD_RANGE[1]:g} s, "
                          f"got {period:g}")
    if harmonics < 1 or harmonics > 20:
        raise DeriveError(f"excite {robot}: --harmonics must be 1 to 20, got {harmonics}")
    if samples < 10 or samples > 2000:
        raise DeriveError(f"excite {robot}: --samples must be 10 to 2000, got {samples}")
    if seed < 0 or seed > MAX_SEED:
        raise DeriveError(f"excite {robot}: --seed must be 0 to 2^63 - 1, got {seed}")
    if max_iterations < 1 or max_iterations > MAX_ITERATIONS:
        raise DeriveError(f"excite {robot}: --iterations must be 1 to {MAX_ITERATIONS:,}, got {max_iterations}")
