"""Issue 24, the robot description: what the readers (models.yaml, URDF) accept, and mimic-joint friction.

- Numbers (items 6, 20, 26): every number of a model, from either reader, is 0 or has a magnitude in
  [FLT_MIN ~1.18e-38, 1e12] (derive.description.numbers). The models file refuses others in one line
  naming the file, robot and field; the URDF reader refuses huge and non-finite ones the same way and
  flushes nonzero ones below FLT_MIN to 0 with one warning line (rounding residue), drops position
  limits beyond 1e12 ("unbounded" placeholders) with a warning, and reads numbers as urdfdom does
  (C-locale decimals: no ``1_0``, no Arabic-Indic or full-width digits, no hex, no inf/nan). Axes are
  normalised robustly (bit-identical to v/|v| for ordinary vectors) and a zero axis is refused; a
  locked joint with a huge axis no longer loses its rotation. The smallest accepted mass and inertia
  build in single precision (-DDERIVE_FLOAT, STRICT).
- Mimic joints keep their own URDF damping and friction (G^T D G): the import writes them, the numeric
  reference models them on the full tree (independently of the symbolic code), the symbolic routes
  and the generated Python match it, and so does MuJoCo's own reading of the URDF.
- Data defects (impossible inertias, a massless link with inertia, a coordinate that moves no mass)
  are refused naming the file and the way forward (``--fix-inertia``, ``--lock J``); ``--fix-inertia``
  repairs them with one warning per link.
- ``import-urdf --out`` writes atomically: on a real full disk (a 64 KiB tmpfs in a private mount
  namespace) the models file stays byte-identical, the line names it, nothing is left beside it.
- Every file the readers read goes through derive.description.files' guards (FIFO, /dev/zero, size).
"""

from __future__ import annotations

import dataclasses
import json
import importlib.util
import math
import os
import re
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pytest
import yaml

from conftest import STRICT
from derive.cli import main
from derive.description.model import load_models, parse_models
from derive.description.numbers import AXIS_RATIO, unit_vector
from derive.description.urdf import import_urdf, import_urdf_named
from derive.reference import NumericRobot
from util import build_library

FLT_MIN = 2.0**-126


# --------------------------------------------------------------------------- helpers


def link(name: str, mass: str | None = "1.0", inertia: str = 'ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"',
         com: str = "0.1 0 0") -> str:
    if mass is None:
        return f'<link name="{name}"/>'
    return (f'<link name="{name}"><inertial><origin xyz="{com}"/><mass value="{mass}"/><inertia {inertia}/>'
            "</inertial></link>")


def joint(name: str, parent: str, child: str, kind: str = "revolute", axis: str = "0 0 1", xyz: str = "0 0 0.1",
          extra: str = "") -> str:
    limit = '<limit lower="-2" upper="2" effort="10" velocity="3"/>' if kind in ("revolute", "prismatic") else ""
    return (f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
            f'<origin xyz="{xyz}"/><axis xyz="{axis}"/>{limit}{extra}</joint>')


def urdf(*parts: str, name: str = "odd") -> str:
    return f'<?xml version="1.0"?>\n<robot name="{name}">\n' + "\n".join(parts) + "\n</robot>\n"


ARM = (link("base", None), link("l1"), link("l2", com="0 0.1 0"),
       joint("j1", "base", "l1"), joint("j2", "l1", "l2", axis="0 1 0", xyz="0.2 0 0"))


def write(folder: Path, text: str, name: str = "robot.urdf") -> Path:
    path = folder / name
    path.write_text(text)
    return path


def cli(capsys, *argv: str) -> tuple[int, str, str]:
    status = main(list(argv))
    out, err = capsys.readouterr()
    return status, out, err


def one_error(capsys, *argv: str, quiet: bool = True) -> str:
    """The command fails with exit 2 and exactly one stderr line ``derive: error: ...`` (and, if ``quiet``,
    nothing on stdout: generate prints its progress there)."""
    status, out, err = cli(capsys, *argv)
    assert status == 2 and (out == "" or not quiet) and err.count("\n") == 1 and err.startswith("derive: error: "), (
        status, out, err)
    return err.strip()


def listing(folder: Path) -> list[str]:
    return sorted(p.name for p in folder.iterdir())


ARM_YAML = """robots:
  arm:
    parameters: {{m: 1.0}}
    links:
      - {{name: base}}
      - {{name: l1, mass: {mass}, com: {com}, inertia: {inertia}}}
      - {{name: l2, mass: 0.5, com: [0.1, 0, 0], inertia: [0.01, 0.01, 0.01]}}
    joints:
      - {{name: j1, type: revolute, parent: base, child: l1, axis: {axis}, origin: {{xyz: {xyz}}}, limits: {limits}}}
      - {{name: j2, type: revolute, parent: l1, child: l2, axis: [0, 1, 0], origin: {{xyz: [0.2, 0, 0]}}{j2}}}
    gravity: {gravity}
    frames: [{{name: tcp, link: l2, xyz: [0.1, 0, 0]}}]
"""
ARM_FIELDS = dict(mass="1.0", com="[0.1, 0, 0]", inertia="[0.01, 0.01, 0.01]", axis="[0, 0, 1]", xyz="[0, 0, 0.1]",
                  limits="{lower: -2, upper: 2}", j2="", gravity="[0, 0, -9.81]")


def arm_yaml(**fields: str) -> str:
    return ARM_YAML.format(**(ARM_FIELDS | fields))


# --------------------------------------------------------------------------- 6. axes


@pytest.mark.parametrize("axis", ["1e200 0 0", "0 1e13 0"])
def test_a_huge_urdf_axis_is_refused_naming_file_joint_and_field(tmp_path, capsys, axis):
    path = write(tmp_path, urdf(*ARM[:3], joint("j1", "base", "l1", axis=axis), ARM[4]))
    for argv in (["import-urdf", str(path)], ["import-urdf", str(path), "--lock", "j1=0.5"]):
        line = one_error(capsys, *argv)
        assert f"{path}: robot 'odd': joints[j1].axis: <axis xyz=\"{axis}\">: " in line and "larger than 1e+12" in line


def test_a_huge_models_file_axis_is_refused_naming_file_robot_and_field(tmp_path, capsys):
    models = tmp_path / "m.yaml"
    models.write_text(arm_yaml(axis="[1e200, 0, 0]"))
    line = one_error(capsys, "--models", str(models), "info")
    assert line == (f"derive: error: {models}: robot 'arm': joints[0].axis[0]: 1e+200 is larger than 1e+12 in "
                    "magnitude: products of such numbers overflow in the dynamics")


def test_zero_axes_are_refused_in_both_readers(tmp_path, capsys):
    path = write(tmp_path, urdf(*ARM[:3], joint("j1", "base", "l1", axis="0 0 0"), ARM[4]))
    assert one_error(capsys, "import-urdf", str(path)) == (
        f"derive: error: {path}: robot 'odd': joints[j1].axis: must not be the zero vector")
    models = tmp_path / "m.yaml"
    models.write_text(arm_yaml(axis="[0, 0.0, -0]"))
    assert one_error(capsys, "--models", str(models), "info") == (
        f"derive: error: {models}: robot 'arm': joints[0].axis: must not be the zero vector")


def test_axes_are_normalised_robustly_and_ordinary_ones_bit_identically():
    # scaled by a power of two first: exactly v / |v| wherever |v|^2 neither overflows nor underflows
    rng = np.random.default_rng(0)
    for v in rng.normal(size=(2000, 3)) * 10.0 ** rng.integers(-30, 12, size=(2000, 1)):
        norm = math.sqrt(sum(a * a for a in v))
        assert unit_vector(v) == tuple(a / norm for a in v)
    assert unit_vector([1e200, 0.0, 0.0]) == (1.0, 0.0, 0.0)
    assert unit_vector([1e-300, 0.0, -1e-300]) == (math.sqrt(0.5), 0.0, -math.sqrt(0.5))
    assert unit_vector([0.0, 0.0, 1.0]) == (0.0, 0.0, 1.0) and unit_vector([0.0, -0.0, 0.0]) is None
    # in a models file: the smallest and largest accepted components give a unit axis
    for axis, want in (("[1e-30, 0, 1e-30]", (math.sqrt(0.5), 0.0, math.sqrt(0.5))), ("[3e11, 4e11, 0]", (0.6, 0.8, 0.0))):
        robot = parse_models(arm_yaml(axis=axis))["arm"]
        assert robot.joints[0].axis == pytest.approx(want, rel=1e-15, abs=0)


def test_a_lock_keeps_the_rotation_of_a_long_axis(tmp_path):
    """--lock J=0.5 on an axis 1e11 long turns by 0.5 rad about it, as on the unit axis."""
    long_axis, unit_axis = (write(tmp_path, urdf(*ARM[:3], joint("j1", "base", "l1", axis=a), ARM[4]), f"{n}.urdf")
                            for n, a in (("long", "0 0 1e11"), ("unit", "0 0 1")))
    poses = []
    for path in (long_axis, unit_axis):
        robot = parse_models("robots:\n  odd:\n" + textwrap.indent(yaml.safe_dump(
            import_urdf(path, lock="j1=0.5")), "    "))["odd"]
        poses.append(NumericRobot(robot).fk(np.zeros(robot.nq))["l2"])
    assert np.array_equal(poses[0], poses[1]) and abs(poses[0][0, 1] + math.sin(0.5)) < 1e-15


# --------------------------------------------------------------------------- 20. tiny numbers


@pytest.mark.parametrize("field, value, where", [
    ("mass", "1e-46", "links[1].mass"),
    ("inertia", "{ixx: 0.01, iyy: 0.01, izz: 0.01, ixy: -3e-40}", "links[1].inertia.ixy"),
    ("com", "[0.1, 1e-39, 0]", "links[1].com[1]"),
    ("xyz", "[0, 0, 1e-45]", "joints[0].origin.xyz[2]"),
    ("axis", "[1e-40, 0, 1]", "joints[0].axis[0]"),
    ("limits", "{lower: -2, upper: 2, velocity: 1e-300}", "joints[0].limits.velocity"),
    ("j2", ", mimic: {joint: j1, multiplier: 1e-39}", "joints[1].mimic.multiplier"),
    ("gravity", "[0, 0, -1e-40]", "gravity[2]"),
    ("mass", "'1e-40 * m'", "links[1].mass"),
])
def test_a_nonzero_number_below_flt_min_in_a_models_file_is_refused(tmp_path, capsys, field, value, where):
    models = tmp_path / "m.yaml"
    models.write_text(arm_yaml(**{field: value}))
    line = one_error(capsys, "--models", str(models), "info")
    assert line.startswith(f"derive: error: {models}: robot 'arm': {where}: ") and "1.18e-38" in line, line
    assert "smallest normal float" in line and "single precision" in line


@pytest.mark.parametrize("field, value, where, fragment", [
    ("limits", "{lower: -2, upper: 1e16}", "joints[0].limits.upper", "1e+16 is larger than 1e+12"),
    ("j2", ", mimic: {joint: j1, offset: 1e13}", "joints[1].mimic.offset", "1e+13 is larger than 1e+12"),
    ("j2", ", actuator: {viscous: 2.0e+12}", "joints[1].actuator.viscous", "2e+12 is larger than 1e+12"),
    ("j2", ", actuator: {viscous: 2e12}", "joints (j2).actuator.viscous", "'2e12' = 2e+12 is larger than 1e+12"),
    ("mass", "1" + "0" * 400, "links[1].mass", "an integer of 401 digits is larger than 1e+12"),
    ("mass", "'1e999'", "links[1] (l1).mass", "'1e999' evaluates to inf"),
    ("mass", "1" * 5000, None, "malformed YAML: Exceeds the limit (4300 digits) for integer string conversion"),
])
def test_a_huge_number_anywhere_in_a_models_file_is_refused(tmp_path, capsys, field, value, where, fragment):
    models = tmp_path / "m.yaml"
    models.write_text(arm_yaml(**{field: value}))
    line = one_error(capsys, "--models", str(models), "info")
    head = f"derive: error: {models}: robot 'arm': {where}: " if where else f"derive: error: models file {models}: "
    assert line.startswith(head) and fragment in line, line


def test_an_axis_component_below_2_to_the_minus_63_of_the_axis(tmp_path, capsys):
    """Its square would be no normal float: refused in a models file, read as 0 (with a warning) from a URDF."""
    models = tmp_path / "m.yaml"
    models.write_text(arm_yaml(axis="[1e-20, 0, 1]"))
    assert one_error(capsys, "--models", str(models), "info") == (
        f"derive: error: {models}: robot 'arm': joints[0].axis[0]: 1e-20 is not 0 but below 1.08e-19 of the axis's "
        "largest component (1): a turn of the axis by less than 1e-19 rad, whose square is no normal float (the "
        "generated code must build in single precision too); write 0")
    path = write(tmp_path, urdf(*ARM[:3], joint("j1", "base", "l1", axis="0 3e-12 -1e8"), ARM[4]))
    status, out, err = cli(capsys, "import-urdf", str(path))
    assert status == 0 and err == (f'warning: {path}: joints[j1].axis: <axis xyz="0 3e-12 -1e8">: 3e-12 is not 0 but '
                                   "below 1.08e-19 of the axis's largest component (1e+08): a turn of the axis by less "
                                   "than 1e-19 rad, whose square is no normal float (the generated code must build in "
                                   "single precision too): read as 0\n")
    assert parse_models("robots:\n" + out)["odd"].joints[0].axis == (0.0, 0.0, -1.0)


def test_tiny_urdf_numbers_are_flushed_to_zero_with_a_warning(tmp_path, capsys):
    """iCub writes rpy 5.77686e-66 and xyz -2.67276e-51: rounding residue, read as 0 (one warning each)."""
    parts = (link("base", None), link("l1", inertia='ixx="0.01" iyy="0.01" izz="0.01" ixy="1e-46" ixz="0" iyz="0"'),
             link("l2", com="0 0.1 -2.67276e-51"),
             joint("j1", "base", "l1"), joint("j2", "l1", "l2", axis="5.77686e-66 1 0", xyz="0.2 0 0"))
    path = write(tmp_path, urdf(*parts))
    status, out, err = cli(capsys, "import-urdf", str(path))
    assert status == 0
    warnings = err.splitlines()
    assert len(warnings) == 3 and all(w.startswith(f"warning: {path}: ") and "read as 0" in w for w in warnings), err
    assert 'links[l1].inertial.inertia.ixy: <inertia ixy="1e-46">: 1e-46 is below the smallest normal float' in warnings[0]
    assert "links[l2].inertial.origin.xyz" in warnings[1] and "joints[j2].axis" in warnings[2]
    robot = parse_models("robots:\n" + out)["odd"]
    assert robot.link("l1").inertia[0][1] == 0.0 and robot.link("l2").com == (0.0, 0.1, 0.0)
    assert robot.joints[1].axis == (0.0, 1.0, 0.0)


def test_urdf_limits_beyond_the_bound_are_placeholders(tmp_path, capsys):
    """iris writes lower="-1e+16" upper="1e+16" for an unbounded rotor: imported without position limits."""
    rotor = ('<joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>'
             '<limit effort="5" lower="-1e+16" upper="1e+16" velocity="3"/></joint>')
    path = write(tmp_path, urdf(link("base", None), link("l1"), rotor))
    status, out, err = cli(capsys, "import-urdf", str(path))
    assert status == 0 and err == (f"warning: {path}: joints[j1].limit: lower = -1e+16 = upper = 1e+16: beyond 1e+12, "
                                   "an exporter's placeholder for no limit: imported without lower and upper limit\n")
    assert parse_models("robots:\n" + out)["odd"].joints[0].limits.lower is None


def test_the_smallest_accepted_numbers_build_in_single_precision(tmp_path):
    """The issue's case (a link mass of 1e-46 broke the float build; now refused) one step inside the rule:
    FLT_MIN itself as a mass and as an inertia product, and an axis component 2^-63 of the axis (its square
    FLT_MIN), are accepted and the generated C compiles with -DDERIVE_FLOAT under STRICT (gcc: "floating
    constant truncated to zero" is an error there)."""
    from derive.codegen.generate import render

    text = arm_yaml(mass=repr(FLT_MIN), inertia=f"{{ixx: 0.01, iyy: 0.01, izz: 0.01, ixy: {FLT_MIN!r}}}")
    robot = parse_models(text.replace("axis: [0, 1, 0]", f"axis: [{AXIS_RATIO!r}, 1, 0]"))["arm"]
    assert robot.link("l1").mass == FLT_MIN == robot.link("l1").inertia[0][1]
    assert robot.joints[1].axis == (AXIS_RATIO, 1.0, 0.0)
    files = render(robot, "0" * 64, lambda _: None)
    for rel_path, content in files.items():
        (tmp_path / "gen" / rel_path).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / "gen" / rel_path).write_text(content)
    sources = sorted((tmp_path / "gen" / "c").glob("*.c"))
    # the tiny values do reach the code: FLT_MIN (the axis component squared) and FLT_MIN times the geometry
    # (below FLT_MIN: a double converted to DERIVE_REAL, see the printer's literal())
    code = "".join(s.read_text() for s in sources)
    assert f"DERIVE_LIT({FLT_MIN!r})" in code and re.search(r"\(\(DERIVE_REAL\)[0-9.]+e-39\)", code)
    build_library(["cc", *STRICT, "-O0", "-fPIC", "-DDERIVE_FLOAT"], sources, tmp_path / "libfloat.so")


def test_a_product_of_tiny_numbers_below_float_range_still_builds_in_single_precision(tmp_path):
    """Two accepted numbers can multiply to a constant below FLT_MIN (1e-30 kg at 1e-30 m: 1e-60): the C
    printer writes it as a double converted to DERIVE_REAL, which compiles under STRICT with -DDERIVE_FLOAT
    (a float literal would be "truncated to zero", an error there) and keeps its value in double."""
    from derive.codegen.generate import render

    text = arm_yaml(mass="1e-30").replace("com: [0.1, 0, 0]", "com: [1e-30, 0, 0]", 1)
    robot = parse_models(text)["arm"]
    files = render(robot, "0" * 64, lambda _: None)
    for rel_path, content in files.items():
        (tmp_path / "gen" / rel_path).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / "gen" / rel_path).write_text(content)
    sources = sorted((tmp_path / "gen" / "c").glob("*.c"))
    code = "".join(s.read_text() for s in sources)
    assert re.search(r"\(\(DERIVE_REAL\)[0-9.]+e-(?:[4-9][0-9]|[1-9][0-9]{2})\)", code)
    build_library(["cc", *STRICT, "-O0", "-fPIC", "-DDERIVE_FLOAT"], sources, tmp_path / "libfloat.so")
    build_library(["cc", *STRICT, "-O0", "-fPIC"], sources, tmp_path / "libdouble.so")


# --------------------------------------------------------------------------- 26. URDF numbers as urdfdom reads them


@pytest.mark.parametrize("text", ["1_0", "\u0661\u0660", "\uff11", "0x10", "inf", "nan", "-inf", "1e", "--1", "1,5",
                                  "1.5.", "\u00a01", "1d0", "+-1", "e3", ".", "1\u20282", "2&#133;"])
@pytest.mark.parametrize("element, attribute, where", [
    ("mass", "value", "links[l1].inertial.mass"),
    ("inertia", "ixx", "links[l1].inertial.inertia.ixx"),
    ("axis", "xyz", "joints[j1].axis"),
    ("limit", "lower", "joints[j1].limit.lower"),
])
def test_urdf_numbers_are_c_locale_decimals_only(tmp_path, capsys, text, element, attribute, where):
    parts = list(ARM)
    if element in ("mass", "inertia"):
        old = '<mass value="1.0"/>' if element == "mass" else 'ixx="0.01"'
        parts[1] = parts[1].replace(old, old.replace("1.0" if element == "mass" else "0.01", text))
    else:
        old = '<axis xyz="0 0 1"/>' if element == "axis" else 'lower="-2"'
        parts[3] = parts[3].replace(old, old.replace("0 0 1" if element == "axis" else "-2", f"0 0 {text}"
                                                     if element == "axis" else text))
    path = write(tmp_path, urdf(*parts))
    line = one_error(capsys, "import-urdf", str(path))
    read = text.replace("&#133;", "\x85")  # what the XML parser makes of the character reference
    escaped = read.replace("\u00a0", "\\xa0").replace("\u2028", "\\u2028").replace("\x85", "\\x85")
    shown = f"0 0 {escaped}" if element == "axis" else escaped
    assert line == (f"derive: error: {path}: robot 'odd': {where}: <{element} {attribute}=\"{shown}\">: '{escaped}' is "
                    "not a number (URDF numbers are decimals such as 0.25, -1.5e-3)"), line


def test_urdf_decimals_in_every_spelling_urdfdom_reads(tmp_path):
    spellings = {"+1.5": 1.5, ".5": 0.5, "5.": 5.0, "1E+2": 100.0, "-0": 0.0, "2.5e-3": 0.0025, "007": 7.0}
    for text, value in spellings.items():
        parts = list(ARM)
        if value:
            parts[1] = parts[1].replace('<mass value="1.0"/>', f'<mass value="{text}"/>')
        parts[3] = parts[3].replace('<origin xyz="0 0 0.1"/>', f'<origin xyz="  0\t{text}   0.1 "/>')
        entry = import_urdf(write(tmp_path, urdf(*parts)))
        assert entry["links"][1]["mass"] == (value or 1.0) and entry["joints"][0]["origin"]["xyz"] == [0.0, value, 0.1]


def test_names_that_hold_line_breaks_still_give_one_line(tmp_path, capsys):
    """A URDF name may carry &#10; or a line separator: errors and warnings show them escaped."""
    parts = (link("base", None), link("a&#10;b").replace('value="1.0"', 'value="x"'), link("l2"),
             joint("j&#8232;1", "base", "a&#10;b"), joint("j2", "a&#10;b", "l2"))
    path = write(tmp_path, urdf(*parts))
    assert one_error(capsys, "import-urdf", str(path)) == (
        f"derive: error: {path}: robot 'odd': links[a\\nb].inertial.mass: <mass value=\"x\">: 'x' is not a number "
        "(URDF numbers are decimals such as 0.25, -1.5e-3)")
    path = write(tmp_path, urdf(*parts).replace('value="x"', 'value="1.0"').replace('lower="-2"', 'lower="-1e+16"', 1))
    status, out, err = cli(capsys, "import-urdf", str(path))
    assert status == 0 and err.count("\n") == 1 and err.startswith(f"warning: {path}: joints[j\\u20281].limit: "), err


def test_lock_values_are_decimals_within_the_bounds(tmp_path, capsys):
    path = write(tmp_path, urdf(*ARM))
    for value, fragment in (("1_0", "the value '1_0' is not a number"), ("\u0661", "is not a number"),
                            ("1e300", "1e+300 is larger than 1e+12"), ("nan", "is not finite")):
        line = one_error(capsys, "import-urdf", str(path), "--lock", f"j1={value}")
        assert line.startswith(f"derive: error: {path}: robot 'odd': lock[j1]: ") and fragment in line, line


# --------------------------------------------------------------------------- mimic joints keep their damping


MIMIC_URDF = urdf(
    link("base", None),
    link("l1", mass="1.2", com="0.1 0.02 0", inertia='ixx="0.01" iyy="0.02" izz="0.025" ixy="0.001" ixz="0" iyz="0"'),
    link("l2", mass="0.5", com="0 0.1 0.03", inertia='ixx="0.004" iyy="0.005" izz="0.006" ixy="0" ixz="0.0005" iyz="0"'),
    link("l3", mass="0.3", com="0.05 0 0", inertia='ixx="0.001" iyy="0.002" izz="0.002" ixy="0" ixz="0" iyz="0"'),
    joint("j1", "base", "l1", axis="0 0 1", xyz="0 0 0.1", extra='<dynamics damping="0.3" friction="0.05"/>'),
    joint("j2", "l1", "l2", axis="0 0 1", xyz="0.2 0 0",
          extra='<mimic joint="j1" multiplier="-2" offset="0.1"/><dynamics damping="0.3" friction="0.02"/>'),
    joint("j3", "l2", "l3", kind="prismatic", axis="1 0 0", xyz="0.15 0 0", extra='<dynamics damping="0.7"/>'),
    name="mim")
A, B = -2.0, 0.1  # j2 = A j1 + B


@pytest.fixture(scope="module")
def mimic(tmp_path_factory):
    """The mimic robot imported from MIMIC_URDF, and the same tree with j2 an ordinary joint."""
    folder = tmp_path_factory.mktemp("mimic")
    path = write(folder, MIMIC_URDF, "mim.urdf")
    name, entry = import_urdf_named(path)
    robot = parse_models("robots:\n  mim:\n" + textwrap.indent(yaml.safe_dump(entry, sort_keys=False), "    "))[name]
    full = dataclasses.replace(robot, joints=tuple(dataclasses.replace(j, mimic=None) for j in robot.joints))
    return path, entry, robot, full


def test_a_mimic_joints_damping_and_friction_are_imported(mimic, tmp_path):
    path, entry, robot, _ = mimic
    j2 = next(j for j in entry["joints"] if j["name"] == "j2")
    assert j2["mimic"] == {"joint": "j1", "multiplier": A, "offset": B}
    assert j2["actuator"] == {"viscous": 0.3, "coulomb": 0.02}
    assert [(j.name, a.viscous, a.coulomb) for j, a in robot.mimic_actuators] == [("j2", 0.3, 0.02)]
    # --no-friction drops them, as the others'
    plain = import_urdf(path, friction=False)
    assert not any("actuator" in j for j in plain["joints"])


def test_the_reference_applies_a_mimic_joints_friction_through_g(mimic):
    """tau = G^T tau_full(G q + b, G v, G a) with every joint's own damping and friction on the full tree,
    i.e. the viscous term G^T D G qd (j1: 0.3 + (-2)^2 0.3) and Coulomb G^T f_c sign(G qd)."""
    _, _, robot, full = mimic
    ref, ref_full = NumericRobot(robot), NumericRobot(full)
    G = np.array([[1.0, 0.0], [A, 0.0], [0.0, 1.0]])
    b = np.array([0.0, B, 0.0])
    assert np.allclose(np.diag(G.T @ np.diag([0.3, 0.3, 0.7]) @ G), ref.viscous, rtol=0, atol=1e-15)
    assert ref.viscous[0] == 0.3 + 4 * 0.3 and ref.coulomb[0] == 0.05 + 2 * 0.02
    rng = np.random.default_rng(1)
    for _ in range(10):
        q, v, a = rng.uniform(-1, 1, 2), rng.normal(size=2), rng.normal(size=2)
        for smooth in (False, True):
            want = G.T @ ref_full.rnea(G @ q + b, G @ v, G @ a, smooth=smooth)
            assert np.allclose(ref.rnea(q, v, a, smooth=smooth), want, rtol=1e-13, atol=1e-13)
        fc = 0.05 * np.sign(v[0]) + A * 0.02 * np.sign(A * v[0])
        assert ref.friction(v)[0] == pytest.approx(1.5 * v[0] + fc, rel=1e-15)
        # forward dynamics inverts it (the smooth friction)
        tau = ref.rnea(q, v, a, smooth=True)
        assert np.allclose(ref.aba(q, v, tau), a, rtol=1e-10, atol=1e-10)


def test_the_symbolic_routes_and_the_generated_python_match_the_reference(mimic, tmp_path):
    import casadi as ca

    from derive.codegen.generate import render
    from derive.symbolic.model import SXModel
    from derive.symbolic.regressor import Regressor

    _, _, robot, _ = mimic
    ref, sx = NumericRobot(robot), SXModel(robot)
    s = sx.sym
    ne = sx.route("newton-euler")
    funcs = {"ne": ca.Function("ne", [s.q, s.qd, s.qdd], [ne.inverse_dynamics()]),
             "lagrange": ca.Function("la", [s.q, s.qd, s.qdd], [sx.inverse_dynamics("lagrange")])}
    fd = ca.Function("fd", [s.q, s.qd, s.tau], [sx.forward_dynamics()])
    reg = Regressor(ne)
    Y = ca.Function("Y", [s.q, s.qd, s.qdd], [reg.matrix])
    pi = reg.values()
    assert np.allclose(pi[-6:], ref.dynamic_parameters()[-6:], rtol=0, atol=1e-15)
    files = render(robot, "0" * 64, lambda _: None)
    # the manifest's actuator table states the follower's friction on its leader's entry: a^2 viscous, |a| coulomb
    table = json.loads(files["manifest.json"])["actuators"]
    assert table["viscous"] == pytest.approx([0.3 + A * A * 0.3, 0.7], rel=1e-15)
    assert table["coulomb"] == pytest.approx([0.05 + abs(A) * 0.02, 0.0], rel=1e-15)
    module_path = tmp_path / "mim.py"
    module_path.write_text(files["python/mim.py"])
    for rel_path, text in files.items():
        if rel_path.startswith("python/") and rel_path != "python/mim.py":
            (tmp_path / Path(rel_path).name).write_text(text)
    spec = importlib.util.spec_from_file_location("mim_generated", module_path)
    py = importlib.util.module_from_spec(spec)
    sys.path.insert(0, str(tmp_path))
    try:
        spec.loader.exec_module(py)
    finally:
        sys.path.remove(str(tmp_path))
    rng = np.random.default_rng(2)
    for _ in range(10):
        q, v, a = rng.uniform(-1, 1, 2), rng.normal(size=2), rng.normal(size=2)
        want = ref.rnea(q, v, a)
        for name, f in funcs.items():
            assert np.allclose(np.array(f(q, v, a)).ravel(), want, rtol=1e-12, atol=1e-12), name
        assert np.allclose(np.array(Y(q, v, a)) @ pi, want, rtol=1e-12, atol=1e-12)
        assert np.allclose(np.ravel(py.inverse_dynamics(q, v, a)), want, rtol=1e-12, atol=1e-12)
        tau = rng.normal(size=2)
        want = ref.aba(q, v, tau)
        assert np.allclose(np.array(fd(q, v, tau)).ravel(), want, rtol=1e-11, atol=1e-11)
        assert np.allclose(np.ravel(py.forward_dynamics(q, v, tau)), want, rtol=1e-11, atol=1e-11)


def test_an_armature_on_a_mimic_joint_adds_a_squared_to_its_leaders_diagonal(mimic):
    from derive.symbolic.model import SXModel
    import casadi as ca

    _, _, robot, _ = mimic
    joints = tuple(dataclasses.replace(j, actuator=dataclasses.replace(j.actuators[0], armature=0.02, motor_inertia=0.001,
                                                                     gear_ratio=3.0)) if j.name == "j2" else j
                   for j in robot.joints)
    geared, plain = dataclasses.replace(robot, joints=joints), robot
    q = np.array([0.3, -0.2])
    extra = NumericRobot(geared).crba(q) - NumericRobot(plain).crba(q)
    assert np.allclose(extra, np.diag([A * A * (0.02 + 9 * 0.001), 0.0]), rtol=0, atol=1e-15)
    sx = SXModel(geared)
    M = np.array(ca.Function("M", [sx.sym.q], [sx.route("newton-euler").mass_matrix])(q))
    assert np.allclose(M, NumericRobot(geared).crba(q), rtol=1e-13, atol=1e-15)


def test_mimic_damping_agrees_with_mujoco(mimic):
    """MuJoCo reads the same URDF (the mimic as an equality constraint j2 = -2 j1 + 0.1, every joint's own
    damping): its inverse dynamics reduced to our coordinates, G^T (M_full G qdd + bias_full - passive_full),
    equals ours; without the mimic joint's own damping it would miss by 4 * 0.3 qd on j1."""
    mujoco = pytest.importorskip("mujoco")
    path, _, robot, _ = mimic
    m = mujoco.MjModel.from_xml_path(str(path))
    d = mujoco.MjData(m)
    assert m.neq == 1 and list(m.dof_damping) == [0.3, 0.3, 0.7]
    ref = NumericRobot(robot)
    G = np.array([[1.0, 0.0], [A, 0.0], [0.0, 1.0]])
    b = np.array([0.0, B, 0.0])
    rng = np.random.default_rng(3)
    worst = 0.0
    for _ in range(10):
        q, v, a = rng.uniform(-1, 1, 2), rng.normal(size=2), rng.normal(size=2)
        d.qpos[:], d.qvel[:] = G @ q + b, G @ v
        mujoco.mj_forward(m, d)
        M = np.zeros((m.nv, m.nv))
        mujoco.mj_fullM(m, d, M)
        theirs = G.T @ (M @ (G @ a) + d.qfrc_bias - d.qfrc_passive)
        ours = ref.rnea(q, v, a) - ref.friction(v) + ref.viscous * v  # MuJoCo's URDF friction is a constraint
        worst = max(worst, float(np.abs(ours - theirs).max() / np.abs(theirs).max()))
    assert worst < 1e-12, worst


# --------------------------------------------------------------------------- data defects: the file and the way out


FETCH_FINGER = link("finger", mass="0.8", inertia='ixx="0.002" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"')
TORSO = link("torso_1", mass="0", inertia='ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"')


def test_an_impossible_inertia_names_the_file_and_fix_inertia_repairs_it(tmp_path, capsys):
    """Fetch's finger: ixx 0.002 and the other moments 0 (the triangle inequality fails)."""
    parts = (*ARM, FETCH_FINGER, joint("finger_joint", "l2", "finger", kind="prismatic", axis="0 1 0"))
    path = write(tmp_path, urdf(*parts))
    line = one_error(capsys, "import-urdf", str(path))
    assert line.startswith(f"derive: error: {path}: robot 'odd': links[3] (finger).inertia: breaks the triangle "
                           "inequality: 0 + 0 < 0.002") and "--fix-inertia" in line, line
    status, out, err = cli(capsys, "import-urdf", str(path), "--fix-inertia")
    assert status == 0 and err == (f"warning: {path}: links[finger].inertial.inertia: breaks the triangle inequality: "
                                   "0 + 0 < 0.002: replaced by the nearest physical inertia (ixx=0.002, ixy=0, ixz=0, "
                                   "iyy=0.001, iyz=0, izz=0.001) (--fix-inertia)\n")
    robot = parse_models("robots:\n" + out)["odd"]
    assert robot.link("finger").inertia == ((0.002, 0.0, 0.0), (0.0, 0.001, 0.0), (0.0, 0.0, 0.001))
    assert "--fix-inertia" in robot.source and "repaired the inertia of finger" in robot.description


def test_an_impossible_inertia_in_an_imported_models_entry_suggests_the_repairing_import(tmp_path, capsys):
    models = tmp_path / "m.yaml"
    models.write_text(arm_yaml(inertia="[0.002, 0, 0]").replace(
        "  arm:\n", "  arm:\n    source: 'f.urdf, imported by `derive import-urdf f.urdf --tip l2`'\n"))
    assert one_error(capsys, "--models", str(models), "info") == (
        f"derive: error: {models}: robot 'arm': links[1] (l1).inertia: breaks the triangle inequality: 0 + 0 < 0.002; "
        "re-import it with the inertia repaired: derive import-urdf f.urdf --tip l2 --fix-inertia")


def test_a_massless_link_with_inertia_names_the_file_and_fix_inertia_zeroes_it(tmp_path, capsys):
    """iCub's torso_1: no mass, but an inertia."""
    parts = (link("base", None), TORSO, link("l2"), joint("j1", "base", "torso_1"),
             joint("j2", "torso_1", "l2", axis="0 1 0", xyz="0.2 0 0"))
    path = write(tmp_path, urdf(*parts))
    line = one_error(capsys, "import-urdf", str(path))
    assert line == (f"derive: error: {path}: robot 'odd': links[torso_1].inertia: a massless link must have zero "
                    "inertia: give it a mass in the URDF, or import with --fix-inertia (sets a massless link's inertia "
                    "to zero, with a warning)")
    status, out, err = cli(capsys, "import-urdf", str(path), "--fix-inertia")
    assert status == 0 and err == (f"warning: {path}: links[torso_1].inertial.inertia: a massless link must have zero "
                                   "inertia: set to zero (--fix-inertia)\n")
    assert parse_models("robots:\n" + out)["odd"].link("torso_1").mass == 0.0


def test_a_coordinate_that_moves_no_mass_names_the_file_and_the_lock_that_imports(tmp_path, capsys):
    """A revolute joint spinning a point mass on its own axis: the import warns; generate --strict refuses naming the
    models file and the import command with --lock; that command imports a robot generate accepts."""
    point = link("spinner", inertia='ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"', com="0 0 0.05")
    parts = (*ARM, point, joint("spin", "l2", "spinner", axis="0 0 1", xyz="0 0.1 0"))
    path = write(tmp_path, urdf(*parts))
    models = tmp_path / "models.yaml"
    status, out, err = cli(capsys, "import-urdf", str(path), "--tip", "spinner", "--out", str(models))
    assert status == 0 and out == "" and err.splitlines()[0] == (
        f"warning: {path}: robot 'odd': joints (spin): coordinate 'spin' moves no mass or inertia: M(q) is singular, so "
        "`derive generate` leaves out forward dynamics and the ODE (--strict refuses the robot); give the links it moves "
        "a mass in the URDF, or lock "
        f"it: derive import-urdf {path} --tip spinner --lock spin")
    line = one_error(capsys, "--models", str(models), "generate", "--strict", "--out", str(tmp_path / "gen"), quiet=False)
    assert line == (f"derive: error: {models}: robot 'odd': joints (spin): coordinate 'spin' moves no mass or inertia, "
                    "so M(q) is singular and forward dynamics do not exist; give the links it moves a mass "
                    "(links[i].mass) or inertia about its axis, or import it with the joint locked: derive import-urdf "
                    f"{path} --tip spinner --lock spin")
    assert not (tmp_path / "gen").exists()
    fixed = tmp_path / "fixed.yaml"
    command = line.split("locked: derive ")[1].split()
    status, out, err = cli(capsys, *command, "--out", str(fixed))
    assert status == 0 and err == f"appended robot 'odd' to {fixed}\n", (command, err)
    from derive.codegen.checks import check_mass_matrix
    from derive.symbolic.model import SXModel
    check_mass_matrix(SXModel(load_models(fixed)["odd"]))


# --------------------------------------------------------------------------- 3. --out is written atomically


def can_unshare(*flags: str) -> str | None:
    try:
        r = subprocess.run(["unshare", *flags, "true"], capture_output=True, text=True, timeout=20)
    except (OSError, subprocess.SubprocessError) as exc:
        return f"no unshare ({exc})"
    return None if r.returncode == 0 else f"unshare {' '.join(flags)} is not permitted here: {r.stderr.strip()}"


FULL_DISK = textwrap.dedent("""\
    set -e
    mount -t tmpfs -o size=64k tmpfs "$HERE/disk"
    cp models.yaml "$HERE/disk/models.yaml"
    head -c 100000 /dev/zero > "$HERE/disk/filler" 2>/dev/null || true
    {python} -c "$IMPORTS"
    cp "$HERE/disk/models.yaml" "$HERE/after.yaml"
    ls -a "$HERE/disk" > "$HERE/listing.txt"
    """)
IMPORTS = textwrap.dedent("""\
    import contextlib, io, os
    from derive.cli import main
    here = os.environ["HERE"]
    for name in ("models.yaml", "new.yaml"):
        err = io.StringIO()
        with contextlib.redirect_stderr(err):
            status = main(["import-urdf", "robot.urdf", "--out", f"{here}/disk/{name}"])
        open(f"{here}/{name}.status", "w").write(f"{status}\\n" + err.getvalue())
    """)


def test_import_urdf_out_on_a_full_disk_leaves_the_models_file_byte_identical(tmp_path):
    """Both the append to an existing models file and a new one: exit 2, one line naming the file, the old
    file byte-identical, no temporary file left on the full disk."""
    reason = can_unshare("--mount", "--map-root-user") if os.getuid() else can_unshare("--mount")
    if reason:
        pytest.skip(reason)
    models_text = arm_yaml()
    (tmp_path / "models.yaml").write_text(models_text)
    write(tmp_path, urdf(*ARM))
    (tmp_path / "disk").mkdir()
    flags = ["--mount"] if os.getuid() == 0 else ["--mount", "--map-root-user"]
    r = subprocess.run(["unshare", *flags, "sh", "-c", FULL_DISK.format(python=sys.executable)], cwd=tmp_path,
                       env={**os.environ, "HERE": str(tmp_path), "IMPORTS": IMPORTS,
                            "PYTHONPATH": str(Path(__file__).parents[1])},
                       capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr
    for name in ("models.yaml", "new.yaml"):
        status, *lines = (tmp_path / f"{name}.status").read_text().splitlines()
        assert status == "2" and lines == [f"derive: error: {tmp_path}/disk/{name}: cannot write models file (No space "
                                           "left on device); it is left as it was"], (status, lines)
    assert (tmp_path / "after.yaml").read_text() == models_text
    assert sorted((tmp_path / "listing.txt").read_text().split()) == [".", "..", "filler", "models.yaml"]


def test_import_urdf_out_appends_and_creates_without_leaving_anything(tmp_path, capsys):
    path = write(tmp_path, urdf(*ARM))
    models = tmp_path / "models.yaml"
    models.write_text(arm_yaml())
    os.chmod(models, 0o640)
    assert cli(capsys, "import-urdf", str(path), "--out", str(models))[0] == 0
    assert list(load_models(models)) == ["arm", "odd"] and (models.stat().st_mode & 0o777) == 0o640
    assert cli(capsys, "import-urdf", str(path), "--out", str(tmp_path / "new.yaml"))[0] == 0
    assert list(load_models(tmp_path / "new.yaml")) == ["odd"]
    assert listing(tmp_path) == ["models.yaml", "new.yaml", "robot.urdf"]


# --------------------------------------------------------------------------- 8. every file read goes through the guards


def test_files_the_readers_read_are_guarded(tmp_path, capsys):
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    big = tmp_path / "big.urdf"
    with open(big, "wb") as f:  # sparse: 17 MiB, over the 16 MiB limit
        f.truncate(17 * 2**20)
    good = write(tmp_path, urdf(*ARM))
    cases = [
        (["import-urdf", str(fifo)], f"{fifo}: cannot read URDF: not a regular file"),
        (["import-urdf", "/dev/zero"], "/dev/zero: cannot read URDF: not a regular file"),
        (["import-urdf", str(big)], f"{big}: URDF is larger than 16 MiB"),
        (["import-urdf", str(tmp_path)], f"{tmp_path}: cannot read URDF: not a regular file"),
        (["import-urdf", str(good), "--out", str(fifo)], f"{fifo}: cannot read models file: not a regular file"),
        (["import-urdf", str(good), "--out", "/dev/zero"], "/dev/zero: cannot read models file: not a regular file"),
        (["import-urdf", str(good), "--out", str(tmp_path)], f"{tmp_path}: cannot read models file: not a regular file"),
        (["--models", str(fifo), "info"], f"{fifo}: cannot read models file: not a regular file"),
        (["import-urdf", ""], "empty path"),
        (["import-urdf", str(good), "--out", ""], "empty path"),
    ]
    for argv, fragment in cases:
        start = time.perf_counter()
        line = one_error(capsys, *argv)
        assert fragment in line and time.perf_counter() - start < 5, (argv, line)
    assert listing(tmp_path) == ["big.urdf", "fifo", "robot.urdf"]
