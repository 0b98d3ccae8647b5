"""Bad command lines end with one line on stderr, exit status 2, no traceback, nothing written.

Every case runs ``derive.cli.main`` in an empty working folder (outputs that default to the
working folder, such as simulate_out/ and trajopt_out/, would land there) and, where the
command takes ``--out``/``--png``, points it into that folder too.
"""

from __future__ import annotations

import os

import pytest

from derive.cli import main
from derive.resources import EXAMPLE_MODELS

OUT = "{tmp}/out"  # replaced by a path inside the test's empty folder
SHIPPED = str(EXAMPLE_MODELS)

# (id, argv, fragment of the error line)
CASES = [
    # the command line itself (argparse): one line too
    ("unknown-command", ["nosuch"], "invalid choice: 'nosuch'"),
    ("argparse-non-numeric", ["simulate", "pendulum", "--q0", "abc"], "--q0: 'abc' is not a number"),
    ("argparse-wrong-count", ["ik", "pendulum", "--xyz", "0", "0"], "--xyz needs 3 values (X Y Z), got 2"),
    ("argparse-missing", ["plan", "planar_2r", "--start", "0", "0"], "required: --goal"),
    # info / eom / generate: models files
    ("info-unknown-robot", ["info", "nosuch"], "robot 'nosuch'"),
    ("info-missing-models", ["info", "--models", "{tmp}/nosuch.yaml"], "cannot read"),
    ("info-empty-models", ["info", "--models", "{tmp}/empty.yaml"], "must hold a mapping"),
    ("info-malformed-models", ["info", "--models", "{tmp}/bad.yaml"], "malformed YAML"),
    ("eom-unknown-robot", ["eom", "nosuch"], "no such robot"),
    ("generate-unknown-robot", ["generate", "--models", SHIPPED, "--robot", "nosuch", "--out", OUT], "no such robot"),
    ("generate-no-models-file", ["generate"], "no models.yaml in"),
    ("generate-prune-with-robot", ["generate", "--models", SHIPPED, "--robot", "pendulum", "--prune", "--out", OUT],
     "cannot be combined with --robot"),
    ("init-exists", ["init", "--out", "{tmp}/bad.yaml"], "exists already"),
    ("init-unknown-robot", ["init", "--robot", "nosuch"], "no shipped robot 'nosuch'"),
    ("generate-malformed-models", ["generate", "--models", "{tmp}/bad.yaml", "--out", OUT], "malformed YAML"),
    # import-urdf
    ("urdf-missing", ["import-urdf", "{tmp}/nosuch.urdf", "--tip", "b"], "cannot read URDF"),
    ("urdf-empty", ["import-urdf", "{tmp}/empty.urdf", "--tip", "b"], "malformed XML"),
    ("urdf-unknown-tip", ["import-urdf", "{tmp}/ok.urdf", "--tip", "nosuch"], "unknown link 'nosuch'"),
    ("urdf-lock-nan", ["import-urdf", "{tmp}/ok.urdf", "--tip", "b", "--lock", "j=nan"], "not finite"),
    ("urdf-lock-out-of-limits", ["import-urdf", "{tmp}/ok.urdf", "--tip", "b", "--lock", "j=5"], "outside the joint limits"),
    # dof
    ("dof-malformed-yaml", ["dof", "{tmp}/bad.yaml"], "line 2, column 1: malformed YAML"),
    ("dof-empty-file", ["dof", "{tmp}/empty.yaml"], "expected a mapping"),
    ("dof-missing-file", ["dof", "{tmp}/nosuch.yaml"], "no such file"),
    ("dof-unknown-robot", ["dof", "nosuch"], "no such robot"),
    # singularities
    ("sing-negative-starts", ["singularities", "planar_2r", "--starts", "-1"], "--starts must be at least 1, got -1"),
    ("sing-zero-starts", ["singularities", "planar_2r", "--starts", "0"], "--starts must be at least 1, got 0"),
    ("sing-overflow-q", ["singularities", "planar_2r", "--q", "1e400", "0"], "theta1 = inf is not a finite number"),
    ("sing-nan-q", ["singularities", "planar_2r", "--q", "nan", "0"], "theta1 = nan is not a finite number"),
    ("sing-wrong-count", ["singularities", "planar_2r", "--q", "1", "2", "3"], "expected 2 values"),
    ("sing-unknown-frame", ["singularities", "planar_2r", "--frame", "nosuch"], "no frame 'nosuch'"),
    ("sing-unknown-task", ["singularities", "planar_2r", "--task", "bogus"], "task 'bogus'"),
    # manipulability
    ("manip-overflow-q", ["manipulability", "planar_2r", "--q", "1e400", "0"], "is not a finite number"),
    ("manip-zero-poses", ["manipulability", "planar_2r", "--poses", "0"], "--poses must be at least 1"),
    ("manip-negative-poses", ["manipulability", "planar_2r", "--poses", "-3", "--png", OUT + ".png"], "--poses must be at least 1"),
    ("manip-unknown-robot", ["manipulability", "nosuch"], "no such robot"),
    # plan
    ("plan-zero-resolution", ["plan", "planar_2r", "--start", "0", "0", "--goal", "1", "1", "--resolution", "0",
                              "--png", OUT + ".png"], "--resolution must be at least 2"),
    ("plan-negative-margin", ["plan", "planar_2r", "--start", "0", "0", "--goal", "1", "1", "--margin", "-1"],
     "margin must be a finite number >= 0"),
    ("plan-nan-margin", ["plan", "planar_2r", "--start", "0", "0", "--goal", "1", "1", "--margin", "nan"],
     "margin must be a finite number >= 0"),
    ("plan-inf-obstacle", ["plan", "planar_2r", "--start", "0", "0", "--goal", "1", "1", "--obstacle", "circle:1e400,0,1"],
     "finite number"),
    ("plan-inf-start", ["plan", "planar_2r", "--start", "inf", "0", "--goal", "1", "1"], "theta1 = inf is not a finite number"),
    ("plan-outside-limits", ["plan", "planar_2r", "--start", "100", "0", "--goal", "1", "1"], "outside the joint box"),
    ("plan-unknown-frame", ["plan", "planar_2r", "--start", "0", "0", "--goal", "1", "1", "--frame", "nosuch"],
     "no frame 'nosuch'"),
    # simulate (default output folder simulate_out/ would be created in the working folder)
    ("sim-nan-q0", ["simulate", "pendulum", "--q0", "nan"], "q0 must be finite numbers"),
    ("sim-inf-tau", ["simulate", "pendulum", "--q0", "0.1", "--tau", "inf"], "tau must be finite numbers"),
    ("sim-wrong-count", ["simulate", "pendulum", "--q0", "0.1", "0.2"], "q0 needs 1 value"),
    ("sim-negative-length", ["simulate", "pendulum", "--q0", "0.1", "--param", "l=-1"], "--param l=-1: changes the sign"),
    ("sim-massless-inertia", ["simulate", "pendulum", "--q0", "0.1", "--param", "m_r=0"],
     "a massless body must have zero inertia (with --param m_r=0)"),
    ("sim-singular-mass-matrix", ["simulate", "pendulum", "--q0", "0.1", "--param", "m_r=0", "--param", "m_s=0",
                                  "--param", "I_r=0", "--param", "I_s=0"], "simulate needs forward dynamics, which do not exist: coordinate phi moves no mass or inertia"),
    ("sim-nan-param", ["simulate", "pendulum", "--q0", "0.1", "--param", "l=nan"], "must be a finite number"),
    ("sim-unknown-param", ["simulate", "pendulum", "--q0", "0.1", "--param", "nosuch=1"], "has no parameter(s) nosuch"),
    ("sim-malformed-param", ["simulate", "pendulum", "--q0", "0.1", "--param", "l"], "expects NAME=VALUE"),
    ("sim-negative-t", ["simulate", "pendulum", "--q0", "0.1", "--t", "-1"], "--t must be positive and finite"),
    ("sim-inf-t", ["simulate", "pendulum", "--q0", "0.1", "--t", "inf"], "--t must be positive and finite"),
    ("sim-zero-dt", ["simulate", "pendulum", "--q0", "0.1", "--dt", "0"], "--dt must be positive and finite"),
    ("sim-dt-over-t", ["simulate", "pendulum", "--q0", "0.1", "--t", "1", "--dt", "5"], "longer than --t"),
    ("sim-too-many-steps", ["simulate", "pendulum", "--q0", "0.1", "--t", "1e6", "--dt", "1e-6"], "steps"),
    ("sim-nan-rtol", ["simulate", "pendulum", "--q0", "0.1", "--method", "RK45", "--rtol", "nan"], "--rtol must be"),
    ("sim-zero-atol", ["simulate", "pendulum", "--q0", "0.1", "--method", "RK45", "--atol", "0"], "--atol must be"),
    ("sim-missing-generated", ["simulate", "pendulum", "--q0", "0.1", "--generated", "{tmp}/nonexistent"],
     "--generated {tmp}/nonexistent: no such folder"),
    ("sim-empty-generated", ["simulate", "pendulum", "--q0", "0.1", "--generated", "{tmp}"], "no generated code at"),
    ("sim-unknown-robot", ["simulate", "nosuch", "--q0", "0.1"], "no such robot"),
    # latex
    ("latex-unknown-robot", ["latex", "nosuch", "--out", OUT + ".tex"], "robot 'nosuch'"),
    ("latex-unknown-fk-frame", ["latex", "pendulum", "--fk", "nosuch", "--out", OUT + ".tex"], "no frame 'nosuch' (known: world, rod, sphere, tcp)"),
    ("latex-unknown-jacobian-frame", ["latex", "pendulum", "--jacobian", "nosuch"], "no frame 'nosuch'"),
    ("latex-zero-width", ["latex", "pendulum", "--width", "0"], "--width must be at least"),
    ("latex-pdf-without-out", ["latex", "pendulum", "--pdf"], "--pdf needs --out"),
    # ik
    ("ik-unknown-robot", ["ik", "nosuch", "--xyz", "0", "0", "0"], "no such robot"),
    ("ik-nan-target", ["ik", "pendulum", "--xyz", "nan", "0", "0"], "must be finite"),
    ("ik-unknown-frame", ["ik", "pendulum", "--xyz", "0", "0", "-0.5", "--frame", "nosuch"], "no frame 'nosuch'"),
    ("ik-wrong-q0", ["ik", "pendulum", "--xyz", "0", "0", "-0.5", "--q0", "1", "2"], "q0 must be 1 finite numbers"),
    ("ik-negative-timeout", ["ik", "pendulum", "--xyz", "0", "0", "-0.5", "--timeout", "-1"], "--timeout must be"),
    ("ik-nan-timeout", ["ik", "pendulum", "--xyz", "0", "0", "-0.5", "--timeout", "nan"], "--timeout must be"),
    ("ik-zero-weights", ["ik", "pendulum", "--xyz", "0", "0", "-0.5", "--weights", "0", "0", "0", "0", "0", "0"],
     "not all zero"),
    # workspace
    ("ws-zero-samples", ["workspace", "planar_2r", "--samples", "0", "--png", OUT + ".png"], "need at least 2"),
    ("ws-unknown-frame", ["workspace", "planar_2r", "--frame", "nosuch"], "no frame 'nosuch'"),
    # trajopt (default output folder trajopt_out/ would be created in the working folder)
    ("trajopt-unknown-robot", ["trajopt", "nosuch", "--swing-up"], "no robot 'nosuch'"),
    ("trajopt-nan-goal", ["trajopt", "planar_2r", "--from", "0,0", "--to", "nan,1"], "not a finite number"),
    ("trajopt-zero-intervals", ["trajopt", "planar_2r", "--from", "0,0", "--to", "1,1", "--intervals", "0"],
     "intervals must be an integer >= 2"),
    ("trajopt-negative-duration", ["trajopt", "planar_2r", "--from", "0,0", "--to", "1,1", "--duration", "-1"],
     "duration must be a finite number > 0"),
    ("trajopt-header-only-guess", ["trajopt", "planar_2r", "--from", "0,0", "--to", "1,1", "--guess", "{tmp}/header.csv"],
     "not a .npy array or a CSV of numbers"),
    ("trajopt-missing-guess", ["trajopt", "planar_2r", "--from", "0,0", "--to", "1,1", "--guess", "{tmp}/nosuch.csv"],
     "no such file"),
    # bench
    ("bench-unknown", ["bench", "nosuch", "--out", OUT + ".md"], "unknown benchmark 'nosuch'"),
]

FILES = {
    "bad.yaml": "a: [1, 2\n",
    "empty.yaml": "",
    "empty.urdf": "",
    "header.csv": "q_theta1,q_theta2\n",
    "ok.urdf": '<robot name="r"><link name="a"/><link name="b"/><joint name="j" type="revolute"><parent link="a"/>'
               '<child link="b"/><axis xyz="0 0 1"/><limit lower="-1" upper="1" effort="1" velocity="1"/></joint></robot>\n',
}


@pytest.mark.parametrize("argv, fragment", [pytest.param(a, f, id=i) for i, a, f in CASES])
def test_bad_input_is_one_line(argv, fragment, tmp_path, monkeypatch, capsys):
    inputs = tmp_path / "inputs"
    inputs.mkdir()
    for name, text in FILES.items():
        (inputs / name).write_text(text)
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    monkeypatch.delenv("DERIVE_MODELS", raising=False)
    fill = {"tmp": str(inputs)}
    argv = [a.replace(OUT, str(work / "out")).format(**fill) for a in argv]
    fragment = fragment.format(**fill)
    before = sorted(os.listdir(inputs))
    status = main(argv)
    err = capsys.readouterr().err
    assert status == 2, err
    assert "Traceback" not in err
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("derive: error: ")
    assert fragment in lines[0], lines[0]
    assert sorted(os.listdir(work)) == [], "a failed command wrote files"
    assert sorted(os.listdir(inputs)) == before


def test_eom_of_a_larger_robot_is_printed_with_common_subexpressions(capsys):
    from derive.cli import main

    assert main(["eom", "rrprr"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("# rrprr:") and "M(q) =" in out and "g(q) =" in out
    assert len(out) < 200_000  # written out in full it is about 25 MB


def test_import_urdf_can_start_a_new_models_file(tmp_path):
    from derive.cli import main
    from derive.description.model import load_models

    out = tmp_path / "mine.yaml"
    assert main(["import-urdf", "example-robot-data:ur_description/urdf/ur5_robot.urdf", "--tip", "tool0",
                 "--name", "myur", "--out", str(out)]) == 0
    robots = load_models(out)
    assert list(robots) == ["myur"] and robots["myur"].nv == 6
