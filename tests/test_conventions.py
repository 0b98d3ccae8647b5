"""One set of command-line conventions: vectors written 1,2,3 or 1 2 3 by every command, one CSV
schema from simulate to identify, --version and plain-text help, import --replace, eom's progress,
derive.generated(), simulate's joint-limit warnings and dissipated work, the first compiled build
saying so."""

from __future__ import annotations

import argparse
import csv
import re
from pathlib import Path

import numpy as np
import pytest

import derive
from derive.cli import build_parser, main
from derive.cli.analysis import parse_q
from derive.errors import DeriveError
from derive.reference import NumericRobot
from util import robots

ROOT = Path(__file__).resolve().parent.parent
GENERATED = ROOT / "generated"

# every vector option of every command: (argv before it, option, values, words that must follow the option)
VECTORS = [
    (["ik", "ur5"], "--xyz", [0.4, -0.1, 0.5], []),
    (["ik", "ur5", "--xyz", "0,0,1"], "--rpy", [3.0, 0.0, -1.5], []),
    (["ik", "ur5", "--xyz", "0,0,1"], "--q0", [0.0, -1.5, 1.0, 0.25, 2.0, -3.0], []),
    (["ik", "ur5", "--xyz", "0,0,1"], "--rest", [0.0, -1.5, 1.0, 0.25, 2.0, -3.0], []),
    (["ik", "ur5", "--xyz", "0,0,1"], "--weights", [1.0, 1.0, 1.0, 0.5, 0.5, 0.5], []),
    (["simulate", "planar_2r"], "--q0", [1.0, -0.5], []),
    (["simulate", "planar_2r", "--q0", "0,0"], "--qd0", [-1.0, 0.5], []),
    (["simulate", "planar_2r", "--q0", "0,0"], "--tau", [0.5, -2.0], []),
    (["trajopt", "planar_2r"], "--from", [-0.25, 1.0], []),
    (["trajopt", "planar_2r"], "--to", [1.0, -0.75], []),
    (["trajopt", "planar_2r"], "--torque-limit", [10.0, 5.0], []),
]


def spellings(values: list[float]) -> list[list[str]]:
    """The ways a user writes one vector: words, commas, both, quoted with blanks after the commas."""
    words = [repr(v) for v in values]
    return [words, [",".join(words)], [w + "," for w in words[:-1]] + words[-1:], [", ".join(words)]]


@pytest.mark.parametrize("before, option, values, after", VECTORS, ids=[f"{v[0][0]} {v[1]}" for v in VECTORS])
def test_every_vector_option_takes_commas_and_blanks(before, option, values, after):
    parser = build_parser()
    dest = {"--from": "start", "--to": "goal"}.get(option, option[2:].replace("-", "_"))
    for words in spellings(values):
        args = parser.parse_args([*before, option, *words, *after])
        assert getattr(args, dest) == values, words
    # one form joined by "=", and a leading negative value ("-0.25,1" is a value, not an option)
    args = parser.parse_args([*before, f"{option}={','.join(map(repr, values))}", *after])
    assert getattr(args, dest) == values


def test_pi_and_negative_values_are_numbers_everywhere():
    args = build_parser().parse_args(["ik", "ur5", "--xyz", "-1e-3", "-.5", "0", "--rpy", "-pi/2,0,pi"])
    assert args.xyz == [-1e-3, -0.5, 0.0] and args.rpy == [-np.pi / 2, 0.0, np.pi]
    robot = robots()["planar_2r"]  # the analysis commands' --q, --start, --goal: the same parser
    for text in (["-pi/2", "0.5"], ["-pi/2,0.5"], ["-pi/2, 0.5"], ["-pi/2,", "0.5"]):
        np.testing.assert_array_equal(parse_q(robot, text, "--start"), [-np.pi / 2, 0.5])


@pytest.mark.parametrize("argv, line", [
    (["ik", "pendulum", "--xyz", "0", "0"], "derive: error: ik: --xyz needs 3 values (X Y Z), got 2 "
                                             "(see `derive ik --help`)"),
    (["ik", "pendulum", "--xyz", "0,0,1", "--weights", "1,1"], "derive: error: ik: --weights needs 6 values, got 2 "
                                                               "(see `derive ik --help`)"),
    (["simulate", "pendulum", "--q0", "0.1,x"], "derive: error: simulate: --q0: 'x' is not a number (values "
                                                 "separated by commas or blanks; pi allowed: pi/2) (see `derive simulate --help`)"),
    (["trajopt", "planar_2r", "--from", "0,,1", "--to", "1,1"], "derive: error: trajopt: --from: an empty value in "
                                                                 "'0,,1' (values separated by commas or blanks) (see `derive trajopt --help`)"),
    (["plan", "planar_2r", "--start", "0", "zero", "--goal", "1,1"], "derive: error: robot 'planar_2r': --start: 'zero' "
                                                                     "is not a number (values separated by commas or blanks; pi allowed: pi/2)"),
    (["singularities", "planar_2r", "--q", "1,2,3"], "derive: error: robot 'planar_2r': --q '1,2,3': expected 2 values "
                                                     "(theta1, theta2), got 3"),
])
def test_a_bad_vector_is_one_line_naming_the_option(argv, line, capsys):
    assert main(argv) == 2
    assert capsys.readouterr().err.splitlines() == [line]


def test_version_and_help_are_plain_text(capsys):
    with pytest.raises(SystemExit) as stop:
        main(["--version"])
    assert stop.value.code == 0 and capsys.readouterr().out == f"derive {derive.__version__}\n"
    parser = build_parser()
    helps = {"derive": parser.format_help()}
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    helps.update({name: p.format_help() for name, p in sub.choices.items()})
    rst = re.compile(r"``|:(func|mod|class|meth|attr|data|ref|doc):`|`_\b")
    assert len(helps) == len(sub.choices) + 1 >= 20
    assert {name: rst.findall(text) for name, text in helps.items() if rst.search(text)} == {}
    assert helps["derive"].startswith("usage: derive [-h] [--models MODELS] [--version] COMMAND ...\n")
    assert "--xyz X Y Z" in helps["ik"] and "--q0 Q0..." in helps["simulate"]


def test_a_simulated_run_is_identified(tmp_path, capsys):
    """simulate's CSV is identify's input: noise-free, the base parameters come back to 1e-9."""
    out = tmp_path / "sim"
    assert main(["simulate", "cartpole", "--q0", "0", "2.5", "--tau", "5,0.2", "--t", "1", "--out", str(out),
                 "--generated", str(GENERATED)]) == 0
    run = capsys.readouterr()
    rows = list(csv.reader((out / "cartpole.csv").open()))
    assert rows[0] == ["t", "q_s", "q_theta", "qd_s", "qd_theta", "qdd_s", "qdd_theta", "tau_s", "tau_theta", "T", "U", "E"]
    assert len(rows) == 1002 and rows[1][7:9] == ["5.0", "0.2"] and rows[-1][7:9] == ["5.0", "0.2"]
    data = np.array(rows[1:], dtype=float)
    ref = NumericRobot(robots()["cartpole"])
    for k in (0, 500, 1000):  # qdd is the forward dynamics at the sample, tau what was integrated with
        np.testing.assert_allclose(data[k, 5:7], ref.aba(data[k, 1:3], data[k, 3:5], data[k, 7:9]), rtol=1e-9, atol=1e-9)
    # the cart is pushed past its limit (+-2 m): one warning line, for that joint only
    warnings = [line for line in run.err.splitlines() if line.startswith("warning:")]
    assert len(warnings) == 1 and re.fullmatch(r"warning: cartpole: s = 2\.00\d* at t = 0\.9\d* s is beyond its limit \+2 "
                                               r"\(the model's limits are not enforced by the dynamics\)", warnings[0])
    models = tmp_path / "identified.yaml"
    assert main(["identify", "cartpole", str(out / "cartpole.csv"), "--out", str(models)]) == 0
    table = capsys.readouterr().out.splitlines()
    head = table.index(next(line for line in table if line.split()[:2] == ["base", "parameter"]))
    found = {}
    for line in table[head + 1:]:
        parts = line.split()
        if len(parts) != 5:
            break
        found[parts[0]] = (float(parts[1]), float(parts[4]))
    assert set(found) == {"MR_cart", "mx_pole", "mz_pole", "YYR_pole", "fv_s", "fc_s", "fv_theta", "fc_theta"}
    for name, (identified, model) in found.items():
        assert abs(identified - model) < 1e-9, name
    assert derive.load_models(models)["cartpole_identified"].nv == 2


DAMPED = """robots:
  damped:
    links:
      - {name: world}
      - {name: bob, mass: 1.0, com: [0, 0, -0.5], inertia: [0.01, 0.01, 0.01]}
    joints:
      - {name: phi, type: revolute, parent: world, child: bob, axis: [0, 1, 0], limits: {lower: -1, upper: 1},
         actuator: {viscous: 0.2}}
"""


def test_friction_losses_are_dissipated_work_not_drift(tmp_path, capsys):
    models = tmp_path / "models.yaml"
    models.write_text(DAMPED)
    assert main(["--models", str(models), "simulate", "damped", "--q0", "0.8", "--t", "2", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    drift = float(re.search(r"max relative drift (\S+)", out).group(1))
    lost = float(re.search(r"dissipated by friction and damping: W_d = (\S+) J", out).group(1))
    data = np.loadtxt(tmp_path / "damped.csv", delimiter=",", skiprows=1)
    energy = data[:, -1]
    assert drift < 1e-10  # measured 7e-12: the integration's error alone (1.2 as "drift" before)
    assert lost == pytest.approx(energy[0] - energy[-1], rel=1e-5) and lost > 0.5  # what the energy lost (6 digits shown)
    assert "energy E + W_d" in out


URDF = """<robot name="arm"><link name="base"/>
<link name="l1"><inertial><mass value="{m}"/><origin xyz="0 0 0.2"/>
<inertia ixx="0.01" iyy="0.01" izz="0.001" ixy="0" ixz="0" iyz="0"/></inertial></link>
<joint name="j1" type="revolute"><parent link="base"/><child link="l1"/><axis xyz="0 0 1"/>
<limit lower="-1" upper="1" effort="10" velocity="1"/></joint></robot>"""

MINE = """# my robots
robots:
  # drawn by hand
  arm:
    links:
      - {name: base}
      - {name: l1, mass: 1.0, com: [0, 0, 0.2], inertia: [0.01, 0.01, 0.001]}
    joints:
      - {name: j1, type: revolute, parent: base, child: l1, axis: [0, 0, 1]}

  # another one, after a blank line
  other:
    links:
      - {name: base}
      - {name: l1, mass: 2.0, com: [0, 0, 0.2], inertia: [0.01, 0.01, 0.001]}
    joints:
      - {name: j1, type: revolute, parent: base, child: l1, axis: [0, 0, 1]}
"""


def test_import_replace_rewrites_the_entry_in_place(tmp_path, capsys):
    urdf, models = tmp_path / "arm.urdf", tmp_path / "models.yaml"
    models.write_text(MINE)
    urdf.write_text(URDF.format(m=3.0))
    assert main(["import-urdf", str(urdf), "--out", str(models)]) == 2
    assert capsys.readouterr().err.splitlines() == [f"derive: error: robot 'arm': {models} robots: already exists; pass "
                                                    "--replace to replace it in place, or pick another --name"]
    assert models.read_text() == MINE
    for mass in (3.0, 4.0):  # the first replaces the hand-written entry, the second the generated one
        urdf.write_text(URDF.format(m=mass))
        assert main(["import-urdf", str(urdf), "--out", str(models), "--replace"]) == 0
        assert capsys.readouterr().err.splitlines()[-1] == f"replaced robot 'arm' in {models}"
        text = models.read_text()
        loaded = derive.load_models(models)
        assert list(loaded) == ["arm", "other"] and float(loaded["arm"].links[1].mass) == mass
        assert text.startswith("# my robots\nrobots:\n  # drawn by hand\n  # arm: generated by `derive import-urdf`")
        assert text.endswith(MINE[MINE.index("\n  # another one"):])  # the rest byte for byte
        assert text.count("# arm: generated by") == 1


def test_eom_of_a_seven_joint_arm_takes_seconds_and_says_so(capsys):
    """More than 600 s before (sympy's cse with optimizations="basic"); 6 s for panda now. Timed here on
    the five-joint rrprr (0.6 s)."""
    assert main(["eom", "rrprr"]) == 0
    run = capsys.readouterr()
    err = run.err.splitlines()
    assert err[0] == "deriving rrprr (5 joints, newton-euler) ..."
    assert re.fullmatch(r"derived rrprr in \d+\.\d s \(`derive latex rrprr` writes it as a LaTeX document\)", err[1])
    assert run.out.startswith("# rrprr: ")


def test_generated_returns_the_module(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # no ./generated here: the checkout's
    m = derive.generated("planar_2r")
    assert Path(m.__file__) == GENERATED / "planar_2r" / "python" / "planar_2r.py"
    assert derive.generated("planar_2r", GENERATED) is m  # imported once
    q = np.array([0.3, -0.7])
    np.testing.assert_allclose(m.mass_matrix(q), NumericRobot(robots()["planar_2r"]).crba(q), rtol=1e-12)
    with pytest.raises(DeriveError, match=r"^robot 'nosuch': no generated Python at .*\(run `derive generate` first\)$"):
        derive.generated("nosuch", tmp_path)


def test_the_first_compiled_build_says_so_and_a_cache_hit_is_silent(tmp_path, monkeypatch, capfd):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.delenv("CC", raising=False)
    derive.compiled("pendulum", GENERATED)
    err = capfd.readouterr().err.splitlines()
    files = len(list((GENERATED / "pendulum" / "c").glob("*.c"))) + 1
    assert err[0] == f"derive: compiling pendulum ({files} C files, once; cached in {tmp_path / 'derive' / 'compiled'}) ..."
    assert re.fullmatch(r"derive: compiled pendulum in \d+\.\d s \(cached: later calls load it at once\)", err[1])
    assert len(err) == 2
    derive.compiled("pendulum", GENERATED)
    assert capfd.readouterr().err == ""


def test_a_command_line_builds_the_parser_of_its_command_alone():
    """COMMANDS names each command's module (the full parser's commands, no more); a command line that
    names one imports only that module, so a bad models file is refused before CasADi or sympy load."""
    import subprocess
    import sys

    from derive.cli import COMMANDS

    full = build_parser()
    sub = next(a for a in full._actions if isinstance(a, argparse._SubParsersAction))
    assert sorted(sub.choices) == sorted(COMMANDS)
    for command, module in COMMANDS.items():
        alone = build_parser([command])
        only = next(a for a in alone._actions if isinstance(a, argparse._SubParsersAction))
        assert command in only.choices and set(only.choices) <= {c for c, m in COMMANDS.items() if m == module}
    assert not next(a for a in build_parser(["--version"])._actions
                    if isinstance(a, argparse._SubParsersAction)).choices
    # the same parse either way: the arguments of one command line, full or alone
    argv = ["--models", "m.yaml", "ik", "ur5", "--xyz", "0,0,1", "--rpy", "-pi/2", "0", "pi"]
    assert vars(full.parse_args(argv)) == vars(build_parser(argv).parse_args(argv))
    code = ("import sys; from derive.cli import main; status = main(sys.argv[1:]); "
            "print(status, sorted(m for m in ('casadi', 'sympy', 'matplotlib', 'jinja2') if m in sys.modules))")
    bad = ROOT / "tests" / "data" / "no_such_models.yaml"
    out = subprocess.run([sys.executable, "-c", code, "--models", str(bad), "generate"], capture_output=True, text=True)
    assert out.stdout.split("\n")[0] == "2 []", out
    assert out.stderr.startswith("derive: error: ") and len(out.stderr.splitlines()) == 1
