"""Dynamic parameter identification from measured motion: ``derive identify ROBOT DATA.csv``.

tau = Y(q, qd, qdd) pi is linear in the standard parameters pi (10 per body and the actuators'
armature, viscous and Coulomb friction, :mod:`derive.symbolic.regressor`); only the base
parameters pi_b = K pi (Gautier's numerical QR, :mod:`derive.analysis.base_parameters`) are
identifiable: tau = Y_b pi_b with Y_b the base columns of Y.

- Data: a CSV with a header, columns ``t, q_<coordinate>..., [qd_<coordinate>..., qdd_...,]
  tau_<coordinate>...`` (trajopt's and excite's CSV). Missing qd and qdd are obtained from q by
  a zero-phase low-pass filter (a 4th-order Butterworth run forwards and backwards) and central
  differences; the report says so.
- Weighted least squares (Gautier): an ordinary least-squares pass gives each joint's residual
  standard deviation sigma_j; its rows are then divided by sigma_j and solved again. The
  standard deviation of each base parameter is sqrt(diag(sigma^2 (W^T W)^-1)) of the weighted
  problem; the report gives it, relative in %, the condition number of W and the residual per joint.
- ``physical=True``: the standard parameters are fitted instead, each body's 10 through the
  Cholesky factor L of its pseudo-inertia J = L L^T (J >= 0: positive mass, positive
  semi-definite inertia, the triangle inequality), the actuators' bounded below by 0, with IPOPT
  (CasADi), starting from the model's values and pulled towards them by 1e-6 of the fit
  (the directions the data does not see stay at the model's values).
- Without ``physical``, the standard parameters written back are the physically consistent ones
  closest to the model's values that reproduce the identified base parameters exactly (K pi = pi_b,
  IPOPT as above), or where none does, the model's values moved the least (in the 2-norm):
  pi = pi0 + K^+ (pi_b - K pi0), which may not load as a model (the report says so).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import casadi as ca
import numpy as np

from derive.description.robot import Robot
from derive.errors import DeriveError
from derive.symbolic.base_parameters import BaseParameters
from derive.symbolic.dynamics import NewtonEuler
from derive.symbolic.regressor import Regressor
from derive.symbolic.symbols import make_symbols

FILTER_ORDER = 4
FILTER_CUTOFF = 0.1  # of the sampling frequency (Nyquist = 0.5)


@dataclass
class Measurements:
    """Samples of one robot's motion: arrays (N, nv); ``derived`` says how qd and qdd were obtained."""

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    tau: np.ndarray
    derived: str = ""


def read_measurements(path: str | Path, coordinates: list[str], what: str = "identify") -> Measurements:
    """Read a CSV (header t, q_<c>..., [qd_<c>..., qdd_<c>...,] tau_<c>...); one-line DeriveError on any problem."""
    path = Path(path)
    if not path.is_file():
        raise DeriveError(f"{what}: {path}: no such file")
    try:
        lines = [line for line in path.read_text().splitlines() if line.strip()]
    except (OSError, UnicodeDecodeError) as exc:
        raise DeriveError(f"{what}: {path}: cannot read ({exc.__class__.__name__})") from None
    if len(lines) < 2:
        raise DeriveError(f"{what}: {path}: needs a header line and samples")
    header = [h.strip() for h in lines[0].split(",")]
    try:
        rows = np.array([[float(x) for x in line.split(",")] for line in lines[1:]])
    except ValueError:
        raise DeriveError(f"{what}: {path}: the samples must be comma-separated numbers") from None
    if rows.ndim != 2 or rows.shape[1] != len(header):
        raise DeriveError(f"{what}: {path}: every line must have {len(header)} values (as the header)")
    if not np.isfinite(rows).all():
        raise DeriveError(f"{what}: {path}: a sample is not finite (nan or inf)")
    col = {h: k for k, h in enumerate(header)}

    def block(prefix: str, required: bool) -> np.ndarray | None:
        names = [f"{prefix}_{c}" for c in coordinates]
        missing = [n for n in names if n not in col]
        if missing and (required or len(missing) < len(names)):
            raise DeriveError(f"{what}: {path}: missing column{'s' * (len(missing) > 1)} {', '.join(missing[:4])}"
                              f"{' ...' if len(missing) > 4 else ''} (header: t, q_<c>, [qd_<c>, qdd_<c>,] tau_<c> "
                              f"for c in {', '.join(coordinates)})")
        return None if missing else rows[:, [col[n] for n in names]]

    if "t" not in col:
        raise DeriveError(f"{what}: {path}: missing column t (time, s)")
    t = rows[:, col["t"]]
    q, tau = block("q", True), block("tau", True)
    qd, qdd = block("qd", False), block("qdd", False)
    derived = ""
    if qd is None or qdd is None:
        qd_f, qdd_f, derived = differentiate(t, q, path, what)
        qd = qd_f if qd is None else qd
        qdd = qdd_f if qdd is None else qdd
        trim = max(10, len(t) // 50)  # the filter's and the differences' edge effects
        t, q, qd, qdd, tau = (x[trim:-trim] for x in (t, q, qd, qdd, tau))
        derived += f"; the first and last {trim} samples dropped (edge effects)"
    return Measurements(t, q, qd, qdd, tau, derived)


def differentiate(t: np.ndarray, q: np.ndarray, path: Path | str = "", what: str = "identify") -> tuple[np.ndarray, np.ndarray, str]:
    """qd and qdd from q: zero-phase Butterworth low-pass (forwards and backwards), then central differences."""
    from scipy.signal import butter, filtfilt  # deferred: scipy is only needed here

    dt = np.diff(t)
    if len(t) < 3 * (FILTER_ORDER + 1) + 2 or not (dt > 0).all():
        raise DeriveError(f"{what}: {path}: qd and qdd are missing and cannot be derived: need at least "
                          f"{3 * (FILTER_ORDER + 1) + 2} samples at increasing times")
    if np.ptp(dt) > 1e-6 * np.mean(dt):
        raise DeriveError(f"{what}: {path}: qd and qdd are missing and the samples are not evenly spaced in t "
                          "(resample, or give qd_<c> and qdd_<c>)")
    h = float(np.mean(dt))
    b, a = butter(FILTER_ORDER, 2 * FILTER_CUTOFF)
    qf = filtfilt(b, a, q, axis=0)
    qd = np.gradient(qf, h, axis=0)
    qdd = np.gradient(qd, h, axis=0)
    note = (f"qd and qdd derived from q: zero-phase Butterworth low-pass (order {FILTER_ORDER}, cut-off "
            f"{FILTER_CUTOFF / h:.4g} Hz) and central differences at {1 / h:.4g} Hz")
    return qd, qdd, note


@dataclass
class Identification:
    """The identified base parameters and their statistics, and standard parameters reproducing them."""

    base_names: list[str]
    base_values: np.ndarray  # pi_b
    base_prior: np.ndarray  # K pi0: the model's values
    std: np.ndarray  # standard deviation of each pi_b
    condition: float  # of the weighted, stacked base regressor
    sigma: np.ndarray  # residual standard deviation per joint (the weights' inverse)
    residual_rms: np.ndarray  # per joint, of tau - Y_b pi_b
    tau_rms: np.ndarray  # per joint, of tau
    standard: np.ndarray  # pi (all standard parameters) with K pi = pi_b
    physical: bool
    samples: int
    derived: str = ""
    notes: list[str] = field(default_factory=list)

    def report(self, joints: list[str]) -> str:
        lines = [f"{self.samples} samples, {len(self.base_names)} base parameters; condition number of the weighted "
                 f"regressor {self.condition:.4g}" + ("; physically consistent fit (pseudo-inertia LMI)" if self.physical
                                                      else "")]
        if self.derived:
            lines.append(self.derived)
        width = max(len(n) for n in self.base_names)
        lines.append(f"  {'base parameter':<{width}}  {'identified':>14}  {'std dev':>11}  {'rel. %':>8}  {'model':>14}")
        for n, v, s, v0 in zip(self.base_names, self.base_values, self.std, self.base_prior):
            rel = 100 * s / abs(v) if v != 0 else math.inf
            lines.append(f"  {n:<{width}}  {v:>14.6g}  {s:>11.3g}  {rel:>8.3g}  {v0:>14.6g}")
        lines.append("torque residual per joint (rms; rms of the torque; relative):")
        for j, r, tr in zip(joints, self.residual_rms, self.tau_rms):
            lines.append(f"  {j}: {r:.4g} ({tr:.4g}; {r / tr if tr else math.inf:.3g})")
        lines.extend(self.notes)
        return "\n".join(lines)


def regressor_along(reg: Regressor, robot: Robot) -> Callable:
    """Y(q, qd, qdd) for (N, nv) arrays -> (N, nv, n): the symbolic regressor at the model's parameter
    values p (pi carries the inertial ones), mapped over the samples in one CasADi call."""
    s = reg.sym
    Ysx = reg.matrix
    if s.p.numel():
        Ysx = ca.substitute(Ysx, s.p, ca.DM([robot.parameter_defaults[n] for n in s.parameter_names]))
    f = ca.Function("Y", [s.q, s.qd, s.qdd], [Ysx])

    def Y(q, qd, qdd):  # the map's blocks side by side, one per sample
        out = np.array(f.map(q.shape[0])(q.T, qd.T, qdd.T))
        return out.reshape(robot.nv, q.shape[0], -1).transpose(1, 0, 2)
    return Y


def torques_along(robot: Robot, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
    """The robot's inverse dynamics at (N, nv) samples (N, nv): data for round trips and benchmarks."""
    s = make_symbols(robot)
    f = ca.Function("id", [s.q, s.qd, s.qdd], [NewtonEuler(robot, s).inverse_dynamics()]).map(q.shape[0])
    return np.array(f(q.T, qd.T, qdd.T)).T


def identify(Y: Callable, base: BaseParameters, pi0: np.ndarray, data: Measurements,
             physical: bool = False, bodies: int = 0) -> Identification:
    """Weighted least squares of tau = Y_b pi_b on the base parameters pi_b = K pi (see the module docstring).

    ``Y(q, qd, qdd)`` is the full regressor, (N, nv, n) for (N, nv) samples (:func:`regressor_along`);
    ``base`` gives K (r x n), the base columns and names; ``pi0`` the model's standard parameters;
    ``bodies`` is the number of 10-parameter blocks at the front of pi (the rest are the actuators'
    armature, viscous, Coulomb: kept >= 0 by ``physical``).
    """
    K = base.K
    full = np.asarray(Y(data.q, data.qd, data.qdd), dtype=float).reshape(-1, K.shape[1])
    tau = data.tau.reshape(-1)
    nv = data.tau.shape[1]
    Yb = full[:, list(base.columns)]  # Y = Y_b K: the base columns
    n_rows, r = Yb.shape
    if n_rows <= r:
        raise DeriveError(f"identify: {data.q.shape[0]} samples give {n_rows} equations for {r} base parameters: "
                          "record more")
    pib_ols = np.linalg.lstsq(Yb, tau, rcond=None)[0]
    res = (tau - Yb @ pib_ols).reshape(-1, nv)
    dof = max(res.shape[0] - r / nv, 1.0)
    sigma = np.sqrt(np.sum(res ** 2, axis=0) / dof)
    sigma = np.where(sigma > 1e-12 * max(1.0, float(np.abs(data.tau).max())), sigma, 1.0)  # noise-free joints
    w = np.tile(1.0 / sigma, res.shape[0])
    W, tw = Yb * w[:, None], tau * w
    sv = np.linalg.svd(W, compute_uv=False)
    condition = float(sv[0] / sv[-1]) if sv[-1] > 0 else math.inf
    if not np.isfinite(condition) or condition > 1e12:
        raise DeriveError(f"identify: the data does not excite every base parameter (condition number "
                          f"{condition:.3g}); record a richer motion (`derive excite`)")
    pib = np.linalg.lstsq(W, tw, rcond=None)[0]
    res_w = tw - W @ pib
    s2 = float(res_w @ res_w) / max(len(tw) - r, 1)
    cov = s2 * np.linalg.inv(W.T @ W)
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    notes = []
    if physical:
        standard = physical_fit(full, tau, w, pi0, bodies)
        pib = K @ standard
        notes.append("base parameters of the physically consistent standard parameters (K pi)")
    else:
        standard = physical_fit(None, None, None, pi0, bodies, K, pib)
        if standard is not None:
            gap = float(np.abs(K @ standard - pib).max() / max(1.0, np.abs(pib).max()))
            notes.append(f"written: the physically consistent standard parameters closest to the model's with "
                         f"K pi = pi_b (to {gap:.1e} relative)")
        else:
            standard = pi0 + np.linalg.pinv(K) @ (pib - K @ pi0)
            notes.append("no physically consistent standard parameters give these base parameters: the written ones "
                         "are the model's moved the least (use --physical for a consistent fit)")
    resid = (tau - Yb @ pib).reshape(-1, nv)
    return Identification(list(base.names), pib, K @ pi0, std, condition, sigma,
                          np.sqrt(np.mean(resid ** 2, axis=0)), np.sqrt(np.mean(data.tau ** 2, axis=0)),
                          standard, physical, data.q.shape[0], data.derived, notes)


def pseudo_inertia_params(L) -> list:
    """Standard parameters [m, hx, hy, hz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz] of the pseudo-inertia J = L L^T,
    J = [[S, h], [h^T, m]] with S = 1/2 tr(I) 1 - I (I about the body origin): I = tr(S) 1 - S."""
    J = L @ L.T
    S, h, m = J[0:3, 0:3], J[0:3, 3], J[3, 3]
    trace = S[0, 0] + S[1, 1] + S[2, 2]
    I = trace * ca.SX.eye(3) - S
    return [m, h[0], h[1], h[2], I[0, 0], I[0, 1], I[1, 1], I[0, 2], I[1, 2], I[2, 2]]


def pseudo_inertia(p: np.ndarray) -> np.ndarray:
    """J of standard parameters p (10): S = 1/2 tr(I) 1 - I."""
    m, h = p[0], np.asarray(p[1:4])
    I = np.array([[p[4], p[5], p[7]], [p[5], p[6], p[8]], [p[7], p[8], p[9]]])
    J = np.zeros((4, 4))
    J[0:3, 0:3] = 0.5 * np.trace(I) * np.eye(3) - I
    J[0:3, 3] = J[3, 0:3] = h
    J[3, 3] = m
    return J


def physical_fit(full: np.ndarray | None, tau: np.ndarray | None, w: np.ndarray | None, pi0: np.ndarray, bodies: int,
                 K: np.ndarray | None = None, pib: np.ndarray | None = None) -> np.ndarray:
    """Physically consistent standard parameters (see the module docstring): the weighted least squares of
    the data, or (``full`` None) the ones closest to ``pi0`` with K pi = ``pib`` exactly."""

    n = len(pi0)
    x, params, x0 = [], [], []
    lower = [(i, j) for j in range(4) for i in range(j, 4)]  # the 10 entries of a lower-triangular 4x4
    for b in range(bodies):
        entries = ca.SX.sym(f"L{b}", len(lower))
        Lt = ca.SX(4, 4)
        for k, (i, j) in enumerate(lower):
            Lt[i, j] = entries[k]
        x.append(entries)
        params += pseudo_inertia_params(Lt)
        J0 = pseudo_inertia(pi0[10 * b:10 * b + 10])
        w_, v_ = np.linalg.eigh(J0)
        L0 = np.linalg.cholesky(v_ @ np.diag(np.maximum(w_, 1e-9 * max(1.0, w_.max()))) @ v_.T)
        x0 += [L0[i, j] for i, j in lower]
    rest = ca.SX.sym("a", n - 10 * bodies)  # the actuators' parameters themselves, bounded below by 0
    x.append(rest)
    params += [rest[k] for k in range(n - 10 * bodies)]
    x0 += list(np.maximum(pi0[10 * bodies:], 0.0))
    X = ca.vertcat(*x)
    lbx = [-math.inf] * (10 * bodies) + [0.0] * (n - 10 * bodies)
    pi = ca.vertcat(*params)
    prior = ca.sumsqr(pi - ca.DM(pi0)) / max(float(np.dot(pi0, pi0)), 1e-12)
    problem, bounds = {"x": X}, {}
    if full is not None:
        W = full * w[:, None]
        tw = tau * w
        A, b = ca.DM(W.T @ W), ca.DM(W.T @ tw)
        fit = ca.dot(pi, A @ pi) - 2 * ca.dot(b, pi) + float(tw @ tw)
        problem["f"] = fit / (float(tw @ tw) or 1.0) + 1e-9 * prior
    else:
        problem["f"], problem["g"] = prior, ca.DM(K) @ pi - ca.DM(pib)
        bounds = {"lbg": 0.0, "ubg": 0.0}
    solver = ca.nlpsol("physical", "ipopt", problem,
                       {"ipopt.print_level": 0, "ipopt.sb": "yes", "print_time": False, "ipopt.tol": 1e-14,
                        "ipopt.max_iter": 3000})
    sol = solver(x0=ca.DM(x0), lbx=ca.DM(lbx), **bounds)
    out = np.array(ca.Function("pi", [X], [pi])(sol["x"])).ravel()
    out[10 * bodies:] = np.maximum(out[10 * bodies:], 0.0)  # IPOPT honours bounds to its tolerance only
    if full is None and np.abs(K @ out - pib).max() > 1e-6 * max(1.0, np.abs(pib).max()):
        return None  # no physically consistent standard parameters reproduce pib
    return out


def identified_entry(raw: dict, robot, names: list[str], pi: np.ndarray, source: str) -> dict:
    """The models.yaml entry ``raw`` of ``robot`` with its mass properties and actuators replaced by ``pi``.

    Each body's 10 parameters (about the body origin, body frame) go to the body's link as mass, centre
    of mass and inertia about the centre of mass; links merged into it through fixed joints become
    massless. Actuator parameters replace the joints' armature (gear ratio 1, no motor inertia),
    viscous and Coulomb friction. ``names`` are the regressor's parameter names (``m_<link>``, ...,
    ``Ia_<coordinate>``, ``fv_<coordinate>``, ``fc_<coordinate>``).
    """
    import copy

    if "links" not in raw or "joints" not in raw:
        raise DeriveError(f"identify: robot '{robot.name}' is a DH table; identification writes link and joint "
                          "entries: write it with links and joints first")
    entry = copy.deepcopy(raw)
    value = dict(zip(names, (float(v) for v in pi)))
    links = {link["name"]: link for link in entry["links"]}
    fixed_below: dict[str, list[str]] = {}
    body_of = {robot.root: robot.root}
    for j in robot.joints:
        body_of[j.child] = body_of[j.parent] if j.type == "fixed" else j.child
    for link, body in body_of.items():
        fixed_below.setdefault(body, []).append(link)
    for body, members in fixed_below.items():
        if f"m_{body}" not in value:
            continue
        m = value[f"m_{body}"]
        h = np.array([value[f"{k}_{body}"] for k in ("mx", "my", "mz")])
        I = np.array([[value[f"Ixx_{body}"], value[f"Ixy_{body}"], value[f"Ixz_{body}"]],
                      [value[f"Ixy_{body}"], value[f"Iyy_{body}"], value[f"Iyz_{body}"]],
                      [value[f"Ixz_{body}"], value[f"Iyz_{body}"], value[f"Izz_{body}"]]])
        c = h / m if m > 0 else np.zeros(3)
        Ic = I - m * (float(c @ c) * np.eye(3) - np.outer(c, c))
        for link in members:
            fields = links[link]
            for key in ("mass", "com", "inertia", "inertia_rpy"):
                fields.pop(key, None)
            if link == body:
                fields.update({"mass": m, "com": [float(x) for x in c],
                               "inertia": {"ixx": Ic[0, 0], "ixy": Ic[0, 1], "ixz": Ic[0, 2], "iyy": Ic[1, 1],
                                           "iyz": Ic[1, 2], "izz": Ic[2, 2]}})
    for joint in entry["joints"]:
        coords = [c.name for c in robot.joint_coordinates if c.joint == joint["name"]]
        acts = [{"armature": value.get(f"Ia_{c}", 0.0), "viscous": value.get(f"fv_{c}", 0.0),
                 "coulomb": value.get(f"fc_{c}", 0.0)} for c in coords]
        acts = [{k: v for k, v in a.items() if v != 0.0} for a in acts]
        joint.pop("actuator", None)
        if any(acts):
            joint["actuator"] = acts[0] if len(acts) == 1 else acts
    entry["description"] = f"{robot.name} with identified dynamic parameters"
    entry["source"] = source
    return entry
