"""Grübler's formula (lecture eq. 9-10): the lecture's Example 2, classic mechanisms, robots, CLI."""

from __future__ import annotations

from pathlib import Path

import pytest

from derive.cli import main
from derive.errors import DeriveError
from derive.analysis.grubler import grubler, load_mechanism, mechanism_from_robot, parse_mechanism
from util import robots, tree_robots

EXAMPLE2 = Path(__file__).resolve().parent.parent / "examples" / "grubler_example2.yaml"


def test_lecture_example2_has_three_dof():
    """7 links plus ground, 8 revolute (the three-link joint counted twice), 1 prismatic: eq. 10."""
    mech = load_mechanism(EXAMPLE2)
    assert (mech.m, mech.n_links, mech.n_joints) == (3, 8, 9)
    assert sum(j.count for j in mech.joints if j.type == "revolute") == 8
    assert sum(j.count for j in mech.joints if j.type == "prismatic") == 1
    assert mech.dof == 3 == 3 * (8 - 1 - 9) + 9


def test_formula_on_classic_mechanisms():
    four_bar = {"space": "planar", "links": 4,
                "joints": [{"type": "revolute", "links": [a, (a + 1) % 4]} for a in range(4)]}
    assert parse_mechanism(four_bar).dof == 1
    slider_crank = {"space": "planar", "links": 4, "joints": [
        {"type": "revolute", "links": [0, 1]}, {"type": "revolute", "links": [1, 2]},
        {"type": "revolute", "links": [2, 3]}, {"type": "prismatic", "links": [3, 0]}]}
    assert parse_mechanism(slider_crank).dof == 1
    # Stewart-Gough platform: 6 UPS legs, N = 14, J = 18 (6 U, 6 P, 6 S): 6 (14 - 1 - 18) + 36 = 6
    links = ["ground", "platform"] + [f"{s}{i}" for i in range(6) for s in ("lower", "upper")]
    joints = []
    for i in range(6):
        joints += [{"type": "universal", "links": ["ground", f"lower{i}"]},
                   {"type": "prismatic", "links": [f"lower{i}", f"upper{i}"]},
                   {"type": "spherical", "links": [f"upper{i}", "platform"]}]
    stewart = parse_mechanism({"space": "spatial", "links": links, "joints": joints})
    assert (stewart.n_links, stewart.n_joints, stewart.dof) == (14, 18, 6)
    # three links pinned at one joint (two joints' worth) and nothing else: 3 (3 - 1 - 2) + 2 = 2
    assert parse_mechanism({"space": "planar", "links": 3, "joints": [{"type": "revolute", "links": [0, 1, 2]}]}).dof == 2
    assert grubler(6, 2, [3]) == 3


@pytest.mark.parametrize("name", tree_robots())  # a closed chain: DOF = len(y), test_closed_chains.py
def test_robots_dof_equals_nv(name):
    """A tree has N - 1 = J, so the formula with m = 6 is the sum of joint freedoms."""
    robot = robots()[name]
    mech = mechanism_from_robot(robot)
    assert mech.m == 6 and mech.loops == 0
    assert mech.dof == robot.nv


@pytest.mark.parametrize("data, message", [
    ({"space": "curved", "links": 2, "joints": [{"type": "revolute", "links": [0, 1]}]}, "neither planar"),
    ({"space": "planar", "links": 2, "joints": [{"type": "spherical", "links": [0, 1]}]}, "does not move in a plane"),
    ({"space": "planar", "links": 2, "joints": [{"type": "hinge", "links": [0, 1]}]}, "unknown joint type 'hinge'"),
    ({"space": "planar", "links": 2, "joints": [{"type": "revolute", "links": [0, 7]}]}, "unknown link '7'"),
    ({"space": "planar", "links": 3, "joints": [{"type": "revolute", "links": [0, 1]}]}, "link '2' is not connected"),
    ({"space": "planar", "links": 2, "joints": [{"type": "revolute", "links": [1]}]}, "at least two links"),
    ({"space": "planar", "links": 2}, "joints: missing"),
])
def test_bad_mechanisms_are_explained(data, message):
    with pytest.raises(DeriveError, match=message):
        parse_mechanism(data)


def test_cli_dof_for_mechanism_file_and_robot(capsys, tmp_path):
    assert main(["dof", str(EXAMPLE2)]) == 0
    out = capsys.readouterr().out
    assert "DOF = m (N - 1 - J) + sum f_i = 3 (8 - 1 - 9) + 9 = 3" in out
    assert main(["dof", "pendulum"]) == 0
    assert "= 6 (3 - 1 - 2) + 1 = 1" in capsys.readouterr().out
    bad = tmp_path / "bad.yaml"
    bad.write_text("space: planar\nlinks: 2\njoints: [{type: revolute, links: [0, 3]}]\n")
    assert main(["dof", str(bad)]) == 2
    assert "unknown link '3'" in capsys.readouterr().err
    assert main(["dof", "no_such_robot"]) == 2
