"""Bad model input: one line naming robot, field and problem; exit status 2; no traceback;
generated/ left as it was."""

from __future__ import annotations

import hashlib
import subprocess
import sys
from pathlib import Path

import pytest

from derive.cli import main

ROOT = Path(__file__).resolve().parent.parent

GOOD_LINK = "{name: l1, mass: 1.0, com: [0, 0, 0.1], inertia: [0.01, 0.01, 0.01]}"


def robot_yaml(links: str = f"[{{name: base}}, {GOOD_LINK}]",
               joints: str = "[{name: j1, type: revolute, parent: base, child: l1, axis: [0, 0, 1]}]",
               name: str = "arm") -> str:
    return f"robots:\n  {name}:\n    links: {links}\n    joints: {joints}\n"


CASES = {
    "malformed_yaml": ("robots:\n  arm:\n    links: [{name: base\n", ["models file", "malformed YAML", "line"]),
    "unknown_joint_type": (robot_yaml(joints="[{name: j1, type: rotary, parent: base, child: l1}]"),
                           ["robot 'arm'", "joints[0].type", "unknown joint type 'rotary'"]),
    "negative_mass": (robot_yaml(links="[{name: base}, {name: l1, mass: -1.0}]"),
                      ["robot 'arm'", "mass", "must be >= 0"]),
    "negative_mass_through_parameter": (
        "robots:\n  arm:\n    parameters: {m: -2.0}\n    links: [{name: base}, {name: l1, mass: m}]\n"
        "    joints: [{name: j1, type: revolute, parent: base, child: l1}]\n",
        ["robot 'arm'", "mass", "must be >= 0"]),
    "inertia_not_positive_definite": (
        robot_yaml(links="[{name: base}, {name: l1, mass: 1.0, inertia: [0.01, -0.02, 0.01]}]"),
        ["robot 'arm'", "inertia", "not positive semi-definite"]),
    "inertia_breaks_triangle_inequality": (
        robot_yaml(links="[{name: base}, {name: l1, mass: 1.0, inertia: [0.01, 0.01, 0.05]}]"),
        ["robot 'arm'", "inertia", "triangle inequality"]),
    "inertia_not_symmetric": (
        robot_yaml(links="[{name: base}, {name: l1, mass: 1.0, inertia: [[1, 0.1, 0], [0, 1, 0], [0, 0, 1]]}]"),
        ["robot 'arm'", "inertia", "not symmetric"]),
    "cycle": (robot_yaml(links=f"[{{name: base}}, {GOOD_LINK}, {{name: l2}}]",
                         joints="[{name: j1, type: revolute, parent: base, child: l1}, "
                                "{name: j2, type: revolute, parent: l1, child: l2}, "
                                "{name: j3, type: revolute, parent: l2, child: l1}]"),
              ["robot 'arm'", "joints[2].child", "already has parent joint"]),
    "pure_cycle_no_root": (robot_yaml(links="[{name: a}, {name: b}]",
                                      joints="[{name: j1, type: revolute, parent: a, child: b}, "
                                             "{name: j2, type: revolute, parent: b, child: a}]"),
                           ["robot 'arm'", "joints", "cycle"]),
    "missing_parent": (robot_yaml(joints="[{name: j1, type: revolute, parent: nowhere, child: l1}]"),
                       ["robot 'arm'", "joints[0].parent", "unknown link 'nowhere'"]),
    "duplicate_link_names": (robot_yaml(links=f"[{{name: base}}, {GOOD_LINK}, {GOOD_LINK}]"),
                             ["robot 'arm'", "links", "duplicate name 'l1'"]),
    "duplicate_joint_names": (robot_yaml(links=f"[{{name: base}}, {GOOD_LINK}, {{name: l2}}]",
                                         joints="[{name: j1, type: revolute, parent: base, child: l1}, "
                                                "{name: j1, type: revolute, parent: l1, child: l2}]"),
                              ["robot 'arm'", "joints", "duplicate name 'j1'"]),
    "link_name_not_c_identifier": (robot_yaml(links="[{name: base}, {name: 2nd-link, mass: 1.0}]",
                                              joints="[{name: j1, type: revolute, parent: base, child: 2nd-link}]"),
                                   ["robot 'arm'", "links[1].name", "not a C identifier"]),
    "robot_name_c_keyword": (robot_yaml(name="double"), ["robot 'double'", "name", "reserved word"]),
    "joint_name_with_space": (robot_yaml(joints="[{name: joint one, type: revolute, parent: base, child: l1}]"),
                              ["robot 'arm'", "joints[0].name", "not a C identifier"]),
    "unknown_field": (robot_yaml(links="[{name: base}, {name: l1, mas: 1.0}]"),
                      ["robot 'arm'", "links[1].mas", "unknown field"]),
    "bad_expression": (robot_yaml(links="[{name: base}, {name: l1, mass: '__import__(1)'}]"),
                       ["robot 'arm'", "mass"]),
    "unknown_parameter": (robot_yaml(links="[{name: base}, {name: l1, mass: m_unknown}]"),
                          ["robot 'arm'", "mass", "unknown parameter 'm_unknown'"]),
    "zero_axis": (robot_yaml(joints="[{name: j1, type: revolute, parent: base, child: l1, axis: [0, 0, 0]}]"),
                  ["robot 'arm'", "joints[0].axis", "zero vector"]),
    "no_moving_joint": (robot_yaml(joints="[{name: j1, type: fixed, parent: base, child: l1}]"),
                        ["robot 'arm'", "joints", "no moving joint"]),
    "no_robots": ("robots: {}\n", ["models file", "robots", "no robots"]),
    "limits_reversed": (robot_yaml(joints="[{name: j1, type: revolute, parent: base, child: l1, "
                                          "limits: {lower: 1.0, upper: -1.0}}]"),
                        ["robot 'arm'", "limits", "above upper"]),
    # whole robots: base, wrenches, mimic joints
    "unknown_base": (robot_yaml() + "    base: wobbly\n", ["robot 'arm'", "base", "expected one of fixed, floating"]),
    "wrenches_not_a_list": (robot_yaml() + "    wrenches: tcp\n", ["robot 'arm'", "wrenches", "a list of frame names"]),
    "wrench_frame_unknown": (robot_yaml() + "    wrenches: [l1, foot]\n",
                             ["robot 'arm'", "wrenches[1]", "unknown frame 'foot'"]),
    "wrench_frame_twice": (robot_yaml() + "    wrenches: [l1, l1]\n", ["robot 'arm'", "wrenches", "listed twice"]),
    "mimic_of_unknown_joint": (robot_yaml(
        links=f"[{{name: base}}, {GOOD_LINK}, {{name: l2, mass: 1.0}}]",
        joints="[{name: j1, type: revolute, parent: base, child: l1}, "
               "{name: j2, type: revolute, parent: l1, child: l2, mimic: {joint: j7}}]"),
        ["robot 'arm'", "joints (j2).mimic.joint", "unknown joint 'j7'"]),
    "mimic_of_itself": (robot_yaml(
        links=f"[{{name: base}}, {GOOD_LINK}, {{name: l2, mass: 1.0}}]",
        joints="[{name: j1, type: revolute, parent: base, child: l1}, "
               "{name: j2, type: revolute, parent: l1, child: l2, mimic: {joint: j2}}]"),
        ["robot 'arm'", "joints (j2).mimic.joint", "not itself"]),
    # a mimic of a mimic composes (tests/test_mimic_chain.py); a cycle of them reaches no coordinate
    "mimic_cycle": (robot_yaml(
        links=f"[{{name: base}}, {GOOD_LINK}, {{name: l2, mass: 1.0}}, {{name: l3, mass: 1.0}}]",
        joints="[{name: j1, type: revolute, parent: base, child: l1}, "
               "{name: j2, type: revolute, parent: l1, child: l2, mimic: {joint: j3}}, "
               "{name: j3, type: revolute, parent: l2, child: l3, mimic: {joint: j2}}]"),
        ["robot 'arm'", "joints (j2).mimic.joint", "the mimic joints 'j2', 'j3' follow each other in a cycle"]),
    "mimic_chain_to_unknown_joint": (robot_yaml(
        links=f"[{{name: base}}, {GOOD_LINK}, {{name: l2, mass: 1.0}}, {{name: l3, mass: 1.0}}]",
        joints="[{name: j1, type: revolute, parent: base, child: l1}, "
               "{name: j2, type: revolute, parent: l1, child: l2, mimic: {joint: j7}}, "
               "{name: j3, type: revolute, parent: l2, child: l3, mimic: {joint: j2}}]"),
        ["robot 'arm'", "joints (j2).mimic.joint", "unknown joint 'j7'"]),
    "mimic_on_a_spherical_joint": (robot_yaml(
        links=f"[{{name: base}}, {GOOD_LINK}, {{name: l2, mass: 1.0}}]",
        joints="[{name: j1, type: revolute, parent: base, child: l1}, "
               "{name: j2, type: spherical, parent: l1, child: l2, mimic: {joint: j1}}]"),
        ["robot 'arm'", "joints[1].mimic", "only a 1-DOF joint can mimic"]),
    "mimic_multiplier_not_a_number": (robot_yaml(
        links=f"[{{name: base}}, {GOOD_LINK}, {{name: l2, mass: 1.0}}]",
        joints="[{name: j1, type: revolute, parent: base, child: l1}, "
               "{name: j2, type: revolute, parent: l1, child: l2, mimic: {joint: j1, multiplier: lots}}]"),
        ["robot 'arm'", "joints[1].mimic.multiplier"]),
    "mimic_unknown_field": (robot_yaml(
        links=f"[{{name: base}}, {GOOD_LINK}, {{name: l2, mass: 1.0}}]",
        joints="[{name: j1, type: revolute, parent: base, child: l1}, "
               "{name: j2, type: revolute, parent: l1, child: l2, mimic: {joint: j1, gain: 2}}]"),
        ["robot 'arm'", "joints[1].mimic.gain", "unknown field"]),
    "floating_base_coordinate_clash": (robot_yaml(joints="[{name: base_qw, type: revolute, parent: base, child: l1}]")
                                       + "    base: floating\n",
                                       ["robot 'arm'", "joints (base_qw)", "coordinate of the floating base"]),
}


def tree_digest(folder: Path) -> str:
    h = hashlib.sha256()
    for p in sorted(folder.rglob("*")):
        if p.is_file():
            h.update(p.relative_to(folder).as_posix().encode())
            h.update(p.read_bytes())
    return h.hexdigest()


@pytest.fixture(scope="module")
def out_dir(tmp_path_factory):
    """A small generated/ to protect: one robot, generated with the good models.yaml."""
    out = tmp_path_factory.mktemp("gen") / "generated"
    assert main(["generate", "--robot", "pendulum", "--out", str(out)]) == 0
    return out


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_model_gives_one_line_and_leaves_generated_alone(case, tmp_path, out_dir, capsys):
    text, fragments = CASES[case]
    models = tmp_path / "models.yaml"
    models.write_text(text)
    before = tree_digest(out_dir)
    capsys.readouterr()
    status = main(["--models", str(models), "generate", "--out", str(out_dir)])
    err = capsys.readouterr().err
    assert status == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert "Traceback" not in err
    for fragment in fragments:
        assert fragment in lines[0], f"{fragment!r} not in {lines[0]!r}"
    assert tree_digest(out_dir) == before
    assert not [p for p in out_dir.parent.iterdir() if p.name.startswith(".generated")], "temporary folder left"


def test_cli_process_prints_no_traceback(tmp_path):
    models = tmp_path / "models.yaml"
    models.write_text(CASES["negative_mass"][0])
    run = subprocess.run([sys.executable, "-m", "derive", "--models", str(models), "generate", "--out",
                          str(tmp_path / "gen")], capture_output=True, text=True, cwd=ROOT)
    assert run.returncode == 2
    assert run.stderr.count("\n") == 1 and "Traceback" not in run.stderr
    assert not (tmp_path / "gen").exists()


def test_failure_during_generation_leaves_previous_output(tmp_path, out_dir, monkeypatch):
    """A crash part-way (after some robots were rendered) keeps the old generated/ intact."""
    import derive.codegen.generate as gen

    out = tmp_path / "generated"
    import shutil
    shutil.copytree(out_dir, out)
    before = tree_digest(out)
    calls = {"n": 0}
    real = gen.render

    def flaky(robot, mhash, log, *more):
        calls["n"] += 1
        if calls["n"] == 2:
            raise RuntimeError("disk full")
        return real(robot, mhash, log, *more)

    monkeypatch.setattr(gen, "render", flaky)
    from derive.description.model import load_models

    with pytest.raises(RuntimeError):
        gen.generate(load_models(), out, only=["cartpole", "planar_2r"], use_cache=False, log=lambda s: None)
    assert tree_digest(out) == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["generated"]
