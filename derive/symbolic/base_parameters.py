"""Base inertial parameters: the identifiable linear combinations of pi (Gautier's numerical QR).

The columns of the regressor Y(q, qd, qdd) (:mod:`derive.symbolic.regressor`) are not independent:
some are zero at every state (a parameter that never acts, e.g. the inertia of the first link about
axes other than its joint's) and others are fixed linear combinations of the rest (the mass of a
link acts on the joints above it as inertia of its parent would). With Y stacked at random states
into W (rows: states x joints), the numerical rank r of W is the number of base parameters, and a
choice of r independent columns Y_1 gives

    Y = Y_1 [1  beta] P^T  for every state,   so   tau = Y pi = Y_1 pi_b,   pi_b = pi_1 + beta pi_2,

pi_1 being the parameters of the chosen columns and pi_2 those of the others (beta = R_1^-1 R_2 of a
QR factorisation of W with the chosen columns first).

Which columns? The rank comes from a QR with column pivoting of W with its columns scaled to unit
norm (Gautier 1990). Pivoting picks columns by size, which is arbitrary between equals and unstable
between near-equals; here the base columns are instead the first independent columns in a fixed
order of preference (bodies from the root out, each body's inertia before its first moment before
its mass, then the actuators): an unpivoted QR of W in that order, a column being independent when
its distance to the span of those before it is above the rank tolerance. That choice is structural
(it depends on the model's geometry, not on the random states), and regroups each link's
parameters into its parent's as Khalil and Bennis' rules do (e.g. ``ZZR_link1 = Izz_link1 +
Iyy_link2 + ...``). The count must equal the pivoted rank, and the result is checked on a second
seeded set of states (same rank, W_2 = W_1 beta to 1e-9): otherwise the model is refused.

A base parameter whose combination is its own column alone keeps the standard name; a regrouped one
is named after its leading parameter in Khalil's style, ``ZZR_<link>``, ``MXR_<link>``, ``IAR_<joint>``.
Coefficients are numbers at the model's parameter values: polynomials in its constant lengths and
angles, so each is cleaned to the shortest decimal within a few times the least-squares noise of the
computed value (0.1225 for 0.35^2, not 0.12249999999999997): exact where the lengths are short decimals,
and the same digits from one machine to the next.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca
import numpy as np

from derive.description.expr import evaluate
from derive.description.robot import Robot
from derive.errors import DeriveError
from derive.symbolic.dynamics import NewtonEuler
from derive.symbolic.regressor import INERTIAL, Regressor
from derive.symbolic.symbols import make_symbols

SEED = 0
RANK_TOL = 1e-8  # a unit column farther than this from the span of the others is independent
GAP = 1e3  # the smallest kept distance must exceed the largest rejected one this many times
SNAP = 1e-10  # |beta| (scaled to unit columns) below this is zero
CLEAN = 3e-14  # coefficients: the shortest decimal within this of the computed one, in units of the unit
# columns (beta / (|w_2| / |w_1|)): a few times the least-squares noise there (~2e-15 to 2e-14)
PREFERENCE = ("Ixx", "Ixy", "Ixz", "Iyz", "Izz", "Iyy", "mx", "my", "mz", "m")
"""A body's parameters in the order the base columns are chosen: the first independent ones stay."""
KHALIL = {"m": "M", "mx": "MX", "my": "MY", "mz": "MZ", "Ixx": "XX", "Ixy": "XY", "Iyy": "YY", "Ixz": "XZ",
          "Iyz": "YZ", "Izz": "ZZ", "Ia": "IA", "fv": "FV", "fc": "FC"}
LATEX = {"m": "m", "mx": "m c_x", "my": "m c_y", "mz": "m c_z", "Ixx": "I_{xx}", "Ixy": "I_{xy}", "Iyy": "I_{yy}",
         "Ixz": "I_{xz}", "Iyz": "I_{yz}", "Izz": "I_{zz}", "Ia": "I_a", "fv": "f_v", "fc": "f_c"}


def states(robot: Robot, count: int, seed: int) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """``count`` seeded (q, qd, qdd): joints uniform in the joint box, a uniform unit base quaternion."""
    rng = np.random.default_rng(seed)
    lo, hi = robot.joint_box()
    out = []
    for _ in range(count):
        q = rng.uniform(lo, hi)
        if robot.floating:
            quat = rng.normal(size=4)
            q[3:7] = quat / np.linalg.norm(quat)
        out.append((q, rng.normal(size=robot.nv), rng.normal(size=robot.nv)))
    return out


def clean(x: float, tol: float) -> float:
    """The shortest decimal within ``tol`` of x: 0.1225 for 0.12249999999999997."""
    if x == 0.0 or not math.isfinite(x):
        return x
    for digits in range(1, 18):
        y = float(f"{x:.{digits}g}")
        if abs(y - x) <= tol:
            return y
    return x


def number(x: float) -> str:
    """A coefficient as text: ``0.25``, ``-1``, ``1.5e-05``."""
    return f"{x:.15g}" if x != int(x) or abs(x) >= 1e15 else str(int(x))


def latex_number(x: float) -> str:
    """A coefficient in LaTeX: ``0.25``, ``1.5 \\cdot 10^{-5}``."""
    mantissa, e, exponent = number(x).partition("e")
    return mantissa + (f" \\cdot 10^{{{int(exponent)}}}" if e else "")


def latex_symbol(name: str) -> str:
    """A standard or base parameter's name in LaTeX: ``I_{zz}^{\\mathrm{link2}}``, ``(m c_x)^{...}``,
    ``\\mathrm{ZZR}^{\\mathrm{link1}}``."""
    kind, _, owner = name.partition("_")
    owner = "^{\\mathrm{" + owner.replace("_", "\\_") + "}}"
    if kind in ("mx", "my", "mz"):  # the first moment is a product
        return f"({LATEX[kind]}){owner}"
    if kind in LATEX:
        return LATEX[kind] + owner
    return f"\\mathrm{{{kind}}}{owner}"  # a regrouped base parameter, ZZR


def _sum(terms, num, space: str) -> str:
    """``a - 0.5 b + c`` of (coefficient, symbol) pairs; coefficients +-1 are not written."""
    out = ""
    for i, (c, symbol) in enumerate(terms):
        mag = "" if abs(c) == 1.0 else num(abs(c)) + space
        sign = ("-" if c < 0 else "") if i == 0 else (" - " if c < 0 else " + ")
        out += sign + mag + symbol
    return out


@dataclass(frozen=True)
class BaseParameters:
    """The base parameters of one robot: pi_b = K pi (r x n_pi) and Y_b = Y[:, columns], Y_b pi_b = Y pi."""

    robot: str
    parameters: tuple[str, ...]  # pi's names (regressor.parameter_names)
    columns: tuple[int, ...]  # Y's base columns, in pi's order: pi_b[k] leads with pi[columns[k]]
    names: tuple[str, ...]  # pi_b's names
    K: np.ndarray  # (r, n_pi): pi_b = K pi; K[:, columns] = 1
    seed: int
    samples: int  # states stacked

    @property
    def rank(self) -> int:
        return len(self.columns)

    @property
    def unidentifiable(self) -> tuple[str, ...]:
        """Standard parameters that enter no base parameter (their columns of Y are zero)."""
        return tuple(n for k, n in enumerate(self.parameters) if not np.any(self.K[:, k]))

    def values(self, pi) -> np.ndarray:
        """pi_b (r) of the standard parameters pi (n_pi)."""
        return self.K @ np.asarray(pi, dtype=float)

    def combination(self, k: int) -> tuple[tuple[str, float], ...]:
        """pi_b[k] as (standard parameter, coefficient) pairs, its leading parameter first."""
        lead = self.columns[k]
        rest = [j for j in np.flatnonzero(self.K[k]) if j != lead]
        return ((self.parameters[lead], 1.0),) + tuple((self.parameters[j], float(self.K[k, j])) for j in rest)

    def equations(self) -> list[str]:
        """``ZZR_link1 = Izz_link1 + Iyy_link2 + 0.1225 m_link2``, one per base parameter."""
        return [f"{name} = " + _sum(((c, std) for std, c in self.combination(k)), number, " ")
                for k, name in enumerate(self.names)]

    def latex(self) -> str:
        """The combinations as a LaTeX ``align*`` environment: ``\\mathrm{ZZR}^{\\mathrm{link1}} &= I_{zz}^{...} + ...``."""
        lines = [f"{latex_symbol(name)} &= " + _sum(((c, latex_symbol(std)) for std, c in self.combination(k)),
                                                   latex_number, "\\,")
                 for k, name in enumerate(self.names)]
        return "\\begin{align*}\n" + " \\\\\n".join(lines) + "\n\\end{align*}\n"

    def manifest(self, pi: np.ndarray) -> list[dict]:
        """Plain data per base parameter: name, its value at pi, its column of Y and its combination."""
        values = [math.fsum(float(x) * float(pi[j]) for j, x in enumerate(row) if x) for row in self.K]
        return [{"name": n, "value": v, "column": int(c),
                 "combination": [{"parameter": p, "coefficient": x} for p, x in self.combination(k)]}
                for k, (n, v, c) in enumerate(zip(self.names, values, self.columns))]


def preference(bodies: int, size: int) -> list[int]:
    """pi's indices in the order base columns are chosen: bodies in order, each by PREFERENCE; then actuators."""
    order = [10 * b + INERTIAL.index(k) for b in range(bodies) for k in PREFERENCE]
    return order + list(range(10 * bodies, size))


def _stack(f: ca.Function, robot: Robot, p: list[float], count: int, seed: int) -> np.ndarray:
    return np.vstack([np.array(f(q, qd, qdd, p)) for q, qd, qdd in states(robot, count, seed)])


def base_parameters(robot: Robot, params: dict | None = None, regressor: Regressor | None = None,
                    actuators: bool = True, seed: int = SEED) -> BaseParameters:
    """The base parameters of ``robot`` at its parameters' defaults (or ``params``).

    ``regressor``: an already derived :class:`Regressor` of the robot (else one is derived).
    ``actuators=False`` leaves out the actuator parameters (the inertial ones only, as Pinocchio's
    ``computeJointTorqueRegressor`` has them).
    """
    from scipy.linalg import qr

    reg = regressor or Regressor(NewtonEuler(robot, make_symbols(robot)))
    s = reg.sym
    p = reg.parameter_vector(params)
    names = reg.names
    n = len(names) if actuators else 10 * len(reg.bodies)
    names = names[:n]
    f = ca.Function("Y", [s.q, s.qd, s.qdd, s.p], [reg.matrix[:, :n]])
    count = max(10, math.ceil(5 * n / robot.nv))
    W = _stack(f, robot, p, count, seed)
    norms = np.linalg.norm(W, axis=0)
    live = norms > 1e-13 * max(norms.max(), 1e-300)
    scale = np.where(live, norms, 1.0)
    Wn = W / scale
    # the rank: a QR with column pivoting of the live unit columns
    R = qr(Wn[:, live], mode="r", pivoting=True)[0]
    d = np.abs(np.diag(R))
    rank = int(np.sum(d > RANK_TOL * d[0])) if d.size else 0
    # the base columns: the first independent ones in the order of preference
    order = [j for j in preference(len(reg.bodies), n) if live[j]]
    Rg = np.linalg.qr(Wn[:, order], mode="r")
    dist = np.abs(np.diag(Rg))
    threshold = RANK_TOL * (d[0] if d.size else 1.0)
    keep = dist > threshold
    columns = tuple(sorted(order[k] for k in np.flatnonzero(keep)))
    if len(columns) != rank or (keep.any() and (~keep).any() and dist[keep].min() < GAP * dist[~keep].max()):
        raise _degenerate(robot, params, names, "no clear numerical rank of the regressor (pivoted QR: "
                          f"{rank}, chosen columns: {len(columns)})", _borderline(order, dist, threshold))
    dependent = [j for j in range(n) if j not in columns]
    B = np.linalg.lstsq(Wn[:, list(columns)], Wn[:, dependent], rcond=None)[0]
    B[np.abs(B) < SNAP] = 0.0
    unit = scale[dependent][None, :] / scale[list(columns)][:, None]  # beta per unit of B
    beta = B * unit
    K = np.zeros((len(columns), n))
    K[np.arange(len(columns)), list(columns)] = 1.0
    K[:, dependent] = [[clean(x, CLEAN * u) for x, u in zip(row, urow)] for row, urow in zip(beta, unit)]
    # check on other states: the same rank, and the dependent columns the same combinations
    W2 = _stack(f, robot, p, count, seed + 1)
    s2 = np.linalg.svd(W2 / np.where(live, np.linalg.norm(W2, axis=0), 1.0), compute_uv=False)
    rank2 = int(np.sum(s2 > RANK_TOL * s2[0])) if s2.size else 0
    err = np.abs(W2[:, list(columns)] @ K - W2).max() / max(np.abs(W2).max(), 1e-300)
    if rank2 != rank or err > 1e-9:
        Wn2 = W2 / np.where(live, np.linalg.norm(W2, axis=0), 1.0)
        dist2 = np.abs(np.diag(np.linalg.qr(Wn2[:, order], mode="r")))
        column_err = np.abs(W2[:, list(columns)] @ K - W2).max(axis=0) / max(np.abs(W2).max(), 1e-300)
        involved = (_borderline(order, dist, threshold)
                    + _borderline(order, dist2, RANK_TOL * (s2[0] if s2.size else 1.0)))
        involved += [(j, float(column_err[j])) for j in np.argsort(-column_err) if column_err[j] > 1e-9]
        raise _degenerate(robot, params, names, f"the base parameters found at one set of states do not hold at "
                          f"another (rank {rank} vs {rank2}, residual {err:.1e})", involved)
    return BaseParameters(robot.name, names, columns, _names(names, columns, K), K, seed, count)


def _borderline(order: list[int], dist: np.ndarray, threshold: float) -> list[tuple[int, float]]:
    """(column, distance / threshold) of the columns near the rank tolerance: neither clearly independent
    of the columns before them nor clearly dependent (within a factor GAP of the threshold)."""
    near = [(order[k], float(x / threshold)) for k, x in enumerate(dist) if threshold / GAP < x < threshold * GAP]
    return sorted(near, key=lambda item: abs(math.log(max(item[1], 1e-300))))


def _suspects(robot: Robot, params: dict | None) -> list[str]:
    """Joint axes and origins with a component nearly but not exactly zero: 1e-5 of the axis' largest, or
    1e-6 m or rad; what usually makes a model nearly degenerate (an axis almost parallel to another)."""
    env = {**robot.parameter_defaults, **(params or {})}
    out = []
    for j in robot.joints:
        for name, vec, tol, relative in (("axis", j.axis, 1e-5, True), ("axis2", j.axis2, 1e-5, True),
                                         ("origin xyz", j.origin.xyz, 1e-6, False),
                                         ("origin rpy", j.origin.rpy, 1e-6, False)):
            if vec is None or j.type == "fixed" and name.startswith("axis"):
                continue
            try:
                v = [float(evaluate(x, env)) for x in vec]
            except (ValueError, TypeError, ArithmeticError):
                continue
            scale = max(abs(x) for x in v) if relative else 1.0
            if any(0.0 < abs(x) < tol * scale for x in v):
                out.append(f"joint {j.name} {name} [{', '.join(f'{x:.3g}' for x in v)}]")
    return out


def _degenerate(robot: Robot, params: dict | None, names: tuple[str, ...], problem: str,
                involved: list[tuple[int, float]]) -> DeriveError:
    """The refusal of a nearly degenerate model: the robot, the parameters and joints involved, the fix."""
    seen: list[int] = []
    for j, _ in involved:
        if j not in seen:
            seen.append(j)
    shown = [names[j] for j in seen[:6]] + (["..."] if len(seen) > 6 else [])
    moved_by = {j.child: j.name for j in robot.joints}
    moved_by.update({c.name: c.joint for c in robot.joint_coordinates})
    joints: list[str] = []
    for j in seen:
        joint = moved_by.get(names[j].partition("_")[2])
        if joint and joint not in joints:
            joints.append(joint)
    text = f"robot '{robot.name}': {problem}: its geometry is nearly degenerate"
    if shown:
        text += (f"; the regressor columns of {', '.join(shown)} are nearly, not exactly, dependent on the others"
                 + (f" (links moved by joint{'s' * (len(joints) > 1)} {', '.join(joints)})" if joints else ""))
    suspects = _suspects(robot, params)
    if suspects:
        text += f"; suspect {'; '.join(suspects[:4])}"
    return DeriveError(text + ": make nearly parallel joint axes exactly parallel and nearly zero offsets exactly 0 "
                       "(or clearly apart, beyond about 1e-6)")


def _names(parameters: tuple[str, ...], columns: tuple[int, ...], K: np.ndarray) -> tuple[str, ...]:
    out = []
    for k, c in enumerate(columns):
        name = parameters[c]
        if np.count_nonzero(K[k]) > 1:
            kind, _, owner = name.partition("_")
            name = f"{KHALIL.get(kind, kind)}R_{owner}"
        out.append(name)
    return tuple(out)
