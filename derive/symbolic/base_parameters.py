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

The numerical rank, stated: RANK_TOL = 1e-4 relative to the regressor's scale. Columns of the same
kind share units (masses, first moments, inertias, armatures, viscous, Coulomb: KINDS); each kind's
columns are divided by the largest norm among them, so the largest column of every kind has norm 1,
and a column is independent when its distance to the span of the columns before it exceeds RANK_TOL:
its own effect, beyond what the others explain, is more than 1e-4 of the strongest effect of its kind.
A 1e-5 rad tilt therefore adds no spurious base parameter: tilting the first joint of an arm 1e-5 rad
off the vertical (the Kinova Gen3's URDF writes 1.5708 for pi/2, 3.7e-6 off) makes gravity act on that
link's first moments about 1e-5 as strongly as on the others', which no measurement resolves. What the
rule sets aside while clearly above rounding (NEAR_FLOOR = 1e-11 on the same scale) is reported as a
near-dependency (:attr:`BaseParameters.near`): Y_1 [1 beta] P^T then reproduces Y to that relative size
rather than to rounding (such a column that itself acts at most RANK_TOL of its kind's scale enters no
base parameter, as an exactly zero one). Exact geometry leaves nothing there (the shipped robots' kept distances are
above 1e-2, their set-aside ones below 1e-13), and their base parameters are those of the former
rule (1e-8 on unit columns).

Which columns? Gautier (1990) takes them from a QR with column pivoting. Pivoting picks columns by
size, which is arbitrary between equals and unstable between near-equals; here the base columns are
instead the first independent columns in a fixed order of preference (bodies from the root out, each body's inertia before its first moment before
its mass, then the actuators): Gram-Schmidt in that order, a column being independent when its
distance to the span of the independent ones before it is above the rank tolerance. That choice is structural
(it depends on the model's geometry, not on the random states), and regroups each link's
parameters into its parent's as Khalil and Bennis' rules do (e.g. ``ZZR_link1 = Izz_link1 +
Iyy_link2 + ...``). The result is checked on a second seeded set of states (W_2 = W_1 beta to 1e-9,
or to 10 times the largest near-dependency): otherwise the model is refused.

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
from typing import Callable

import casadi as ca
import numpy as np

from derive.description.expr import evaluate
from derive.description.robot import Robot
from derive.errors import DeriveError
from derive.symbolic.dynamics import NewtonEuler
from derive.symbolic.regressor import INERTIAL, Regressor
from derive.symbolic.symbols import make_symbols

SEED = 0
RANK_TOL = 1e-4  # the stated rank tolerance, relative to the regressor's scale (see the module docstring)
NEAR_FLOOR = 1e-11  # a column set aside above this (relative, as RANK_TOL) is a near-dependency: reported
GAP = 1e3  # a distance within this factor of the rank tolerance is borderline (named in a refusal)
SNAP = 1e-10  # |beta| (scaled to unit columns) below this is zero
CLEAN = 3e-14  # coefficients: the shortest decimal within this of the computed one, in units of the unit
# columns (beta / (|w_2| / |w_1|)): a few times the least-squares noise there (~2e-15 to 2e-14)
PREFERENCE = ("Ixx", "Ixy", "Ixz", "Iyz", "Izz", "Iyy", "mx", "my", "mz", "m")
"""A body's parameters in the order the base columns are chosen: the first independent ones stay."""
KINDS = {"m": "m", "mx": "mc", "my": "mc", "mz": "mc", "Ixx": "I", "Ixy": "I", "Iyy": "I", "Ixz": "I", "Iyz": "I",
         "Izz": "I", "Ia": "Ia", "fv": "fv", "fc": "fc"}
"""A parameter's kind: its units. Column norms are compared within a kind only."""
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
    near: tuple[tuple[str, float], ...] = ()  # near-dependencies: (parameter, relative size), largest first

    def near_text(self, limit: int = 6) -> str:
        """One line on the near-dependencies, or '' when there are none."""
        if not self.near:
            return ""
        shown = ", ".join(f"{n} ({x:.1e})" for n, x in self.near[:limit]) + (" ..." if len(self.near) > limit else "")
        return (f"near-dependencies (columns of Y set aside though above rounding, relative size; rank tolerance "
                f"{RANK_TOL:g}): {shown}: nearly, not exactly, degenerate geometry (e.g. angles written 1.5708 for "
                "pi/2: import with --snap-angles)")

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
                    actuators: bool = True, seed: int = SEED, stack: Callable[[int, int], np.ndarray] | None = None,
                    rows: int | None = None, rank_tol: float = RANK_TOL) -> BaseParameters:
    """The base parameters of ``robot`` at its parameters' defaults (or ``params``).

    ``regressor``: an already derived :class:`Regressor` of the robot (else one is derived).
    ``actuators=False`` leaves out the actuator parameters (the inertial ones only, as Pinocchio's
    ``computeJointTorqueRegressor`` has them).
    ``stack(count, seed)``: another regressor (every column of pi) stacked at ``count`` seeded states of
    ``rows`` rows each, instead of Y at :func:`states` (a closed chain's Y_y in y,
    :mod:`derive.symbolic.closed_regressor`); ``rank_tol`` its rank tolerance (relative, as RANK_TOL).
    """
    reg = regressor or Regressor(NewtonEuler(robot, make_symbols(robot)))
    s = reg.sym
    p = reg.parameter_vector(params)
    names = reg.names
    n = len(names) if actuators else 10 * len(reg.bodies)
    names = names[:n]
    if stack is None:
        f = ca.Function("Y", [s.q, s.qd, s.qdd, s.p], [reg.matrix[:, :n]])
        stack = lambda count_, seed_: _stack(f, robot, p, count_, seed_)  # noqa: E731
    count = max(10, math.ceil(5 * n / (rows or robot.nv)))
    W = stack(count, seed)[:, :n]
    norms = np.linalg.norm(W, axis=0)
    kind = _kind_scale(norms, names)
    live = norms > 1e-13 * kind  # exactly zero columns, to rounding
    scale = np.where(live, norms, 1.0)
    Wn = W / scale  # unit columns: the combinations beta
    Wk = W / kind  # the regressor at its scale: each kind's largest column has norm 1 (the rank)
    threshold = rank_tol
    # the base columns: the first independent ones in the order of preference
    order = [j for j in preference(len(reg.bodies), n) if live[j]]
    dist = _distances(Wk[:, order], threshold)
    keep = dist > threshold
    columns = tuple(sorted(order[k] for k in np.flatnonzero(keep)))
    near = sorted(((names[order[k]], float(x)) for k, x in enumerate(dist) if not keep[k] and x > NEAR_FLOOR),
                  key=lambda item: -item[1])
    dependent = [j for j in range(n) if j not in columns]
    B = np.linalg.lstsq(Wn[:, list(columns)], Wn[:, dependent], rcond=None)[0]
    B[np.abs(B) < SNAP] = 0.0
    # a column that acts at most RANK_TOL of its kind's scale and is not exactly dependent (a near-dependency,
    # e.g. gravity on the first link of an arm tilted 1e-5 rad) enters no base parameter, as if exactly zero
    slight = {names[j] for j in dependent if norms[j] <= threshold * kind[j]} & {name for name, _ in near}
    B[:, [names[j] in slight for j in dependent]] = 0.0
    unit = scale[dependent][None, :] / scale[list(columns)][:, None]  # beta per unit of B
    beta = B * unit
    K = np.zeros((len(columns), n))
    K[np.arange(len(columns)), list(columns)] = 1.0
    K[:, dependent] = [[clean(x, CLEAN * u) for x, u in zip(row, urow)] for row, urow in zip(beta, unit)]
    # check on other states: the same rank, and the dependent columns the same combinations
    W2 = stack(count, seed + 1)[:, :n]
    norms2 = np.linalg.norm(W2, axis=0)
    Wk2 = W2 / _kind_scale(norms2, names)
    dist2 = _distances(Wk2[:, order], threshold)
    rank2 = int(np.sum(dist2 > threshold))
    err = np.abs(W2[:, list(columns)] @ K - W2).max() / max(np.abs(W2).max(), 1e-300)
    # exact geometry: the combinations hold to rounding; near-dependencies set aside: to their size
    if err > max(1e-9, 10 * max((x for _, x in near), default=0.0)):
        column_err = np.abs(W2[:, list(columns)] @ K - W2).max(axis=0) / max(np.abs(W2).max(), 1e-300)
        involved = (_borderline(order, dist, threshold)
                    + _borderline(order, dist2, threshold))
        involved += [(j, float(column_err[j])) for j in np.argsort(-column_err) if column_err[j] > 1e-9]
        raise _degenerate(robot, params, names, f"the base parameters found at one set of states do not hold at "
                          f"another (rank {len(columns)} vs {rank2}, residual {err:.1e})", involved)
    return BaseParameters(robot.name, names, columns, _names(names, columns, K), K, seed, count, tuple(near))


def near_dependencies(W: np.ndarray, names, count: int = 2) -> list[tuple[float, tuple[tuple[str, float], ...]]]:
    """The ``count`` smallest singular values of W with its columns scaled to unit norm, over the largest,
    each with its combination of ``names`` (W's columns): the right singular vector, entries of magnitude
    0.1 or more, the largest positive. W v = s u: s / s_max near 0 means those columns are nearly dependent
    (cond(W) with unit columns = s_max / s_min)."""
    W = np.asarray(W, dtype=float)
    if W.size == 0:
        return []
    norms = np.linalg.norm(W, axis=0)
    _, s, Vt = np.linalg.svd(W / np.where(norms > 0, norms, 1.0), full_matrices=False)
    out = []
    for k in range(1, min(count, len(s)) + 1):
        v = Vt[-k] * (1.0 if Vt[-k][np.argmax(np.abs(Vt[-k]))] > 0 else -1.0)
        terms = tuple((names[i], float(v[i])) for i in np.argsort(-np.abs(v), kind="stable") if abs(v[i]) >= 0.1)
        out.append((float(s[-k] / s[0]) if s[0] > 0 else 0.0, terms))
    return out


def dependencies_text(deps) -> str:
    """``near-dependencies (smallest singular values, unit columns, relative): 3.2e-06 (0.71 ZZR_a - 0.7 XX_b)``."""
    parts = [f"{x:.2g} (" + _sum(((round(c, 2), n) for n, c in terms[:5]), lambda c: f"{c:g}", " ")
             + (" ..." if len(terms) > 5 else "") + ")" for x, terms in deps]
    return "near-dependencies (smallest singular values with unit columns, relative): " + "; ".join(parts)


def _distances(A: np.ndarray, threshold: float) -> np.ndarray:
    """Per column of A, in order, its distance to the span of the columns before it that were farther than
    ``threshold`` from theirs (Gram-Schmidt, orthogonalised twice). Only the kept columns span: a column set
    aside as nearly dependent must not hide, through the sliver by which it is independent, a later column."""
    basis = np.zeros((A.shape[0], 0))
    out = np.zeros(A.shape[1])
    for k in range(A.shape[1]):
        r = A[:, k].copy()
        for _ in range(2):
            r -= basis @ (basis.T @ r)
        out[k] = np.linalg.norm(r)
        if out[k] > threshold:
            basis = np.column_stack([basis, r / out[k]])
    return out


def _kind_scale(norms: np.ndarray, names: tuple[str, ...]) -> np.ndarray:
    """Per column, the largest norm among the columns of its kind (KINDS: the same units); 1 for a kind that
    never acts."""
    kinds = [KINDS[n.partition("_")[0]] for n in names]
    largest = {k: max(x for x, kk in zip(norms, kinds) if kk == k) for k in sorted(set(kinds))}
    return np.array([largest[k] if largest[k] > 0 else 1.0 for k in kinds])


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
