"""Contacts (models.yaml's ``contacts:``): one-line errors for bad ``contacts:`` and ``contact_sets:``; a
model without contacts keeps its hash."""

from __future__ import annotations

import pytest

from derive.description.model import load_models, parse_models
from derive.description.robot import Contact, ContactSet, ModelError, model_data


BIPED = """
robots:
  biped:
    base: floating
    links:
      - {name: pelvis, mass: 5.0, com: [0.01, 0.02, 0.03], inertia: [0.1, 0.2, 0.3]}
      - {name: l_hip, mass: 1.0, com: [0.0, 0.02, -0.1], inertia: [0.01, 0.02, 0.015]}
      - {name: l_thigh, mass: 1.5, com: [0.02, 0.0, -0.15], inertia: [0.02, 0.02, 0.01]}
      - {name: l_shin, mass: 0.8, com: [0.0, 0.01, -0.15], inertia: [0.01, 0.012, 0.005]}
      - {name: r_hip, mass: 1.0, com: [0.0, -0.02, -0.1], inertia: [0.01, 0.02, 0.015]}
      - {name: r_thigh, mass: 1.5, com: [0.02, 0.0, -0.15], inertia: [0.02, 0.02, 0.01]}
      - {name: r_shin, mass: 0.8, com: [0.0, -0.01, -0.15], inertia: [0.01, 0.012, 0.005]}
    joints:
      - {name: l_j1, type: revolute, parent: pelvis, child: l_hip, axis: [1, 0, 0], origin: {xyz: [0, 0.1, -0.05], rpy: [0.1, 0, 0]}}
      - {name: l_j2, type: revolute, parent: l_hip, child: l_thigh, axis: [0, 1, 0], origin: {xyz: [0, 0, -0.1]}}
      - {name: l_j3, type: revolute, parent: l_thigh, child: l_shin, axis: [0, 1, 0], origin: {xyz: [0, 0, -0.3], rpy: [0, 0.2, 0]}}
      - {name: r_j1, type: revolute, parent: pelvis, child: r_hip, axis: [1, 0, 0], origin: {xyz: [0, -0.1, -0.05], rpy: [-0.1, 0, 0]}}
      - {name: r_j2, type: revolute, parent: r_hip, child: r_thigh, axis: [0, 1, 0], origin: {xyz: [0, 0, -0.1]}}
      - {name: r_j3, type: revolute, parent: r_thigh, child: r_shin, axis: [0, 1, 0], origin: {xyz: [0, 0, -0.3], rpy: [0, -0.2, 0]}}
    frames:
      - {name: l_foot, link: l_shin, xyz: [0.02, 0, -0.3], rpy: [0.1, -0.2, 0.3], aliases: [left_sole]}
      - {name: r_foot, link: r_shin, xyz: [0.02, 0, -0.3]}
      - {name: l_toe, link: l_shin, xyz: [0.1, 0, -0.3]}
    contacts:
      - {frame: left_sole, kind: surface}
      - {frame: r_foot}
      - {frame: l_toe, kind: point}
    contact_sets:
      both: [l_foot, r_foot]
      redundant: [l_foot, l_toe]
"""


# ---------------------------------------------------------------------------------------------- description

def arm(extra: str) -> str:
    return ("robots:\n  arm:\n    links: [{name: base}, {name: l1, mass: 1.0}, {name: l2, mass: 1.0}, {name: l3, mass: 1.0}]\n"
            "    joints: [{name: j1, type: revolute, parent: base, child: l1, axis: [0, 0, 1]},\n"
            "             {name: j2, type: revolute, parent: l1, child: l2, axis: [0, 1, 0], origin: {xyz: [0, 0, 0.3]}},\n"
            "             {name: j3, type: revolute, parent: l2, child: l3, axis: [0, 1, 0], origin: {xyz: [0.3, 0, 0]}}]\n"
            "    frames: [{name: tip, link: l3, xyz: [0.2, 0, 0]}]\n" + extra)


BAD = {
    "not_a_list": ("    contacts: tip\n", "contacts", "expected a non-empty list of {frame, kind}"),
    "unknown_frame": ("    contacts: [{frame: toe}]\n", "contacts[0].frame", "unknown frame 'toe'"),
    "unknown_kind": ("    contacts: [{frame: tip, kind: line}]\n", "contacts[0].kind", "unknown contact kind 'line' (known: point, surface)"),
    "unknown_field": ("    contacts: [{frame: tip, mu: 0.7}]\n", "contacts[0].mu", "unknown field"),
    "no_frame": ("    contacts: [{kind: point}]\n", "contacts[0].frame", "missing"),
    "twice": ("    contacts: [{frame: tip}, {frame: tip, kind: surface}]\n", "contacts[1].frame", "listed twice"),
    "fixed_root": ("    contacts: [{frame: base}]\n", "contacts[0].frame", "is the fixed base"),
    "too_many_rows": ("    contacts: [{frame: tip, kind: surface}]\n", "contacts", "6 constraint rows for 3 velocities"),
    "set_not_a_contact": ("    contacts: [{frame: tip}]\n    contact_sets: {stance: [l2]}\n", "contact_sets.stance[0]",
                          "'l2' is not a contact (contacts: tip)"),
    "set_empty": ("    contacts: [{frame: tip}]\n    contact_sets: {stance: []}\n", "contact_sets.stance",
                  "non-empty list of contact frames"),
    "set_name": ("    contacts: [{frame: tip}]\n    contact_sets: {2legs: [tip]}\n", "contact_sets.2legs", ""),
    "sets_without_contacts": ("    contact_sets: {stance: [tip]}\n", "contacts", "missing: contact_sets name frames"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_contacts_give_one_line_naming_the_field(case):
    extra, field, problem = BAD[case]
    with pytest.raises(ModelError) as info:
        parse_models(arm(extra))
    message = str(info.value)
    assert "\n" not in message and "robot 'arm'" in message and f"{field}:" in message and problem in message, message


def test_contacts_parse_with_aliases_and_default_set():
    robot = parse_models(BIPED)["biped"]
    assert robot.contacts == (Contact("l_foot", "surface"), Contact("r_foot", "point"), Contact("l_toe", "point"))
    assert robot.stances == (ContactSet("both", ("l_foot", "r_foot")), ContactSet("redundant", ("l_foot", "l_toe")))
    one = parse_models(arm("    contacts: [{frame: tip}]\n"))["arm"]
    assert one.stances == (ContactSet("all", ("tip",)),) and one.centroidal
    plain = load_models()["ur5"]
    assert not plain.contacts and not plain.stances and "contacts" not in model_data(plain)  # the hash stays


def test_bad_contacts_from_the_command_line(tmp_path, capsys):
    from derive.cli import main
    models = tmp_path / "models.yaml"
    models.write_text(arm("    contacts: [{frame: tip, kind: line}]\n"))
    assert main(["--models", str(models), "generate", "--out", str(tmp_path / "out")]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("derive: error: ") and "contacts[0].kind" in lines[0], lines
    assert not (tmp_path / "out" / "arm").exists()
