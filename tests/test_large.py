"""Larger robots: the Coriolis matrix by the cheaper exact form.

Up to CHRISTOFFEL_MAX_NV coordinates both forms (the Christoffel symbols of M, and half the
qd-derivative of the Newton-Euler velocity terms) are built and the one with fewer operations is
kept; above, only the derivative form. Both are the same matrix: checked here against the
symbols of M on generic chains, with Mdot - 2 C skew-symmetric.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from derive.bench.large import generic_chain
from derive.description.model import parse_models
from derive.symbolic import dynamics
from derive.symbolic.model import SXModel


@pytest.mark.parametrize("n", [8, 14])
def test_coriolis_by_derivative_is_the_christoffel_matrix(n):
    robot = parse_models(generic_chain(n))[f"chain{n}"]
    model = SXModel(robot)
    s, ne = model.sym, model.newton_euler
    C = ne.coriolis_matrix
    symbols = dynamics.christoffel_coriolis(ne.mass_matrix, s.q, s.qd)
    cost = dynamics.graph_cost(C, s.q, s.qd)
    assert cost < dynamics.graph_cost(symbols, s.q, s.qd)  # the cheaper form was kept (8 joints: 9.4k against 12.4k)
    Mdot = ca.jtimes(ne.mass_matrix, s.q, s.qd)
    f = ca.Function("f", [s.q, s.qd], [C, symbols, Mdot - 2 * C])
    rng = np.random.default_rng(n)
    for _ in range(3):
        got, want, skew = (np.array(v) for v in f(rng.uniform(-3, 3, n), rng.normal(size=n)))
        scale = np.abs(want).max()
        assert np.abs(got - want).max() <= 1e-12 * scale
        assert np.abs(skew + skew.T).max() <= 1e-12 * scale


def test_small_robots_keep_the_symbols_where_they_are_cheaper():
    from util import robots
    model = SXModel(robots()["panda"])  # right-angle URDF placements: the symbols of M are sparser
    s, ne = model.sym, model.newton_euler
    symbols = dynamics.christoffel_coriolis(ne.mass_matrix, s.q, s.qd)
    assert dynamics.graph_cost(ne.coriolis_matrix, s.q, s.qd) == dynamics.graph_cost(symbols, s.q, s.qd)
