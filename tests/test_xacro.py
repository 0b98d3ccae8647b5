"""xacro import (derive/description/xacro_expand.py): ``derive import-urdf robot.urdf.xacro``.

The fixture tests/fixtures/xacro/arm.urdf.xacro is a 3-joint arm as ROS packages write them: a macro
per segment, an arg (``upper_length``), and the macro's file included through ``$(find mypkg)``, with
mypkg given by ``--package-path``. Beside it, arm.urdf is the same robot written out by hand: the two
imports give the same models.yaml entry (to rounding: xacro computes the inertias, the URDF writes
them as decimals) and the same M(q), g(q) and inverse dynamics. Then every way it goes wrong is one
line ``derive: error: <file>: ...`` with exit status 2: no xacro package (``sys.modules['xacro'] =
None``), an unknown package, an undefined arg, a bad macro, an include that
is no regular file, --arg on a plain URDF.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from derive.cli import main
from derive.description.model import load_models, parse_robot
from derive.description.urdf import import_urdf, import_urdf_named
from derive.description.xacro_expand import XacroError
from derive.reference import NumericRobot

FIXTURES = Path(__file__).resolve().parent / "fixtures" / "xacro"
XACRO = FIXTURES / "arm.urdf.xacro"
PACKAGE = f"mypkg={FIXTURES / 'mypkg'}"


@pytest.fixture(scope="module")
def xacro():
    return pytest.importorskip("xacro", reason="the xacro extra is not installed (pip install derive-robotics[xacro])")


def close(a, b, path: str = "") -> None:
    """``a`` and ``b`` (entries) equal: same keys, names and order; numbers to 1e-15 relative."""
    if isinstance(a, dict):
        assert isinstance(b, dict) and list(a) == list(b), path
        for k in a:
            close(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, list):
        assert isinstance(b, list) and len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            close(x, y, f"{path}[{i}]")
    elif isinstance(a, float):
        assert isinstance(b, float) and abs(a - b) <= 1e-15 * max(abs(a), abs(b)), (path, a, b)
    else:
        assert a == b, path


def run(argv: list[str], capsys) -> tuple[int, str, str]:
    rc = main(argv)
    out, err = capsys.readouterr()
    return rc, out, err


def test_xacro_imports_in_one_command_and_equals_the_urdf(xacro, tmp_path, capsys):
    """One command: $(find mypkg) through --package-path, the arg through --arg; the entry equals the
    hand-written URDF's but for description and source, and the source records the whole command."""
    models = tmp_path / "models.yaml"
    rc, _, err = run(["import-urdf", str(XACRO), "--arg", "upper_length=0.35", "--package-path", PACKAGE,
                      "--tip", "tool", "--out", str(models)], capsys)
    assert (rc, err) == (0, f"appended robot 'xarm' to {models}\n")
    robot = load_models(models)["xarm"]
    entry = import_urdf(XACRO, "tool", xacro_args={"upper_length": "0.35"}, package_paths=[PACKAGE])
    plain = import_urdf(FIXTURES / "arm.urdf", "tool")
    assert entry["description"] == "xarm imported from xacro (tip tool)"
    assert entry["source"] == (f"arm.urdf.xacro, imported by `derive import-urdf {XACRO} --arg upper_length=0.35 "
                               f"--package-path {PACKAGE} --tip tool`")
    assert robot.source == entry["source"]
    close({k: v for k, v in entry.items() if k not in ("description", "source")},
          {k: v for k, v in plain.items() if k not in ("description", "source")})
    a, b = NumericRobot(robot), NumericRobot(parse_robot("xarm", plain))
    rng = np.random.default_rng(0)
    for _ in range(5):
        q, qd, qdd = (a.random_configuration(rng), rng.standard_normal(3), rng.standard_normal(3))
        for x, y in ((a.crba(q), b.crba(q)), (a.gravity(q), b.gravity(q)), (a.rnea(q, qd, qdd), b.rnea(q, qd, qdd)),
                     (a.frame_pose(q, "tcp"), b.frame_pose(q, "tcp"))):
            assert np.max(np.abs(x - y)) <= 1e-14 * max(1.0, np.max(np.abs(y)))


def test_xacro_arg_default_applies(xacro):
    """Without --arg the xacro default (upper_length 0.3) holds: the forearm's joint sits 0.3 up."""
    name, entry = import_urdf_named(XACRO, package_paths={"mypkg": FIXTURES / "mypkg"})
    assert name == "xarm"
    fore = next(j for j in entry["joints"] if j["name"] == "fore_joint")
    assert fore["origin"]["xyz"] == [0.0, 0.0, 0.3]
    assert entry["source"] == (f"arm.urdf.xacro, imported by `derive import-urdf {XACRO} "
                               f"--package-path mypkg={FIXTURES / 'mypkg'}`")


def test_xacro_hooks_are_restored(xacro):
    """The ROS lookups are answered for the expansion only: xacro's own functions are back after it."""
    from xacro import substitution_args

    def hooked():
        return (substitution_args._eval_find, substitution_args._eval_dict["find"], xacro.parse,
                xacro.abs_filename_spec, xacro.substitution_args_context, xacro.warning, xacro.print_location)

    before = hooked()
    import_urdf(XACRO, package_paths=[PACKAGE])
    with pytest.raises(XacroError):
        import_urdf(XACRO)  # fails inside the expansion: no mypkg
    assert hooked() == before


def _write(tmp_path: Path, name: str, body: str) -> str:
    path = tmp_path / name
    path.write_text(f'<?xml version="1.0"?>\n<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro">\n{body}\n'
                    "</robot>\n")
    return str(path)


SEGMENT = (f'<xacro:include filename="$(find mypkg)/urdf/segment.xacro"/><link name="b"/>'
           '<xacro:segment name="s" parent="b" at="0" length="{length}" mass="1" axis="1 0 0" rpy="0 0 0"/>')


@pytest.mark.parametrize("case", ["no-package-path", "unknown-package", "undefined-arg", "bad-macro-parameter",
                                  "bad-expression", "include-not-a-file", "include-missing", "malformed-xml",
                                  "arg-on-plain-urdf", "arg-malformed", "package-path-not-a-folder"])
def test_xacro_errors_are_one_line(xacro, case, tmp_path, capsys):
    pkg = ["--package-path", PACKAGE]
    if case == "no-package-path":
        argv, line = [str(XACRO)], (f"{XACRO}: xacro: $(find mypkg): unknown package 'mypkg': give its folder with "
                                    "--package-path mypkg=DIR")
    elif case == "unknown-package":
        argv, line = [str(XACRO), "--package-path", f"otherpkg={FIXTURES}"], \
            f"{XACRO}: xacro: $(find mypkg): unknown package 'mypkg': give its folder with --package-path mypkg=DIR"
    elif case == "undefined-arg":
        f = _write(tmp_path, "a.urdf.xacro", SEGMENT.format(length="$(arg len)"))
        argv, line = [f, *pkg], (f"{f}: xacro: undefined substitution argument 'len': give it with --arg len=VALUE "
                                 "(in macro 'segment')")
    elif case == "bad-macro-parameter":
        f = _write(tmp_path, "a.urdf.xacro", SEGMENT.format(length="1").replace('mass="1"', 'mas="1"'))
        argv, line = [f, *pkg], f"{f}: xacro: Invalid parameter \"mas\" (in macro 'segment')"
    elif case == "bad-expression":
        f = _write(tmp_path, "a.urdf.xacro", SEGMENT.format(length="${2*nosuch}"))
        argv, line = [f, *pkg], (f"{f}: xacro: name 'nosuch' is not defined; when evaluating expression '2*nosuch' "
                                 "(in macro 'segment')")
    elif case == "include-not-a-file":
        f = _write(tmp_path, "a.urdf.xacro", '<xacro:include filename="/dev/zero"/>')
        argv, line = [f], f"{f}: xacro: /dev/zero: cannot read it: not a regular file"
    elif case == "include-missing":
        f = _write(tmp_path, "a.urdf.xacro", '<xacro:include filename="nosuch.xacro"/>')
        argv, line = [f], f"{f}: xacro: {tmp_path}/nosuch.xacro: cannot read xacro include (No such file or directory)"
    elif case == "malformed-xml":
        f = _write(tmp_path, "a.urdf.xacro", "<link name='b'>")
        argv, line = [f], f"{f}: xacro: mismatched tag: line 4, column 2"
    elif case == "arg-on-plain-urdf":
        f = str(FIXTURES / "arm.urdf")
        argv, line = [f, "--arg", "a=1"], (f"{f}: --arg is for xacro files; this one is plain URDF (no .xacro "
                                           "name, no xacro element or substitution)")
    elif case == "arg-malformed":
        argv, line = [str(XACRO), "--arg", "upper_length"], f"{XACRO}: --arg 'upper_length': expected NAME=VALUE"
    else:
        argv, line = [str(XACRO), "--package-path", f"mypkg={tmp_path}/nosuch"], \
            f"{XACRO}: --package-path mypkg={tmp_path}/nosuch: not a folder"
    rc, out, err = run(["import-urdf", *argv], capsys)
    assert (rc, out, err) == (2, "", f"derive: error: {line}\n")


def test_unused_arg_is_named(xacro, capsys):
    """An --arg the file never declares or reads (a misspelling) is named in a warning; the import goes on."""
    rc, out, err = run(["import-urdf", str(XACRO), "--package-path", PACKAGE, "--arg", "uper_length=0.35"], capsys)
    assert rc == 0 and "  xarm:\n" in out
    assert err == f"warning: {XACRO}: --arg uper_length: the xacro file declares no such arg (ignored)\n"


def test_xacro_warnings_are_one_line(xacro, tmp_path, capsys):
    """xacro's own warnings (here: a property named like a global symbol) come as one line naming the file."""
    f = _write(tmp_path, "w.urdf.xacro", '<xacro:property name="pi" value="3.14"/><link name="b"/>'
               '<link name="c"><inertial><mass value="${pi}"/>'
               '<inertia ixx="0.1" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>'
               '<joint name="j" type="revolute"><parent link="b"/><child link="c"/><axis xyz="0 0 1"/></joint>')
    rc, out, err = run(["import-urdf", f], capsys)
    assert rc == 0 and "mass: 3.14\n" in out
    assert err == f"warning: {f}: xacro: redefining global symbol: pi\n"


def test_missing_extra_is_one_line(monkeypatch, tmp_path, capsys):
    """Without the xacro package (``sys.modules['xacro'] = None``: its import fails) a xacro file is one
    line naming the extra, not a misleading URDF error; a plain URDF that only declares the xacro
    namespace (as xacro's output often does: example-robot-data's ur5) still imports, as URDF."""
    monkeypatch.setitem(sys.modules, "xacro", None)
    rc, out, err = run(["import-urdf", str(XACRO), "--package-path", PACKAGE], capsys)
    assert (rc, out, err) == (2, "", f"derive: error: {XACRO}: this file is xacro; install the extra: "
                                     "pip install 'derive-robotics[xacro]'\n")
    declared = tmp_path / "arm.urdf"
    declared.write_text((FIXTURES / "arm.urdf").read_text().replace(
        '<robot name="xarm">', '<robot name="xarm" xmlns:xacro="http://www.ros.org/wiki/xacro">'))
    entry = import_urdf(declared, "tool")
    assert entry["description"] == "xarm imported from URDF (tip tool)"
    assert {k: v for k, v in entry.items() if k != "source"} == \
        {k: v for k, v in import_urdf(FIXTURES / "arm.urdf", "tool").items() if k != "source"}
