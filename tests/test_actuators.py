"""Actuators and friction: armature (reflected rotor inertia) on M's diagonal, viscous and Coulomb friction.

The Panda with an actuator on every joint is generated (C and Python) and compared with the numpy
reference and with Pinocchio (``model.armature``: its crba, rnea and aba include it; its rnea has no
friction, which is added here): M, ID (Coulomb as sign(qd)), FD and the ODE (Coulomb as
tanh(qd / eps)), df/dx by complex step through the reference. Models without actuators keep every
generated function byte for byte (tests/test_codegen.py regenerates generated/ and compares).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from derive.description.model import load_models, parse_models
from derive.description.robot import Actuator, ModelError
from derive.reference import NumericRobot
from test_whole_robots import Case, erd, sym
from util import assert_close

pin = pytest.importorskip("pinocchio")

TOL = 1e-9


def actuated_panda():
    robot = load_models()["panda"]
    acts = [Actuator(armature=0.1 * (k + 1), gear_ratio=50.0 + k, motor_inertia=1e-5, viscous=0.2 + 0.1 * k,
                     coulomb=0.5 + 0.05 * k) for k in range(7)]
    joints = tuple(dataclasses.replace(j, actuator=acts[i]) for i, j in enumerate(robot.joints))
    return dataclasses.replace(robot, name="panda_act", joints=joints, wrenches=("tcp",))


@pytest.fixture(scope="module")
def panda_act(tmp_path_factory):
    robot = actuated_panda()
    full = pin.buildModelFromUrdf(erd("panda_description/urdf/panda.urdf"))
    locked = [full.getJointId(n) for n in ("panda_finger_joint1", "panda_finger_joint2")]
    pm = pin.buildReducedModel(full, locked, pin.neutral(full))
    pm.armature = np.array([0.1 * (k + 1) + (50.0 + k) ** 2 * 1e-5 for k in range(7)])
    return Case(robot, pm, {"tcp": "panda_hand_tcp"}, tmp_path_factory.mktemp("panda_act"))


def test_actuated_panda_against_pinocchio_and_the_reference(panda_act):
    case = panda_act
    pm, pd = case.pm, case.pd
    ref = NumericRobot(case.robot)
    assert case.robot.actuated
    rng = np.random.default_rng(3)
    for q, qd, qdd, tau in case.states():
        w = rng.normal(size=6)
        fric, smooth = ref.friction(qd), ref.friction(qd, smooth=True)
        case.check("mass_matrix", sym(pin.crba(pm, pm.createData(), q)), q)
        case.check("inverse_dynamics", pin.rnea(pm, pd, q, qd, qdd) + fric, q, qd, qdd)
        case.check("inverse_dynamics", ref.rnea(q, qd, qdd), q, qd, qdd)
        case.check("forward_dynamics", pin.aba(pm, pd, q, qd, tau - smooth), q, qd, tau)
        case.check("forward_dynamics", ref.aba(q, qd, tau), q, qd, tau)
        case.check("inverse_dynamics_fext", ref.rnea(q, qd, qdd, {"tcp": w}), q, qd, qdd, w)
        case.check("forward_dynamics_fext", ref.aba(q, qd, tau, {"tcp": w}), q, qd, tau, w)
        case.check("gravity", pin.computeGeneralizedGravity(pm, pd, q), q)
        x = np.r_[q, qd]
        case.check("ode_rhs", np.r_[qd, ref.aba(q, qd, tau)], x, tau)
        eye, h = np.eye(14), 1e-30  # complex step through the reference ABA (tanh is analytic)
        A = np.array([np.r_[(x + 1j * h * e)[7:], ref.aba((x + 1j * h * e)[:7], (x + 1j * h * e)[7:],
                                                       tau.astype(complex))].imag / h for e in eye]).T
        case.check("ode_jac_x", A, x, tau)
        case.check("ode_jac_u", np.vstack([np.zeros((7, 7)), np.linalg.inv(ref.crba(q))]), x, tau)


def test_coulomb_friction_sign_in_inverse_dynamics_smooth_in_the_ode(panda_act):
    """ID uses sign(qd) (0 at rest), FD tanh(qd / eps): ID(FD(tau)) = tau up to f_c (sign - tanh)."""
    case = panda_act
    ref = NumericRobot(case.robot)
    q = np.zeros(7)
    at_rest = case.py.inverse_dynamics(q, np.zeros(7), np.zeros(7))
    assert_close(at_rest, ref.gravity(q), 1e-12, "no friction at rest")
    qd = np.array([1e-3, -1e-3, 0.5, -0.5, 0.0, 2.0, -2.0])
    qdd = case.py.forward_dynamics(q, qd, np.ones(7))
    gap = case.py.inverse_dynamics(q, qd, qdd) - np.ones(7)
    assert_close(gap, ref.coulomb * (np.sign(qd) - np.tanh(qd / case.robot.smoothing)), 1e-9, "sign - tanh")
    assert case.manifest["actuators"]["coulomb_smoothing"] == case.robot.smoothing
    assert case.manifest["actuators"]["armature"] == pytest.approx(list(ref.armature), rel=1e-15)


def test_actuator_fields_are_validated():
    base = """
robots:
  arm:
    links: [{name: base}, {name: l1, mass: 1.0, com: [0.1, 0, 0], inertia: [0.01, 0.01, 0.01]}]
    joints: [{name: j1, type: revolute, parent: base, child: l1, ACT}]
"""
    ok = parse_models(base.replace("ACT", "actuator: {armature: 0.1, gear_ratio: 100, motor_inertia: 1e-5, "
                                          "viscous: 0.3, coulomb: 1.0}"))["arm"]
    assert ok.actuated and ok.joint_coordinates[0].actuator.gear_ratio == 100.0
    for text, match in (("actuator: {viscous: -1}", r"actuator\.viscous: must be >= 0"),
                        ("actuator: {gear_ratio: 0}", r"actuator\.gear_ratio: must not be 0"),
                        ("actuator: {damping: 1}", r"actuator\.damping: unknown field"),
                        ("actuator: [{viscous: 1}, {viscous: 2}]", r"expected 1 actuators"),
                        ("actuator: 3", r"expected a mapping")):
        with pytest.raises(ModelError, match=match):
            parse_models(base.replace("ACT", text))
    with pytest.raises(ModelError, match="coulomb_smoothing: must be > 0"):
        parse_models(base.replace("ACT", "axis: [0, 0, 1]") + "    coulomb_smoothing: 0\n")
