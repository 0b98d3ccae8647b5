"""The inertial-parameter regressor and the base parameters (issue 14, items 2 and 3).

- pi: names and values (derive.symbolic.regressor) equal the reference's (spatial inertias read back)
  and Pinocchio's ``Inertia.toDynamicParameters``; actuators [I_a, f_v, f_c] per joint coordinate.
- Y pi = inverse dynamics to 1e-12 relative at seeded states: the symbolic Y against the symbolic ID,
  the reference's own Y (Featherstone's linear form, derive.reference) against its rnea, and the two Y
  against each other, for every shipped robot, an actuated Panda, floating bases, multi-DOF joints
  and mimic joints (fixed and floating); the generated C and Python the same way.
- Y's inertial part equals Pinocchio's ``computeJointTorqueRegressor`` (1e-9) for the Panda and the UR5,
  fixed and floating.
- Base parameters: as many as the rank of Pinocchio's stacked regressor (panda 43, ur5 36, planar_2r 6,
  rrprr 27, cartpole 4; floating panda 59, ur5 52); Y_b pi_b = ID to 1e-12 at other states; the choice
  is deterministic and does not depend on the states; the combinations are exact where they are
  products of short lengths.
"""

from __future__ import annotations

import ctypes
import dataclasses
import json
import re
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from derive.description.model import load_models, parse_models
from derive.description.robot import Actuator
from derive.reference import NumericRobot
from derive.symbolic.base_parameters import base_parameters, clean
from derive.symbolic.model import SXModel
from derive.symbolic.regressor import Regressor, body_links, parameter_names, parameter_values
from test_joint_types import ZOO
from util import load_module, robots, tree_robots

ROOT = Path(__file__).resolve().parent.parent
GENERATED = ROOT / "generated"
SHIPPED = tree_robots()  # a closed chain has no tree regressor generated
TOL = 1e-12
PINOCCHIO_RANK = {"panda": 43, "ur5": 36, "planar_2r": 6, "rrprr": 27, "cartpole": 4, "panda_floating": 59, "ur5_floating": 52}
STATES = 12


def actuated_panda():
    robot = load_models()["panda"]
    acts = [Actuator(armature=0.1 * (k + 1), gear_ratio=50.0 + k, motor_inertia=1e-5, viscous=0.2 + 0.1 * k,
                     coulomb=0.5 + 0.05 * k) for k in range(7)]
    joints = tuple(dataclasses.replace(j, actuator=acts[i]) for i, j in enumerate(robot.joints))
    return dataclasses.replace(robot, name="panda_act", joints=joints)


def mimic_tree(base: str, helical: bool = True):
    """tests/test_reference_mimic.py's tree of five mimic joints (needs Pinocchio only to be imported)."""
    module = pytest.importorskip("test_reference_mimic")
    return dataclasses.replace(module.robot_of(base, helical=helical), name=f"mimic_{base}")


def case_robot(name: str):
    if name in robots():
        return robots()[name]
    if name == "panda_act":
        return actuated_panda()
    if name.endswith("_floating") and name.removesuffix("_floating") in robots():
        base = robots()[name.removesuffix("_floating")]
        return dataclasses.replace(base, name=name, base="floating")
    if name.startswith("zoo"):
        return dataclasses.replace(parse_models(ZOO)["zoo"], name=name, base=name.removeprefix("zoo_"))
    if name.startswith("mimic"):
        return mimic_tree(name.removeprefix("mimic_"))
    raise KeyError(name)


CASES = SHIPPED + ["panda_act", "panda_floating", "ur5_floating", "zoo_fixed", "zoo_floating", "mimic_fixed",
                   "mimic_floating"]


class Derived:
    """One robot's symbolic Y, Y_b and ID as CasADi functions of (q, qd, qdd, p), and its reference."""

    def __init__(self, robot):
        self.robot = robot
        model = SXModel(robot)
        s = model.sym
        self.reg = Regressor(model.newton_euler)
        self.base = base_parameters(robot, regressor=self.reg)
        self.f = ca.Function("f", [s.q, s.qd, s.qdd, s.p],
                             [self.reg.matrix, self.reg.matrix[:, list(self.base.columns)],
                              model.newton_euler.inverse_dynamics()])
        self.p = self.reg.parameter_vector()
        self.pi = self.reg.values()
        self.ref = NumericRobot(robot)

    def __call__(self, q, qd, qdd, p=None):
        Y, Yb, tau = self.f(q, qd, qdd, self.p if p is None else p)
        return np.array(Y), np.array(Yb), np.array(tau).reshape(-1)

    def states(self, seed: int, count: int = STATES):
        rng = np.random.default_rng(seed)
        for _ in range(count):
            yield self.ref.random_configuration(rng), rng.normal(size=self.robot.nv), rng.normal(size=self.robot.nv)


_DERIVED: dict[str, Derived] = {}


def derived(name: str) -> Derived:
    if name not in _DERIVED:
        _DERIVED[name] = Derived(case_robot(name))
    return _DERIVED[name]


def rel(actual, expected) -> float:
    """max |a - e| / max |e| (the whole array's scale, as util.assert_close)."""
    actual, expected = np.asarray(actual, dtype=float), np.asarray(expected, dtype=float)
    assert actual.shape == expected.shape, (actual.shape, expected.shape)
    return float(np.abs(actual - expected).max(initial=0.0) / max(np.abs(expected).max(initial=0.0), 1e-300))


WORST: dict[str, float] = {}


def check(what: str, actual, expected, tol: float = TOL) -> None:
    err = rel(actual, expected)
    WORST[what] = max(WORST.get(what, 0.0), err)
    assert err <= tol, f"{what}: relative error {err:.3e} > {tol:g}"


# --------------------------------------------------------------------------- pi


@pytest.mark.parametrize("name", CASES)
def test_parameter_names_and_values(name):
    """10 names per body (Pinocchio's joints: the root body first with a floating base) and 3 per joint
    coordinate, unique identifiers; the values equal the reference's, read off its spatial inertias."""
    d = derived(name)
    robot = d.robot
    names = parameter_names(robot)
    links = body_links(robot)
    assert len(names) == 10 * len(links) + 3 * len(robot.joint_coordinates) == d.reg.size
    assert len(set(names)) == len(names)
    assert all(re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", n) for n in names)
    assert names[:10] == tuple(f"{k}_{links[0]}" for k in ("m", "mx", "my", "mz", "Ixx", "Ixy", "Iyy", "Ixz", "Iyz", "Izz"))
    coordinate = robot.joint_coordinates[0].name
    assert names[10 * len(links):10 * len(links) + 3] == (f"Ia_{coordinate}", f"fv_{coordinate}", f"fc_{coordinate}")
    check("pi vs reference", parameter_values(robot), d.ref.dynamic_parameters())
    np.testing.assert_array_equal(d.pi, parameter_values(robot))


def test_parameter_values_take_parameters():
    robot = robots()["planar_2r"]
    pi = parameter_values(robot, {"m2": 2.0, "L2": 0.5})
    k = parameter_names(robot).index("mx_link2_dh")
    assert abs(pi[k]) == pytest.approx(2.0 * 0.25)  # m2 times the COM's distance L2/2 from the link's origin
    check("pi vs reference", pi, NumericRobot(robot, {"m2": 2.0, "L2": 0.5}).dynamic_parameters())
    with pytest.raises(ValueError, match="no parameter"):
        parameter_values(robot, {"nope": 1.0})


@pytest.mark.parametrize("name", ["panda", "ur5", "panda_floating"])
def test_values_are_pinocchios_dynamic_parameters(name):
    pytest.importorskip("pinocchio")
    from pin_model import build_model

    robot = case_robot(name)
    model = build_model(robot)
    theirs = np.concatenate([model.inertias[j].toDynamicParameters() for j in range(1, model.njoints)])
    check("pi vs Pinocchio", parameter_values(robot)[:len(theirs)], theirs)
    assert len(theirs) == 10 * len(body_links(robot))


# --------------------------------------------------------------------------- Y


@pytest.mark.parametrize("name", CASES)
def test_regressor_times_pi_is_inverse_dynamics(name):
    """Y pi = ID (symbolic), Y_ref pi = rnea (reference), Y = Y_ref, Y_b pi_b = ID and Y = Y_b K."""
    d = derived(name)
    tol_ref = TOL  # ur5 writes exact pi/2 since its import with --snap-angles: no 1e-11 gap to the reference
    pi_b = d.base.values(d.pi)
    for q, qd, qdd in d.states(3):
        Y, Yb, tau = d(q, qd, qdd)
        check("Y pi vs ID (symbolic)", Y @ d.pi, tau)
        y_ref = d.ref.regressor(q, qd, qdd)
        check("Y pi vs rnea (reference)", y_ref @ d.ref.dynamic_parameters(), d.ref.rnea(q, qd, qdd))
        check("Y vs the reference's Y", Y, y_ref, tol_ref)
        check("Y_b pi_b vs ID", Yb @ pi_b, tau)
        check("Y vs Y_b K", Yb @ d.base.K, Y)


@pytest.mark.parametrize("name", ["panda", "ur5", "panda_floating", "ur5_floating"])
def test_matches_pinocchio_joint_torque_regressor(name):
    """Pinocchio's computeJointTorqueRegressor (the same 10 parameters per joint, same order) is Y's inertial part."""
    pin = pytest.importorskip("pinocchio")
    from pin_model import build_model

    d = derived(name)
    model = build_model(d.robot)
    data = model.createData()
    nb = 10 * (model.njoints - 1)
    assert nb == 10 * len(body_links(d.robot))
    for q, qd, qdd in d.states(4):
        theirs = pin.computeJointTorqueRegressor(model, data, q, qd, qdd)
        check("Y vs Pinocchio", d(q, qd, qdd)[0][:, :nb], theirs, 1e-9)


# --------------------------------------------------------------------------- base parameters


@pytest.mark.parametrize("name", sorted(PINOCCHIO_RANK))
def test_base_parameter_count_is_the_rank_of_pinocchios_regressor(name):
    """The inertial base parameters number the rank of Pinocchio's regressor stacked at 100 states; with the
    actuators, each joint adds f_v and f_c, and I_a unless it regroups into an inertia (a first joint)."""
    pin = pytest.importorskip("pinocchio")
    from pin_model import build_model

    d = derived(name)
    model = build_model(d.robot)
    data = model.createData()
    stacked = np.vstack([np.array(pin.computeJointTorqueRegressor(model, data, q, qd, qdd)).reshape(d.robot.nv, -1)
                         for q, qd, qdd in d.states(5, 100)])
    rank = np.linalg.matrix_rank(stacked)
    inertial = base_parameters(d.robot, regressor=d.reg, actuators=False)
    assert inertial.rank == rank == PINOCCHIO_RANK[name]
    n = len(d.robot.joint_coordinates)
    assert inertial.rank + 2 * n <= d.base.rank <= inertial.rank + 3 * n


def test_base_parameters_are_deterministic_and_do_not_depend_on_the_states():
    d = derived("panda")
    again = base_parameters(d.robot, regressor=d.reg)
    other = base_parameters(d.robot, regressor=d.reg, seed=11)
    for b in (again, other):
        assert (b.columns, b.names) == (d.base.columns, d.base.names)
        np.testing.assert_array_equal(b.K, d.base.K)


def test_combinations_are_exact_and_readable():
    """Coefficients are the products of the model's lengths, exactly (0.425^2 = 0.180625, not 0.18062499999999998)."""
    ur5 = derived("ur5").base
    lines = ur5.equations()
    assert ("XXR_upper_arm_link = Ixx_upper_arm_link - Izz_upper_arm_link + 0.180625 m_forearm_link + "
            "0.180625 m_wrist_1_link + 0.180625 m_wrist_2_link + 0.180625 m_wrist_3_link") in lines
    assert "MZR_forearm_link = mz_forearm_link + 0.39225 m_wrist_1_link + 0.39225 m_wrist_2_link + " \
           "0.39225 m_wrist_3_link" in lines
    assert ur5.unidentifiable[:10] == tuple(f"{k}_shoulder_link" for k in ("m", "mx", "my", "mz", "Ixx", "Ixy", "Iyy",
                                                                              "Ixz", "Iyz"))
    panda = derived("panda").base
    assert panda.equations()[0] == "ZZR_panda_link1 = Izz_panda_link1 + Iyy_panda_link2 + Ia_panda_joint1"
    latex = panda.latex()
    assert latex.startswith("\\begin{align*}") and r"\mathrm{ZZR}^{\mathrm{panda\_link1}} &= I_{zz}^{\mathrm{panda\_link1}}" in latex
    # planar 2R at other lengths: ZZR_1 = Izz_1 + L1^2 m_2 (+ I_a1), MXR_1 = mx_1 + L1 m_2, exactly
    robot = robots()["planar_2r"]
    b = base_parameters(robot, {"L1": 0.35})
    combos = {n: dict(b.combination(k)) for k, n in enumerate(b.names)}
    assert combos["ZZR_link1_dh"] == {"Izz_link1_dh": 1.0, "m_link2_dh": 0.1225, "Ia_theta1": 1.0}
    assert combos["MXR_link1_dh"] == {"mx_link1_dh": 1.0, "m_link2_dh": 0.35}
    assert clean(0.12249999999999997, 1e-15) == 0.1225 and clean(1 / 3, 1e-17) == 1 / 3


def test_base_regressor_at_other_parameters():
    """A robot with parameters p: Y_b takes p; pi_b at those p reproduces ID there (the base columns do not move)."""
    d = derived("planar_2r")
    params = {"L1": 0.8, "L2": 0.45, "m1": 1.7, "m2": 0.3, "g": 9.0}
    b = base_parameters(d.robot, params, regressor=d.reg)
    assert b.columns == d.base.columns
    p = d.reg.parameter_vector(params)
    pi_b = b.values(d.reg.values(params))
    for q, qd, qdd in d.states(6):
        _, Yb, tau = d(q, qd, qdd, p)
        check("Y_b pi_b vs ID (other p)", Yb @ pi_b, tau)


# --------------------------------------------------------------------------- generated code


def load_python(robot: str):
    module = load_module(GENERATED / robot / "python" / f"{robot}.py", f"regressor_{robot}")
    return module


@pytest.mark.parametrize("robot", SHIPPED)
def test_generated_c_and_python(robot, committed_library):
    """generated/: the manifest's pi and base parameters are derive's; Y pi = ID and Y_b pi_b = ID to 1e-12
    in the generated Python and C (double)."""
    manifest = json.loads((GENERATED / robot / "manifest.json").read_text())
    fns = {f["quantity"]: f for f in manifest["functions"]}
    d = derived(robot)
    pi = np.array([e["value"] for e in fns["regressor"]["regressor_parameters"]])
    assert [e["name"] for e in fns["regressor"]["regressor_parameters"]] == list(parameter_names(d.robot))
    np.testing.assert_array_equal(pi, d.pi)
    base = fns["base_regressor"]["base_parameters"]
    assert [e["name"] for e in base] == list(d.base.names)
    assert [e["column"] for e in base] == list(d.base.columns)
    pi_b = np.array([e["value"] for e in base])
    index = {n: k for k, n in enumerate(parameter_names(d.robot))}
    for e, row in zip(base, d.base.K):
        K = np.zeros(len(pi))
        for term in e["combination"]:
            K[index[term["parameter"]]] = term["coefficient"]
        np.testing.assert_array_equal(K, row)
    check("manifest pi_b", pi_b, d.base.values(pi))
    assert fns["regressor"]["outputs"][0]["shape"] == [d.robot.nv, len(pi)]
    assert fns["base_regressor"]["outputs"][0]["shape"] == [d.robot.nv, len(base)]
    assert fns["base_regressor"]["rank"] == len(base) == d.base.rank

    py = load_python(robot)
    # regressor, base_regressor and inverse_dynamics from the session's -O1 build of generated/<robot>/c
    # (conftest.py; tests/test_codegen.py checks the rest of it)
    c = ctypes.CDLL(str(committed_library(robot)))
    ptr = ctypes.POINTER(ctypes.c_double)

    def call(name, shape, *args):
        out = np.zeros(shape)
        ins = [np.ascontiguousarray(a, dtype=float) for a in args]
        getattr(c, f"{robot}_{name}")(*[a.ctypes.data_as(ptr) for a in ins + [out]])
        return out

    p = (np.array(d.p),) if d.p else ()
    nv = d.robot.nv
    for q, qd, qdd in d.states(7):
        tau = py.inverse_dynamics(q, qd, qdd, *p)
        check("generated Python Y pi vs ID", py.regressor(q, qd, qdd, *p) @ pi, tau)
        check("generated Python Y_b pi_b vs ID", py.base_regressor(q, qd, qdd, *p) @ pi_b, tau)
        tau_c = call("inverse_dynamics", (nv,), q, qd, qdd, *p)
        check("generated C Y pi vs ID", call("regressor", (nv, len(pi)), q, qd, qdd, *p) @ pi, tau_c)
        check("generated C Y_b pi_b vs ID", call("base_regressor", (nv, len(pi_b)), q, qd, qdd, *p) @ pi_b, tau_c)


def test_zz_report(capsys):
    """Op counts of Y and Y_b against inverse dynamics (generated/), and the worst errors of this module."""
    lines = []
    for robot in SHIPPED:
        manifest = json.loads((GENERATED / robot / "manifest.json").read_text())
        ops = {f["quantity"]: f["ops"]["total"] for f in manifest["functions"] if f["ops"]}
        assert ops["base_regressor"] <= ops["regressor"]
        lines.append(f"{robot}: ID {ops['inverse_dynamics']} ops, Y {ops['regressor']}, Y_b {ops['base_regressor']}")
    with capsys.disabled():
        print("\n" + "\n".join(lines))
        for what, err in sorted(WORST.items()):
            print(f"  worst {what}: {err:.2e}")
