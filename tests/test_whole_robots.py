"""Whole robots against Pinocchio: floating base, mimic joints, external wrenches, frame
accelerations, centre of mass and centroidal momentum.

Each robot is generated into a temporary folder (C and Python), and every new function, in
Python and in C (double, via ctypes), is compared at seeded states with Pinocchio's own
algorithms on a model Pinocchio builds from the same URDF (free flyer via
``JointModelFreeFlyer``, mimic joints via ``mimic=True``), to 1e-9 relative:
``crba``, ``rnea`` (also with ``fext``), ``aba`` (also with ``fext``),
``getFrameClassicalAcceleration``, ``centerOfMass``, ``jacobianCenterOfMass``,
``computeCentroidalMap``, ``computeABADerivatives``. The ODE of a floating base is checked
through the quaternion product and ``integrateCoeffWiseJacobian``, and ``rk4_step`` keeps the
quaternion unit over a 10 s simulation.
"""

from __future__ import annotations

import ctypes
import dataclasses
import json
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from derive.codegen.generate import generate
from derive.codegen.program import build_program
from derive.symbolic.model import SXModel
from derive.description.model import load_models, parse_models, parse_robot
from derive.description.urdf import example_robot_data_dir, import_urdf_named
from util import assert_close, build_library, load_module

pin = pytest.importorskip("pinocchio")

N_STATES = 10
TOL = 1e-9
CFLAGS = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O0", "-shared", "-fPIC"]  # -O0: compiles fast

GRIPPER_URDF = """<?xml version="1.0"?>
<robot name="gripper">
  <link name="base"/>
  <link name="l1"><inertial><origin xyz="0.1 0 0.02" rpy="0.1 0.2 0.3"/><mass value="1"/>
    <inertia ixx="0.01" ixy="0.001" ixz="0" iyy="0.02" iyz="0" izz="0.03"/></inertial></link>
  <link name="fa"><inertial><origin xyz="0 0.05 0.01"/><mass value="0.3"/>
    <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.002" iyz="0" izz="0.001"/></inertial></link>
  <link name="fb"><inertial><origin xyz="0 -0.05 0.02"/><mass value="0.2"/>
    <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.002" iyz="0" izz="0.003"/></inertial></link>
  <link name="l2"><inertial><origin xyz="0.1 0 0"/><mass value="0.5"/>
    <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.002" iyz="0" izz="0.003"/></inertial></link>
  <link name="l3"><inertial><origin xyz="0.05 0.02 0"/><mass value="0.4"/>
    <inertia ixx="0.002" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.002"/></inertial></link>
  <link name="tool"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="fa_joint" type="prismatic"><parent link="l1"/><child link="fa"/><origin xyz="0.2 0 0"/>
    <axis xyz="0 1 0"/><limit lower="-0.1" upper="0.1" effort="1" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="fa"/><child link="l2"/><origin xyz="0 0.1 0" rpy="0.3 0 0"/>
    <axis xyz="1 0 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
  <joint name="fb_joint" type="prismatic"><parent link="l1"/><child link="fb"/><origin xyz="0.2 0 0"/>
    <axis xyz="0 1 0"/><limit lower="-0.2" upper="0.2" effort="1" velocity="1"/>
    <mimic joint="fa_joint" multiplier="-2" offset="0.01"/></joint>
  <joint name="j3" type="revolute"><parent link="fb"/><child link="l3"/><origin xyz="0 -0.1 0"/>
    <axis xyz="0 1 0"/><limit lower="-3" upper="3" effort="1" velocity="1"/>
    <mimic joint="j2" multiplier="0.5" offset="0.2"/></joint>
  <joint name="tool_joint" type="fixed"><parent link="l2"/><child link="tool"/><origin xyz="0.1 0 0"/></joint>
</robot>
"""

GRIPPER_YAML = """
robots:
  gripper:
    links:
      - {name: base}
      - {name: l1, mass: 1.0, com: [0.1, 0, 0.02], inertia_rpy: [0.1, 0.2, 0.3],
         inertia: [[0.01, 0.001, 0], [0.001, 0.02, 0], [0, 0, 0.03]]}
      - {name: fa, mass: 0.3, com: [0, 0.05, 0.01], inertia: [[0.001, 0, 0], [0, 0.002, 0], [0, 0, 0.001]]}
      - {name: l2, mass: 0.5, com: [0.1, 0, 0], inertia: [[0.001, 0, 0], [0, 0.002, 0], [0, 0, 0.003]]}
      - {name: fb, mass: 0.2, com: [0, -0.05, 0.02], inertia: [[0.001, 0, 0], [0, 0.002, 0], [0, 0, 0.003]]}
      - {name: l3, mass: 0.4, com: [0.05, 0.02, 0], inertia: [[0.002, 0, 0], [0, 0.001, 0], [0, 0, 0.002]]}
    joints:
      - {name: j1, type: revolute, parent: base, child: l1, axis: [0, 0, 1]}
      - {name: fa_joint, type: prismatic, parent: l1, child: fa, origin: {xyz: [0.2, 0, 0]}, axis: [0, 1, 0]}
      - {name: j2, type: revolute, parent: fa, child: l2, origin: {xyz: [0, 0.1, 0], rpy: [0.3, 0, 0]}, axis: [1, 0, 0]}
      - {name: fb_joint, type: prismatic, parent: l1, child: fb, origin: {xyz: [0.2, 0, 0]}, axis: [0, 1, 0],
         mimic: {joint: fa_joint, multiplier: -2.0, offset: 0.01}}
      - {name: j3, type: revolute, parent: fb, child: l3, origin: {xyz: [0, -0.1, 0]}, axis: [0, 1, 0],
         mimic: {joint: j2, multiplier: 0.5, offset: 0.2}}
    frames:
      - {name: tcp, link: l2, xyz: [0.1, 0, 0]}
    wrenches: [tcp, l3]
"""


class Case:
    """One robot: its derive model, generated Python and C, and Pinocchio's model of the same URDF."""

    def __init__(self, robot, pm, frames: dict[str, str], out: Path, compile_c: bool = True):
        self.robot, self.pm, self.pd, self.frames = robot, pm, pm.createData(), frames
        generate({robot.name: robot}, out, log=lambda s: None)
        folder = out / robot.name
        self.manifest = json.loads((folder / "manifest.json").read_text())
        self.py = load_module(folder / "python" / f"{robot.name}.py", f"whole_{robot.name}")
        self.lib = None
        if compile_c:
            lib = build_library(["cc", *CFLAGS], sorted((folder / "c").glob("*.c")), out / f"lib{robot.name}.so")
            self.lib = ctypes.CDLL(str(lib))
        self.fn = {f["name"].removeprefix(robot.name + "_"): f for f in self.manifest["functions"]}

    def c(self, short: str, *args) -> list[np.ndarray]:
        f = self.fn[short]
        ins = [np.ascontiguousarray(a, dtype=float) for a in args]
        outs = [np.zeros(o["shape"]) for o in f["outputs"]]
        ptr = ctypes.POINTER(ctypes.c_double)
        getattr(self.lib, f["name"])(*[a.ctypes.data_as(ptr) for a in ins + outs])
        return outs

    def check(self, short: str, expected, *args) -> None:
        """Python and C of ``short`` at ``args`` against ``expected`` (1e-9 relative)."""
        expected = np.asarray(expected, dtype=float)
        py = np.asarray(getattr(self.py, short)(*args), dtype=float)
        assert_close(py.reshape(expected.shape), expected, TOL, f"{self.robot.name} {short} (Python)")
        if self.lib is not None:
            assert_close(self.c(short, *args)[0].reshape(expected.shape), expected, TOL, f"{self.robot.name} {short} (C)")

    def states(self, seed: int = 0):
        rng = np.random.default_rng(seed)
        for _ in range(N_STATES):
            q = pin.randomConfiguration(self.pm, -np.ones(self.pm.nq), np.ones(self.pm.nq))
            yield q, rng.normal(size=self.pm.nv), rng.normal(size=self.pm.nv), rng.normal(size=self.pm.nv) * 5

    def aba(self, q, v, tau, fext=None) -> np.ndarray:
        """Pinocchio's ABA; with mimic joints (which its ABA refuses) M^-1 (tau - rnea(q, v, 0, fext))."""
        pm, pd = self.pm, self.pd
        args = (fext,) if fext is not None else ()
        if any(j.shortname() == "JointModelMimic" for j in pm.joints):
            return np.linalg.solve(sym(pin.crba(pm, pd, q)), tau - pin.rnea(pm, pd, q, v, 0 * v, *args))
        return pin.aba(pm, pd, q, v, tau, *args)

    def fext(self, q, w: np.ndarray) -> list:
        """derive's world-aligned wrenches at frame origins as Pinocchio's per-joint local forces."""
        pin.framesForwardKinematics(self.pm, self.pd, q)
        forces = [pin.Force.Zero() for _ in range(self.pm.njoints)]
        for k, name in enumerate(self.robot.wrench_frames):
            fid = self.pm.getFrameId(self.frames.get(name, name))
            joint = self.pm.frames[fid].parentJoint
            at_world_origin = pin.SE3(np.eye(3), self.pd.oMf[fid].translation).act(pin.Force(w[6 * k:6 * k + 3], w[6 * k + 3:6 * k + 6]))
            forces[joint] += self.pd.oMi[joint].actInv(at_world_origin)
        return forces


def sym(M: np.ndarray) -> np.ndarray:
    return np.triu(M) + np.triu(M, 1).T


def erd(rel: str) -> str:
    base = example_robot_data_dir()
    if base is None:
        pytest.fail("example-robot-data is not installed (the Makefile installs it with pinocchio)")
    return str(base / rel)


@pytest.fixture(scope="module")
def panda_floating(tmp_path_factory):
    robot = dataclasses.replace(load_models()["panda"], name="panda_ff", base="floating", wrenches=("tcp", "panda_link4"))
    full = pin.buildModelFromUrdf(erd("panda_description/urdf/panda.urdf"), pin.JointModelFreeFlyer())
    locked = [full.getJointId(n) for n in ("panda_finger_joint1", "panda_finger_joint2")]
    pm = pin.buildReducedModel(full, locked, pin.neutral(full))
    return Case(robot, pm, {"tcp": "panda_hand_tcp"}, tmp_path_factory.mktemp("panda_ff"))


@pytest.fixture(scope="module")
def gripper(tmp_path_factory):
    robot = parse_models(GRIPPER_YAML)["gripper"]
    pm = pin.buildModelFromXML(GRIPPER_URDF, mimic=True)
    pm.addFrame(pin.Frame("tcp", pm.getJointId("j2"), pm.getFrameId("l2"), pin.SE3(np.eye(3), np.array([0.1, 0, 0])),
                          pin.FrameType.OP_FRAME))
    return Case(robot, pm, {}, tmp_path_factory.mktemp("gripper"))


def check_dynamics(case: Case) -> None:
    """M, g, ID, FD, ID and FD with wrenches, CoM, its Jacobian, the centroidal map and every frame's
    accelerations against Pinocchio."""
    pm, pd = case.pm, case.pd
    frames = [f.name for f in case.robot.frames]
    for q, v, a, tau in case.states():
        w = np.random.default_rng(len(case.robot.name)).normal(size=6 * len(case.robot.wrench_frames))
        case.check("mass_matrix", sym(pin.crba(pm, pm.createData(), q)), q)  # a fresh Data: crba of mimic models accumulates
        case.check("gravity", pin.computeGeneralizedGravity(pm, pd, q), q)
        case.check("inverse_dynamics", pin.rnea(pm, pd, q, v, a), q, v, a)
        fext = case.fext(q, w)
        case.check("forward_dynamics", case.aba(q, v, tau), q, v, tau)
        case.check("inverse_dynamics_fext", pin.rnea(pm, pd, q, v, a, fext), q, v, a, w)
        case.check("forward_dynamics_fext", case.aba(q, v, tau, fext), q, v, tau, w)
        case.check("com", pin.centerOfMass(pm, pd, q), q)
        case.check("com_jacobian", pin.jacobianCenterOfMass(pm, pd, q), q)
        case.check("centroidal_map", pin.computeCentroidalMap(pm, pd, q), q)
        for name in frames:
            fid = pm.getFrameId(case.frames.get(name, name))
            pin.forwardKinematics(pm, pd, q, v, a)
            pin.updateFramePlacements(pm, pd)
            case.check(f"fk_{name}", pd.oMf[fid].homogeneous, q)
            acc = pin.getFrameClassicalAcceleration(pm, pd, fid, pin.LOCAL_WORLD_ALIGNED)
            case.check(f"frame_acceleration_{name}", np.r_[acc.linear, acc.angular], q, v, a)
            pin.forwardKinematics(pm, pd, q, v, 0 * a)
            acc = pin.getFrameClassicalAcceleration(pm, pd, fid, pin.LOCAL_WORLD_ALIGNED)
            case.check(f"jdot_qd_{name}", np.r_[acc.linear, acc.angular], q, v)
            pin.computeJointJacobians(pm, pd, q)
            case.check(f"jacobian_{name}", pin.getFrameJacobian(pm, pd, fid, pin.LOCAL_WORLD_ALIGNED), q)


def test_floating_panda_against_pinocchio(panda_floating):
    case = panda_floating
    assert (case.robot.nq, case.robot.nv) == (case.pm.nq, case.pm.nv) == (14, 13)
    assert case.manifest["base"] == "floating" and case.manifest["velocities"][:6] == [
        "base_vx", "base_vy", "base_vz", "base_wx", "base_wy", "base_wz"]
    assert "ik_tcp" not in case.fn
    check_dynamics(case)
    for q, v, _, _ in case.states(seed=2):  # the spatial factorisation (Christoffel needs qd = dq/dt)
        case.check("coriolis_matrix", pin.computeCoriolisMatrix(case.pm, case.pd, q, v), q, v)


def test_floating_ode_against_pinocchio(panda_floating):
    """dq/dt: R v and 1/2 quat (x) (w, 0); df/dx on the tangent space equals computeABADerivatives."""
    case = panda_floating
    pm, pd, nq = case.pm, case.pd, case.pm.nq
    for q, v, _, tau in case.states(seed=1):
        quat = pin.Quaternion(q[6], *q[3:6])  # (w, x, y, z)
        rate = quat * pin.Quaternion(0.0, *v[3:6])
        q_rate = np.r_[quat.matrix() @ v[:3], 0.5 * rate.coeffs(), v[6:]]  # coeffs: (x, y, z, w)
        x = np.r_[q, v]
        case.check("ode_rhs", np.r_[q_rate, pin.aba(pm, pd, q, v, tau)], x, tau)
        pin.computeABADerivatives(pm, pd, q, v, tau)
        A = np.asarray(case.py.ode_jac_x(x, tau))
        A_c = case.c("ode_jac_x", x, tau)[0]
        assert_close(A_c, A, 1e-12, "ode_jac_x C against Python")
        # d(q (+) dv)/d dv at dv = 0 (nq x nv): R for the position, 1/2 quat (x) (e_k, 0) for the quaternion
        tangent = np.zeros((nq, pm.nv))
        tangent[:3, :3] = quat.matrix()
        for k in range(3):
            tangent[3:7, 3 + k] = 0.5 * (quat * pin.Quaternion(0.0, *np.eye(3)[k])).coeffs()
        tangent[7:, 6:] = np.eye(pm.nv - 6)
        assert_close(A[nq:, :nq] @ tangent, pd.ddq_dq, TOL, "d qdd / dq on the tangent space")
        assert_close(A[nq:, nq:], pd.ddq_dv, TOL, "d qdd / dv")
        assert_close(np.asarray(case.py.ode_jac_u(x, tau))[nq:], np.linalg.inv(sym(pin.crba(pm, pd, q))), TOL, "df/du")


def test_floating_rk4_keeps_the_quaternion_unit(panda_floating):
    """10 s of free fall with the base spinning: |quat| stays 1 to 1e-12 (rk4_step renormalises)."""
    case = panda_floating
    x = np.r_[pin.neutral(case.pm), np.zeros(case.pm.nv)]
    x[13:19] = [0.1, 0.0, 0.2, 0.3, -0.5, 1.0]
    worst = 0.0
    for _ in range(2000):  # 10 s at 5 ms
        x = case.py.rk4_step(x, np.zeros(case.pm.nv), 5e-3)
        worst = max(worst, abs(np.linalg.norm(x[3:7]) - 1))
    assert np.isfinite(x).all() and worst <= 1e-12, worst
    x_c = np.r_[pin.neutral(case.pm), np.zeros(case.pm.nv)]
    x_c[13:19] = [0.1, 0.0, 0.2, 0.3, -0.5, 1.0]
    for _ in range(200):
        x_c = case.c("rk4_step", x_c, np.zeros(case.pm.nv), [5e-3])[0]
    assert abs(np.linalg.norm(x_c[3:7]) - 1) <= 1e-12


def test_mimic_joints_against_pinocchio(gripper):
    case = gripper
    assert (case.robot.nq, case.robot.nv) == (case.pm.nq, case.pm.nv) == (3, 3)
    assert [c.name for c in case.robot.coordinates] == ["j1", "fa_joint", "j2"]
    check_dynamics(case)


def test_fixed_base_com_and_accelerations_against_pinocchio(tmp_path):
    """The new functions of a fixed-base arm (ur5 with a wrench at the TCP and one at wrist_1_link)."""
    robot = dataclasses.replace(load_models()["ur5"], name="ur5_w", wrenches=("tcp", "wrist_1_link"))
    pm = pin.buildModelFromUrdf(erd("ur_description/urdf/ur5_robot.urdf"))
    check_dynamics(Case(robot, pm, {"tcp": "tool0", "base": "base", "ee_link": "ee_link", "base_link": "base_link"},
                        tmp_path))


def imported(rel: str, floating: bool = True):
    """A URDF imported whole; without its <dynamics> friction, which Pinocchio's rnea and aba leave out
    (tests/test_actuators.py and tests/test_urdf_trees.py check the friction)."""
    name, entry = import_urdf_named("example-robot-data:" + rel, floating=floating, friction=False)
    return parse_robot(name, entry)


@pytest.fixture(scope="module")
def solo12(tmp_path_factory):
    rel = "solo_description/robots/solo12.urdf"
    robot = dataclasses.replace(imported(rel), wrenches=("FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT"))
    pm = pin.buildModelFromUrdf(erd(rel), pin.JointModelFreeFlyer())
    # Python only: the generated C is compared with Pinocchio for the floating panda (same templates)
    return Case(robot, pm, {}, tmp_path_factory.mktemp("solo12"), compile_c=False)


def test_solo12_floating_against_pinocchio(solo12):
    """solo12 imported whole with --floating: every generated function Pinocchio has, with the four feet
    taking contact wrenches, and its generated ODE keeps the quaternion unit over 10 s."""
    case = solo12
    assert (case.robot.nq, case.robot.nv) == (case.pm.nq, case.pm.nv) == (19, 18)
    check_dynamics(case)
    x = np.r_[pin.neutral(case.pm), np.zeros(case.pm.nv)]
    x[19:25] = [0.2, -0.1, 0.5, 1.0, -2.0, 3.0]
    worst = 0.0
    for _ in range(2000):  # 10 s at 5 ms, falling and tumbling with the joints limp
        x = case.py.rk4_step(x, np.zeros(case.pm.nv), 5e-3)
        worst = max(worst, abs(np.linalg.norm(x[3:7]) - 1))
    assert np.isfinite(x).all() and worst <= 1e-12, worst


def test_talos_reduced_floating_against_pinocchio():
    """talos_reduced (32 joints) with a floating base: M, ID, FD, the centre of mass and its Jacobian of the
    derived model (evaluated through CasADi, without generating its 146 functions) against Pinocchio's
    free-flyer model, and the ODE with rk4_step's renormalisation keeps the quaternion unit over 10 s."""
    rel = "talos_data/robots/talos_reduced.urdf"
    robot = imported(rel)
    m = SXModel(robot)
    s, ne, wb = m.sym, m.newton_euler, m.whole_body
    f = ca.Function("f", [s.q, s.qd, s.qdd, s.tau], [ne.mass_matrix, ne.inverse_dynamics(), m.forward_dynamics(),
                                                      wb.com, wb.com_jacobian])
    pm = pin.buildModelFromUrdf(erd(rel), pin.JointModelFreeFlyer())
    pd = pm.createData()
    assert (robot.nq, robot.nv) == (pm.nq, pm.nv) == (39, 38)
    rng = np.random.default_rng(0)
    for _ in range(5):
        q = pin.randomConfiguration(pm, -np.ones(pm.nq), np.ones(pm.nq))
        v, a, tau = rng.normal(size=(3, pm.nv))
        M, tau_id, qdd, com, J_com = [np.asarray(x) for x in f(q, v, a, tau)]
        assert_close(M, sym(pin.crba(pm, pd, q)), TOL, "M")
        assert_close(tau_id.ravel(), pin.rnea(pm, pd, q, v, a), TOL, "ID")
        assert_close(qdd.ravel(), pin.aba(pm, pd, q, v, tau), TOL, "FD")
        assert_close(com.ravel(), pin.centerOfMass(pm, pd, q), TOL, "com")
        assert_close(J_com, pin.jacobianCenterOfMass(pm, pd, q), TOL, "com Jacobian")
    ode = ca.Function("ode", [s.x, s.tau], [m.ode_rhs()])
    x = np.r_[pin.neutral(pm), np.zeros(pm.nv)]
    x[39:45] = [0.2, -0.1, 0.5, 1.0, -2.0, 3.0]
    worst, h, u = 0.0, 1e-2, np.zeros(pm.nv)
    for _ in range(1000):  # 10 s; the same step and projection as the generated rk4_step
        k1 = np.asarray(ode(x, u)).ravel()
        k2 = np.asarray(ode(x + h / 2 * k1, u)).ravel()
        k3 = np.asarray(ode(x + h / 2 * k2, u)).ravel()
        k4 = np.asarray(ode(x + h * k3, u)).ravel()
        x = x + h / 6 * (k1 + 2 * (k2 + k3) + k4)
        x[3:7] /= np.linalg.norm(x[3:7])
        worst = max(worst, abs(np.linalg.norm(x[3:7]) - 1))
    assert np.isfinite(x).all() and worst <= 1e-12, worst


def legged(legs: int, depth: int = 3):
    """A floating body with ``legs`` legs of ``depth`` revolute joints each (a synthetic quadruped family)."""
    links = ["{name: base, mass: 5.0, inertia: [0.1, 0.2, 0.3]}"]
    joints = []
    for leg in range(legs):
        parent = "base"
        for d in range(depth):
            links.append(f"{{name: l{leg}_{d}, mass: 1.0, com: [0.1, 0.02, 0.01], inertia: [0.01, 0.02, 0.015]}}")
            joints.append(f"{{name: j{leg}_{d}, type: revolute, parent: {parent}, child: l{leg}_{d}, "
                          f"axis: {[[0, 0, 1], [0, 1, 0], [1, 0, 0]][d % 3]}, "
                          f"origin: {{xyz: [0.3, {0.1 * leg if d == 0 else 0}, 0], rpy: [0.1, 0.2, {0.3 * leg}]}}}}")
            parent = f"l{leg}_{d}"
    text = ("robots:\n  legs:\n    base: floating\n    links:\n" + "".join(f"      - {x}\n" for x in links)
            + "    joints:\n" + "".join(f"      - {x}\n" for x in joints))
    return parse_models(text)["legs"]


def test_inverse_and_forward_dynamics_grow_linearly_on_trees():
    """Doubling the legs of a floating robot doubles the ops of ID, M and FD (RNEA, CRBA and the LTDL
    solve along the tree: no fill-in), where LDL^T from the root filled the whole matrix (FD 4x)."""
    ops = []
    for legs in (4, 8, 16):
        m = SXModel(legged(legs))
        s, ne = m.sym, m.newton_euler
        ops.append([build_program(ins, [("out", e)]).ops()["total"] for ins, e in (
            ([("q", s.q), ("qd", s.qd), ("qdd", s.qdd)], ne.inverse_dynamics()),
            ([("q", s.q)], ne.mass_matrix),
            ([("q", s.q), ("qd", s.qd), ("tau", s.tau)], m.forward_dynamics()))])
    for small, large in zip(ops, ops[1:]):
        for a, b in zip(small, large):
            assert b <= 2.1 * a, ops
    m = SXModel(legged(4))
    rng = np.random.default_rng(0)
    f = ca.Function("f", [m.sym.q, m.sym.qd, m.sym.tau], [m.forward_dynamics(), m.newton_euler.mass_matrix,
                                                          m.newton_euler.bias])
    for _ in range(5):
        q = rng.normal(size=m.sym.nq)
        q[3:7] /= np.linalg.norm(q[3:7])
        qd, tau = rng.normal(size=(2, m.sym.nv))
        qdd, M, bias = [np.asarray(x) for x in f(q, qd, tau)]
        assert_close(qdd.ravel(), np.linalg.solve(M, tau - bias.ravel()), 1e-12, "LTDL solve")
