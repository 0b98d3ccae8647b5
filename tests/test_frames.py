"""Frames (issue 25, item 6): a URDF tip keeps its own name as an alias of ``tcp``, usable in the
description, the symbolic model, the numeric reference, the CLI, the generated C, Python and JAX
and derive.compiled; one set of generated functions, the alias spelled as references to it."""

from __future__ import annotations

import json
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
import yaml

from derive.cli import main
from derive.description.model import parse_models
from derive.description.urdf import import_urdf
from derive.reference import NumericRobot
from derive.symbolic.model import SXModel

from util import load_module

# base -(shoulder)- upper -(elbow)- fore -(fixed)- tool_frame; upper is a moving link with no fixed child
ARM_URDF = """\
<robot name="arm">
  <link name="base"/>
  <link name="upper"><inertial><mass value="1.2"/><origin xyz="0.2 0 0"/>
    <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.02"/></inertial></link>
  <link name="fore"><inertial><mass value="0.7"/><origin xyz="0.15 0 0"/>
    <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
  <link name="tool_frame"/>
  <joint name="shoulder" type="revolute"><parent link="base"/><child link="upper"/>
    <axis xyz="0 1 0"/><limit lower="-2" upper="2" effort="40" velocity="3"/></joint>
  <joint name="elbow" type="revolute"><parent link="upper"/><child link="fore"/><origin xyz="0.4 0 0"/>
    <axis xyz="0 1 0"/><limit lower="-2.5" upper="2.5" effort="20" velocity="3"/></joint>
  <joint name="tool_joint" type="fixed"><parent link="fore"/><child link="tool_frame"/>
    <origin xyz="0.3 0 0.05" rpy="0 0.5 0"/></joint>
</robot>
"""
Q = np.array([0.3, -0.7])
ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def arm(tmp_path_factory):
    """(models file, robot, generated folder) of the arm imported with --tip tool_frame."""
    folder = tmp_path_factory.mktemp("frames")
    urdf = folder / "arm.urdf"
    urdf.write_text(ARM_URDF)
    entry = import_urdf(urdf, "tool_frame")
    models = folder / "models.yaml"
    models.write_text(yaml.safe_dump({"robots": {"arm": entry}}, sort_keys=False))
    robot = parse_models(models.read_text())["arm"]
    out = folder / "generated"
    assert main(["--models", str(models), "generate", "--out", str(out)]) == 0
    return models, robot, out


def test_urdf_tip_keeps_its_name_as_an_alias_of_tcp(arm):
    _, robot, _ = arm
    (tcp,) = robot.frames
    assert (tcp.name, tcp.link, tcp.aliases) == ("tcp", "fore", ("tool_frame",))
    assert robot.frame_aliases == {"tool_frame": "tcp"} and robot.frame_name("tool_frame") == "tcp"
    model = SXModel(robot)
    for quantity in (model.fk, model.jacobian):
        assert ca.SX(quantity("tool_frame") - quantity("tcp")).is_zero()  # the same expression, structurally
    ref = NumericRobot(robot)
    np.testing.assert_array_equal(ref.frame_pose(Q, "tool_frame"), ref.frame_pose(Q, "tcp"))
    np.testing.assert_array_equal(ref.jacobian(Q, "tool_frame"), ref.jacobian(Q, "tcp"))


def test_a_moving_tip_needs_no_alias(tmp_path):
    urdf = tmp_path / "arm.urdf"
    urdf.write_text(ARM_URDF)
    (tcp,) = [f for f in import_urdf(urdf, "fore")["frames"] if f["name"] == "tcp"]
    assert "aliases" not in tcp  # the link 'fore' is a frame of its own


def test_alias_is_one_set_of_functions_under_both_names(arm):
    _, robot, out = arm
    manifest = json.loads((out / "arm" / "manifest.json").read_text())
    assert manifest["aliases"] == {"tool_frame": "tcp"}
    names = [f["name"] for f in manifest["functions"]]
    assert not [n for n in names if "tool_frame" in n]  # no duplicated code
    header = (out / "arm" / "c" / "arm.h").read_text()
    tcp_functions = [n for n in names if n.endswith("_tcp")]
    assert len(tcp_functions) == 7  # fk, jacobian, jdot_qd, frame_acceleration, fk_jacobian, ik, manipulability
    for n in tcp_functions:
        assert f"#define {n[:-3]}tool_frame {n}\n" in header
    py = load_module(out / "arm" / "python" / "arm.py", "arm_frames_py")
    assert py.fk_tool_frame is py.fk_tcp and py.ik_tool_frame is py.ik_tcp
    T = py.fk_tool_frame(Q)
    np.testing.assert_allclose(T, NumericRobot(robot).frame_pose(Q, "tool_frame"), rtol=0, atol=1e-15)
    jax_text = (out / "arm" / "jax" / "arm.py").read_text()
    assert "fk_tool_frame = fk_tcp\n" in jax_text and "ik_tool_frame" not in jax_text  # no IK in JAX


def test_alias_in_compiled_c(arm):
    from derive.runtime import compiled
    _, robot, out = arm
    mod = compiled("arm", out)
    assert mod.fk_tool_frame is mod.fk_tcp and mod.jacobian_tool_frame is mod.jacobian_tcp
    np.testing.assert_allclose(mod.fk_tool_frame(Q), NumericRobot(robot).frame_pose(Q, "tcp"), rtol=0, atol=1e-15)


def test_alias_in_the_cli(arm, capsys):
    models, robot, _ = arm
    target = NumericRobot(robot).frame_pose(Q, "tcp")[:3, 3]
    assert main(["--models", str(models), "ik", "arm", "--xyz", *map(str, target), "--frame", "tool_frame"]) == 0
    assert "position target for frame 'tool_frame': solved" in capsys.readouterr().out


@pytest.mark.parametrize("aliases, problem", [
    ("[upper]", "frames: name 'upper' is used by both links and frames"),
    ("[tcp]", "frames: duplicate name 'tcp'"),
    ("[1tool]", "frames[0].aliases[0]: '1tool' is not a C identifier"),
    ("tool", "frames[0].aliases: expected a list of names"),
])
def test_bad_alias_is_one_line(arm, aliases, problem):
    models, _, _ = arm
    data = yaml.safe_load(models.read_text())
    data["robots"]["arm"]["frames"][0]["aliases"] = yaml.safe_load(aliases)
    with pytest.raises(Exception) as info:
        parse_models(yaml.safe_dump(data, sort_keys=False))
    assert problem in str(info.value)


def test_alias_in_wrenches_and_bundles_stands_for_its_frame(arm):
    models, _, _ = arm
    data = yaml.safe_load(models.read_text())
    data["robots"]["arm"]["wrenches"] = ["tool_frame"]
    data["robots"]["arm"]["bundles"] = [{"name": "tick", "quantities": ["fk_tool_frame", "jacobian_upper"]}]
    robot = parse_models(yaml.safe_dump(data))["arm"]
    assert robot.wrench_frames == ("tcp",)
    data["robots"]["arm"]["wrenches"] = ["tool_frame", "tcp"]
    with pytest.raises(Exception, match=r"wrenches: a frame is listed twice \(by its name and an alias\)"):
        parse_models(yaml.safe_dump(data))


# ---- fk_all: every link's pose in one pass, in C, Python and JAX

SHIPPED = ("pendulum", "planar_2r", "rrprr", "cartpole", "ur5", "panda")


def random_qs(robot, n=4, seed=7):
    rng = np.random.default_rng(seed)
    lo, hi = (np.clip(np.array(b), -3, 3) for b in robot.joint_box())
    return rng.uniform(lo, hi, size=(n, robot.nq))


@pytest.mark.parametrize("name", SHIPPED)
def test_fk_all_of_the_shipped_robots_matches_the_reference_and_pinocchio(name):
    from derive.description.model import load_models
    from derive.reference.pinocchio_model import PinRobot
    robot = load_models()[name]
    folder = ROOT / "generated" / name
    (entry,) = [f for f in json.loads((folder / "manifest.json").read_text())["functions"] if f["quantity"] == "fk_all"]
    links = robot.link_names
    assert entry["name"] == f"{name}_fk_all" and entry["links"] == list(links)
    assert entry["outputs"] == [{"name": "T", "shape": [4 * len(links), 4]}]
    mod = load_module(folder / "python" / f"{name}.py", f"frames_{name}")
    ref, pin = NumericRobot(robot), PinRobot(robot)
    Q = random_qs(robot)
    batch = mod.fk_all(Q).reshape(len(Q), len(links), 4, 4)
    for q, poses in zip(Q, batch):
        np.testing.assert_array_equal(poses, mod.fk_all(q).reshape(len(links), 4, 4))  # a batch: bit for bit
        expected = ref.fk(q)
        for link, T in zip(links, poses):
            np.testing.assert_allclose(T, expected[link], rtol=0, atol=1e-12, err_msg=link)
            np.testing.assert_allclose(T, pin.pose(q, link), rtol=0, atol=1e-12, err_msg=link)


def test_fk_all_in_compiled_c_and_jax(arm):
    from derive.runtime import compiled
    _, robot, out = arm
    ref = NumericRobot(robot)
    Q = random_qs(robot)
    c = compiled("arm", out).fk_all(Q).reshape(len(Q), 3, 4, 4)
    for q, poses in zip(Q, c):
        expected = ref.fk(q)
        for link, T in zip(robot.link_names, poses):
            np.testing.assert_allclose(T, expected[link], rtol=0, atol=1e-12, err_msg=link)
    jax = pytest.importorskip("jax", reason="the jax extra is not installed (pip install derive-robotics[jax])")
    module = load_module(out / "arm" / "jax" / "arm.py", "arm_frames_jax")
    with jax.enable_x64(True):  # in float64 whichever test module of this process turned it on or not
        got = np.asarray(module.fk_all(Q))
    np.testing.assert_allclose(got.reshape(c.shape), c, rtol=0, atol=1e-13)
    header = (out / "arm" / "c" / "arm_fk_all.h").read_text()
    assert "void arm_fk_all(const DERIVE_REAL *q, DERIVE_REAL *T);" in header.replace("DERIVE_FN ", "")


# ---- every link is a frame where asked: derive fk, and generate: {frames: [...]}


def test_derive_fk_prints_any_link_frame_or_alias(arm, capsys):
    models, robot, _ = arm
    assert main(["--models", str(models), "fk", "arm", "--q", "0.3", "-0.7", "--frame", "upper,tool_frame",
                 "--jacobian"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == "arm: world_T_frame at q = [0.3, -0.7] and J (6x2, [linear; angular], LOCAL_WORLD_ALIGNED)"
    assert lines[1] == "upper:" and lines[13] == "tool_frame (alias of tcp):" and lines[6] == lines[18] == "  J:"
    ref = NumericRobot(robot)
    for first, frame in ((2, "upper"), (14, "tcp")):
        T = np.array([[float(x) for x in line.split()] for line in lines[first:first + 4]])
        J = np.array([[float(x) for x in line.split()] for line in lines[first + 5:first + 11]])
        np.testing.assert_allclose(T, ref.frame_pose(Q, frame), rtol=0, atol=1e-11)
        np.testing.assert_allclose(J, ref.jacobian(Q, frame), rtol=0, atol=1e-11)
    assert main(["--models", str(models), "fk", "arm", "--frame", "elbow"]) == 2
    assert capsys.readouterr().err == ("derive: error: robot 'arm': no frame 'elbow' (links and frames: base, upper, "
                                       "fore, tcp, tool_frame)\n")


def test_generate_frames_gives_links_their_functions(arm, tmp_path):
    models, robot, _ = arm
    data = yaml.safe_load(models.read_text())
    data["robots"]["arm"]["generate"] = {"frames": ["tool_frame", "upper"]}  # an alias stands for its frame
    mine = tmp_path / "models.yaml"
    mine.write_text(yaml.safe_dump(data, sort_keys=False))
    out = tmp_path / "generated"
    assert main(["--models", str(mine), "generate", "--out", str(out)]) == 0
    manifest = json.loads((out / "arm" / "manifest.json").read_text())
    assert manifest["frames"] == ["tcp", "upper"]
    framed = [f["name"][4:] for f in manifest["functions"] if f["frame"] is not None and f["quantity"] != "bundle"]
    assert framed == ["fk_tcp", "jacobian_tcp", "jdot_qd_tcp", "frame_acceleration_tcp",
                      "fk_upper", "jacobian_upper", "jdot_qd_upper", "frame_acceleration_upper", "fk_jacobian_tcp",
                      "ik_tcp", "manipulability_tcp"]  # upper's origin never moves: no manipulability
    mod = load_module(out / "arm" / "python" / "arm.py", "arm_frames_links")
    ref = NumericRobot(robot)
    np.testing.assert_allclose(mod.fk_upper(Q), ref.frame_pose(Q, "upper"), rtol=0, atol=1e-15)
    np.testing.assert_allclose(mod.jacobian_upper(Q), ref.jacobian(Q, "upper"), rtol=0, atol=1e-15)
    assert mod.fk_tool_frame is mod.fk_tcp


@pytest.mark.parametrize("generate, problem", [
    ({"frames": ["elbow"]}, "generate.frames[0]: unknown frame 'elbow' (links and frames: base, upper, fore, tcp, tool_frame)"),
    ({"frames": ["tcp", "tool_frame"]}, "generate.frames[1]: 'tool_frame' is listed twice (by its name or an alias)"),
    ({"frames": "tcp"}, "generate.frames: expected a list of link or frame names"),
    ({"quantity": ["fk"]}, "generate.quantity"),  # a misspelt key
])
def test_bad_generate_is_one_line(arm, generate, problem):
    models, _, _ = arm
    data = yaml.safe_load(models.read_text())
    data["robots"]["arm"]["generate"] = generate
    with pytest.raises(Exception) as info:
        parse_models(yaml.safe_dump(data, sort_keys=False))
    assert problem in str(info.value)


def test_a_frame_called_all_is_refused(arm):
    models, _, _ = arm
    data = yaml.safe_load(models.read_text())
    data["robots"]["arm"]["frames"].append({"name": "all", "link": "upper"})
    with pytest.raises(Exception, match="frames: the frame name 'all' is reserved: fk_all is the pose of every link"):
        parse_models(yaml.safe_dump(data, sort_keys=False))


# ---- generate: {quantities: [...]}: a selection per robot; without it, every function


def test_generate_quantities_keeps_those_and_what_they_call(arm, tmp_path):
    from derive.description.robot import (CENTROIDAL_QUANTITIES, CLOSED_CHAIN_QUANTITIES, CONTACT_QUANTITIES,
                                          FUNCTION_QUANTITIES)
    models, robot, full = arm
    every = json.loads((full / "arm" / "manifest.json").read_text())["functions"]
    # the list is the catalogue's: a tree robot without contacts has all but the closed chains' and the contacts' own
    assert {f["quantity"] for f in every} == (set(FUNCTION_QUANTITIES) - set(CLOSED_CHAIN_QUANTITIES)
                                              - set(CONTACT_QUANTITIES) - set(CENTROIDAL_QUANTITIES))
    data = yaml.safe_load(models.read_text())
    data["robots"]["arm"]["generate"] = {"frames": ["upper", "tcp"], "quantities": ["fk_all", "jacobian", "ik", "rk4_step"]}
    mine = tmp_path / "models.yaml"
    mine.write_text(yaml.safe_dump(data, sort_keys=False))
    out = tmp_path / "generated"
    assert main(["--models", str(mine), "generate", "--out", str(out)]) == 0
    names = [f["name"][4:] for f in json.loads((out / "arm" / "manifest.json").read_text())["functions"]]
    assert names == ["jacobian_upper", "jacobian_tcp", "fk_jacobian_tcp", "fk_all", "ode_rhs", "rk4_step", "ik_tcp"]
    assert sorted(p.name for p in (out / "arm" / "c").glob("arm_*.c")) == sorted(f"arm_{n}.c" for n in names)
    mod = load_module(out / "arm" / "python" / "arm.py", "arm_frames_selected")
    assert mod.jacobian_tool_frame is mod.jacobian_tcp and not hasattr(mod, "fk_tool_frame")
    np.testing.assert_allclose(mod.jacobian_upper(Q), NumericRobot(robot).jacobian(Q, "upper"), rtol=0, atol=1e-15)
    assert "#define arm_ik_tool_frame arm_ik_tcp\n" in (out / "arm" / "c" / "arm.h").read_text()


@pytest.mark.parametrize("quantities, problem", [
    (["fk", "mass"], "generate.quantities[1]: unknown quantity 'mass' (one of fk, jacobian, "),
    (["fk", "fk"], "generate.quantities: a quantity is listed twice"),
    ([], "generate.quantities: expected a non-empty list of quantities"),
])
def test_bad_generate_quantities_is_one_line(arm, quantities, problem):
    models, _, _ = arm
    data = yaml.safe_load(models.read_text())
    data["robots"]["arm"]["generate"] = {"quantities": quantities}
    with pytest.raises(Exception) as info:
        parse_models(yaml.safe_dump(data, sort_keys=False))
    assert problem in str(info.value)


def test_double_pendulum_links_get_fk_and_jacobians_against_pinocchio(tmp_path, capsys):
    """example-robot-data's double_pendulum has no fixed child, hence no named frame: fk_all places both
    links, generate: {frames: [link1, link2]} gives them their functions; Pinocchio reads the URDF itself."""
    import pinocchio as pin  # a hard requirement, as in tests/test_urdf.py
    from derive.description.urdf import example_robot_data_dir
    urdf = "example-robot-data:double_pendulum_description/urdf/double_pendulum.urdf"
    entry = import_urdf(urdf)
    assert entry["frames"] == []
    entry["generate"] = {"frames": ["link1", "link2"], "quantities": ["fk", "jacobian", "fk_all"]}
    models = tmp_path / "models.yaml"
    models.write_text(yaml.safe_dump({"robots": {"double_pendulum": entry}}, sort_keys=False))
    out = tmp_path / "generated"
    assert main(["--models", str(models), "generate", "--out", str(out)]) == 0
    mod = load_module(out / "double_pendulum" / "python" / "double_pendulum.py", "frames_double_pendulum")
    model = pin.buildModelFromUrdf(str(example_robot_data_dir() / urdf.split(":", 1)[1]))
    data = model.createData()
    for q in random_qs(parse_models(models.read_text())["double_pendulum"]):
        pin.framesForwardKinematics(model, data, q)
        poses = mod.fk_all(q).reshape(3, 4, 4)
        for k, link in enumerate(("base_link", "link1", "link2")):
            fid = model.getFrameId(link, pin.BODY)
            np.testing.assert_allclose(poses[k], data.oMf[fid].homogeneous, rtol=0, atol=1e-12, err_msg=link)
            if link != "base_link":
                np.testing.assert_allclose(getattr(mod, f"fk_{link}")(q), poses[k], rtol=0, atol=1e-15)
                J = pin.computeFrameJacobian(model, data, q, fid, pin.LOCAL_WORLD_ALIGNED)
                np.testing.assert_allclose(getattr(mod, f"jacobian_{link}")(q), J, rtol=0, atol=1e-12, err_msg=link)


def test_a_selection_derives_only_what_it_keeps(arm, tmp_path, monkeypatch):
    """The costly derivations (dID/dx, the regressor and base parameters, the bundles) are not even
    started for a selection without them; templates bring what they call (catalogue.CALLS)."""
    from derive.codegen import catalogue

    def refuse(*args, **kwargs):
        raise AssertionError("derived although not selected")
    for name in ("inverse_dynamics_derivatives_spec", "regressor_specs", "bundle_specs"):
        monkeypatch.setattr(catalogue, name, refuse)
    models, _, _ = arm
    data = yaml.safe_load(models.read_text())
    data["robots"]["arm"]["generate"] = {"quantities": ["fk_all", "mass_matrix", "ik", "rk4_step", "manipulability",
                                                        "ode_jac_u"]}
    mine = tmp_path / "models.yaml"
    mine.write_text(yaml.safe_dump(data, sort_keys=False))
    out = tmp_path / "generated"
    assert main(["--models", str(mine), "generate", "--out", str(out)]) == 0
    names = [f["name"][4:] for f in json.loads((out / "arm" / "manifest.json").read_text())["functions"]]
    assert names == ["jacobian_tcp", "fk_jacobian_tcp", "fk_all", "mass_matrix", "ode_rhs", "ode_jac_u", "rk4_step",
                     "ik_tcp", "manipulability_tcp"]  # jacobian_tcp: manipulability_tcp calls it


def test_info_shows_aliases_and_the_selection(arm, tmp_path, capsys):
    models, _, _ = arm
    data = yaml.safe_load(models.read_text())
    data["robots"]["arm"]["generate"] = {"frames": ["tcp", "upper"], "quantities": ["fk"]}
    mine = tmp_path / "models.yaml"
    mine.write_text(yaml.safe_dump(data, sort_keys=False))
    assert main(["--models", str(mine), "info", "arm"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[1:4] == ["  frames: tcp (alias tool_frame)",
                          "  per-frame functions for: tcp, upper (generate.frames; fk_all places every link)",
                          "  generated quantities: fk (generate.quantities, and what they call)"]


def test_fk_all_of_a_floating_base_places_the_base_too(arm, tmp_path):
    models, _, _ = arm
    data = yaml.safe_load(models.read_text())
    data["robots"]["arm"]["base"] = "floating"
    data["robots"]["arm"]["links"][0] = {**data["robots"]["arm"]["links"][1], "name": "base", "mass": 3.0}  # a body
    data["robots"]["arm"]["generate"] = {"quantities": ["fk_all"]}
    mine = tmp_path / "models.yaml"
    mine.write_text(yaml.safe_dump(data, sort_keys=False))
    out = tmp_path / "generated"
    assert main(["--models", str(mine), "generate", "--out", str(out)]) == 0
    robot = parse_models(mine.read_text())["arm"]
    mod = load_module(out / "arm" / "python" / "arm.py", "arm_frames_floating")
    rng = np.random.default_rng(3)
    for _ in range(3):
        quat = rng.normal(size=4)
        q = np.concatenate([rng.normal(size=3), quat / np.linalg.norm(quat), rng.uniform(-2, 2, size=2)])
        expected = NumericRobot(robot).fk(q)
        for link, T in zip(robot.link_names, mod.fk_all(q).reshape(3, 4, 4)):
            np.testing.assert_allclose(T, expected[link], rtol=0, atol=1e-12, err_msg=link)


def test_c_alias_compiles_and_calls_the_same_function(arm, tmp_path):
    import shutil
    import subprocess
    cc = shutil.which("cc") or shutil.which("gcc")
    _, robot, out = arm
    c = out / "arm" / "c"
    main_c = tmp_path / "main.c"
    main_c.write_text('#include <stdio.h>\n#include "arm.h"\nint main(void) {\n'
                      '    const double q[2] = {0.3, -0.7};\n    double T[16];\n    arm_fk_tool_frame(q, T);\n'
                      '    for (int i = 0; i < 16; ++i) printf("%.17g\\n", T[i]);\n    return 0;\n}\n')
    exe = tmp_path / "alias"
    subprocess.run([cc, "-std=c99", "-Wall", "-Werror", f"-I{c}", str(main_c), str(c / "arm_fk_tcp.c"), "-lm", "-o",
                    str(exe)], check=True)
    T = np.array([float(x) for x in subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout.split()])
    np.testing.assert_allclose(T.reshape(4, 4), NumericRobot(robot).frame_pose(Q, "tool_frame"), rtol=0, atol=1e-15)
