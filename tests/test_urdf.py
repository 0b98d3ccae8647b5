"""The URDF importer (derive/urdf.py).

- The ur5 and panda entries of models.yaml are exactly what a fresh import of
  example-robot-data's URDFs gives (the file cannot drift from the URDFs).
- Whole-tree imports (the default), ``--chain``, ``--floating`` and the example-robot-data
  sweep: tests/test_urdf_trees.py.
- The importer against Pinocchio's own URDF parser: the imported models, run
  through the numeric reference (derive.reference), give Pinocchio's frame poses,
  frame Jacobians, mass matrix, gravity vector and inverse dynamics at 50 seeded
  random states, to 1e-9 relative. A synthetic URDF covers what ur5 and panda
  leave out (continuous joints, rotated inertials, locks at non-zero values,
  moving joints hanging off merged links, dropped and merged side branches).
- Error cases give one-line ModelErrors; the YAML text round-trips exactly.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from derive.description.model import default_models_path, load_models, parse_robot
from derive.cli.models import cmd_import_urdf as import_urdf_command
from derive.description.robot import ModelError
from derive.reference import NumericRobot
from derive.description.urdf import (
    c_identifier,
    dump_entry,
    example_robot_data_dir,
    import_urdf,
    import_urdf_named,
    matrix_rpy,
    rpy_matrix,
)

TOL = 1e-9
N_SAMPLES = 50

# The shipped imports: models.yaml name -> import_urdf arguments.
SHIPPED = {
    "ur5": dict(path="example-robot-data:ur_description/urdf/ur5_robot.urdf", tip="tool0", lock=None, snap_angles=1e-4),
    "panda": dict(path="example-robot-data:panda_description/urdf/panda.urdf", tip="panda_hand_tcp",
                  lock="panda_finger_joint1,panda_finger_joint2", friction=False),
}

# Covers what ur5 and panda do not: a massless root named world fixed to a massive, rotated
# base; axes off the coordinate axes; a continuous joint; full inertias with rotated inertial
# frames; a moving joint hanging off a link merged through a rotated fixed joint; revolute and
# prismatic joints locked at non-zero values (with mass behind them); a massive fixed branch
# off the tip path (merged), a massless moving branch off it (dropped); a tip behind a lock.
ZOO_URDF = """<?xml version="1.0"?>
<robot name="zoo-bot">
  <link name="world"/>
  <link name="base">
    <inertial><origin xyz="0.01 0.02 0.1" rpy="0.1 0.2 0.3"/><mass value="3.0"/>
      <inertia ixx="0.03" ixy="0.001" ixz="-0.002" iyy="0.04" iyz="0.003" izz="0.05"/></inertial>
  </link>
  <link name="link1">
    <inertial><origin xyz="0.1 0.02 -0.03" rpy="0.3 -0.5 1.1"/><mass value="1.2"/>
      <inertia ixx="0.02" ixy="0.001" ixz="-0.002" iyy="0.03" iyz="0.003" izz="0.025"/></inertial>
  </link>
  <link name="link2">
    <inertial><origin xyz="0.05 0 0.1"/><mass value="0.6"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.012" iyz="0" izz="0.005"/></inertial>
  </link>
  <link name="link2b">
    <inertial><origin xyz="0.0 0.05 0.0" rpy="0.1 0.2 0.3"/><mass value="0.4"/>
      <inertia ixx="0.002" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.002"/></inertial>
  </link>
  <link name="camera">
    <inertial><origin xyz="0.01 0 0.01"/><mass value="0.25"/>
      <inertia ixx="0.0002" ixy="0" ixz="0" iyy="0.0003" iyz="0" izz="0.0002"/></inertial>
  </link>
  <link name="sensor"/>
  <link name="sensor_tip"/>
  <link name="link3">
    <inertial><origin xyz="0 0.1 0" rpy="0 0.4 0"/><mass value="0.5"/>
      <inertia ixx="0.004" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.004"/></inertial>
  </link>
  <link name="link4">
    <inertial><origin xyz="0.02 0.03 0.04"/><mass value="0.7"/>
      <inertia ixx="0.005" ixy="0.0001" ixz="0" iyy="0.006" iyz="0" izz="0.007"/></inertial>
  </link>
  <link name="slider">
    <inertial><origin xyz="0 0 0.01"/><mass value="0.3"/>
      <inertia ixx="0.0004" ixy="0" ixz="0" iyy="0.0004" iyz="0" izz="0.0001"/></inertial>
  </link>
  <link name="tool"/>
  <joint name="world_joint" type="fixed">
    <parent link="world"/><child link="base"/><origin xyz="0.1 0.2 0.3" rpy="0 0 0.5"/>
  </joint>
  <joint name="j1" type="revolute">
    <parent link="base"/><child link="link1"/><origin xyz="0.1 -0.05 0.3" rpy="0.2 -0.3 0.4"/>
    <axis xyz="0.6 0 0.8"/><limit lower="-2.5" upper="2.5" velocity="2.0" effort="40"/>
  </joint>
  <joint name="sensor_joint" type="revolute">
    <parent link="link1"/><child link="sensor"/><origin xyz="0 0 0.1"/>
    <axis xyz="0 0 1"/><limit lower="-1" upper="1" velocity="1" effort="1"/>
  </joint>
  <joint name="sensor_tip_joint" type="fixed">
    <parent link="sensor"/><child link="sensor_tip"/><origin xyz="0 0 0.05"/>
  </joint>
  <joint name="j2" type="continuous">
    <parent link="link1"/><child link="link2"/><origin xyz="0.3 0 0.05" rpy="1.5707963267948966 0 0"/>
    <axis xyz="0 1 0"/><limit velocity="3.0" effort="20"/>
  </joint>
  <joint name="camera_mount" type="fixed">
    <parent link="link2"/><child link="camera"/><origin xyz="0.05 0.05 0" rpy="0 -0.7 0.2"/>
  </joint>
  <joint name="j2b" type="fixed">
    <parent link="link2"/><child link="link2b"/><origin xyz="0 0.2 0" rpy="0 0.7 0"/>
  </joint>
  <joint name="j3" type="prismatic">
    <parent link="link2b"/><child link="link3"/><origin xyz="0.1 0 0.15" rpy="-0.6 0.2 0.9"/>
    <axis xyz="0 0.6 -0.8"/><limit lower="-0.2" upper="0.3" velocity="0.5" effort="100"/>
  </joint>
  <joint name="slide_lock" type="prismatic">
    <parent link="link3"/><child link="slider"/><origin xyz="0 0.1 0"/>
    <axis xyz="1 0 0"/><limit lower="0" upper="0.1" velocity="0.1" effort="10"/>
  </joint>
  <joint name="wrist_lock" type="revolute">
    <parent link="link3"/><child link="link4"/><origin xyz="0.1 0 0.2" rpy="0.3 0.2 0.1"/>
    <axis xyz="0 0 1"/><limit lower="-1" upper="1" velocity="1" effort="5"/>
  </joint>
  <joint name="tool_mount" type="fixed">
    <parent link="link4"/><child link="tool"/><origin xyz="0 0.15 0" rpy="0.3 0.3 0.3"/>
  </joint>
</robot>
"""
ZOO_LOCKS = {"slide_lock": 0.04, "wrist_lock": 0.3}
ZOO_LOCK_ARG = "slide_lock=0.04,wrist_lock=0.3"


# --------------------------------------------------------------------------- helpers


def erd_path(spec: str) -> Path:
    return example_robot_data_dir() / spec.split(":", 1)[1]


def rel(ours: np.ndarray, theirs: np.ndarray) -> float:
    """Relative error in the Frobenius norm (absolute when the reference is exactly zero)."""
    scale = np.linalg.norm(theirs)
    err = np.linalg.norm(np.asarray(ours) - np.asarray(theirs))
    return float(err / scale) if scale > 0 else float(err)


def write(tmp_path: Path, text: str, name: str = "robot.urdf") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.fixture(scope="module")
def pin():
    return pytest.importorskip("pinocchio")


class PinSide:
    """Pinocchio's model of a URDF (locked joints removed), indexed by our joint names."""

    def __init__(self, pin, urdf: Path | str, robot, locks: dict[str, float], tip: str, from_xml: bool = False):
        self.pin = pin
        full = pin.buildModelFromXML(urdf) if from_xml else pin.buildModelFromUrdf(str(urdf))
        if locks:
            q0 = pin.neutral(full)
            for name, value in locks.items():
                jid = full.getJointId(name)
                assert full.joints[jid].nq == 1
                q0[full.joints[jid].idx_q] = value
            model = pin.buildReducedModel(full, [full.getJointId(n) for n in locks], q0)
        else:
            model = full
        self.model, self.data = model, model.createData()
        self.tip = tip
        names = [j.name for j in robot.moving_joints]
        assert sorted(names) == sorted(model.names[1:]), (names, list(model.names))
        assert model.nv == len(names)
        # our joint i <-> Pinocchio joint (idx_q, nq, idx_v)
        self.joints = [model.joints[model.getJointId(n)] for n in names]
        self.perm = np.array([j.idx_v for j in self.joints])

    def q(self, ours: np.ndarray) -> np.ndarray:
        q = np.zeros(self.model.nq)
        for qi, j in zip(ours, self.joints):
            if j.nq == 2:  # continuous: (cos, sin)
                q[j.idx_q], q[j.idx_q + 1] = math.cos(qi), math.sin(qi)
            else:
                q[j.idx_q] = qi
        return q

    def v(self, ours: np.ndarray) -> np.ndarray:
        v = np.zeros(self.model.nv)
        v[self.perm] = ours
        return v

    def frame_id(self, name: str) -> int:
        name = self.tip if name == "tcp" else name
        return self.model.getFrameId(name, self.pin.BODY)

    def pose(self, q, name: str) -> np.ndarray:
        self.pin.framesForwardKinematics(self.model, self.data, self.q(q))
        return self.data.oMf[self.frame_id(name)].homogeneous

    def jacobian(self, q, name: str) -> np.ndarray:
        jac = self.pin.computeFrameJacobian(self.model, self.data, self.q(q), self.frame_id(name),
                                            self.pin.LOCAL_WORLD_ALIGNED)
        return jac[:, self.perm]

    def crba(self, q) -> np.ndarray:
        m = np.array(self.pin.crba(self.model, self.data, self.q(q)))
        m = np.triu(m) + np.triu(m, 1).T
        return m[np.ix_(self.perm, self.perm)]

    def gravity(self, q) -> np.ndarray:
        return np.array(self.pin.computeGeneralizedGravity(self.model, self.data, self.q(q)))[self.perm]

    def rnea(self, q, qd, qdd) -> np.ndarray:
        return np.array(self.pin.rnea(self.model, self.data, self.q(q), self.v(qd), self.v(qdd)))[self.perm]


def random_q(robot, rng) -> np.ndarray:
    q = []
    for j in robot.moving_joints:
        lo = -math.pi if j.limits.lower is None else j.limits.lower
        hi = math.pi if j.limits.upper is None else j.limits.upper
        q.append(rng.uniform(lo, hi))
    return np.array(q)


class SymbolicSide:
    """The derived symbolic model (CasADi SX, Newton-Euler route for dynamics, Lagrangian M),
    with NumericRobot's interface."""

    def __init__(self, robot):
        import casadi as ca

        from derive.symbolic.model import SXModel

        m = SXModel(robot)
        s = m.sym
        self.frames = {n: ca.Function("k", [s.q], [m.fk(n), m.jacobian(n)]) for n in robot.frame_names}
        self.dyn = ca.Function("d", [s.q, s.qd, s.qdd], [m.mass_matrix("lagrange"), m.gravity_vector("lagrange"),
                                                         m.inverse_dynamics("newton-euler")])

    def fk(self, q):
        return {n: np.array(f(q)[0]) for n, f in self.frames.items()}

    def frame_pose(self, q, name):
        return np.array(self.frames[name](q)[0])

    def jacobian(self, q, name):
        return np.array(self.frames[name](q)[1])

    def crba(self, q):
        return np.array(self.dyn(q, 0, 0)[0])

    def gravity(self, q):
        return np.array(self.dyn(q, 0, 0)[1]).ravel()

    def rnea(self, q, qd, qdd):
        return np.array(self.dyn(q, qd, qdd)[2]).ravel()


def cross_check(robot, pin_side: PinSide, nr=None) -> dict[str, float]:
    """Worst relative errors of ours (NumericRobot, or ``nr``) vs Pinocchio over N_SAMPLES random states."""
    nr = nr or NumericRobot(robot)
    rng = np.random.default_rng(0)
    worst = dict.fromkeys(["pose", "jacobian", "crba", "gravity", "rnea"], 0.0)
    names = robot.frame_names
    assert "tcp" in names
    for _ in range(N_SAMPLES):
        q = random_q(robot, rng)
        qd, qdd = rng.standard_normal(robot.nv), rng.standard_normal(robot.nv)
        fk = nr.fk(q)
        for name in names:
            worst["pose"] = max(worst["pose"], rel(fk[name], pin_side.pose(q, name)))
            assert rel(nr.frame_pose(q, name), pin_side.pose(q, name)) < TOL, name
            worst["jacobian"] = max(worst["jacobian"], rel(nr.jacobian(q, name), pin_side.jacobian(q, name)))
        worst["crba"] = max(worst["crba"], rel(nr.crba(q), pin_side.crba(q)))
        worst["gravity"] = max(worst["gravity"], rel(nr.gravity(q), pin_side.gravity(q)))
        worst["rnea"] = max(worst["rnea"], rel(nr.rnea(q, qd, qdd), pin_side.rnea(q, qd, qdd)))
    print(f"\n{robot.name}: worst relative errors vs Pinocchio over {N_SAMPLES} states:",
          ", ".join(f"{k} {v:.2e}" for k, v in worst.items()))
    for key, err in worst.items():
        assert err < TOL, (key, err)
    return worst


# --------------------------------------------------------------------------- shipped models


@pytest.mark.parametrize("name", SHIPPED)
def test_models_yaml_matches_a_fresh_import(pin, name):
    args = SHIPPED[name]
    fresh_name, fresh = import_urdf_named(**args)
    assert fresh_name == name
    # the links' <visual> meshes, which the shipped entries predate: kept by a fresh import (spelled within
    # the installed package), no part of the dynamics or the generated code (test_visuals.py)
    looks = [link.pop("visual") for link in fresh["links"]]
    assert all(item["mesh"].startswith("example-robot-data:") for items in looks for item in items)
    # the tip keeps its URDF name as an alias of tcp; the shipped entries predate aliases and keep
    # their generated code byte for byte without one (models.yaml frames[].aliases is optional)
    assert fresh["frames"][0].pop("aliases") == [args["tip"]]
    data = yaml.safe_load(default_models_path().read_text())["robots"]
    assert data[name] == fresh  # exact, float for float
    assert dump_entry(name, fresh) in default_models_path().read_text()  # comments and layout too
    # the same URDF given as a plain path imports identically
    again = import_urdf(erd_path(args["path"]), args["tip"], args["lock"], friction=args.get("friction", True),
                        snap_angles=args.get("snap_angles"))
    assert again["frames"][0].pop("aliases") == [args["tip"]]
    assert [link.pop("visual") for link in again["links"]] == looks
    assert again == fresh


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_import_against_pinocchio(pin, name):
    args = SHIPPED[name]
    robot = load_models()[name]
    locks = {n: 0.0 for n in (args["lock"] or "").split(",") if n}
    side = PinSide(pin, erd_path(args["path"]), robot, locks, args["tip"])
    cross_check(robot, side)
    # masses: the total moving mass is Pinocchio's (root/world mass does not move)
    moving = sum(link.mass for link in robot.links if link.name != robot.root)
    assert moving == pytest.approx(sum(i.mass for i in side.model.inertias[1:]), rel=1e-15)


@pytest.mark.parametrize("name", SHIPPED)
def test_symbolic_model_against_pinocchio(pin, name):
    """FK and Jacobian of every frame, M (kinetic energy), g (potential energy) and inverse
    dynamics (recursive route) of the derived symbolic model against Pinocchio on the same URDF."""
    args = SHIPPED[name]
    robot = load_models()[name]
    locks = {n: 0.0 for n in (args["lock"] or "").split(",") if n}
    cross_check(robot, PinSide(pin, erd_path(args["path"]), robot, locks, args["tip"]), SymbolicSide(robot))


def test_ur5_structure():
    robot = load_models()["ur5"]
    assert robot.root == "world"
    assert [j.name for j in robot.moving_joints] == ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint",
                                                    "wrist_1_joint", "wrist_2_joint", "wrist_3_joint"]
    assert all(j.type == "revolute" for j in robot.joints)
    frames = {f.name: f for f in robot.frames}
    assert set(frames) == {"tcp", "base_link", "base", "ee_link"}
    # imported with --snap-angles 1e-4: the UR files' truncated pi/2 (1.57079632679) and pi are made exact
    assert frames["tcp"].link == "wrist_3_link" and frames["tcp"].origin.rpy == (-math.pi / 2, 0.0, 0.0)
    assert frames["base"].origin.rpy == (0.0, 0.0, -math.pi)
    # without it, single URDF origins are copied, not recomputed: the truncated values survive
    as_written = {f["name"]: f for f in import_urdf(SHIPPED["ur5"]["path"], "tool0")["frames"]}
    assert as_written["tcp"]["rpy"] == [-1.57079632679, 0.0, 0.0]
    assert as_written["base"]["rpy"] == [0.0, 0.0, -3.14159265359]
    assert robot.link("world").mass == 4.0  # base_link merged into the root


def test_panda_structure():
    robot = load_models()["panda"]
    assert robot.nv == 7 and robot.root == "panda_link0"
    hand = robot.link("panda_link7")  # link7 + hand + two fingers (locked at 0)
    assert hand.mass == pytest.approx(0.735522 + 0.73 + 2 * 0.015, rel=1e-15)
    frames = {f.name: f for f in robot.frames}
    assert set(frames) == {"tcp", "panda_link8", "panda_hand", "panda_leftfinger", "panda_rightfinger"}
    assert frames["tcp"].origin.xyz == (0.0, 0.0, 0.107 + 0.1034)
    assert frames["tcp"].origin.rpy == (0.0, 0.0, -0.7853981633974483)


# --------------------------------------------------------------------------- synthetic URDF


def test_zoo_against_pinocchio(pin, tmp_path):
    path = write(tmp_path, ZOO_URDF)
    name, entry = import_urdf_named(path, "tool", ZOO_LOCK_ARG)
    assert name == "zoo_bot"
    robot = parse_robot(name, entry)
    assert [link.name for link in robot.links] == ["world", "link1", "link2", "link3"]
    assert [j.name for j in robot.joints] == ["j1", "j2", "j3"]
    assert {f.name for f in robot.frames} == {"tcp", "base", "camera", "link2b", "slider", "link4"}
    j2 = next(j for j in robot.joints if j.name == "j2")
    assert j2.type == "continuous" and (j2.limits.lower, j2.limits.upper) == (None, None)
    assert (j2.limits.velocity, j2.limits.effort) == (3.0, 20.0)
    assert all(link.inertia_rpy == (0.0, 0.0, 0.0) for link in robot.links)
    assert entry["description"] == ("zoo-bot imported from URDF (tip tool; locked slide_lock = 0.04, wrist_lock = 0.3; "
                                    "dropped the massless moving branch sensor_joint)")
    # Pinocchio keeps the massless sensor branch that the importer drops: remove it there too
    side = PinSide(pin, ZOO_URDF, robot, ZOO_LOCKS | {"sensor_joint": 0.0}, "tool", from_xml=True)
    cross_check(robot, side)
    # --chain tool imports the same model
    chained = import_urdf(path, lock=ZOO_LOCK_ARG, chain="tool")
    assert {k: v for k, v in chained.items() if k not in ("description", "source")} == \
        {k: v for k, v in entry.items() if k not in ("description", "source")}


def test_lock_zero_copies_origin(tmp_path):
    """Locking at 0 (the default) leaves a single origin exact; merging is what computes."""
    path = write(tmp_path, ZOO_URDF)
    entry = import_urdf(path, "tool", "slide_lock,wrist_lock")
    frames = {f["name"]: f for f in entry["frames"]}
    assert frames["link4"]["xyz"] == [0.1, 0.0, 0.2] and frames["link4"]["rpy"] == [0.3, 0.2, 0.1]
    assert frames["slider"]["xyz"] == [0.0, 0.1, 0.0]


def test_rpy_round_trip_near_gimbal_lock():
    rng = np.random.default_rng(0)
    for k in range(500):
        r, p, y = rng.uniform(-math.pi, math.pi, 3)
        if k % 2:
            p = math.copysign(math.pi / 2 - [0.0, 1e-14, 1e-9, 1e-5][k % 4], p)
        rot = rpy_matrix((r, p, y))
        assert np.abs(rpy_matrix(matrix_rpy(rot)) - rot).max() < 1e-15 * 4


# --------------------------------------------------------------------------- YAML text and command


def test_dump_entry_round_trips_exactly(tmp_path):
    path = write(tmp_path, ZOO_URDF)
    name, entry = import_urdf_named(path, "tool", ZOO_LOCK_ARG)
    entry["links"][1]["mass"] = 1e-05  # repr '1e-05' is a string to YAML 1.1: must be written 1.0e-05
    text = dump_entry(name, entry)
    assert "1.0e-05" in text
    assert text.startswith("  # zoo_bot: generated by `derive import-urdf` from robot.urdf")
    assert f"  # Regenerate with: derive import-urdf {path} --tip tool --lock {ZOO_LOCK_ARG}\n" in text
    assert yaml.safe_load("robots:\n" + text) == {"robots": {name: entry}}
    assert dump_entry(name, entry) == text  # deterministic


def test_command_prints_and_appends(tmp_path, capsys):
    path = write(tmp_path, ZOO_URDF)
    models = tmp_path / "models.yaml"
    models.write_text(default_models_path().read_text())
    ns = argparse.Namespace(file=str(path), tip="tool", lock=ZOO_LOCK_ARG, name=None, out=None, chain=None, floating=False)
    assert import_urdf_command(ns) == 0
    printed = capsys.readouterr().out
    assert printed == dump_entry("zoo_bot", import_urdf(path, "tool", ZOO_LOCK_ARG))
    ns.out, ns.name = str(models), "zoo"
    assert import_urdf_command(ns) == 0
    loaded = load_models(models)
    assert list(loaded)[-1] == "zoo" and loaded["zoo"].nv == 3
    assert "--name zoo" in loaded["zoo"].source
    with pytest.raises(ModelError, match=r"^robot 'zoo': .*models.yaml robots: already exists"):
        import_urdf_command(ns)


def test_c_identifier():
    assert c_identifier("zoo-bot") == "zoo_bot"
    assert c_identifier("3dof/arm") == "_3dof_arm"
    assert c_identifier("double") == "double_"


# --------------------------------------------------------------------------- errors


def one_line_error(match: str, *args, **kwargs) -> ModelError:
    with pytest.raises(ModelError, match=match) as info:
        import_urdf(*args, **kwargs)
    assert "\n" not in str(info.value)
    return info.value


def test_mimic_joint_follows_its_joint(pin):
    """panda's second finger mimics the first: imported as a mimic joint (no entry in q); with the first
    finger locked, the second must be locked too (one line, with the command that works)."""
    entry = import_urdf(SHIPPED["panda"]["path"], "panda_hand_tcp")
    robot = parse_robot("panda", entry)
    finger = next(j for j in robot.joints if j.name == "panda_finger_joint2")
    assert (finger.mimic.joint, finger.mimic.multiplier, finger.mimic.offset) == ("panda_finger_joint1", 1.0, 0.0)
    assert robot.nq == robot.nv == 8 and "panda_finger_joint2" not in [c.name for c in robot.coordinates]
    err = one_line_error(r"^example-robot-data:panda_description/urdf/panda\.urdf: robot 'panda': joints\[panda_finger_joint2\]\.mimic: mimics 'panda_finger_joint1', a locked "
                         r"joint: lock it \(--lock panda_finger_joint1,panda_finger_joint2\)",
                         SHIPPED["panda"]["path"], "panda_hand_tcp", "panda_finger_joint1")
    assert err.field == "joints[panda_finger_joint2].mimic"


def test_moving_branch_with_mass_off_the_chain(tmp_path):
    path = write(tmp_path, ZOO_URDF)
    one_line_error(r"^.*/robot\.urdf: robot 'zoo_bot': joints\[slide_lock\]: moves a branch with mass \(0.3 kg\) that does not lead "
                   r"to the tip 'tool'; lock it \(--lock wrist_lock,slide_lock\)", path, lock="wrist_lock", chain="tool")
    # the whole tree (the default) keeps the branch: slide_lock moves; the massless sensor branch is dropped
    entry = import_urdf(path, "tool", "wrist_lock")
    assert [j["name"] for j in entry["joints"]] == ["j1", "j2", "j3", "slide_lock"]
    assert entry["description"] == ("zoo-bot imported from URDF (tip tool; locked wrist_lock = 0; dropped the massless "
                                     "moving branch sensor_joint)")
    # with both locked, the chain and the whole tree give the same joints
    chain = import_urdf(path, lock=ZOO_LOCK_ARG, chain="tool")
    whole = import_urdf(path, "tool", ZOO_LOCK_ARG)
    assert chain["joints"] == whole["joints"] and chain["links"] == whole["links"] and chain["frames"] == whole["frames"]
    assert chain["description"] == "zoo-bot imported from URDF (chain to tool; locked slide_lock = 0.04, wrist_lock = 0.3)"


def test_unknown_tip(tmp_path):
    path = write(tmp_path, ZOO_URDF)
    one_line_error(r"^.*/robot\.urdf: robot 'zoo_bot': tip: unknown link 'flange' \(links: world, base, ", path, "flange")


def test_unknown_lock_joint(tmp_path):
    path = write(tmp_path, ZOO_URDF)
    one_line_error(r"^.*/robot\.urdf: robot 'zoo_bot': lock\[elbow\]: unknown joint \(moving joints: j1, ", path, "tool", "elbow")
    one_line_error(r"^.*/robot\.urdf: robot 'zoo_bot': lock\[tool_mount\]: the joint is fixed already", path, "tool", "tool_mount")
    one_line_error(r"^.*/robot\.urdf: robot 'zoo_bot': lock\[wrist_lock\]: 2.0 is outside the joint limits \[-1.0, 1.0\]",
                   path, "tool", "slide_lock,wrist_lock=2")


@pytest.mark.parametrize("jtype", ["floating", "planar"])
def test_floating_and_planar_joints_are_refused(tmp_path, jtype):
    """A floating joint is read only from a massless root link to the base (tests/test_urdf_trees.py); here j1
    hangs off the massive base."""
    text = ZOO_URDF.replace('<joint name="j1" type="revolute">', f'<joint name="j1" type="{jtype}">')
    path = write(tmp_path, text)
    one_line_error(rf"^.*/robot\.urdf: robot 'zoo_bot': joints\[j1\]: {jtype} joints are not supported", path, "tool", ZOO_LOCK_ARG)


def test_malformed_xml(tmp_path):
    path = write(tmp_path, ZOO_URDF.replace("</joint>\n  <joint name=\"j1\"", "\n  <joint name=\"j1\"", 1))
    err = one_line_error(r"^robot 'robot': .*robot.urdf line \d+, column \d+: malformed XML: mismatched tag$",
                         path, "tool")
    assert err.robot == "robot"


def test_missing_file(tmp_path):
    one_line_error(r"^robot 'nothing': .*nothing.urdf: cannot read URDF \(No such file or directory\)$",
                   tmp_path / "nothing.urdf", "tool")


def test_bad_numbers_and_names(tmp_path):
    path = write(tmp_path, ZOO_URDF.replace('<mass value="0.6"/>', '<mass value="0.6kg"/>'))
    one_line_error(r"^.*/robot\.urdf: robot 'zoo_bot': links\[link2\]\.inertial\.mass: <mass value=\"0\.6kg\">: '0\.6kg' is not a number", path, "tool")
    path = write(tmp_path, ZOO_URDF)
    one_line_error(r"^robot 'for': name: 'for' is a reserved word", path, "tool", ZOO_LOCK_ARG, name="for")
