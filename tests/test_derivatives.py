"""Analytical inverse-dynamics derivatives (derive.symbolic.derivatives) against automatic
differentiation of the RNEA, at seeded random states: chains with revolute, prismatic and helical
joints, a branched tree, multi-DOF joints, actuators with friction and parameters; the Coriolis
matrix from them against the Christoffel symbols of M; the generated inverse_dynamics_derivatives of
a chain long enough to take the analytic form against reverse automatic differentiation, and of every
shipped fixed-base robot against Pinocchio's computeRNEADerivatives.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from derive.bench.large import generic_chain
from derive.codegen.catalogue import AD_COMPARE_MAX_NV, function_specs, template_functions
from derive.description.model import parse_models
from derive.symbolic import derivatives, dynamics
from derive.symbolic.model import SXModel
from derive.symbolic.ode import inverse_dynamics_jacobian
from pin_model import PinRobot
from test_codegen import load_python
from util import assert_close, params, robots, states, tree_robots

TREE = """
robots:
  tree:
    parameters: {m2: 1.3, f: 0.2}
    links:
      - {name: base}
      - {name: trunk, mass: 3.0, com: [0.01, 0.02, 0.1], inertia: [0.05, 0.06, 0.04]}
      - {name: arm1, mass: m2, com: [0.1, 0.0, 0.02], inertia: [0.01, 0.02, 0.02]}
      - {name: arm2, mass: 0.8, com: [0.05, 0.01, 0.0], inertia: [0.01, 0.01, 0.005]}
      - {name: slide, mass: 0.5, com: [0.0, 0.03, 0.0], inertia: [0.002, 0.003, 0.002]}
      - {name: wrist, mass: 0.4, com: [0.0, 0.0, 0.03], inertia: [0.001, 0.001, 0.002]}
      - {name: screw, mass: 0.3, com: [0.01, 0.0, 0.0], inertia: [0.001, 0.002, 0.001]}
      - {name: leg, mass: 1.1, com: [0.0, -0.05, -0.1], inertia: [0.02, 0.02, 0.01]}
    joints:
      - {name: yaw, type: revolute, parent: base, child: trunk, axis: [0, 0, 1], origin: {xyz: [0, 0, 0.3]}}
      - {name: shoulder, type: revolute, parent: trunk, child: arm1, axis: [0, 1, 0], origin: {xyz: [0.1, 0.2, 0.4], rpy: [0.3, 0, 0.2]},
         actuator: {armature: 0.01, viscous: f, coulomb: 0.3}}
      - {name: elbow, type: revolute, parent: arm1, child: arm2, axis: [0.6, 0, 0.8], origin: {xyz: [0.3, 0, 0]}}
      - {name: slider, type: prismatic, parent: arm2, child: slide, axis: [1, 0, 0], origin: {xyz: [0.2, 0, 0]}}
      - {name: ball, type: spherical, parent: slide, child: wrist, origin: {xyz: [0.05, 0, 0]}}
      - {name: screw, type: helical, parent: wrist, child: screw, axis: [0, 0, 1], pitch: 0.01, origin: {xyz: [0, 0, 0.05]}}
      - {name: hip, type: revolute, parent: trunk, child: leg, axis: [1, 0, 0], origin: {xyz: [0, -0.2, 0], rpy: [0, 0.4, 0]},
         actuator: {viscous: 0.1, coulomb: 0.2}}
"""


def _robots():
    yield parse_models(generic_chain(9))["chain9"]
    yield parse_models(TREE)["tree"]


@pytest.mark.parametrize("robot", list(_robots()), ids=lambda r: r.name)
def test_analytic_derivatives_equal_automatic_differentiation(robot):
    model = SXModel(robot)
    s, ne = model.sym, model.newton_euler
    assert derivatives.supported(ne)
    dq, dqd = derivatives.inverse_dynamics_derivatives(ne, s.qdd)
    ad = ca.jacobian(ne.inverse_dynamics(smooth=True), ca.vertcat(s.q, s.qd))
    inputs = [s.q, s.qd, s.qdd] + ([s.p] if s.p.numel() else [])
    f = ca.Function("f", inputs, [ca.horzcat(dq, dqd), ad])
    rng = np.random.default_rng(7)
    p = [np.array([p.default for p in robot.parameters])] if s.p.numel() else []
    for _ in range(5):
        got, want = (np.array(v) for v in f(rng.uniform(-2, 2, s.nv), rng.normal(size=s.nv), rng.normal(size=s.nv), *p))
        assert np.abs(got - want).max() <= 1e-12 * np.abs(want).max()


def test_analytic_coriolis_is_the_christoffel_matrix():
    robot = parse_models(TREE)["tree"]
    model = SXModel(robot)
    s, ne = model.sym, model.newton_euler
    zeros = ca.SX.zeros(s.nv, 1)
    C = 0.5 * derivatives.inverse_dynamics_derivatives(ne, zeros, actuators=False)[1]
    symbols = dynamics.christoffel_coriolis(ne.rigid_mass_matrix, s.q, s.qd)
    f = ca.Function("f", [s.q, s.qd, s.p], [C, symbols])
    rng = np.random.default_rng(3)
    for _ in range(3):
        got, want = (np.array(v) for v in f(rng.uniform(-2, 2, s.nv), rng.normal(size=s.nv), [1.3, 0.2]))
        assert np.abs(got - want).max() <= 1e-12 * np.abs(want).max()


def test_long_chain_takes_the_analytic_forms_and_they_are_right():
    n = AD_COMPARE_MAX_NV + 2
    robot = parse_models(generic_chain(n))[f"chain{n}"]
    model = SXModel(robot)
    s, ne = model.sym, model.newton_euler
    # the Coriolis matrix is the analytic one (cheaper than automatic differentiation above 12 joints)
    analytic = 0.5 * derivatives.inverse_dynamics_derivatives(ne, ca.SX.zeros(n, 1), actuators=False)[1]
    assert dynamics.graph_cost(ne.coriolis_matrix, s.q, s.qd) == dynamics.graph_cost(analytic, s.q, s.qd)
    by_ad = 0.5 * ca.jacobian(ne.rnea(s.qd, ca.SX.zeros(n, 1), gravity=False), s.qd)
    assert dynamics.graph_cost(analytic, s.q, s.qd) < dynamics.graph_cost(by_ad, s.q, s.qd)
    # inverse_dynamics_derivatives (which the ODE Jacobians' template calls) takes the analytic dID/dx:
    # the same matrix as by reverse AD; the ODE Jacobians are template functions, no expressions
    specs = {spec.short_name: spec for spec in function_specs(model)}
    assert "ode_jac_x" not in specs and "ode_jac_u" not in specs
    assert {t.short_name for t in template_functions(model)} >= {"ode_jac_x", "ode_jac_u"}
    did = specs["inverse_dynamics_derivatives"]
    assert dict(did.manifest)["algorithm"] == "the analytic RNEA derivatives"
    f = ca.Function("f", [x for _, x in did.inputs], [did.outputs[0][1]])
    g = ca.Function("g", [s.q, s.qd, s.qdd], [inverse_dynamics_jacobian(ne, "reverse", s.qdd)])
    rng = np.random.default_rng(11)
    for _ in range(3):
        q, qd, qdd = rng.uniform(-2, 2, n), rng.normal(size=n), rng.normal(size=n)
        got, want = np.array(f(q, qd, qdd)), np.array(g(q, qd, qdd))
        assert np.abs(got - want).max() <= 1e-10 * np.abs(want).max()


@pytest.mark.parametrize("name", [n for n in tree_robots() if not robots()[n].floating])
def test_generated_inverse_dynamics_derivatives_match_pinocchio(name):
    """The generated inverse_dynamics_derivatives (C's arithmetic, in Python) of every shipped fixed-base
    robot against Pinocchio's computeRNEADerivatives, at seeded states."""
    robot = robots()[name]
    py = load_python(name)
    pin = PinRobot(robot, dict(zip((p.name for p in robot.parameters), params(robot))))
    for q, qd, qdd in states(robot, seed=5):
        args = (q, qd, qdd) + ((params(robot),) if robot.parameters else ())
        assert_close(py.inverse_dynamics_derivatives(*args), pin.rnea_derivatives(q, qd, qdd), 1e-9,
                     f"{name} inverse_dynamics_derivatives against Pinocchio")
