"""Whole-tree URDF import (``derive import-urdf FILE`` with no ``--chain``).

- Every URDF of example-robot-data that Pinocchio loads imports whole, with no tip and no
  lock, and the numpy reference (derive.reference) matches Pinocchio built from the same
  URDF at 3 seeded states to 1e-9 relative: the pose and the Jacobian of every frame, the
  mass matrix, gravity and inverse dynamics (fixed base). The importer drops moving branches
  that carry no mass at all; Pinocchio keeps them, so the comparison locks them there (at
  their neutral position; they move nothing). q comes in Pinocchio's order. The URDFs with
  moving mimic joints fail with the clear mimic message instead, those without any moving
  joint with a hint at ``--floating``, and three with impossible inertias with the model's
  inertia error. The whole sweep (68 URDFs) takes about 5 s, so all of it runs.
- A synthetic tree: branches with mass, a massless moving leaf (dropped), frames, a tip.
- ``--chain`` keeps the path-only import; ``--floating`` and a URDF ``floating`` joint from a
  massless world give ``base: floating``; the errors of the new options are one line.
"""

from __future__ import annotations

import math
import re
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from derive.cli import main
from derive.description.model import parse_models, parse_robot
from derive.description.robot import ModelError
from derive.description.urdf import (c_identifier, dump_entry, example_robot_data_dir, import_urdf, import_urdf_named,
                                     parse_lock)
from derive.reference import NumericRobot
from test_urdf import rel, write

TOL = 1e-9
N_STATES = 3

# Moving <mimic> joints become mimic joints (compared with Pinocchio's mimic models); alex_psyonic_hands'
# mimic tags name joints that do not exist (index_q1 for Left_index_q1): refused with a working --lock.
# romeo.urdf has 22 mimic joints too, all in its hands, which carry no mass: they are dropped.
MIMIC = {
    "baxter_description/urdf/baxter.urdf",
    "panda_description/urdf/panda.urdf",
    "panda_description/urdf/panda_collision.urdf",
    "pr2_description/urdf/pr2.urdf",
    "talos_data/robots/talos_full_v2.urdf",
    "talos_data/robots/talos_full_v2_box.urdf",
    "tiago_pro_description/robots/tiago_pro.urdf",
}
MIMIC_UNKNOWN = {"alex_description/urdf/alex_psyonic_hands.urdf"}
# One rigid body, no moving joint: a fixed base would have nothing to move.
NO_DOF = {
    "hector_description/robots/quadrotor_base.urdf",
    "iris_description/robots/iris_simple.urdf",
}
# Physically impossible inertias, which Pinocchio loads as written and the importer refuses.
BAD_INERTIA = {
    "bolt_description/robots/bolt.urdf": r"links\[FL_FOOT\]\.inertia \(merged into 'FL_LOWER_LEG'\): a massless link must "
                                         r"have zero inertia",
    "romeo_description/urdf/romeo_laas_small.urdf": r"links\[0\] \(base_link\)\.inertia: not positive semi-definite",
    "romeo_description/urdf/romeo_small.urdf": r"links\[26\] \(RShoulderYawLink\)\.inertia: breaks the triangle inequality",
}


# --------------------------------------------------------------------------- Pinocchio side


class TreePin:
    """Pinocchio's model of a URDF with the joints our import lacks locked at neutral (they must move no
    mass: dropped massless branches, or joints the caller locked), indexed by our (C identifier) names."""

    def __init__(self, pin, urdf: Path, robot, tip: str | None = None, locks: dict[str, float] | None = None,
                 from_xml: bool = False):
        self.pin = pin
        root = (pin.JointModelFreeFlyer(),) if robot.floating else ()  # free flyer: q[0:7], v[0:6] as ours
        # mimic joints are ordinary joints here, reduced by hand below (q_m = a q_J + b: G maps our v to Pinocchio's);
        # Pinocchio's own mimic models refuse some of these trees (a leader after its mimic, talos_full_v2)
        full = pin.buildModelFromXML(str(urdf), *root) if from_xml else pin.buildModelFromUrdf(str(urdf), *root)
        first = 2 if robot.floating else 1  # Pinocchio's first joint of the tree
        ours = {j.name for j in robot.moving_joints}
        locks = dict(locks or {})
        q0 = pin.neutral(full)
        self.dropped = []
        for jid in range(first, full.njoints):
            jname = full.names[jid]
            if c_identifier(jname) in ours:
                continue
            if jname in locks:
                idx, value = full.joints[jid].idx_q, locks[jname]
                if full.joints[jid].nq == 2:  # continuous: (cos, sin)
                    q0[idx], q0[idx + 1] = math.cos(value), math.sin(value)
                else:
                    q0[idx] = value
            else:
                self.dropped.append(jname)
            assert jname in locks or self.subtree_mass(full, jid) == 0, (jname, self.subtree_mass(full, jid))
        lock_ids = [full.getJointId(n) for n in locks] + [full.getJointId(n) for n in self.dropped]
        model = pin.buildReducedModel(full, sorted(lock_ids), q0) if lock_ids else full
        self.model, self.data = model, model.createData()
        names = [j.name for j in robot.moving_joints]
        pin_names = {c_identifier(n): n for n in model.names[1:]}
        assert [c_identifier(n) for n in model.names[first:]] == names, (names, list(model.names))  # the same q order
        self.joints = [model.joints[model.getJointId(pin_names[n])] for n in names]
        column = {name: k for k, name in enumerate(robot.velocity_names)}  # our v index (q index - 1 past a free flyer)
        self.drive = [(column[j.name], 1.0, 0.0) if j.mimic is None else
                      (column[j.mimic.joint], j.mimic.multiplier, j.mimic.offset) for j in robot.moving_joints]
        self.nb = 6 if robot.floating else 0
        self.G = np.zeros((model.nv, robot.nv))  # Pinocchio's v = G (our v)
        self.G[:self.nb, :self.nb] = np.eye(self.nb)
        for j, (k, a, _) in zip(self.joints, self.drive):
            self.G[j.idx_v, k] = a
        assert model.nv == len(names) + self.nb
        bodies = {c_identifier(f.name): i for i, f in enumerate(model.frames) if f.type == pin.BODY}
        self.frame_ids = {n: bodies[n] for n in robot.frame_names if n != "tcp"}
        if tip is not None:
            self.frame_ids["tcp"] = bodies[c_identifier(tip)]

    @staticmethod
    def subtree_mass(model, jid: int) -> float:
        return math.fsum(model.inertias[k].mass for k in model.subtrees[jid])

    def q(self, ours: np.ndarray) -> np.ndarray:
        q = np.zeros(self.model.nq)
        q[:self.nb + 1 if self.nb else 0] = ours[:self.nb + 1 if self.nb else 0]  # the free flyer's 7
        for (k, a, b), j in zip(self.drive, self.joints):
            qi = a * ours[k + (1 if self.nb else 0)] + b
            if j.nq == 2:  # continuous: (cos, sin)
                q[j.idx_q], q[j.idx_q + 1] = math.cos(qi), math.sin(qi)
            else:
                q[j.idx_q] = qi
        return q

    def v(self, ours: np.ndarray) -> np.ndarray:
        return self.G @ ours

    def poses(self, q) -> dict[str, np.ndarray]:
        self.pin.framesForwardKinematics(self.model, self.data, self.q(q))
        return {n: self.data.oMf[i].homogeneous for n, i in self.frame_ids.items()}

    def jacobians(self, q) -> dict[str, np.ndarray]:
        self.pin.computeJointJacobians(self.model, self.data, self.q(q))
        self.pin.updateFramePlacements(self.model, self.data)
        return {n: self.pin.getFrameJacobian(self.model, self.data, i, self.pin.LOCAL_WORLD_ALIGNED) @ self.G
                for n, i in self.frame_ids.items()}

    def crba(self, q) -> np.ndarray:
        m = np.array(self.pin.crba(self.model, self.data, self.q(q)))
        m = np.triu(m) + np.triu(m, 1).T
        return self.G.T @ m @ self.G

    def gravity(self, q) -> np.ndarray:
        return self.G.T @ np.array(self.pin.computeGeneralizedGravity(self.model, self.data, self.q(q)))

    def rnea(self, q, qd, qdd) -> np.ndarray:
        return self.G.T @ np.array(self.pin.rnea(self.model, self.data, self.q(q), self.v(qd), self.v(qdd)))


def random_q(robot, rng) -> np.ndarray:
    q = []
    if robot.floating:
        quat = rng.normal(size=4)
        q = list(rng.uniform(-1, 1, 3)) + list(quat / np.linalg.norm(quat))
    for j in robot.moving_joints:
        if j.mimic is not None:  # no entry in q
            continue
        lo = -math.pi if j.limits.lower is None else j.limits.lower
        hi = math.pi if j.limits.upper is None else j.limits.upper
        q.append(rng.uniform(lo, hi))
    return np.array(q)


def compare(robot, side: TreePin, states: int = N_STATES, seed: int = 0) -> dict[str, float]:
    """Worst relative errors of NumericRobot against Pinocchio over ``states`` seeded random states."""
    nr = NumericRobot(robot)
    rng = np.random.default_rng(seed)
    worst = dict.fromkeys(["pose", "jacobian", "crba", "gravity", "rnea"], 0.0)
    for _ in range(states):
        q = random_q(robot, rng)
        qd, qdd = rng.standard_normal(robot.nv), rng.standard_normal(robot.nv)
        ours, theirs = nr.fk(q), side.poses(q)
        jac = side.jacobians(q)
        for name in side.frame_ids:
            worst["pose"] = max(worst["pose"], rel(ours[name], theirs[name]))
            worst["jacobian"] = max(worst["jacobian"], rel(nr.jacobian(q, name), jac[name]))
        worst["crba"] = max(worst["crba"], rel(nr.crba(q), side.crba(q)))
        worst["gravity"] = max(worst["gravity"], rel(nr.gravity(q), side.gravity(q)))
        rigid = nr.rnea(q, qd, qdd) - nr.friction(qd)  # Pinocchio's rnea has no joint friction
        worst["rnea"] = max(worst["rnea"], rel(rigid, side.rnea(q, qd, qdd)))
    # <dynamics damping friction> as Pinocchio reads it (model.damping, model.friction, every joint of the full
    # tree), reduced through the mimic map (G^T D G: a mimic joint's own friction reaches its leader's coordinate)
    want_viscous, want_coulomb = np.zeros(nr.nv), np.zeros(nr.nv)
    for joint, (k, a, _) in zip(side.joints, side.drive):
        want_viscous[k] += a * a * side.model.damping[joint.idx_v]
        want_coulomb[k] += abs(a) * side.model.friction[joint.idx_v]
    assert np.allclose(nr.viscous, want_viscous, rtol=1e-15, atol=0), (nr.viscous, want_viscous)
    assert np.allclose(nr.coulomb, want_coulomb, rtol=1e-15, atol=0), (nr.coulomb, want_coulomb)
    return worst


# --------------------------------------------------------------------------- the example-robot-data sweep


def erd_urdfs() -> list[str]:
    root = example_robot_data_dir()
    return [] if root is None else sorted(p.relative_to(root).as_posix() for p in root.rglob("*.urdf"))


def sweep_one(pin, rel_path: str, lock: str | None = None, floating: bool = False) -> dict:
    """Import one example-robot-data URDF whole and compare it with Pinocchio: a row of the report."""
    path = example_robot_data_dir() / rel_path
    try:
        full = pin.buildModelFromUrdf(str(path), *((pin.JointModelFreeFlyer(),) if floating else ()))
    except (RuntimeError, ValueError) as exc:
        return {"urdf": rel_path, "status": "pinocchio refuses", "why": str(exc).splitlines()[0]}
    start = time.perf_counter()
    try:
        name, entry = import_urdf_named("example-robot-data:" + rel_path, lock=lock, floating=floating)
    except ModelError as exc:
        return {"urdf": rel_path, "status": "refused", "why": str(exc), "pin_nv": full.nv}
    seconds = time.perf_counter() - start
    robot = parse_robot(name, entry)
    locks = {n: v for n, (v, _) in parse_lock(lock).items()}
    side = TreePin(pin, path, robot, locks=locks)
    worst = compare(robot, side)
    return {"urdf": rel_path, "status": "ok", "nv": robot.nv, "mimic": sum(j.mimic is not None for j in robot.joints), "pin_nv": full.nv - len(locks), "frames": len(robot.frame_names),
            "dropped": side.dropped, "seconds": seconds, "worst": worst, "description": entry["description"]}


@pytest.fixture(scope="module")
def pin():
    return pytest.importorskip("pinocchio")


@pytest.mark.parametrize("floating", [False, True], ids=["fixed", "floating"])
@pytest.mark.parametrize("rel_path", erd_urdfs())
def test_example_robot_data_whole_tree(pin, rel_path, floating, capsys):
    row = sweep_one(pin, rel_path, floating=floating)
    with capsys.disabled():
        if row["status"] == "ok":
            print(f"\n{rel_path}: nv {row['nv']} (Pinocchio {row['pin_nv']}), {row['frames']} frames, "
                  f"import {row['seconds']:.3f} s, dropped {len(row['dropped'])}; worst relative error: "
                  + ", ".join(f"{k} {v:.1e}" for k, v in row["worst"].items()))
        else:
            print(f"\n{rel_path}: {row['status']}: {row['why']}")
    if row["status"] == "pinocchio refuses":
        with pytest.raises(ModelError):  # ur3.urdf: an empty <robot>, no name (Pinocchio's complaint)
            import_urdf("example-robot-data:" + rel_path)
        return  # nothing to compare with: Pinocchio does not load it either
    if rel_path in MIMIC_UNKNOWN:
        assert row["status"] == "refused", row
        found = re.search(r"joints\[[^]]+\]\.mimic: mimics '[^']+', an unknown joint \(and \d+ more mimic joints alike\): "
                          r"lock them \(--lock (\S+)\)$", row["why"])
        assert found, row["why"]
        row = sweep_one(pin, rel_path, found.group(1), floating)  # the suggested lock imports, and matches Pinocchio locked so
        with capsys.disabled():
            print(f"  with the suggested --lock: nv {row.get('nv')}, worst {row.get('worst')}")
    if rel_path in MIMIC:
        assert row["status"] == "ok" and row["mimic"] > 0, row
    if rel_path in NO_DOF and not floating:
        assert row["status"] == "refused" and "no moving joint" in row["why"] and "--floating" in row["why"], row
        return
    if rel_path in BAD_INERTIA:
        assert row["status"] == "refused" and re.search(BAD_INERTIA[rel_path], row["why"]), row
        return
    assert row["status"] == "ok", row
    for key, err in row["worst"].items():
        assert err < TOL, (key, err)
    assert row["nv"] == row["pin_nv"] - len(row["dropped"]) - row["mimic"]
    assert row["seconds"] < 5.0


def test_the_sweep_covers_example_robot_data(pin):
    """The sweep sees the installed example-robot-data (not an empty list), and the expectations name real files."""
    found = set(erd_urdfs())
    assert len(found) >= 60, len(found)
    assert MIMIC | MIMIC_UNKNOWN | NO_DOF | set(BAD_INERTIA) <= found


def test_mimic_of_a_locked_joint_suggests_a_lock_that_imports(pin):
    """baxter's two gripper mimic joints: with the joints they follow locked, the refusal's --lock (which
    adds the mimic joints) imports as given."""
    path = "example-robot-data:baxter_description/urdf/baxter.urdf"
    _, whole = import_urdf_named(path)
    leaders = [j["mimic"]["joint"] for j in whole["joints"] if "mimic" in j]
    assert len(leaders) == 2
    lock = ",".join(leaders)
    with pytest.raises(ModelError, match=r"a locked joint \(and 1 more mimic joint alike\): lock them") as info:
        import_urdf(path, lock=lock)
    lock = re.search(r"--lock (\S+)\)$", str(info.value)).group(1)
    name, entry = import_urdf_named(path, lock=lock)
    assert "(locked " in entry["description"] and f"--lock {lock}`" in entry["source"]
    assert not any(j.mimic for j in parse_robot(name, entry).joints)


# --------------------------------------------------------------------------- a synthetic tree

# A torso on the world with two arms (the left ends in a gripper of two massive fingers), a
# massless pan-tilt camera head (dropped: no mass anywhere on it), a massless sensor link fixed
# to the torso (a frame), a massless moving link between two massive ones (kept: mass below it),
# and a tool frame on the right arm.
TREE_URDF = """<?xml version="1.0"?>
<robot name="tree-bot">
  <link name="world"/>
  <link name="torso"><inertial><origin xyz="0 0 0.2"/><mass value="10"/>
    <inertia ixx="0.3" ixy="0" ixz="0" iyy="0.3" iyz="0" izz="0.1"/></inertial></link>
  <link name="imu"/>
  <link name="l_upper"><inertial><origin xyz="0 0.1 0" rpy="0.2 0 0.1"/><mass value="2"/>
    <inertia ixx="0.02" ixy="0.001" ixz="0" iyy="0.01" iyz="0" izz="0.02"/></inertial></link>
  <link name="l_lower"><inertial><origin xyz="0 0.1 0"/><mass value="1"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.005" iyz="0" izz="0.01"/></inertial></link>
  <link name="l_finger_a"><inertial><origin xyz="0 0.02 0"/><mass value="0.1"/>
    <inertia ixx="0.0001" ixy="0" ixz="0" iyy="0.0001" iyz="0" izz="0.0001"/></inertial></link>
  <link name="l_finger_b"><inertial><origin xyz="0 0.02 0"/><mass value="0.1"/>
    <inertia ixx="0.0001" ixy="0" ixz="0" iyy="0.0001" iyz="0" izz="0.0001"/></inertial></link>
  <link name="r_yaw"/>
  <link name="r_upper"><inertial><origin xyz="0 -0.1 0"/><mass value="2"/>
    <inertia ixx="0.02" ixy="0" ixz="0.002" iyy="0.01" iyz="0" izz="0.02"/></inertial></link>
  <link name="r_tool"/>
  <link name="head_pan"/>
  <link name="head_tilt"/>
  <link name="camera"/>
  <joint name="world_torso" type="fixed"><parent link="world"/><child link="torso"/><origin xyz="0 0 0.5"/></joint>
  <joint name="imu_mount" type="fixed"><parent link="torso"/><child link="imu"/><origin xyz="0.05 0 0.3" rpy="0 0 1.0"/></joint>
  <joint name="r_shoulder_yaw" type="revolute"><parent link="torso"/><child link="r_yaw"/>
    <origin xyz="0 -0.2 0.4"/><axis xyz="0 0 1"/><limit lower="-1.5" upper="1.5" effort="50" velocity="2"/></joint>
  <joint name="r_shoulder_pitch" type="revolute"><parent link="r_yaw"/><child link="r_upper"/>
    <origin xyz="0 0 0"/><axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="50" velocity="2"/></joint>
  <joint name="r_tool_mount" type="fixed"><parent link="r_upper"/><child link="r_tool"/><origin xyz="0 -0.3 0" rpy="0 1.2 0"/></joint>
  <joint name="l_shoulder" type="revolute"><parent link="torso"/><child link="l_upper"/>
    <origin xyz="0 0.2 0.4" rpy="0.3 0 0"/><axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="50" velocity="2"/></joint>
  <joint name="l_elbow" type="continuous"><parent link="l_upper"/><child link="l_lower"/>
    <origin xyz="0 0.25 0"/><axis xyz="1 0 0"/></joint>
  <joint name="l_finger_a_joint" type="prismatic"><parent link="l_lower"/><child link="l_finger_a"/>
    <origin xyz="0.02 0.2 0"/><axis xyz="1 0 0"/><limit lower="0" upper="0.04" effort="5" velocity="0.1"/></joint>
  <joint name="l_finger_b_joint" type="prismatic"><parent link="l_lower"/><child link="l_finger_b"/>
    <origin xyz="-0.02 0.2 0"/><axis xyz="-1 0 0"/><limit lower="0" upper="0.04" effort="5" velocity="0.1"/></joint>
  <joint name="head_pan_joint" type="revolute"><parent link="torso"/><child link="head_pan"/>
    <origin xyz="0 0 0.6"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="5" velocity="1"/></joint>
  <joint name="head_tilt_joint" type="revolute"><parent link="head_pan"/><child link="head_tilt"/>
    <origin xyz="0 0 0.05"/><axis xyz="0 1 0"/><limit lower="-1" upper="1" effort="5" velocity="1"/></joint>
  <joint name="camera_mount" type="fixed"><parent link="head_tilt"/><child link="camera"/><origin xyz="0.1 0 0"/></joint>
</robot>
"""
TREE_JOINTS = ["l_shoulder", "l_elbow", "l_finger_a_joint", "l_finger_b_joint", "r_shoulder_yaw", "r_shoulder_pitch"]


def test_synthetic_tree_against_pinocchio(pin, tmp_path):
    path = write(tmp_path, TREE_URDF)
    name, entry = import_urdf_named(path)
    assert name == "tree_bot"
    assert entry["description"] == "tree-bot imported from URDF (dropped the massless moving branch head_pan_joint)"
    assert entry["source"] == f"{path.name}, imported by `derive import-urdf {path}`"
    robot = parse_robot(name, entry)
    # depth-first, siblings by joint name (Pinocchio's order), though the right arm comes first in the file
    assert [j.name for j in robot.moving_joints] == TREE_JOINTS
    assert [link.name for link in robot.links] == ["world", "l_upper", "l_lower", "l_finger_a", "l_finger_b", "r_yaw",
                                                   "r_upper"]
    assert robot.link("r_yaw").mass == 0.0  # massless, but mass hangs below it: kept (as Pinocchio does)
    assert {f.name: f.link for f in robot.frames} == {"torso": "world", "imu": "world", "r_tool": "r_upper"}
    assert "tcp" not in robot.frame_names
    side = TreePin(pin, path, robot)
    assert side.dropped == ["head_pan_joint", "head_tilt_joint"]
    assert list(pin.buildModelFromUrdf(str(path)).names[1:]) == ["head_pan_joint", "head_tilt_joint"] + TREE_JOINTS
    worst = compare(robot, side, states=10)
    for key, err in worst.items():
        assert err < TOL, (key, err)
    assert np.linalg.eigvalsh(NumericRobot(robot).crba(np.zeros(robot.nv)))[0] > 0  # M stays positive definite

    # a tip only adds the frame tcp; a tip on the massless head keeps the path to it
    entry = import_urdf(path, "r_tool")
    assert entry["frames"][0] == {"name": "tcp", "link": "r_upper", "xyz": [0.0, -0.3, 0.0], "rpy": [0.0, 1.2, 0.0],
                                  "aliases": ["r_tool"]}  # r_tool keeps its name
    assert [j["name"] for j in entry["joints"]] == TREE_JOINTS
    entry = import_urdf(path, "camera")
    assert [j["name"] for j in entry["joints"]] == ["head_pan_joint", "head_tilt_joint"] + TREE_JOINTS
    assert entry["description"] == "tree-bot imported from URDF (tip camera)"
    # locks work in whole-tree mode: the fingers locked are merged into the lower arm
    entry = import_urdf(path, lock="l_finger_a_joint=0.01,l_finger_b_joint")
    robot = parse_robot("tree_bot", entry)
    assert [j.name for j in robot.moving_joints] == TREE_JOINTS[:2] + TREE_JOINTS[4:]
    assert robot.link("l_lower").mass == pytest.approx(1.2, rel=1e-15)
    side = TreePin(pin, path, robot, locks={"l_finger_a_joint": 0.01, "l_finger_b_joint": 0.0})
    for key, err in compare(robot, side).items():
        assert err < TOL, (key, err)


def test_chain_keeps_the_path_only_import(tmp_path):
    path = write(tmp_path, TREE_URDF)
    err = import_error(r"^.*/robot\.urdf: robot 'tree_bot': joints\[l_shoulder\]: moves a branch with mass \(3.2 kg\) that does not lead "
                       r"to the tip 'r_tool'; lock it \(--lock l_shoulder,l_elbow,l_finger_a_joint,l_finger_b_joint\)",
                       path, chain="r_tool")
    lock = re.search(r"--lock (\S+)\)", str(err)).group(1)
    name, entry = import_urdf_named(path, lock=lock, chain="r_tool")
    assert [j["name"] for j in entry["joints"]] == ["r_shoulder_yaw", "r_shoulder_pitch"]  # the head: massless, dropped
    assert entry["frames"][0]["name"] == "tcp"
    assert entry["description"] == f"tree-bot imported from URDF (chain to r_tool; locked {lock.replace(',', ' = 0, ')} = 0)"
    assert entry["source"].endswith(f"imported by `derive import-urdf {path} --chain r_tool --lock {lock}`")
    assert import_urdf(path, "r_tool", lock, chain="r_tool") == entry  # --tip equal to --chain: the same


def test_floating_base(pin, tmp_path):
    path = write(tmp_path, TREE_URDF)
    entry = import_urdf(path, floating=True)
    assert entry["base"] == "floating" and list(entry)[:3] == ["description", "source", "base"]
    assert entry["description"] == ("tree-bot imported from URDF (floating base world; dropped the massless moving branch "
                                    "head_pan_joint)")
    assert entry["source"].endswith(f"`derive import-urdf {path} --floating`")
    robot = parse_robot("tree_bot", entry)
    assert robot.floating and robot.nv == 6 + len(TREE_JOINTS) and robot.nq == robot.nv + 1
    model = pin.buildModelFromUrdf(str(path), pin.JointModelFreeFlyer())
    assert model.nv == robot.nv + 2  # the dropped head
    assert robot.link("world").mass == model.inertias[1].mass == 10.0  # the root link is the floating body
    assert math.fsum(link.mass for link in robot.links) == pytest.approx(math.fsum(i.mass for i in model.inertias), rel=1e-15)
    text = dump_entry("tree_bot", entry)
    assert "\n    base: floating\n" in text and parse_models("robots:\n" + text)["tree_bot"].floating

    # a URDF with a massless world and a floating joint to the base: the same as --floating on the base
    floating = TREE_URDF.replace('<joint name="world_torso" type="fixed"><parent link="world"/><child link="torso"/>'
                                 '<origin xyz="0 0 0.5"/></joint>',
                                 '<joint name="world_torso" type="floating"><parent link="world"/><child link="torso"/></joint>')
    path2 = write(tmp_path, floating, "floating.urdf")
    entry2 = import_urdf(path2)
    assert entry2["base"] == "floating"
    assert entry2["description"] == ("tree-bot imported from URDF (floating base torso: the floating joint world_torso "
                                     "from world; dropped the massless moving branch head_pan_joint)")
    robot2 = parse_robot("tree_bot", entry2)
    assert robot2.root == "torso" and "world" not in robot2.frame_names
    assert [j.name for j in robot2.moving_joints] == TREE_JOINTS
    assert robot2.link("torso").mass == 10.0 and robot2.nv == robot.nv
    assert import_urdf(path2, floating=True)["links"] == entry2["links"]
    # ... locked, it is a fixed joint again
    entry3 = import_urdf(path2, lock="world_torso")
    assert "base" not in entry3 and parse_robot("tree_bot", entry3).nv == len(TREE_JOINTS)


# --------------------------------------------------------------------------- errors


def import_error(match: str, *args, **kwargs) -> ModelError:
    with pytest.raises(ModelError, match=match) as info:
        import_urdf(*args, **kwargs)
    assert "\n" not in str(info.value)
    return info.value


def test_errors_of_the_new_options(tmp_path):
    path = write(tmp_path, TREE_URDF)
    import_error(r"^.*/robot\.urdf: robot 'tree_bot': chain: unknown link 'flange' \(links: world, torso, ", path, chain="flange")
    import_error(r"^.*/robot\.urdf: robot 'tree_bot': tip: 'camera' is not the --chain link 'r_tool'; --chain puts the frame 'tcp' at "
                 r"its link \(give --chain alone\)$", path, "camera", chain="r_tool")
    # floating joints: only world -> base with an identity origin
    inner = TREE_URDF.replace('name="l_elbow" type="continuous"', 'name="l_elbow" type="floating"')
    import_error(r"^.*/robot\.urdf: robot 'tree_bot': joints\[l_elbow\]: floating joints are not supported but as the only joint of a "
                 r"massless root link \(the world\) to the base, .*\(--lock l_elbow\)", write(tmp_path, inner))
    offset = TREE_URDF.replace('name="world_torso" type="fixed"', 'name="world_torso" type="floating"')
    import_error(r"^.*/robot\.urdf: robot 'tree_bot': joints\[world_torso\].origin: a floating joint read as the floating base must have "
                 r"the identity origin", write(tmp_path, offset))
    import_error(r"^.*/robot\.urdf: robot 'tree_bot': lock\[world_torso\]: a floating joint is locked at its origin only",
                 write(tmp_path, offset), lock="world_torso=0.2")
    heavy_world = offset.replace('<link name="world"/>', '<link name="world"><inertial><mass value="1"/>'
                                 '<inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>')
    import_error(r"joints\[world_torso\]: floating joints are not supported but as the only joint of a massless root",
                 write(tmp_path, heavy_world))
    planar = TREE_URDF.replace('name="l_elbow" type="continuous"', 'name="l_elbow" type="planar"')
    import_error(r"^.*/robot\.urdf: robot 'tree_bot': joints\[l_elbow\]: planar joints are not supported \(", write(tmp_path, planar))
    import_error(r"^.*/robot\.urdf: robot 'tree_bot': tip: 'world' is the world above the floating joint 'world_torso'",
                 write(tmp_path, TREE_URDF.replace('name="world_torso" type="fixed"', 'name="world_torso" type="floating"')
                       .replace('<origin xyz="0 0 0.5"/></joint>', '</joint>', 1)), "world")
    # nothing moves: a hint at --floating
    rigid = '<robot name="brick"><link name="a"><inertial><mass value="1"/><inertia ixx="1" ixy="0" ixz="0" iyy="1" ' \
            'iyz="0" izz="1"/></inertial></link></robot>'
    import_error(r"^.*/robot\.urdf: robot 'brick': joints: no moving joint is left to import .*\(--floating\)$", write(tmp_path, rigid))
    assert parse_robot("brick", import_urdf(write(tmp_path, rigid), floating=True)).nv == 6


@pytest.mark.parametrize("argv, fragment", [
    (["--chain", "nosuch"], "chain: unknown link 'nosuch'"),
    (["--tip", "camera", "--chain", "r_tool"], "is not the --chain link 'r_tool'"),
    (["--lock", "world_torso"], "lock[world_torso]: the joint is fixed already"),
    (["--floating", "--lock", "l_elbow=nan"], "not finite"),
])
def test_command_line_errors(tmp_path, capsys, argv, fragment):
    path = write(tmp_path, TREE_URDF)
    assert main(["import-urdf", str(path), *argv]) == 2
    out, err = capsys.readouterr()
    assert out == "" and err.count("\n") == 1 and err.startswith("derive: error: ") and fragment in err, err


def test_command_line_options(tmp_path, capsys):
    path = write(tmp_path, TREE_URDF)
    models = tmp_path / "models.yaml"
    assert main(["import-urdf", str(path), "--floating", "--tip", "r_tool", "--name", "tb", "--out", str(models)]) == 0
    data = yaml.safe_load(models.read_text())["robots"]["tb"]
    assert data["base"] == "floating"
    assert data["source"].endswith(f"`derive import-urdf {path} --tip r_tool --floating --name tb`")
    assert main(["import-urdf", str(path), "--chain", "camera", "--lock",
                 "l_shoulder,l_elbow,l_finger_a_joint,l_finger_b_joint,r_shoulder_yaw,r_shoulder_pitch"]) == 0
    out = capsys.readouterr().out
    robot = parse_models("robots:\n" + out)["tree_bot"]
    assert [j.name for j in robot.moving_joints] == ["head_pan_joint", "head_tilt_joint"]
    # the recorded command reproduces the entry
    command = robot.source.split("`")[1].split()[1:]
    assert main(command) == 0 and capsys.readouterr().out == out
