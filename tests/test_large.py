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

from derive.description.model import parse_models
from derive.symbolic import dynamics
from derive.symbolic.model import SXModel


def generic_chain(n: int, seed: int = 0) -> str:
    """An n-joint chain with random placements, axes cycling z, y, x, and random mass properties."""
    rng = np.random.default_rng(seed)
    axes = ("[0, 0, 1]", "[0, 1, 0]", "[1, 0, 0]")
    links = ["      - {name: base}"]
    joints = []
    for i in range(1, n + 1):
        c, xyz, rpy = rng.uniform(-0.1, 0.1, 3), rng.uniform(-0.2, 0.2, 3), rng.uniform(-1, 1, 3)
        links.append(f"      - {{name: l{i}, mass: {rng.uniform(0.5, 2):.3f}, com: [{c[0]:.3f}, {c[1]:.3f}, {c[2]:.3f}], "
                     "inertia: [0.02, 0.03, 0.04]}")
        joints.append(f"      - {{name: q{i}, type: revolute, parent: {'base' if i == 1 else f'l{i - 1}'}, child: l{i}, "
                      f"axis: {axes[i % 3]}, origin: {{xyz: [{xyz[0]:.3f}, {xyz[1]:.3f}, {xyz[2]:.3f}], "
                      f"rpy: [{rpy[0]:.3f}, {rpy[1]:.3f}, {rpy[2]:.3f}]}}}}")
    return f"robots:\n  chain{n}:\n    links:\n" + "\n".join(links) + "\n    joints:\n" + "\n".join(joints) + "\n"


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
