"""Every joint type of the lecture's Table 1 (plus fixed), derived and checked.

One arm per type (revolute j0, the joint under test, revolute j2; unaligned axes,
full inertias, tilted gravity), one branched tree using all types at once and the
README's examples/joint_types.yaml. At
50 seeded states: M, g and the inverse dynamics of both symbolic routes against the
numpy reference's crba / gravity / rnea (1e-9 relative); the reference against
itself (rnea vs crba, aba and the complex-step Christoffel C) and against
Pinocchio; Jacobians against complex-step derivatives of FK; the joint
transforms in closed form; Table 1's counts; gimbal lock; validation errors;
generated C and Python.
"""

from __future__ import annotations

import ctypes
import json
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from derive.description import expr
from derive.symbolic.model import SXModel
from derive.cli import main
from derive.codegen.generate import generate
from derive.description.model import load_models, parse_models
from derive.description.joints import JOINT_TYPES, MOVES_AS
from derive.description.robot import ModelError
from derive.reference import NumericRobot
from derive.reference.rnea import rpy_matrix
from util import assert_close, build_library, load_module

TABLE_1 = {"revolute": (1, 5), "prismatic": (1, 5), "helical": (1, 5), "cylindrical": (2, 4), "universal": (2, 4),
           "spherical": (3, 3), "fixed": (0, 6)}
"""The lecture's Table 1 (DOF, constraints), and the fixed joint."""

A = "[0.6, 0, 0.8]"  # an unaligned unit axis: exercises Rodrigues, not Rx/Ry/Rz
UNDER_TEST = {
    "revolute": f"type: revolute, axis: {A}",
    "continuous": f"type: continuous, axis: {A}, limits: {{velocity: 2, effort: 5}}",
    "prismatic": f"type: prismatic, axis: {A}",
    "helical": f"type: helical, axis: {A}, pitch: h",
    "cylindrical": f"type: cylindrical, axis: {A}, limits: [{{lower: -3, upper: 3}}, {{lower: -0.5, upper: 0.5}}]",
    "universal": f"type: universal, axis: {A}, axis2: [0, 1, 0]",
    "spherical": "type: spherical",
    "fixed": "type: fixed",
}

ARM = """
robots:
  {name}:
    parameters: {{h: 0.05}}
    gravity: [0.3, -0.2, -9.81]
    links:
      - {{name: base}}
      - {{name: l1, mass: 1.3, com: [0.1, -0.05, 0.2], inertia: [[0.03, 0.002, -0.001], [0.002, 0.025, 0.003], [-0.001, 0.003, 0.02]], inertia_rpy: [0.1, 0.2, 0.3]}}
      - {{name: l2, mass: 0.8, com: [0.05, 0.1, -0.1], inertia: [0.01, 0.012, 0.008], inertia_rpy: [-0.3, 0.1, 0.5]}}
      - {{name: l3, mass: 0.5, com: [0.2, 0.0, 0.02], inertia: [0.002, 0.004, 0.004]}}
    joints:
      - {{name: j0, type: revolute, parent: base, child: l1, origin: {{xyz: [0.1, 0, 0.3], rpy: [0.2, -0.1, 0.3]}}, axis: [0, 0, 1]}}
      - {{name: jt, parent: l1, child: l2, origin: {{xyz: [0.2, 0.1, 0.4], rpy: [0.0, 0.4, -0.2]}}, {joint}}}
      - {{name: j2, type: revolute, parent: l2, child: l3, origin: {{xyz: [0.3, 0, 0]}}, axis: [0, 1, 0]}}
    frames:
      - {{name: tcp, link: l3, xyz: [0.4, 0.0, 0.05], rpy: [0.1, 0.2, 0.3]}}
"""

ZOO = """
robots:
  zoo:
    parameters: {h: 0.05}
    gravity: [0.3, -0.2, -9.81]
    links:
      - {name: base}
      - {name: l1, mass: 1.3, com: [0.1, -0.05, 0.2], inertia: [[0.03, 0.002, -0.001], [0.002, 0.025, 0.003], [-0.001, 0.003, 0.02]], inertia_rpy: [0.1, 0.2, 0.3]}
      - {name: l2, mass: 0.8, com: [0.05, 0.1, -0.1], inertia: [0.01, 0.012, 0.008]}
      - {name: l2b, mass: 0.3, com: [0.02, 0.0, 0.05], inertia: [0.002, 0.003, 0.001]}
      - {name: l3, mass: 1.1, com: [-0.1, 0.05, 0.15], inertia: [0.02, 0.015, 0.01], inertia_rpy: [-0.3, 0.1, 0.5]}
      - {name: l4, mass: 0.6, com: [0.0, 0.08, 0.03], inertia: [0.004, 0.005, 0.006]}
      - {name: l5, mass: 0.4, com: [0.03, 0.02, 0.1], inertia: [0.001, 0.002, 0.0015]}
    joints:
      - {name: ball, type: spherical, parent: base, child: l1, origin: {xyz: [0.1, 0.0, 0.3], rpy: [0.2, -0.1, 0.3]}}
      - {name: uj, type: universal, parent: l1, child: l2, origin: {xyz: [0.2, 0.1, 0.4], rpy: [0.0, 0.4, -0.2]}, axis: [0.6, 0, 0.8], axis2: [0, 1, 0]}
      - {name: weld, type: fixed, parent: l2, child: l2b, origin: {xyz: [0.0, 0.1, 0.2], rpy: [0.3, 0.0, 0.0]}}
      - {name: cyl, type: cylindrical, parent: base, child: l3, origin: {xyz: [-0.2, 0.1, 0.1], rpy: [0.5, 0.2, 0.0]}, axis: [0.0, 0.6, 0.8]}
      - {name: screw, type: helical, parent: l3, child: l4, origin: {xyz: [0.1, 0.2, 0.3]}, axis: [1, 1, 0], pitch: -0.02}
      - {name: slide, type: prismatic, parent: l1, child: l5, origin: {xyz: [0.0, 0.0, 0.1], rpy: [0.0, 0.0, 0.7]}, axis: [0, 0, 1]}
    frames:
      - {name: tcp, link: l2b, xyz: [0.1, 0.0, 0.05], rpy: [0.1, 0.2, 0.3]}
      - {name: tip, link: l4, xyz: [0.0, 0.1, 0.2]}
"""

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "joint_types.yaml"  # the README's example
ROBOTS = {**{t: parse_models(ARM.format(name=f"{t}_arm", joint=UNDER_TEST[t]))[f"{t}_arm"] for t in UNDER_TEST},
          "zoo": parse_models(ZOO)["zoo"], "example": load_models(EXAMPLE)["joint_types"]}
N_STATES = 50
H = 1e-30  # complex step


def params(robot) -> np.ndarray:
    return np.array([p.default for p in robot.parameters])


def random_q(robot, rng) -> np.ndarray:
    """Angles in [-pi, pi] (a spherical joint's pitch within [-1.2, 1.2], off gimbal lock), lengths in [-0.5, 0.5] m."""
    out = []
    for c in robot.coordinates:
        span = 1.2 if c.type == "spherical" and c.name.endswith("_y") else np.pi if c.unit == "rad" else 0.5
        out.append(rng.uniform(-span, span))
    return np.array(out)


def states(robot, n: int = N_STATES):
    rng = np.random.default_rng(0)
    for _ in range(n):
        yield random_q(robot, rng), rng.normal(size=robot.nv), rng.normal(size=robot.nv)


@pytest.fixture(scope="module", params=list(ROBOTS))
def case(request):
    robot = ROBOTS[request.param]
    model = SXModel(robot)
    s = model.sym
    outs = [model.mass_matrix("lagrange"), model.mass_matrix("newton-euler"),
            model.gravity_vector("lagrange"), model.gravity_vector("newton-euler"),
            model.inverse_dynamics("lagrange"), model.inverse_dynamics("newton-euler")]
    return robot, model, ca.Function("dyn", [s.q, s.qd, s.qdd, s.p], outs), NumericRobot(robot)


# ---------------------------------------------------------------- Table 1


def test_dof_and_constraints_follow_table_1():
    assert set(JOINT_TYPES) - set(MOVES_AS) == set(TABLE_1) == {j.type for j in ROBOTS["example"].joints}
    assert ROBOTS["continuous"].joints[1].summary == "jt (continuous, 1 DOF, 5 constraints)"  # a revolute's motion
    for jtype, (dof, constraints) in TABLE_1.items():
        joint = ROBOTS[jtype].joints[1]
        assert (joint.type, joint.dof, joint.constraints) == (jtype, dof, constraints)
        assert ROBOTS[jtype].nq == ROBOTS[jtype].nv == 2 + dof
        assert len(joint.coordinates) == dof
    assert ROBOTS["fixed"].joints[1].summary == "jt (fixed, 0 DOF, 6 constraints)"
    assert ROBOTS["helical"].joints[1].summary == "jt (helical, 1 DOF, 5 constraints)"
    zoo = ROBOTS["zoo"]
    assert [c.name for c in zoo.coordinates] == ["ball_z", "ball_y", "ball_x", "uj_1", "uj_2", "slide",
                                                 "cyl_rot", "cyl_trans", "screw"]  # depth-first, a joint's own order
    assert [c.unit for c in zoo.coordinates] == ["rad", "rad", "rad", "rad", "rad", "m", "rad", "m", "rad"]
    assert list(SXModel(zoo).sym.joint_names) == [c.name for c in zoo.coordinates]


def test_info_reports_dof_constraints_and_gimbal_lock(tmp_path, capsys):
    path = tmp_path / "zoo.yaml"
    path.write_text(ZOO)
    assert main(["--models", str(path), "info", "zoo"]) == 0
    out = capsys.readouterr().out
    assert "ball (spherical, 3 DOF, 3 constraints: ball_z, ball_y, ball_x)" in out
    assert "uj (universal, 2 DOF, 4 constraints: uj_1, uj_2)" in out
    assert "cyl (cylindrical, 2 DOF, 4 constraints: cyl_rot, cyl_trans)" in out
    assert "screw (helical, 1 DOF, 5 constraints)" in out and "slide (prismatic, 1 DOF, 5 constraints)" in out
    assert "gimbal lock: cos(ball_y) = 0" in out


def test_limits_per_coordinate():
    cyl = ROBOTS["cylindrical"].joints[1]
    assert [(c.name, c.unit, c.limits.lower, c.limits.upper) for c in cyl.coordinates] == [
        ("jt_rot", "rad", -3.0, 3.0), ("jt_trans", "m", -0.5, 0.5)]
    one = parse_models(ARM.format(name="a", joint="type: spherical, limits: {lower: -1, upper: 1}"))["a"]
    assert [c.limits.upper for c in one.joints[1].coordinates] == [1.0, 1.0, 1.0]


# ---------------------------------------------------------------- symbolic vs reference


def test_mass_matrix_gravity_and_inverse_dynamics_match_reference(case):
    robot, _, f, ref = case
    for q, qd, qdd in states(robot):
        M_lag, M_ne, g_lag, g_ne, tau_lag, tau_ne = (np.array(o) for o in f(q, qd, qdd, params(robot)))
        M, g, tau = ref.crba(q), ref.gravity(q), ref.rnea(q, qd, qdd)
        assert_close(M_lag, M, what=f"{robot.name} M (Lagrange)")
        assert_close(M_ne, M, what=f"{robot.name} M (CRBA)")
        assert_close(g_lag.ravel(), g, what=f"{robot.name} g = dU/dq")
        assert_close(g_ne.ravel(), g, what=f"{robot.name} g (RNEA)")
        assert_close(tau_lag.ravel(), tau, what=f"{robot.name} tau (Lagrange)")
        assert_close(tau_ne.ravel(), tau, what=f"{robot.name} tau (RNEA)")
        assert np.linalg.eigvalsh(M_ne).min() > 0, f"{robot.name}: M not positive definite at q = {q}"


def test_reference_rnea_is_consistent_with_crba_aba_and_christoffel(case):
    robot, _, _, ref = case
    zero = np.zeros(robot.nv)
    for q, qd, qdd in states(robot):
        M, g = ref.crba(q), ref.gravity(q)
        assert_close(M, M.T, rtol=1e-15, what=f"{robot.name} M symmetric")
        assert_close(np.column_stack([ref.rnea(q, zero, e) for e in np.eye(robot.nv)]) - g[:, None], M,
                     what=f"{robot.name} rnea(q, 0, e_i) - g = M e_i")
        tau = ref.rnea(q, qd, qdd)
        assert_close(ref.aba(q, qd, tau), qdd, what=f"{robot.name} aba(rnea) = qdd")
        # c_J = Sdot qd of the multi-DOF joints enters rnea only; C comes from complex-step dM/dq
        assert_close(ref.coriolis_matrix(q, qd) @ qd, ref.rnea(q, qd, zero) - g, what=f"{robot.name} C qd")
        assert ref.kinetic_energy(q, qd) == pytest.approx(0.5 * qd @ M @ qd, rel=1e-12)


def test_jacobians_match_complex_step_fk(case):
    """Symbolic and reference Jacobians [v; w] against Im fk(q + i h e_k) / h (exact derivatives)."""
    robot, model, _, ref = case
    s = model.sym
    frames = [fr for fr in robot.frame_names if fr != robot.root]
    fn = ca.Function("k", [s.q, s.p], [e for fr in frames for e in (model.fk(fr), model.jacobian(fr))])
    for q, _, _ in states(robot, 20):
        out = [np.array(o) for o in fn(q, params(robot))]
        for n, fr in enumerate(frames):
            T, J = out[2 * n], out[2 * n + 1]
            assert_close(T, ref.frame_pose(q, fr), what=f"{robot.name} fk {fr}")
            dp, w = np.zeros((3, robot.nv)), np.zeros((3, robot.nv))
            for k in range(robot.nv):
                Tc = ref.frame_pose(q + 1j * H * np.eye(robot.nv)[k], fr)
                dp[:, k] = Tc[:3, 3].imag / H
                W = (Tc[:3, :3].imag / H) @ T[:3, :3].T  # [w]x = Rdot R^T
                w[:, k] = [W[2, 1], W[0, 2], W[1, 0]]
            expected = np.vstack([dp, w])
            assert_close(J, expected, what=f"{robot.name} J {fr}")
            assert_close(ref.jacobian(q, fr), expected, what=f"{robot.name} reference J {fr}")


def pinocchio_model(robot, pin):
    """The same tree built joint by joint in Pinocchio (no URDF has these joint types)."""
    num = lambda v: float(expr.evaluate(v, robot.parameter_defaults))  # noqa: E731

    def se3(xyz, rpy):
        return pin.SE3(rpy_matrix(*map(num, rpy)), np.array([num(x) for x in xyz]))

    def joint_model(j):
        a = np.array(j.axis)
        if j.type == "cylindrical":
            composite = pin.JointModelComposite(pin.JointModelRevoluteUnaligned(a))
            composite.addJoint(pin.JointModelPrismaticUnaligned(a))
            return composite
        return {"revolute": lambda: pin.JointModelRevoluteUnaligned(a),
                "continuous": lambda: pin.JointModelRevoluteUnaligned(a),  # one angle, not (cos, sin)
                "prismatic": lambda: pin.JointModelPrismaticUnaligned(a),
                "helical": lambda: pin.JointModelHelicalUnaligned(a, num(j.pitch)),
                "universal": lambda: pin.JointModelUniversal(a, np.array(j.axis2)),
                "spherical": pin.JointModelSphericalZYX}[j.type]()

    model = pin.Model()
    model.gravity.linear = np.array([num(x) for x in robot.gravity])
    placed = {robot.root: (0, pin.SE3.Identity())}
    for j in robot.joints:
        parent, at = placed[j.parent]
        pose = at * se3(j.origin.xyz, j.origin.rpy)
        placed[j.child] = (parent, pose) if j.type == "fixed" else (
            model.addJoint(parent, joint_model(j), pose, j.name), pin.SE3.Identity())
    for link in robot.links:
        joint, at = placed[link.name]
        if joint:
            rot = rpy_matrix(*map(num, link.inertia_rpy))
            inertia = rot @ np.array([[num(x) for x in row] for row in link.inertia]) @ rot.T
            com = np.array([num(x) for x in link.com])
            model.appendBodyToJoint(joint, pin.Inertia(num(link.mass), com, inertia), at)
    return model


def test_reference_matches_pinocchio(case):
    pin = pytest.importorskip("pinocchio")
    robot, _, _, ref = case
    model = pinocchio_model(robot, pin)
    data = model.createData()
    assert (model.nq, model.nv) == (robot.nq, robot.nv)
    for q, qd, qdd in states(robot):
        M = pin.crba(model, data, q)
        assert_close(np.triu(M) + np.triu(M, 1).T, ref.crba(q), what=f"{robot.name} M vs Pinocchio")
        assert_close(pin.rnea(model, data, q, qd, qdd), ref.rnea(q, qd, qdd), what=f"{robot.name} tau vs Pinocchio")


# ---------------------------------------------------------------- joint transforms


def relative_pose(robot, q) -> np.ndarray:
    """Pose of the child of the joint under test in its joint frame: T_J(q) alone."""
    fk = NumericRobot(robot).fk(q)
    joint = robot.joints[1]
    origin = np.eye(4)
    origin[:3, :3], origin[:3, 3] = rpy_matrix(*joint.origin.rpy), joint.origin.xyz
    return np.linalg.inv(fk[joint.parent] @ origin) @ fk[joint.child]


def axis_rotation(axis, angle) -> np.ndarray:
    return Rotation.from_rotvec(np.asarray(axis) * angle).as_matrix()


def symbolic_relative_pose(robot, q) -> np.ndarray:
    model = SXModel(robot)
    joint = robot.joints[1]
    f = ca.Function("f", [model.sym.q, model.sym.p], [ca.solve(model.fk(joint.parent), model.fk(joint.child))])
    origin = np.eye(4)
    origin[:3, :3], origin[:3, 3] = rpy_matrix(*joint.origin.rpy), joint.origin.xyz
    return np.linalg.inv(origin) @ np.array(f(q, params(robot)))


@pytest.mark.parametrize("jtype", ["helical", "cylindrical", "universal", "spherical"])
def test_joint_transform_in_closed_form(jtype):
    """T_J of each multi-DOF or coupled joint, written with scipy's rotations, in both derivations."""
    robot = ROBOTS[jtype]
    a = np.array([0.6, 0.0, 0.8])
    rng = np.random.default_rng(0)
    for _ in range(10):
        q = random_q(robot, rng)
        qj = q[1:-1]
        expected = np.eye(4)
        if jtype == "helical":
            expected[:3, :3], expected[:3, 3] = axis_rotation(a, qj[0]), 0.05 * qj[0] * a
        elif jtype == "cylindrical":
            expected[:3, :3], expected[:3, 3] = axis_rotation(a, qj[0]), qj[1] * a
        elif jtype == "universal":
            expected[:3, :3] = axis_rotation(a, qj[0]) @ axis_rotation([0, 1, 0], qj[1])
        else:  # intrinsic Z, Y', X'': R = Rz(a) Ry(b) Rx(c)
            expected[:3, :3] = Rotation.from_euler("ZYX", qj).as_matrix()
        assert_close(relative_pose(robot, q), expected, rtol=1e-13, what=f"{jtype} reference T_J")
        assert_close(symbolic_relative_pose(robot, q), expected, rtol=1e-13, what=f"{jtype} symbolic T_J")


def test_helical_travel_is_pitch_times_angle():
    """A full turn brings the orientation back and advances 2 pi * pitch along the axis, in both derivations."""
    robot = ROBOTS["helical"]
    pitch = 0.05
    a = np.array([0.6, 0.0, 0.8])
    for angle in (0.3, -1.0, 2 * np.pi, 5 * np.pi):
        q = np.array([0.2, angle, -0.4])
        for pose in (relative_pose(robot, q), symbolic_relative_pose(robot, q)):
            assert pose[:3, 3] @ a == pytest.approx(pitch * angle, rel=1e-13)
            assert np.linalg.norm(np.cross(pose[:3, 3], a)) < 1e-15
            assert Rotation.from_matrix(pose[:3, :3]).as_rotvec() @ a == pytest.approx(
                np.arctan2(np.sin(angle), np.cos(angle)), abs=1e-13)
    # velocity of a point on the axis: pitch * rate along it (the Jacobian's helical column)
    model = SXModel(robot)
    J = np.array(ca.Function("J", [model.sym.q, model.sym.p], [model.jacobian("l2")])([0.2, 0.7, -0.4], params(robot)))
    world_axis = NumericRobot(robot).fk([0.2, 0.7, -0.4])["l2"][:3, :3] @ a
    assert_close(J[:3, 1], pitch * world_axis, rtol=1e-14, what="helical column at its own origin")
    assert_close(J[3:, 1], world_axis, rtol=1e-14, what="helical angular column")


# ---------------------------------------------------------------- gimbal lock


def test_spherical_gimbal_lock_is_reported_and_real():
    robot = ROBOTS["spherical"]
    ball = robot.joints[1]
    assert ball.gimbal_lock.startswith("cos(jt_y) = 0")
    assert [j.gimbal_lock for j in robot.joints if j is not ball] == [None, None]
    model = SXModel(robot)
    fn = ca.Function("f", [model.sym.q, model.sym.p],
                     [model.jacobian("l2")[3:, 1:4], model.mass_matrix("newton-euler")])  # ball's angular columns, M
    rng = np.random.default_rng(0)
    for q in [random_q(robot, rng) for _ in range(20)]:
        assert robot.gimbal_locked(q) == ()
        E, _ = (np.array(o) for o in fn(q, params(robot)))
        assert abs(np.linalg.det(E)) == pytest.approx(abs(np.cos(q[2])), rel=1e-12)  # det of the rate map = cos(b)
        for b in (np.pi / 2, -np.pi / 2):
            locked = np.array([q[0], q[1], b, q[3], q[4]])
            assert robot.gimbal_locked(locked) == ("jt",)
            E, M = (np.array(o) for o in fn(locked, params(robot)))
            null = np.array([1.0, 0.0, np.sign(b)])  # d(ball_z) = +-d(ball_x) turns nothing
            assert np.abs(E @ null).max() < 1e-15
            assert np.linalg.svd(E, compute_uv=False)[-1] < 1e-15
            assert np.linalg.eigvalsh(M).min() < 1e-15 * np.abs(M).max()
    assert robot.gimbal_locked([0, 0, np.pi / 2 + 1e-3, 0, 0]) == ()
    assert ROBOTS["zoo"].gimbal_locked(np.r_[0.3, -np.pi / 2, 0.2, np.zeros(6)]) == ("ball",)


# ---------------------------------------------------------------- validation


@pytest.mark.parametrize("joint, message", [
    ("type: helical, axis: [0, 0, 1]", "joints[1].pitch: missing: a helical joint needs 'pitch'"),
    ("type: helical, axis: [0, 0, 1], pitch: 0", "joints (jt).pitch: must not be 0"),
    ("type: helical, axis: [0, 0, 1], pitch: h - 0.05", "joints (jt).pitch: must not be 0"),
    ("type: revolute, axis: [0, 0, 1], pitch: 0.1",
     "joints[1].pitch: only a helical joint has 'pitch' (this one is revolute)"),
    ("type: universal, axis: [1, 0, 0]", "joints[1].axis2: missing: a universal joint needs 'axis2'"),
    ("type: universal, axis: [1, 0, 0], axis2: [0, 0, 0]", "joints[1].axis2: must not be the zero vector"),
    ("type: universal, axis: [1, 0, 0], axis2: [-2, 0, 0]", "joints[1].axis2: [-1.0, 0.0, 0.0] is parallel to axis"),
    ("type: universal, axis: [1, 0, 0], axis2: [1, 1, 0]",
     "joints[1].axis2: must be perpendicular to axis [1.0, 0.0, 0.0]"),
    ("type: cylindrical, axis: [0, 0, 1], axis2: [1, 0, 0]", "joints[1].axis2: only a universal joint has 'axis2'"),
    ("type: spherical, axis: [0, 0, 1]", "joints[1].axis: a spherical joint turns about z, y, x of its joint frame"),
    ("type: spherical, limits: [{lower: -1}, {lower: -1}]",
     "joints[1].limits: expected 3 limits (one per coordinate), got 2"),
    ("type: cylindrical, limits: [{lower: 1, upper: 0}, {}]", "joints[1].limits[0]: lower (1.0) is above upper (0.0)"),
    ("type: screw", "joints[1].type: unknown joint type 'screw' (known: revolute, continuous, prismatic, helical, "
                    "cylindrical, universal, spherical, fixed)"),
])
def test_bad_joint_fields_give_one_line_errors(joint, message):
    with pytest.raises(ModelError) as err:
        parse_models(ARM.format(name="bad", joint=joint))
    text = str(err.value)
    assert text.startswith("robot 'bad': ") and message in text and "\n" not in text, text


@pytest.mark.parametrize("edit, message", [
    (("name: j2, type: revolute", "name: jt_y, type: revolute"),
     "joints (jt_y): coordinate name 'jt_y' is already a coordinate of joint 'jt'"),
    (("{h: 0.05}", "{h: 0.05, jt_x: 1.0}"), "joints (jt): coordinate name 'jt_x' is already a parameter"),
])
def test_coordinate_name_collisions_are_errors(edit, message):
    text = ARM.format(name="bad", joint="type: spherical").replace(*edit)
    with pytest.raises(ModelError) as err:
        parse_models(text)
    assert message in str(err.value), str(err.value)


# ---------------------------------------------------------------- generated code


def test_generated_c_and_python_match_reference(tmp_path):
    """The tree of all joint types through the whole pipeline: C (strict C99) and Python against the reference."""
    robot = ROBOTS["zoo"]
    out = tmp_path / "gen"
    generate({"zoo": robot}, out, use_cache=False, log=lambda s: None)
    manifest = json.loads((out / "zoo" / "manifest.json").read_text())
    assert [j["name"] for j in manifest["joints"]] == [c.name for c in robot.coordinates]
    py = load_module(out / "zoo" / "python" / "zoo.py", "generated_zoo")
    assert py.JOINTS == tuple(c.name for c in robot.coordinates)
    names = ["zoo_mass_matrix", "zoo_inverse_dynamics", "zoo_forward_dynamics", "zoo_jacobian_tcp"]
    sources = [out / "zoo" / "c" / f"{n}.c" for n in names]
    lib = build_library(["cc", "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O1", "-fPIC"], sources,
                        tmp_path / "libzoo.so")
    c = ctypes.CDLL(str(lib))
    ptr = ctypes.POINTER(ctypes.c_double)

    def call(name, shape, *args):
        result = np.zeros(shape)
        arrays = [np.ascontiguousarray(a, dtype=float) for a in args] + [result]
        getattr(c, name)(*[a.ctypes.data_as(ptr) for a in arrays])
        return result

    ref, p, n = NumericRobot(robot), params(robot), robot.nv
    for q, qd, qdd in states(robot, 10):
        tau = ref.rnea(q, qd, qdd)
        for got, expected, what in [
            (call("zoo_mass_matrix", (n, n), q, p), ref.crba(q), "C M"),
            (call("zoo_inverse_dynamics", n, q, qd, qdd, p), tau, "C tau"),
            (call("zoo_forward_dynamics", n, q, qd, tau, p), qdd, "C qdd"),
            (call("zoo_jacobian_tcp", (6, n), q, p), ref.jacobian(q, "tcp"), "C J"),
            (np.asarray(py.mass_matrix(q, p)).reshape(n, n), ref.crba(q), "Python M"),
            (np.asarray(py.inverse_dynamics(q, qd, qdd, p)).ravel(), tau, "Python tau"),
        ]:
            assert_close(got, expected, what=what)
