"""Mimic chains: a mimic of a mimic is one mimic of the chain's root, in the URDF importer and in models.yaml.

tests/fixtures/gripper_mimic_chain.urdf: a wrist, then a gripper whose drive joint has the coordinate
and three joints in a chain, f1 mimics drive (1.5, 0.1), f2 (prismatic) mimics f1 (-0.02, 0.01), f3
mimics f2 (25, -0.2), as Inspire's hands write them. q_C = m2 (m1 q_A + o1) + o2 composes them into
f2 = -0.03 drive + 0.008 and f3 = -0.75 drive + 0: gripper_mimic_direct.urdf writes those by hand.
Both import to the same entry and the same M(q), g(q), inverse dynamics and frame poses; Pinocchio
(which refuses the chain itself: "Mimicking and mimicked configuration spaces have different
sizes") loads the direct file, and its crba and rnea agree with derive's import of the chain.
A cycle of mimics is one line naming the joints.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from derive.description.model import parse_robot
from derive.description.robot import ModelError
from derive.description.urdf import import_urdf
from derive.reference import NumericRobot

FIXTURES = Path(__file__).resolve().parent / "fixtures"
CHAIN = FIXTURES / "gripper_mimic_chain.urdf"
DIRECT = FIXTURES / "gripper_mimic_direct.urdf"
COMPOSED = {"f1": ("drive", 1.5, 0.1), "f2": ("drive", -0.03, 0.008), "f3": ("drive", -0.75, 0.0)}


def states(ref: NumericRobot, n: int = 5):
    rng = np.random.default_rng(0)
    for _ in range(n):
        yield ref.random_configuration(rng), rng.standard_normal(ref.robot.nv), rng.standard_normal(ref.robot.nv)


def scaled(x, y) -> float:
    return float(np.max(np.abs(np.asarray(x) - np.asarray(y)))) / max(1.0, float(np.max(np.abs(y))))


def test_mimic_chain_composes_to_the_direct_mimics():
    chain, direct = import_urdf(CHAIN, "tip"), import_urdf(DIRECT, "tip")
    mimics = {j["name"]: (j["mimic"]["joint"], j["mimic"]["multiplier"], j["mimic"]["offset"])
              for j in chain["joints"] if "mimic" in j}
    assert mimics.keys() == COMPOSED.keys()
    for name, (joint, a, b) in mimics.items():
        assert joint == COMPOSED[name][0]
        assert abs(a - COMPOSED[name][1]) <= 1e-16 and abs(b - COMPOSED[name][2]) <= 1e-16
    for key in ("links", "joints", "frames", "gravity"):
        assert len(chain[key]) == len(direct[key])
    assert [j for j in chain["joints"] if "mimic" not in j] == [j for j in direct["joints"] if "mimic" not in j]
    assert chain["links"] == direct["links"] and chain["frames"] == direct["frames"]
    a, b = NumericRobot(parse_robot("gripper", chain)), NumericRobot(parse_robot("gripper", direct))
    assert a.robot.nq == a.robot.nv == 2  # wrist, drive
    for q, qd, qdd in states(a):
        assert scaled(a.crba(q), b.crba(q)) <= 1e-15
        assert scaled(a.gravity(q), b.gravity(q)) <= 1e-15
        assert scaled(a.rnea(q, qd, qdd), b.rnea(q, qd, qdd)) <= 1e-15
        assert scaled(a.frame_pose(q, "tcp"), b.frame_pose(q, "tcp")) <= 1e-15


def test_mimic_chain_matches_pinocchio():
    """Pinocchio's URDF parser (mimic=True) on the direct file against derive's import of the chain."""
    pin = pytest.importorskip("pinocchio")
    model = pin.buildModelFromUrdf(str(DIRECT), mimic=True)
    assert [model.names[i] for i in range(1, model.njoints)] == ["wrist", "drive", "f1", "f2", "f3"]
    assert (model.nq, model.nv) == (2, 2)
    ref = NumericRobot(parse_robot("gripper", import_urdf(CHAIN, "tip")))
    for q, qd, qdd in states(ref):
        M = pin.crba(model, model.createData(), q)  # a fresh Data: Pinocchio's crba with mimic joints needs it
        M = np.triu(M) + np.triu(M, 1).T
        assert scaled(ref.crba(q), M) <= 1e-12
        assert scaled(ref.rnea(q, qd, qdd), pin.rnea(model, model.createData(), q, qd, qdd)) <= 1e-12
        assert scaled(ref.gravity(q), pin.computeGeneralizedGravity(model, model.createData(), q)) <= 1e-12


def test_models_yaml_mimic_chain_composes():
    """A hand-written models.yaml chain composes as the importer does (each joint keeps its actuator)."""
    entry = import_urdf(DIRECT, "tip")
    written = {"f1": {"joint": "drive", "multiplier": 1.5, "offset": 0.1},
               "f2": {"joint": "f1", "multiplier": -0.02, "offset": 0.01},
               "f3": {"joint": "f2", "multiplier": 25.0, "offset": -0.2}}
    for j in entry["joints"]:
        if j["name"] in written:
            j["mimic"] = written[j["name"]]
    j3 = next(j for j in entry["joints"] if j["name"] == "f3")
    j3["actuator"] = {"viscous": 0.01}
    robot = parse_robot("gripper", entry)
    got = {j.name: j.mimic for j in robot.joints if j.mimic is not None}
    assert got.keys() == COMPOSED.keys()
    for name, m in got.items():
        assert m.joint == "drive" and abs(m.multiplier - COMPOSED[name][1]) <= 1e-16
        assert abs(m.offset - COMPOSED[name][2]) <= 1e-16
    assert [(j.name, a.viscous) for j, a in robot.mimic_actuators] == [("f3", 0.01)]
    direct = parse_robot("gripper", import_urdf(DIRECT, "tip"))
    a, b = NumericRobot(robot), NumericRobot(direct)
    for q, _, _ in states(a, 3):
        assert scaled(a.crba(q), b.crba(q)) <= 1e-15


def _edited(tmp_path: Path, **mimics: str) -> Path:
    """The chain fixture with ``<mimic joint=...>`` of the named joints pointing elsewhere."""
    text = CHAIN.read_text()
    for joint, target in mimics.items():
        start = text.index(f'<joint name="{joint}"')
        at = text.index('<mimic joint="', start) + len('<mimic joint="')
        end = text.index('"', at)
        text = text[:at] + target + text[end:]
    path = tmp_path / "gripper.urdf"
    path.write_text(text)
    return path


@pytest.mark.parametrize("case", ["cycle-of-two", "cycle-of-three", "cycle-off-the-chain", "root-locked",
                                  "middle-locked", "root-unknown", "itself"])
def test_mimic_chain_errors_are_one_line(tmp_path, case):
    lock = None
    if case == "cycle-of-two":
        path, field = _edited(tmp_path, f1="f2"), "joints[f1].mimic"
        problem = ("the mimic joints 'f1', 'f2' follow each other in a cycle (f1 mimics f2, f2 mimics f1): none of "
                   "them has a coordinate; lock them (--lock f1,f2) or remove one <mimic>")
    elif case == "cycle-of-three":
        path, field = _edited(tmp_path, f1="f3"), "joints[f1].mimic"
        problem = ("the mimic joints 'f1', 'f3', 'f2' follow each other in a cycle (f1 mimics f3, f3 mimics f2, "
                   "f2 mimics f1): none of them has a coordinate; lock them (--lock f1,f3,f2) or remove one <mimic>")
    elif case == "cycle-off-the-chain":  # f3 follows into a cycle it is not part of
        path, field = _edited(tmp_path, f1="f2", f2="f1"), "joints[f1].mimic"
        problem = ("the mimic joints 'f1', 'f2' follow each other in a cycle (f1 mimics f2, f2 mimics f1): none of "
                   "them has a coordinate; lock them (--lock f1,f2) or remove one <mimic>")
    elif case == "root-locked":
        path, lock, field = CHAIN, "drive", "joints[f1].mimic"
        problem = "mimics 'drive', a locked joint (and 2 more mimic joints alike): lock them (--lock drive,f1,f2,f3)"
    elif case == "middle-locked":
        path, lock, field = CHAIN, "f1", "joints[f2].mimic"
        problem = "mimics 'f1', a locked joint (and 1 more mimic joint alike): lock them (--lock f1,f2,f3)"
    elif case == "root-unknown":
        path, field = _edited(tmp_path, f1="nosuch"), "joints[f1].mimic"
        problem = ("mimics 'nosuch', an unknown joint (and 2 more mimic joints alike): lock them "
                   "(--lock f1,f2,f3)")
    else:
        path, field = _edited(tmp_path, f2="f2"), "joints[f2].mimic"
        problem = "mimics 'f2', itself: lock it (--lock f2)"
    with pytest.raises(ModelError) as info:
        import_urdf(path, "tip", lock)
    assert (info.value.field, info.value.problem) == (field, problem)
    assert str(info.value) == f"{path}: robot 'gripper': {field}: {problem}"


def test_chain_message_names_the_joints_it_passes(tmp_path):
    """A chain that ends in an unknown joint says which joints it passes on the way."""
    path = _edited(tmp_path, f1="f3", f2="nosuch")  # f1 -> f3 -> f2 -> nosuch
    with pytest.raises(ModelError) as info:
        import_urdf(path, "tip")
    assert info.value.problem == ("mimics 'f3', which mimics 'f2', which mimics 'nosuch', an unknown joint (and 2 "
                                  "more mimic joints alike): lock them (--lock f1,f2,f3)")
