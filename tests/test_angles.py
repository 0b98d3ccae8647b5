"""Angles as written, or snapped on purpose (derive.description.angles).

- tests/data/rounded_arm_7dof.urdf (derive's own made-up 7-dof arm) writes 1.5708, -1.5708 and 3.1416
  for +-pi/2 and pi, as vendor-exported URDFs do. Imported as it is, its numbers stay the file's (the
  symbolic model matches the numeric reference on the file's numbers to 1e-14) and one warning line
  lists the eight angles.
- ``--snap-angles 1e-4`` makes them exact and says so in ``source``: the op counts are then those of a
  copy of the URDF snapped by hand, and the model has 62 base parameters. The rank tolerance gives 62
  for the file as written too (65 with the former 1e-8 on unit columns), naming the near-dependencies
  the rounded angles cause.
- A Sawyer-like URDF (1.57079632679, pi/2 - 4.9e-12) is no longer moved silently: gravity matches the
  file as written to 1e-14 (the former 1e-11 snap moved it by ~1e-11).
"""

from __future__ import annotations

import re
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from derive.cli import main
from derive.codegen.program import build_program
from derive.description.angles import EXACT, quarter, snapped
from derive.description.model import parse_robot
from derive.description.robot import ModelError
from derive.description.urdf import import_urdf, import_urdf_named
from derive.reference import NumericRobot
from derive.symbolic.base_parameters import base_parameters
from derive.symbolic.model import SXModel

ARM = Path(__file__).resolve().parent / "data" / "rounded_arm_7dof.urdf"
TIP = "tool"
ROUNDED = {"joints[waist].origin.rpy[1]": "3.1416 (pi + 7.3e-06)",
           "joints[shoulder_pitch].origin.rpy[0]": "1.5708 (pi/2 + 3.7e-06)",
           "joints[upper_roll].origin.rpy[0]": "-1.5708 (-pi/2 - 3.7e-06)",
           "joints[elbow_pitch].origin.rpy[0]": "1.5708 (pi/2 + 3.7e-06)",
           "joints[elbow_pitch].origin.rpy[2]": "3.1416 (pi + 7.3e-06)",
           "joints[fore_roll].origin.rpy[0]": "-1.5708 (-pi/2 - 3.7e-06)",
           "joints[wrist_pitch].origin.rpy[0]": "1.5708 (pi/2 + 3.7e-06)",
           "joints[flange_roll].origin.rpy[0]": "-1.5708 (-pi/2 - 3.7e-06)"}
JOINTS = ["waist", "shoulder_pitch", "upper_roll", "elbow_pitch", "fore_roll", "wrist_pitch", "flange_roll"]


def file_rpy(text: str) -> dict[str, list[float]]:
    """Each joint's origin rpy as the URDF writes it."""
    return {m.group(1): [float(v) for v in m.group(2).split()]
            for m in re.finditer(r'<joint name="([^"]+)".*?<origin [^>]*rpy="([^"]+)"', text, re.S)}


def hand_snapped(text: str) -> str:
    """The URDF with every rpy value within 1e-4 of k pi/2 written as the double nearest k pi/2."""
    def one(value: str) -> str:
        k = quarter(float(value), 1e-4)
        return value if k is None else repr(snapped(float(value), 1e-4))
    return re.sub(r'rpy="([^"]*)"', lambda m: 'rpy="' + " ".join(one(v) for v in m.group(1).split()) + '"', text)


def ops(robot) -> dict[str, int]:
    m = SXModel(robot)
    ne, s = m.newton_euler, m.sym
    return {"mass_matrix": build_program([("q", s.q)], [("M", ne.mass_matrix)]).ops()["total"],
            "inverse_dynamics": build_program([("q", s.q), ("qd", s.qd), ("qdd", s.qdd)],
                                              [("tau", ne.inverse_dynamics())]).ops()["total"]}


def symbolic_matches_file(robot, tol: float, written=None) -> float:
    """Largest relative gap of the symbolic M and g of ``robot`` against the numeric reference (plain cos and
    sin) of ``written`` (the file's numbers; default ``robot``) at seeded states; asserts it is within ``tol``."""
    m = SXModel(robot)
    f = ca.Function("f", [m.sym.q], [m.newton_euler.mass_matrix, m.newton_euler.gravity_vector])
    ref = NumericRobot(written or robot)
    rng = np.random.default_rng(0)
    worst = 0.0
    for _ in range(5):
        q = rng.uniform(-np.pi, np.pi, robot.nq)
        M, g = (np.array(x) for x in f(q))
        worst = max(worst, np.abs(M - ref.crba(q)).max() / np.abs(M).max(),
                    np.abs(g.ravel() - ref.gravity(q)).max() / np.abs(g).max())
    assert worst <= tol, worst
    return worst


def test_arm_as_written_keeps_the_numbers_and_lists_the_rounded_angles(capsys):
    name, entry = import_urdf_named(ARM, tip=TIP)
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"warning: {ARM}: angles: 8 constant angles are within 0.0001 rad of a "
                                               "multiple of pi/2 without being one (kept as written; --snap-angles")
    assert err[0].endswith(": " + ", ".join(f"{where} = {value}" for where, value in ROUNDED.items()))
    written = file_rpy(ARM.read_text())
    assert {j["name"]: j["origin"]["rpy"] for j in entry["joints"]} == {j: written[j] for j in JOINTS}  # exact copies
    assert entry["frames"] == [{"name": "tcp", "link": "flange", "xyz": [0.0, 0.0, -0.058],
                                "rpy": written["tool_mount"], "aliases": ["tool"]}]  # 3.14159265358979: pi to 3.2e-15, kept as written
    assert "--snap-angles" not in entry["source"]
    symbolic_matches_file(parse_robot(name, entry), 1e-14)


def test_arm_snapped_on_purpose_has_the_hand_snapped_ops_and_62_base_parameters(tmp_path, capsys):
    name, entry = import_urdf_named(ARM, tip=TIP, snap_angles=1e-4)
    assert capsys.readouterr().err == ""
    assert entry["source"] == f"{ARM.name}, imported by `derive import-urdf {ARM} --tip {TIP} --snap-angles 0.0001`"
    half = np.pi / 2
    assert [j["origin"]["rpy"] for j in entry["joints"]] == [[0.0, np.pi, 0.0], [half, 0.0, 0.0], [-half, 0.0, 0.0],
                                                             [half, 0.0, np.pi], [-half, 0.0, 0.0], [half, 0.0, 0.0],
                                                             [-half, 0.0, 0.0]]
    assert entry["frames"][0]["rpy"] == [np.pi, 0.0, 0.0]
    hand = tmp_path / "arm_hand.urdf"
    hand.write_text(hand_snapped(ARM.read_text()))
    assert {v for rpy in file_rpy(hand.read_text()).values() for v in rpy} == {0.0, np.pi / 2, -np.pi / 2, np.pi}
    by_hand = import_urdf(hand, tip=TIP)
    assert capsys.readouterr().err == ""
    assert by_hand["joints"] == entry["joints"] and by_hand["frames"] == entry["frames"]
    snapped_robot, hand_robot = parse_robot(name, entry), parse_robot(name, by_hand)
    assert ops(snapped_robot) == ops(hand_robot) == {"mass_matrix": 610, "inverse_dynamics": 924}
    assert ops(parse_robot(name, import_urdf(ARM, tip=TIP))) == {"mass_matrix": 1086, "inverse_dynamics": 1132}
    bp, bp_hand = base_parameters(snapped_robot), base_parameters(hand_robot)
    assert bp.rank == bp_hand.rank == 62 and bp.near == bp_hand.near == ()


def test_arm_as_written_gets_62_base_parameters_and_names_the_near_dependencies():
    """The rank tolerance (1e-4 of the regressor's scale): the 3.7e-6 and 7.3e-6 rad roundings add no base
    parameter (65 with the former 1e-8 on unit columns); what they nearly create is named."""
    bp = base_parameters(parse_robot("rounded_arm", import_urdf(ARM, tip=TIP)))
    assert bp.rank == 62 and len(bp.near) == 11
    # first order in the roundings (~4e-6 of the regressor's scale), then second order (~1e-7)
    assert sorted(n for n, x in bp.near if x > 1e-6) == ["Ia_shoulder_pitch", "mx_turret", "my_turret", "mz_shoulder"]
    assert all(x < 5e-6 for _, x in bp.near)
    assert "near-dependencies" in bp.near_text() and "--snap-angles" in bp.near_text()


SAWYER_LIKE = """<robot name="sawyer_like">
  <link name="base"/>
  <link name="l1"><inertial><origin xyz="0.02 0.01 0.1"/><mass value="5"/>
    <inertia ixx="0.05" ixy="0" ixz="0" iyy="0.05" iyz="0" izz="0.02"/></inertial></link>
  <link name="l2"><inertial><origin xyz="0.2 0.01 0.02"/><mass value="4"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.06" iyz="0" izz="0.06"/></inertial></link>
  <link name="l3"><inertial><origin xyz="0.15 0 0.03"/><mass value="2"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.02"/></inertial></link>
  <joint name="j0" type="revolute"><parent link="base"/><child link="l1"/><origin xyz="0 0 0.08"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="80" velocity="1.7"/></joint>
  <joint name="j1" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin rpy="-1.57079632679 1.57079632679 0" xyz="0.081 0.05 0.237"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="80" velocity="1.3"/></joint>
  <joint name="j2" type="revolute"><parent link="l2"/><child link="l3"/>
    <origin rpy="1.57079632679 0 0" xyz="0 -0.14 0.1425"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="40" velocity="1.9"/></joint>
</robot>
"""


def test_truncated_right_angles_are_not_moved_silently(tmp_path, capsys):
    path = tmp_path / "sawyer_like.urdf"
    path.write_text(SAWYER_LIKE)
    name, entry = import_urdf_named(path)
    err = capsys.readouterr().err
    assert "3 constant angles are within 0.0001 rad" in err and "1.57079632679 (pi/2 - 4.9e-12)" in err
    written = parse_robot(name, entry)
    symbolic_matches_file(written, 1e-14)
    # snapped on purpose: M and g move from the file by the rounding (~5e-12), and the entry says so
    _, exact = import_urdf_named(path, snap_angles=1e-9)
    assert "--snap-angles 1e-09" in exact["source"] and capsys.readouterr().err == ""
    gap = symbolic_matches_file(parse_robot(name, exact), 1e-10, written)
    assert gap > 1e-12


def test_exact_to_rounding_is_1e_14():
    assert snapped(1.5707963267948966) == np.pi / 2 and snapped(3.14159265358979) == np.pi
    assert snapped(1.57079632679) == 1.57079632679 and snapped(2e-14) == 2e-14 and snapped(-5e-15) == 0.0
    assert EXACT == 1e-14


@pytest.mark.parametrize("tol", ["0", "-1e-4", "1", "nan", "inf"])
def test_snap_tolerance_out_of_range_is_one_line(tol, capsys):
    status = main(["import-urdf", str(ARM), f"--snap-angles={tol}"])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 2 and len(err) == 1, err
    assert err[0].startswith(f"derive: error: {ARM}: robot 'rounded_arm': snap_angles: must be a tolerance in rad")


def test_cli_snap_is_recorded_and_reproduces(tmp_path, capsys):
    out = tmp_path / "models.yaml"
    assert main(["import-urdf", str(ARM), "--tip", TIP, "--snap-angles", "1e-4", "--out", str(out)]) == 0
    text = out.read_text()
    assert f"# Regenerate with: derive import-urdf {ARM} --tip {TIP} --snap-angles 0.0001" in text
    assert "rpy: [1.5707963267948966, 0.0, 0.0]" in text and "1.5708" not in text.replace("1.5707963267948966", "")
    assert "rpy: [0.0, 3.141592653589793, 0.0]" in text and "3.1416" not in text
