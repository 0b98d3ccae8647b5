"""The default selection of big robots (issue 25, item 6): more than BIG_FRAMES named frames or more
than BIG_NV velocities give per-frame functions to the tcp, the wrench frames and the leaves only, and
above BIG_NV leave out the O(nv^3) quantities; ``generate: {frames: all, quantities: all}`` restores
everything; manifest.json, ``derive info`` and ``derive import-urdf`` say so."""

from __future__ import annotations

import json

import yaml

from derive.cli import main
from derive.codegen.catalogue import wanted
from derive.description.model import parse_models
from derive.description.robot import BIG_FRAMES, BIG_NV, FUNCTION_QUANTITIES, LEAN_LEFT_OUT
from derive.description.urdf import import_urdf

SENSORS = BIG_FRAMES + 1  # one named frame more than a small robot may have


def tree(sensors: int = SENSORS, chain: int = 2, wrenches: str = "") -> str:
    """models.yaml text of ``tree``: base -> a1 -> ... -> a<chain> (the tcp at its end) and base -> b1 -> c1,
    base -> b1 -> c2; ``sensors`` named frames s<k> on a1; leaves a<chain>, c1, c2."""
    links = ["base"] + [f"a{i}" for i in range(1, chain + 1)] + ["b1", "c1", "c2"]
    joints = [(f"a{i}", "base" if i == 1 else f"a{i - 1}") for i in range(1, chain + 1)] + [
        ("b1", "base"), ("c1", "b1"), ("c2", "b1")]
    text = "robots:\n  tree:\n    links:\n" + "".join(
        f"      - {{name: {n}" + ("}" if n == "base" else ", mass: 1.0, com: [0.1, 0, 0], inertia: [0.01, 0.02, 0.03]}")
        + "\n" for n in links)
    text += "    joints:\n" + "".join(
        f"      - {{name: j_{child}, type: revolute, parent: {parent}, child: {child}, axis: [0, 0, 1], "
        "origin: {xyz: [0.2, 0, 0]}}\n" for child, parent in joints)
    text += f"    frames:\n      - {{name: tcp, link: a{chain}, xyz: [0.1, 0, 0]}}\n" + "".join(
        f"      - {{name: s{k}, link: a1, xyz: [0, 0, {0.01 * k}]}}\n" for k in range(sensors))
    return text + wrenches


def test_big_robot_gets_tcp_wrench_frames_and_leaves():
    robot = parse_models(tree(wrenches="    wrenches: [tcp, s3]\n"))["tree"]
    assert robot.big and robot.leaves == ("a2", "c1", "c2")
    assert robot.function_frames == ("tcp", "s3", "a2", "c1", "c2")
    assert robot.function_quantities is None  # 4 velocities: every quantity
    assert robot.selection == {"frames": "default for a big robot (more than 8 named frames (10)): the tcp, the wrench "
                               "frames and the leaves of the tree (links with no child); generate: {frames: all} gives "
                               "every link and named frame"}


def test_small_robot_keeps_every_named_frame():
    robot = parse_models(tree(sensors=BIG_FRAMES - 1))["tree"]
    assert not robot.big and robot.selection == {}
    assert robot.function_frames == ("tcp",) + tuple(f"s{k}" for k in range(BIG_FRAMES - 1))


def test_frames_all_and_quantities_all_give_everything():
    robot = parse_models(tree(wrenches="    generate: {frames: all, quantities: all}\n"))["tree"]
    assert robot.function_frames == ("base", "a1", "a2", "b1", "c1", "c2", "tcp") + tuple(f"s{k}" for k in range(SENSORS))
    assert robot.function_quantities == FUNCTION_QUANTITIES
    assert robot.selection == {"frames": "generate.frames", "quantities": "generate.quantities, and what they call"}


def test_more_than_big_nv_velocities_leave_out_the_cubic_quantities():
    robot = parse_models(tree(sensors=0, chain=BIG_NV - 2))["tree"]  # nv = BIG_NV + 1
    assert robot.nv == BIG_NV + 1 and robot.big
    assert robot.function_frames == ("tcp", f"a{BIG_NV - 2}", "c1", "c2")
    assert robot.function_quantities == tuple(q for q in FUNCTION_QUANTITIES if q not in LEAN_LEFT_OUT)
    need = wanted(robot)
    assert [q for q in FUNCTION_QUANTITIES if not need(q)] == [q for q in FUNCTION_QUANTITIES if q in LEAN_LEFT_OUT]
    assert robot.selection["quantities"] == (
        f"default for more than {BIG_NV} velocities ({BIG_NV + 1}): all but coriolis_matrix, "
        "inverse_dynamics_derivatives, ode_rhs, ode_jac_x, ode_jac_u, rk4_step, regressor, base_regressor; "
        "generate: {quantities: all} gives them")
    again = parse_models(tree(sensors=0, chain=BIG_NV - 2, wrenches="    generate: {quantities: all}\n"))["tree"]
    assert all(wanted(again)(q) for q in FUNCTION_QUANTITIES)


def test_manifest_and_info_state_the_default(tmp_path, capsys):
    models = tmp_path / "models.yaml"
    models.write_text(tree().replace("  tree:\n", "  tree:\n    generate: {quantities: [fk]}\n"))
    assert main(["--models", str(models), "generate", "--out", str(tmp_path / "out")]) == 0
    manifest = json.loads((tmp_path / "out" / "tree" / "manifest.json").read_text())
    assert manifest["frames"] == ["tcp", "a2", "c1", "c2"]
    assert [f["name"] for f in manifest["functions"]] == ["tree_fk_tcp", "tree_fk_a2", "tree_fk_c1", "tree_fk_c2"]
    assert manifest["selection"] == {"frames": parse_models(tree())["tree"].selection["frames"],
                                     "quantities": "generate.quantities, and what they call"}
    capsys.readouterr()
    assert main(["--models", str(models), "info", "tree"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[2] == ("  per-frame functions for: tcp, a2, c1, c2 (default for a big robot (more than 8 named frames "
                        "(10)): the tcp, the wrench frames and the leaves of the tree (links with no child); generate: "
                        "{frames: all} gives every link and named frame; fk_all places every link)")


def big_urdf() -> str:
    """base -(j1)- a1 -(j2, mimics j1)- a2, base -(j3)- b1; SENSORS fixed sensor links on a1."""
    inertial = '<inertial><mass value="1"/><inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial>'
    links = "".join(f'<link name="{n}">{inertial}</link>' for n in ("a1", "a2", "b1"))
    joints = "".join(f'<joint name="{j}" type="revolute"><parent link="{p}"/><child link="{c}"/><origin xyz="0.2 0 0"/>'
                     f'<axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/>{extra}</joint>'
                     for j, p, c, extra in (("j1", "base", "a1", ""), ("j2", "a1", "a2", '<mimic joint="j1"/>'),
                                            ("j3", "base", "b1", "")))
    sensors = "".join(f'<link name="s{k}"/><joint name="f{k}" type="fixed"><parent link="a1"/><child link="s{k}"/></joint>'
                      for k in range(SENSORS))
    return f'<robot name="big"><link name="base"/>{links}{joints}{sensors}</robot>'


def test_import_of_a_big_robot_says_which_frames_in_one_line(tmp_path, capsys):
    urdf = tmp_path / "big.urdf"
    urdf.write_text(big_urdf())
    assert main(["import-urdf", str(urdf)]) == 0
    err = [line for line in capsys.readouterr().err.splitlines() if line.startswith("note:")]
    assert err == [f"note: {urdf}: robot 'big' is big (9 named frames, 4 links, nv = 2): by default `derive generate` "
                   "gives the per-frame functions (fk_<frame>, jacobian_<frame>, ...) to 2 frames (the tcp, wrench "
                   "frames and leaves: a2, b1; fk_all places every link); for more, add to its entry generate: "
                   "{frames: all} (or lists of frames and quantities)"]


def test_a_mimic_joint_leaves_the_import_command_alone(tmp_path):
    """The mimic check once reused the name of --chain: the entry's source said '--chain ('j2',)'."""
    urdf = tmp_path / "big.urdf"
    urdf.write_text(big_urdf())
    entry = import_urdf(urdf)
    assert entry["source"] == f"big.urdf, imported by `derive import-urdf {urdf}`"
    assert entry["description"] == "big imported from URDF"
    assert yaml.safe_load(yaml.safe_dump(entry))["joints"][1]["mimic"] == {"joint": "j1", "multiplier": 1.0, "offset": 0.0}
