"""The inertial-parameter regressor of a closed chain in its independent coordinates y, and its base parameters.

The tree's inverse dynamics is linear in the standard parameters pi (:mod:`derive.symbolic.regressor`):
rnea(q, qd, qdd) = Y(q, qd, qdd) pi. The closed chain's constrained inverse dynamics projects it
(:mod:`derive.symbolic.closure`), so it is linear in the same pi:

    tau_y = G^T rnea(q, G yd, G ydd + Gdot yd) = Y_y(y, yd, ydd) pi,
    Y_y = G^T Y(q, G yd, G ydd + Gdot yd),   q = gamma(y)

(ny x n_pi). The closure takes freedom away, so Y_y can have fewer independent columns than the
tree's Y: parameters that the tree tells apart can act together once the loops tie the motions (the
four-bar's rocker's first moment along its length acts as the crank's, coupler's and rocker's other
parameters do: 15 base parameters, its tree 16). The base parameters of the closed chain are therefore
found on Y_y itself: Gautier's numerical QR (:func:`derive.symbolic.base_parameters.base_parameters`,
the same choice of columns and names) on Y_y stacked at seeded closed states (:func:`closed_states`:
y within +-:data:`SPREAD` of the reference configuration's where the loops close on a well-conditioned
chart; yd, ydd standard normal), with the rank tolerance :data:`RANK_TOL`.
"""

from __future__ import annotations

from functools import cached_property
from typing import Callable

import casadi as ca
import numpy as np

from derive.description.robot import Robot
from derive.errors import DeriveError
from derive.symbolic.base_parameters import SEED, BaseParameters, base_parameters
from derive.symbolic.closure import ClosedChainModel, ReducedChain
from derive.symbolic.regressor import Regressor

SPREAD = 0.5
"""The closed states of the base parameters: y within +-SPREAD (rad or m) of the reference configuration's."""
CLOSED = 1e-10
"""A closed state: max |phi(gamma(y))| at most this."""
CHART = 0.05
"""A closed state: sigma_min / sigma_max of K_z at least this (G = [I; -K_z^-1 K_y] well conditioned)."""
DRAWS = 20
"""At most DRAWS times the states needed are drawn."""
RANK_TOL = 1e-8
"""The closed chain's rank tolerance (relative to each kind's largest column, as the tree's
:data:`~derive.symbolic.base_parameters.RANK_TOL` = 1e-4): the states span only the chart around the
reference configuration, where a passive joint's armature or friction can act as little as 1e-5 of
the motors' beyond what the other columns explain (example2's Ia_theta2, Ia_theta3), while the
dependent columns are dependent to rounding (below 1e-14). 1e-8 sits three orders from both."""


def closed_states(robot: Robot, count: int, seed: int, check=None) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """``count`` seeded (y, yd, ydd): y uniform within +-SPREAD of the reference configuration's, yd and
    ydd standard normal. ``check(y)``: whether the mechanism assembles well at y (else y is drawn again)."""
    rng = np.random.default_rng(seed)
    names = [c.name for c in robot.coordinates]
    y_ref = np.array([robot.reference_q[names.index(c)] for c in robot.independent])
    ny = len(y_ref)
    out = []
    for _ in range(DRAWS * count):
        y, yd, ydd = y_ref + rng.uniform(-SPREAD, SPREAD, ny), rng.normal(size=ny), rng.normal(size=ny)
        if check is None or check(y):
            out.append((y, yd, ydd))
            if len(out) == count:
                return out
    raise DeriveError(f"robot '{robot.name}': the loops close well (residual <= {CLOSED:g}, sigma_min/sigma_max "
                      f"of K_z >= {CHART:g}) at only {len(out)} of {DRAWS * count} states drawn within +-{SPREAD:g} of "
                      f"the reference configuration's y; need {count} for the base parameters")


class ClosedRegressor:
    """Y_y of a closed chain, in CasADi SX: of the closed tree configuration q (:attr:`matrix`) or of y
    (:meth:`in_y`), with the rates' symbols of the :class:`ClosedChainModel` (``yd``, ``ydd``) and p."""

    def __init__(self, ccm: ClosedChainModel, regressor: Regressor | None = None):
        self.ccm = ccm
        self.robot = ccm.robot
        self.reg = regressor or Regressor(ccm.model.newton_euler)

    @cached_property
    def matrix(self) -> ca.SX:
        """Y_y = G^T Y(q, G yd, G ydd + Gdot yd) (ny x n_pi), of q, yd, ydd and p."""
        c, s = self.ccm, self.ccm.sym
        G = c.projection
        Y = ca.substitute(self.reg.matrix, ca.vertcat(s.qd, s.qdd), ca.vertcat(c.qd, G @ c.ydd + c.gdot_yd))
        return G.T @ Y

    def in_y(self, reduced: ReducedChain) -> ca.SX:
        """Y_y with q = gamma(y) of ``reduced`` (:meth:`ClosedChainModel.in_y`) put in: of y, yd, ydd and p."""
        return ca.substitute(self.matrix, self.ccm.sym.q, reduced.gamma)

    def function(self, reduced: ReducedChain) -> ca.Function:
        """(y, yd, ydd, p) -> Y_y."""
        c = self.ccm
        return ca.Function("regressor_y", [reduced.y, c.yd, c.ydd, c.sym.p], [ca.densify(self.in_y(reduced))],
                           ["y", "yd", "ydd", "p"], ["Y_y"])


def assembles(ccm: ClosedChainModel, reduced: ReducedChain, p) -> Callable[[np.ndarray], bool]:
    """``check(y)``: whether q = gamma(y) closes the loops (max |phi| <= CLOSED) on a well-conditioned chart
    (sigma_min / sigma_max of K_z >= CHART) at the parameters p."""
    s = ccm.sym
    at = ca.Function("at", [reduced.y, s.p], [ca.substitute(ca.vertcat(ca.vec(ccm.phi), ca.vec(ccm.k_z)), s.q,
                                                            reduced.gamma)])
    nphi, shape = ccm.phi.numel(), ccm.k_z.shape

    def check(y) -> bool:
        v = np.array(at(y, p)).ravel()
        if not np.isfinite(v).all() or np.abs(v[:nphi]).max() > CLOSED:
            return False
        sv = np.linalg.svd(v[nphi:].reshape(shape, order="F"), compute_uv=False)
        return bool(sv[-1] >= CHART * sv[0])

    return check


def closed_base_parameters(regressor: ClosedRegressor, reduced: ReducedChain, params: dict | None = None,
                           seed: int = SEED) -> BaseParameters:
    """The base parameters of the closed chain: those of Y_y (not of the tree's Y), Gautier's QR on Y_y
    stacked at :func:`closed_states` (seeds ``seed`` and ``seed + 1``, the second the check)."""
    robot = regressor.robot
    f = regressor.function(reduced)
    p = regressor.reg.parameter_vector(params)

    check = assembles(regressor.ccm, reduced, p)

    def stack(count: int, seed_: int) -> np.ndarray:
        return np.vstack([np.array(f(y, yd, ydd, p)) for y, yd, ydd in closed_states(robot, count, seed_, check)])

    ny = len(robot.independent)
    return base_parameters(robot, params, regressor=regressor.reg, seed=seed, stack=stack, rows=ny, rank_tol=RANK_TOL)


def closed_regressor(robot: Robot, ccm: ClosedChainModel | None = None,
                     params: dict | None = None) -> tuple[ClosedRegressor, ReducedChain, BaseParameters]:
    """Y_y of ``robot`` (which has loops), its model in y and its base parameters."""
    ccm = ccm or ClosedChainModel(robot)
    cr = ClosedRegressor(ccm)
    red = ccm.in_y()
    return cr, red, closed_base_parameters(cr, red, params)


def stacked_rank(Y: np.ndarray, tol: float = 1e-9) -> int:
    """The numerical rank of a stacked regressor with unit columns (the zero columns dropped): singular
    values above ``tol`` of the largest. A cross-check of the base parameters' count."""
    norms = np.linalg.norm(Y, axis=0)
    live = norms > 1e-13 * max(float(norms.max()), 1e-300)
    s = np.linalg.svd(Y[:, live] / norms[live], compute_uv=False)
    return int(np.sum(s > tol * s[0])) if len(s) else 0

