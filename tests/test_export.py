"""derive export: models.yaml -> URDF -> import-urdf gives the same robot, and MuJoCo is a second oracle.

- URDF round trip: every shipped robot and three hand-written ones (a gripper with a mimic finger,
  rotor inertia, friction, a fixed camera and a tool frame; spherical, universal, cylindrical and
  helical joints; a floating base) come back from ``derive import-urdf`` with M(q), g(q) and
  ID(q, qd, qdd) equal to the original's numpy reference to 1e-12 (relative) at seeded states, every
  link and frame at the same pose, and the same limits. What URDF cannot hold is stated and accounted
  for: gravity other than -9.81 z (planar_2r) and rotor inertia (the gripper's).
- MJCF: MuJoCo loads every exported robot; mj_fullM (after mj_forward), mj_rne (with qacc) plus the
  armature and damping, and the body and site poses equal derive's numpy reference to 1e-10 at
  seeded states, mimic joints (MuJoCo equality constraints) and the free joint converted as stated
  in derive.description.export.
- MJCF round trip: models.yaml -> MJCF -> ``derive import-mjcf`` gives the same q and v, M, g, ID
  to 1e-12 and the same poses, compared like with like (the masses and moments raised for MuJoCo's
  minimum raised in the original too); and MJCF -> import -> export -> import (the project's MJCF
  fixtures, a ball joint and a free joint among them) likewise, MuJoCo agreeing on the exported file.

Without the mujoco package the MuJoCo tests are skipped, except in CI (CI=true), where that fails.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from derive.cli import main
from derive.description import expr
from derive.description.export import FLOOR, MJ_MINVAL, export_mjcf, export_urdf, to_mjcf, to_urdf
from derive.description.mjcf import import_mjcf_named
from derive.description.model import load_models, parse_models, parse_robot
from derive.description.robot import ModelError
from derive.description.urdf import import_urdf_named
from derive.reference import NumericRobot
from derive.resources import EXAMPLE_MODELS
from derive.reference.rnea import quaternion_matrix

HAND = """
robots:
  gripper:
    description: an arm with a parallel gripper (a mimic finger), a fixed camera and a tool frame
    parameters: {m1: 1.5, L: 0.4}
    links:
      - {name: base, mass: 2.0, inertia: [0.01, 0.01, 0.01]}
      - {name: upper, mass: m1, com: [0, 0, L/2], inertia_rpy: [0.1, -0.2, 0.3],
         inertia: {ixx: 0.02, iyy: 0.021, izz: 0.004, ixy: 0.001, ixz: -0.002, iyz: 0.0015}}
      - {name: palm, mass: 0.5, com: [0.01, 0, 0.02], inertia: [0.001, 0.0012, 0.0008]}
      - {name: finger_a, mass: 0.05, com: [0, 0.01, 0.02], inertia: [1.0e-5, 1.0e-5, 5.0e-6]}
      - {name: finger_b, mass: 0.05, com: [0, -0.01, 0.02], inertia: [1.0e-5, 1.0e-5, 5.0e-6]}
      - {name: camera, mass: 0.1, com: [0, 0, 0.01], inertia: [1.0e-4, 1.0e-4, 1.0e-4]}
    joints:
      - {name: shoulder, type: revolute, parent: base, child: upper, origin: {xyz: [0, 0, 0.1], rpy: [0.3, 0, 0]},
         axis: [0, 0, 1], limits: {lower: -2.5, upper: 2.5, velocity: 2.0, effort: 30.0},
         actuator: {armature: 0.05, viscous: 0.2, coulomb: 0.1}}
      - {name: wrist, type: revolute, parent: upper, child: palm, origin: {xyz: [0, 0, L], rpy: [0, 0.4, -0.2]},
         axis: [0, 0.6, 0.8], limits: {lower: -2, upper: 2, velocity: 3.0, effort: 10.0},
         actuator: {gear_ratio: 50, motor_inertia: 1.0e-5, viscous: 0.05}}
      - {name: finger_a_joint, type: prismatic, parent: palm, child: finger_a, origin: {xyz: [0, 0.02, 0.05]},
         axis: [0, 1, 0], limits: {lower: 0, upper: 0.04, velocity: 0.1, effort: 20}}
      - {name: finger_b_joint, type: prismatic, parent: palm, child: finger_b, origin: {xyz: [0, -0.02, 0.05]},
         axis: [0, 1, 0], mimic: {joint: finger_a_joint, multiplier: -1.0, offset: 0.005}, actuator: {viscous: 0.3}}
      - {name: camera_mount, type: fixed, parent: upper, child: camera,
         origin: {xyz: [0.05, 0, 0.2], rpy: [0, 1.5707963267948966, 0]}}
    frames:
      - {name: tcp, link: palm, xyz: [0, 0, 0.12], rpy: [0, 0, 0.7853981633974483]}

  twist:
    description: every multi-DOF joint type in one chain
    links:
      - {name: ground}
      - {name: a, mass: 1.0, com: [0.1, 0, 0], inertia: [0.01, 0.02, 0.02]}
      - {name: b, mass: 0.8, com: [0, 0.1, 0], inertia: [0.01, 0.005, 0.01]}
      - {name: c, mass: 0.6, com: [0, 0, 0.1], inertia: [0.004, 0.004, 0.002]}
      - {name: d, mass: 0.4, com: [0.02, 0, 0.05], inertia: [0.002, 0.002, 0.001]}
    joints:
      - {name: ball, type: spherical, parent: ground, child: a, origin: {xyz: [0, 0, 0.5], rpy: [0.1, 0.2, 0.3]}}
      - {name: cardan, type: universal, parent: a, child: b, origin: {xyz: [0.2, 0, 0]}, axis: [0, 0, 1], axis2: [0, 1, 0]}
      - {name: sleeve, type: cylindrical, parent: b, child: c, origin: {xyz: [0, 0.2, 0]}, axis: [0, 1, 0],
         limits: [{lower: -3, upper: 3, velocity: 2, effort: 5}, {lower: 0, upper: 0.2, velocity: 0.1, effort: 50}],
         actuator: [{viscous: 0.4}, {viscous: 1.0}]}
      - {name: screw, type: helical, parent: c, child: d, origin: {xyz: [0, 0, 0.2]}, axis: [0, 0, 1], pitch: 0.01}
    frames:
      - {name: tip, link: d, xyz: [0, 0, 0.1]}

  flyer:
    description: a floating body with an arm
    base: floating
    links:
      - {name: hull, mass: 3.0, com: [0.01, 0.02, -0.03], inertia: {ixx: 0.05, iyy: 0.06, izz: 0.07, ixy: 0.001}}
      - {name: arm, mass: 0.5, com: [0.1, 0, 0], inertia: [0.001, 0.004, 0.004]}
    joints:
      - {name: hinge, type: revolute, parent: hull, child: arm, origin: {xyz: [0.2, 0, 0.1], rpy: [0, 0, 0.5]},
         axis: [0, 1, 0], limits: {lower: -1, upper: 1, velocity: 1, effort: 1}}
    frames:
      - {name: imu, link: hull, xyz: [0, 0, 0.05]}
"""

SHIPPED = ("pendulum", "planar_2r", "rrprr", "cartpole", "ur5", "panda")
STATES = 5
URDF_RTOL = 1e-12
MUJOCO_RTOL = 1e-10


def all_robots():
    return {**load_models(EXAMPLE_MODELS), **parse_models(HAND, source="test_export")}


ROBOTS = all_robots()
FIXTURES = Path(__file__).resolve().parent / "fixtures" / "mjcf"
NAMES = SHIPPED + ("gripper", "twist", "flyer")


def states(robot, seed: int = 0):
    ref = NumericRobot(robot)
    rng = np.random.default_rng(seed)
    for _ in range(STATES):
        yield ref.random_configuration(rng), rng.normal(size=robot.nv), rng.normal(size=robot.nv)


def relative(actual, expected) -> float:
    a, e = np.asarray(actual, dtype=float), np.asarray(expected, dtype=float)
    return float(np.abs(a - e).max() / max(np.abs(e).max(), 1e-300))


# --------------------------------------------------------------------------- URDF round trip


def urdf_round_trip(robot, tmp_path: Path):
    path = tmp_path / f"{robot.name}.urdf"
    path.write_text(to_urdf(robot))
    name, entry = import_urdf_named(path)
    return parse_robot(name, entry)


@pytest.mark.parametrize("name", NAMES)
def test_urdf_round_trip_reproduces_m_g_id_and_frames(name, tmp_path):
    """models.yaml -> URDF -> import-urdf: M, g, ID within 1e-12 at seeded states, q and v entries by name."""
    robot = ROBOTS[name]
    back = urdf_round_trip(robot, tmp_path)
    ref = NumericRobot(robot)
    assert back.name == robot.name and back.floating == robot.floating
    assert sorted(c.name for c in back.coordinates) == sorted(c.name for c in robot.coordinates)
    assert back.gravity == (0.0, 0.0, -9.81)
    # URDF has no gravity (the note says so): the comparison gives the import the original's
    mine = NumericRobot(dataclasses.replace(back, gravity=tuple(ref.gravity_vector)))
    pq = [[c.name for c in robot.coordinates].index(c.name) for c in back.coordinates]
    pv = [robot.velocity_names.index(n) for n in back.velocity_names]
    rotor = ref.armature  # URDF has no rotor inertia (the note says so): the import has none
    assert (mine.armature == 0).all()
    for q, qd, qdd in states(robot):
        M = ref.crba(q) - np.diag(rotor)
        assert relative(mine.crba(q[pq]), M[np.ix_(pv, pv)]) <= URDF_RTOL
        assert relative(mine.gravity(q[pq]), ref.gravity(q)[pv]) <= URDF_RTOL
        tau = ref.rnea(q, qd, qdd) - rotor * qdd
        assert relative(mine.rnea(q[pq], qd[pv], qdd[pv]), tau[pv]) <= URDF_RTOL
        poses, back_poses = ref.fk(q), mine.fk(q[pq])
        for frame in robot.frame_names:
            assert np.abs(back_poses[frame] - poses[frame]).max() <= URDF_RTOL, frame
    for c in robot.joint_coordinates:
        assert next(x for x in back.joint_coordinates if x.name == c.name).limits == c.limits, c.name


def test_urdf_notes_say_what_urdf_cannot_hold():
    notes = export_urdf(ROBOTS["planar_2r"]).notes
    assert notes == ("URDF has no gravity (readers assume 0 0 -9.81 m/s^2); this robot's is 0 -9.81 0: written as a "
                     "comment only",)
    text = to_urdf(ROBOTS["gripper"])
    assert "<!-- note: URDF has no rotor inertia (armature): left out, in comments only, for shoulder 0.05, wrist " \
           "0.025 -->" in text
    assert '<mimic joint="finger_a_joint" multiplier="-1.0" offset="0.005"/>' in text
    assert '<dynamics damping="0.2" friction="0.1"/>' in text
    assert "parameters, at their defaults: m1 = 1.5, L = 0.4" in text and '<mass value="1.5"/>' in text
    assert '<joint name="root_joint" type="floating">' in to_urdf(ROBOTS["flyer"])
    twist = to_urdf(ROBOTS["twist"])
    assert '<mimic joint="screw" multiplier="0.01" offset="0"/>' in twist
    assert [line.split('"')[1] for line in twist.splitlines() if "<joint name=" in line] == [
        "ball_z", "ball_y", "ball_x", "cardan_1", "cardan_2", "sleeve_rot", "sleeve_trans", "screw", "screw_slide",
        "tip_joint"]


# --------------------------------------------------------------------------- MuJoCo as a second oracle


def mujoco_state(mujoco, model, robot, q, v, a):
    """MuJoCo's qpos, qvel, qacc for derive's (q, v, a), and P with qvel = P v (so M = P^T M_mj P,
    tau = P^T tau_mj). A free joint: qpos quaternion (w, x, y, z), qvel = [R v_lin; w] (world linear
    velocity), so qacc = [R (a_lin + w x v_lin); dw]. A mimic joint (an equality joint1 = c0 + c1 joint2):
    its row of P is c1 times its leader's."""
    qpos, P, drift = np.zeros(model.nq), np.zeros((model.nv, robot.nv)), np.zeros(model.nv)
    index = {n: k for k, n in enumerate(robot.velocity_names)}
    shift = robot.nq - robot.nv
    mimics = []
    for jid in range(model.njnt):
        name, dof, adr = model.joint(jid).name, model.jnt_dofadr[jid], model.jnt_qposadr[jid]
        if model.jnt_type[jid] == mujoco.mjtJoint.mjJNT_FREE:
            R = quaternion_matrix(q[3:7])
            qpos[adr:adr + 3], qpos[adr + 3], qpos[adr + 4:adr + 7] = q[:3], q[6], q[3:6]
            P[dof:dof + 3, :3], P[dof + 3:dof + 6, 3:6] = R, np.eye(3)
            drift[dof:dof + 3] = R @ np.cross(v[3:6], v[:3])
        elif name in index:
            P[dof, index[name]], qpos[adr] = 1.0, q[index[name] + shift]
        else:
            mimics.append((jid, dof, adr))
    for jid, dof, adr in mimics:
        eq = next(e for e in range(model.neq) if model.eq_obj1id[e] == jid)
        leader = model.eq_obj2id[eq]
        c0, c1 = model.eq_data[eq, :2]
        P[dof] = c1 * P[model.jnt_dofadr[leader]]
        qpos[adr] = c0 + c1 * qpos[model.jnt_qposadr[leader]]
    return qpos, P @ v, P @ a + drift, P


def mujoco_differences(mujoco, robot) -> dict[str, float]:
    """Largest relative differences of M, ID and poses between MuJoCo on the exported MJCF and derive's reference."""
    model = mujoco.MjModel.from_xml_string(to_mjcf(robot))
    data = mujoco.MjData(model)
    ref = NumericRobot(robot)
    worst = {"M": 0.0, "ID": 0.0, "poses": 0.0}
    for q, v, a in states(robot, seed=1):
        data.qpos[:], data.qvel[:], qacc, P = mujoco_state(mujoco, model, robot, q, v, a)
        mujoco.mj_forward(model, data)
        full = np.zeros((model.nv, model.nv))
        mujoco.mj_fullM(model, data, full)
        worst["M"] = max(worst["M"], relative(P.T @ full @ P, ref.crba(q)))
        rne = np.zeros(model.nv)
        data.qacc[:] = qacc  # mj_forward wrote its own
        mujoco.mj_rne(model, data, 1, rne)  # M qacc + bias, without the armature and the passive forces
        theirs = P.T @ (rne + model.dof_armature * qacc - data.qfrc_passive)
        ours = ref.rnea(q, v, a) - ref.friction(v) + ref.viscous * v  # MuJoCo's dry friction is a constraint
        worst["ID"] = max(worst["ID"], relative(theirs, ours))
        for name, pose in ref.fk(q).items():
            if name in {f.name for f in robot.frames}:
                site = model.site(name).id
                pos, rot = data.site_xpos[site], data.site_xmat[site].reshape(3, 3)
            else:
                body = model.body(name).id
                pos, rot = data.xpos[body], data.xmat[body].reshape(3, 3)
            worst["poses"] = max(worst["poses"], float(np.abs(pos - pose[:3, 3]).max()),
                                 float(np.abs(rot - pose[:3, :3]).max()))
    return worst


@pytest.mark.parametrize("name", NAMES)
def test_mujoco_loads_the_mjcf_and_agrees_with_the_reference(mujoco, name):
    """MuJoCo as a second oracle on derive's own robots: M, ID and every body and site pose within 1e-10."""
    worst = mujoco_differences(mujoco, ROBOTS[name])
    assert max(worst.values()) <= MUJOCO_RTOL, worst


def test_mjcf_spells_mimic_joints_armature_and_the_free_joint(mujoco):
    text = to_mjcf(ROBOTS["gripper"])
    assert '<joint name="finger_b_joint" joint1="finger_b_joint" joint2="finger_a_joint" polycoef="0.005 -1.0 0 0 0"/>' \
        in text
    model = mujoco.MjModel.from_xml_string(text)
    assert list(model.dof_armature) == [0.05, 0.025, 0.0, 0.0]  # 50^2 * 1e-5 for the wrist
    assert list(model.dof_damping) == [0.2, 0.05, 0.0, 0.3] and list(model.dof_frictionloss) == [0.1, 0.0, 0.0, 0.0]
    assert list(model.actuator_ctrlrange[0]) == [-30.0, 30.0] and model.nu == 3  # one motor per coordinate
    flyer = mujoco.MjModel.from_xml_string(to_mjcf(ROBOTS["flyer"]))
    assert flyer.jnt_type[0] == mujoco.mjtJoint.mjJNT_FREE and flyer.joint(0).name == "root_joint"
    assert list(mujoco.MjModel.from_xml_string(to_mjcf(ROBOTS["planar_2r"])).opt.gravity) == [0.0, -9.81, 0.0]
    notes = export_mjcf(ROBOTS["cartpole"]).notes
    assert notes[0] == ("MuJoCo refuses a body with a joint whose mass or a principal moment is below 1e-15 (mjMINVAL): "
                        "raised to 1e-12 of the robot's largest: pole (moment 0 -> 1e-14 kg m^2)")


# --------------------------------------------------------------------------- MJCF round trip


def as_mujoco_holds(robot):
    """The robot with what export_mjcf raises for MuJoCo's least mass and moment raised the same way
    (export.py: a body moved by a joint gets mass >= FLOOR * the largest mass and principal moments >=
    FLOOR * the largest moment, about the same principal axes): the model the MJCF holds, to compare
    like with like."""
    ref = {lk.name: (float(expr.evaluate(lk.mass, robot.parameter_defaults)),
                     np.array([[float(expr.evaluate(x, robot.parameter_defaults)) for x in row] for row in lk.inertia]))
           for lk in robot.links}
    floor_mass = max(FLOOR * max(m for m, _ in ref.values()), 10 * MJ_MINVAL)
    floor_moment = max(FLOOR * max(float(np.abs(np.linalg.eigvalsh(i)).max()) for _, i in ref.values()), 10 * MJ_MINVAL)
    moving = {j.child for j in robot.joints if j.dof > 0} | ({robot.root} if robot.floating else set())
    links = []
    for lk in robot.links:
        mass, inertia = ref[lk.name]
        eig, axes = np.linalg.eigh(inertia)
        if lk.name in moving and (mass < floor_mass or (eig < floor_moment).any()):
            inertia = axes @ np.diag(np.maximum(eig, floor_moment)) @ axes.T
            lk = dataclasses.replace(lk, mass=max(mass, floor_mass), inertia=tuple(tuple(float(x) for x in row)
                                                                                for row in inertia))
        links.append(lk)
    return dataclasses.replace(robot, links=tuple(links))


def mjcf_round_trip(robot, tmp_path: Path, **options):
    path = tmp_path / f"{robot.name}.xml"
    path.write_text(to_mjcf(robot))
    name, entry = import_mjcf_named(path, **options)
    return parse_robot(name, entry)


def round_trip_differences(robot, back) -> dict[str, float]:
    """Largest relative differences of M, g, ID (rotor inertia, viscous and Coulomb friction included)
    and largest pose difference of every link and frame of ``robot``, ``back`` against ``robot`` as the
    MJCF holds it, at seeded states (q and v of both are the same vectors: asserted by the caller)."""
    ref, mine = NumericRobot(as_mujoco_holds(robot)), NumericRobot(back)
    worst = {"M": 0.0, "g": 0.0, "ID": 0.0, "poses": 0.0}
    for q, qd, qdd in states(robot, seed=2):
        worst["M"] = max(worst["M"], relative(mine.crba(q), ref.crba(q)))
        worst["g"] = max(worst["g"], relative(mine.gravity(q), ref.gravity(q)))
        worst["ID"] = max(worst["ID"], relative(mine.rnea(q, qd, qdd), ref.rnea(q, qd, qdd)))
        poses, back_poses = ref.fk(q), mine.fk(q)
        worst["poses"] = max([worst["poses"], *(float(np.abs(back_poses[f] - poses[f]).max())
                                                for f in robot.frame_names)])
    return worst


@pytest.mark.parametrize("name", NAMES)
def test_mjcf_round_trip_reproduces_m_g_id_and_frames(mujoco, name, tmp_path):
    """models.yaml -> MJCF (export) -> import-mjcf: the same q and v (names and order), M, g and ID within
    1e-12 of the original as the MJCF holds it (tiny masses and moments raised for MuJoCo: planar_2r's
    massless DH links, cartpole's thin pole), every link and frame at the same pose, the same gravity,
    position and effort limits. What changes, as both modules state: the fixed root is MuJoCo's world
    (the original root link a frame on it), fixed joints are welded bodies (frames, masses merged), a
    multi-DOF joint comes back as its 1-DOF joints (a spherical one as ZYX hinges ball_z, ball_y, ball_x)
    through massless links, rotor inertia as armature, and MJCF keeps no velocity limit. A floating base
    comes back floating with derive's own q = [p, qx qy qz qw] and body-frame v: the free joint's
    conversions (MuJoCo's qpos (w, x, y, z), its world-frame linear qvel) cancel out."""
    robot = ROBOTS[name]
    back = mjcf_round_trip(robot, tmp_path)
    assert back.name == robot.name and back.floating == robot.floating and back.gravity == tuple(
        float(expr.evaluate(g, robot.parameter_defaults)) for g in robot.gravity)
    assert [c.name for c in back.coordinates] == [c.name for c in robot.coordinates]
    assert back.velocity_names == robot.velocity_names
    assert set(robot.frame_names) <= set(back.frame_names)
    worst = round_trip_differences(robot, back)
    assert max(worst.values()) <= URDF_RTOL, worst
    for c in robot.joint_coordinates:
        x = next(x for x in back.joint_coordinates if x.name == c.name)
        assert x.limits == dataclasses.replace(c.limits, velocity=None), c.name


def test_mjcf_round_trip_keeps_the_effort_limit(mujoco, tmp_path):
    """The effort limit goes out as the joint's actuatorfrcrange (MuJoCo's joint torque limit), which
    import-mjcf reads back; before, only the motor's ctrlrange held it and the import lost it."""
    text = to_mjcf(ROBOTS["ur5"])
    assert '<joint name="wrist_3_joint" type="hinge" axis="0 1.0 0" limited="true" range="-6.28318530718 ' \
           '6.28318530718" actuatorfrcrange="-28.0 28.0"/>' in text
    back = mjcf_round_trip(ROBOTS["ur5"], tmp_path)
    assert [c.limits.effort for c in back.joint_coordinates] == [150.0, 150.0, 150.0, 28.0, 28.0, 28.0]


def test_mjcf_round_trip_keeps_a_one_sided_range(mujoco, tmp_path, capsys):
    """A joint with a lower limit only: MJCF's range needs two ends, export writes +1e16 for the missing
    one, and import-mjcf reads that back as no upper limit with one warning line (it refused the entry
    before: a limit beyond 1e12 overflows in the dynamics)."""
    robot = parse_models("""
robots:
  slider:
    links:
      - {name: base}
      - {name: carriage, mass: 1.0, inertia: [0.01, 0.01, 0.01]}
    joints:
      - {name: s, type: prismatic, parent: base, child: carriage, axis: [1, 0, 0], limits: {lower: -0.5, effort: 40}}
""", source="t.yaml")["slider"]
    assert 'range="-0.5 1e+16"' in to_mjcf(robot)
    back = mjcf_round_trip(robot, tmp_path)
    assert back.joint_coordinates[0].limits == robot.joint_coordinates[0].limits
    assert capsys.readouterr().err == (f"warning: {tmp_path / 'slider.xml'}: <joint name=\"s\">: upper 1e+16: beyond "
                                       "1e+12, a placeholder for no limit: imported without it\n")


@pytest.mark.parametrize("file, floating", [("arm.xml", None), ("walker.xml", None), ("walker.xml", False)])
def test_imported_mjcf_exports_and_imports_back(mujoco, file, floating, tmp_path):
    """MJCF -> import-mjcf -> export -> MuJoCo and import-mjcf again: MuJoCo on the exported file agrees
    with the import to 1e-10 (walker's ball joint neck, imported as ZYX angles, goes out as three hinges
    neck_z, neck_y, neck_x), and the second import has the first's q, v, M, g and ID to 1e-12 (the
    first's massless joint links raised for MuJoCo as the export notes say)."""
    name, entry = import_mjcf_named(FIXTURES / file, floating=floating)
    robot = parse_robot(name, entry)
    assert max(mujoco_differences(mujoco, robot).values()) <= MUJOCO_RTOL
    back = mjcf_round_trip(robot, tmp_path)
    assert [c.name for c in back.coordinates] == [c.name for c in robot.coordinates]
    assert back.velocity_names == robot.velocity_names
    assert max(round_trip_differences(robot, back).values()) <= URDF_RTOL


# --------------------------------------------------------------------------- the command


def test_export_command_writes_both_files(tmp_path, capsys):
    models = tmp_path / "m.yaml"
    models.write_text(HAND)
    urdf, mjcf = tmp_path / "g.urdf", tmp_path / "g.xml"
    assert main(["--models", str(models), "export", "gripper", "--urdf", str(urdf), "--mjcf", str(mjcf)]) == 0
    robot = ROBOTS["gripper"]
    assert urdf.read_text() == to_urdf(robot) and mjcf.read_text() == to_mjcf(robot)
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith("note: robot 'gripper': URDF: URDF has no rotor inertia") and err[-2:] == [
        f"wrote {urdf}", f"wrote {mjcf}"]


def test_export_command_errors_are_one_line(tmp_path, capsys):
    def error(*argv) -> str:
        assert main(list(argv)) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1, err
        return err.strip()

    assert error("export", "pendulum") == ("derive: error: export pendulum: give --urdf FILE and/or --mjcf FILE")
    assert error("export", "nobody", "--urdf", str(tmp_path / "x.urdf")).startswith(
        "derive: error: robot 'nobody': robots: no such robot")
    assert error("export", "pendulum", "--urdf", str(tmp_path)) == (
        f"derive: error: {tmp_path}: cannot write URDF (is a folder); it is left as it was")
    assert error("export", "pendulum", "--urdf", str(tmp_path / "u.urdf"), "--mjcf", str(tmp_path)) == (
        f"derive: error: {tmp_path}: cannot write MJCF (is a folder); it is left as it was")
    assert error("export", "pendulum", "--mjcf", "").startswith("derive: error: export: argument --mjcf: empty path")
    assert not list(tmp_path.iterdir())  # nothing written, the URDF of a refused pair neither


def test_export_prints_with_a_dash(capsys):
    assert main(["export", "rrprr", "--mjcf", "-"]) == 0
    assert capsys.readouterr().out == to_mjcf(ROBOTS["rrprr"])


def test_names_the_formats_cannot_take_are_one_line_errors():
    clash = parse_models(HAND.replace("      - {name: d, mass: 0.4,", "      - {name: cam}\n      - {name: d, mass: 0.4,")
                         .replace("    frames:\n      - {name: tip,", "      - {name: sleeve_rot, type: fixed, parent: ground, "
                                  "child: cam}\n    frames:\n      - {name: tip,"), source="m.yaml")["twist"]
    with pytest.raises(ModelError) as exc:
        to_urdf(clash)
    assert str(exc.value) == ("m.yaml: robot 'twist': joints (sleeve_rot): 'sleeve_rot' would name a joint of both "
                              "'sleeve' and 'sleeve_rot' in the exported file: rename one")
    world = parse_models(HAND.replace("{name: hull,", "{name: world,").replace("parent: hull", "parent: world").replace(
        "link: hull", "link: world"), source="m.yaml")["flyer"]
    with pytest.raises(ModelError) as exc:
        to_mjcf(world)
    assert str(exc.value) == ("m.yaml: robot 'flyer': links: MJCF calls its world body 'world': a link of that name "
                              "must be the root of a fixed-base robot; rename it")
