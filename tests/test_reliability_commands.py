"""The analysis and solver commands never hurt (issue 24): sizes, option values, non-finite results,
atomic outputs, PNG names and temporary folders.

Every command runs in-process (``derive.cli.main``) in an empty working folder whose ``generated``
is a link to the checkout's generated/ (so simulate and trajopt find current code without
generating it), with ``tempfile`` pointed at a private folder that must be empty afterwards. A
refusal is exit status 2 and one line ``derive: error: ...`` that names the option, with nothing
written and no numpy RuntimeWarning; work that is accepted is checked for its numbers and files.
"""

from __future__ import annotations

import csv
import os
import signal
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import pytest
import yaml

import derive.analysis.workspace as workspace_module
import derive.cli.common as cli_common
import derive.solvers.simulate as simulate_module
import derive.solvers.trajopt as trajopt_module
from derive.analysis.manipulability import MAX_POSES, default_poses
from derive.analysis.singularity import MAX_STARTS, TaskJacobian, find_singularities
from derive.analysis.workspace import MAX_SAMPLES, Arm, sample_configurations, workspace
from derive.cli import main
from derive.errors import DeriveError
from derive.filesystem import TEMPORARIES
from derive.plot.figure import write_png
from derive.reference import NumericRobot
from derive.resources import EXAMPLE_MODELS
from derive.filesystem import write_chunks_atomically
from derive.solvers.simulate import simulate
from derive.solvers.trajopt import generated_forward_dynamics
from util import params, robots

ROOT = Path(__file__).resolve().parent.parent
PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
START_GOAL = ["--start", "0", "0", "--goal", "1", "1"]
FROM_TO = ["--from", "0,0", "--to", "1,1"]


@pytest.fixture(scope="module")
def models(tmp_path_factory) -> Path:
    """The shipped pendulum, planar_2r and rrprr alone (the same models, hence the same generated code):
    reading all six shipped robots costs most of a refused command's time."""
    data = yaml.load(EXAMPLE_MODELS.read_text(), Loader=yaml.SafeLoader)
    data["robots"] = {name: data["robots"][name] for name in ("pendulum", "planar_2r", "rrprr")}
    path = tmp_path_factory.mktemp("models") / "models.yaml"
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


@pytest.fixture(autouse=True)
def work(tmp_path, monkeypatch, models):
    """An empty working folder (plus the link to generated/) and a private temp folder, empty at the end."""
    folder = tmp_path / "work"
    folder.mkdir()
    (folder / "generated").symlink_to(ROOT / "generated")
    scratch = tmp_path / "tmp"
    scratch.mkdir()
    monkeypatch.chdir(folder)
    monkeypatch.setenv("DERIVE_MODELS", str(models))
    monkeypatch.setattr(tempfile, "tempdir", str(scratch))
    yield folder
    assert sorted(os.listdir(scratch)) == [], "a command left temporary files behind"


def written(folder: Path) -> list[str]:
    """Everything under ``folder`` except the link to generated/, as sorted relative paths."""
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.name != "generated")


def run(argv, capsys) -> tuple[int, str, str, list]:
    """main(argv) -> (status, stdout, stderr, RuntimeWarnings raised)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        status = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return status, out, err, [w for w in caught if issubclass(w.category, RuntimeWarning)]


def refused(argv, capsys, *fragments) -> str:
    """Run a command that must be refused: exit 2, one line naming the problem, no warning, nothing written."""
    folder = Path.cwd()
    before = written(folder)
    status, out, err, runtime_warnings = run(argv, capsys)
    assert status == 2, err
    lines = err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("derive: error: "), err
    for fragment in fragments:
        assert fragment in lines[0], lines[0]
    assert not runtime_warnings, [str(w.message) for w in runtime_warnings]
    assert written(folder) == before, "a refused command wrote files"
    return lines[0]


# ---- sizes: refused in one line naming the option and the limit (item 9) ----

SIZES = [
    ("workspace-samples", ["workspace", "planar_2r", "--samples", "1e9"], "--samples must be at most 10000000"),
    ("workspace-samples-int", ["workspace", "planar_2r", "--samples", "10000001"], "--samples must be at most 10000000"),
    ("manipulability-poses", ["manipulability", "planar_2r", "--poses", "1e9"], "--poses must be at most 1000"),
    ("singularities-starts", ["singularities", "planar_2r", "--starts", "1e9"], "--starts must be at most 10000"),
    ("plan-resolution", ["plan", "planar_2r", *START_GOAL, "--resolution", "1e6"], "--resolution 1000000",
     "more than 2000000; at most 1414 per joint"),
    ("trajopt-intervals", ["trajopt", "planar_2r", *FROM_TO, "--intervals", "1e9"], "--intervals must be at most 10000"),
    ("trajopt-substeps", ["trajopt", "planar_2r", *FROM_TO, "--substeps", "1e6"], "--substeps must be at most 10000"),
    ("trajopt-check-steps", ["trajopt", "planar_2r", *FROM_TO, "--substeps", "5000"],
     "intervals x substeps = 50 x 5000", "more than 200000"),
    ("trajopt-nlp-memory", ["trajopt", "planar_2r", *FROM_TO, "--intervals", "10000", "--method", "rk4"],
     "10000 intervals (rk4) would need about", "GiB for the NLP", "use at most"),
    ("simulate-steps", ["simulate", "pendulum", "--q0", "0.1", "--t", "1e5"], "= 1e+08 steps, more than 1e+07"),
    ("simulate-memory", ["simulate", "rrprr", "--q0", *["0"] * 5, "--t", "7000"], "7000001 samples of 5 joints",
     "would hold 1.4 GiB (more than the budget of 1 GiB)"),
    ("latex-width", ["latex", "pendulum", "--width", "1e9"], "--width must be at most 10000"),
]


@pytest.mark.parametrize("argv, fragments", [pytest.param(a, f, id=i) for i, a, *f in SIZES])
def test_absurd_sizes_are_refused_at_once(argv, fragments, capsys):
    start = time.perf_counter()
    refused(argv, capsys, *fragments)
    assert time.perf_counter() - start < 10, "refused only after the work"


def test_the_analysis_functions_refuse_absurd_sizes_too():
    robot = robots()["planar_2r"]
    with pytest.raises(DeriveError, match=f"more than {MAX_SAMPLES}"):
        workspace(robot, "tcp", MAX_SAMPLES + 1)
    with pytest.raises(DeriveError, match=f"1 .. {MAX_STARTS}"):
        find_singularities(TaskJacobian(robot), MAX_STARTS + 1)
    with pytest.raises(DeriveError, match=f"1 .. {MAX_POSES}"):
        default_poses(robot, MAX_POSES + 1)


def test_workspace_in_chunks_equals_all_at_once(monkeypatch):
    robot = robots()["planar_2r"]
    arm = Arm(robot)
    whole = workspace(robot, "tcp", 2000, "grid", arm=arm)
    monkeypatch.setattr(workspace_module, "CHUNK", 97)
    calls = []
    chunked = workspace(robot, "tcp", 2000, "grid", arm=arm, progress=lambda done, total: calls.append((done, total)))
    np.testing.assert_array_equal(chunked.q, whole.q)
    np.testing.assert_array_equal(chunked.points, whole.points)
    assert chunked.summary() == whole.summary() and chunked.count == 45 ** 2
    assert calls[0] == (97, 2025) and calls[-1] == (2025, 2025) and len(calls) == 21
    # random samples are the same stream in chunks as at once
    np.testing.assert_array_equal(workspace(robot, "tcp", 1000, "random", seed=4).q,
                                  sample_configurations(robot, 1000, "random", seed=4))


def test_a_large_workspace_keeps_a_subset_but_measures_every_sample(monkeypatch):
    """Beyond `keep` samples a seeded subset is kept (for the figure); extents and reach cover all of them."""
    robot = robots()["planar_2r"]
    monkeypatch.setattr(workspace_module, "CHUNK", 512)
    ws = workspace(robot, "tcp", 5000, "random", seed=3, keep=400)
    Q = sample_configurations(robot, 5000, "random", seed=3)
    P = Arm(robot).position(Q)
    assert ws.count == 5000 and ws.q.shape == (400, 2) and ws.points.shape == (400, 3)
    rows = {tuple(q) for q in Q}
    assert all(tuple(q) in rows for q in ws.q)  # kept samples are samples
    np.testing.assert_allclose(ws.points, Arm(robot).position(ws.q), atol=1e-15)
    np.testing.assert_array_equal(ws.lower, P.min(axis=0))
    np.testing.assert_array_equal(ws.upper, P.max(axis=0))
    r = np.linalg.norm(P, axis=1)
    assert ws.reach_range == (r.min(), r.max())
    assert ws.summary().startswith("planar_2r/tcp: 5000 configurations -> workspace (planar in xy)")


def test_long_work_shows_progress_on_stderr(monkeypatch, capsys):
    monkeypatch.setattr(cli_common, "PROGRESS_INTERVAL", 0.0)
    monkeypatch.setattr(workspace_module, "CHUNK", 1000)
    status, out, err, _ = run(["workspace", "planar_2r", "--samples", "3000", "--method", "random"], capsys)
    assert status == 0 and "3000 configurations -> workspace" in out
    assert err.splitlines() == [f"workspace planar_2r: {p} % ({k}000 of 3000 configurations)"
                                for k, p in ((1, 33), (2, 67), (3, 100))]


# ---- option values: nan, inf, negative, zero, absurd (item 13) and empty paths (item 25) ----

BAD_VALUES = [
    ("ik-rpy-nan", ["ik", "planar_2r", "--xyz", "1", "0", "0", "--rpy", "nan", "0", "0"], "--rpy must be a finite number"),
    ("ik-rpy-inf", ["ik", "planar_2r", "--xyz", "1", "0", "0", "--rpy", "0", "inf", "0"], "--rpy must be a finite number"),
    ("ik-rpy-huge", ["ik", "planar_2r", "--xyz", "1", "0", "0", "--rpy", "1e300", "0", "0"], "--rpy", "<= 1e+06"),
    ("ik-seed-negative", ["ik", "planar_2r", "--xyz", "1", "0", "0", "--seed", "-1"], "--seed must be an integer from 0"),
    ("ik-seed-huge", ["ik", "planar_2r", "--xyz", "1", "0", "0", "--seed", str(2**64)], "--seed must be an integer"),
    ("ik-seed-fraction", ["ik", "planar_2r", "--xyz", "1", "0", "0", "--seed", "1.5"],
     "argument --seed: expected an integer, got '1.5'"),
    ("ik-xyz-huge", ["ik", "planar_2r", "--xyz", "1e300", "0", "0"], "--xyz must be a finite number >= -1e+06"),
    ("ik-q0-nan", ["ik", "planar_2r", "--xyz", "1", "0", "0", "--q0", "nan", "0"], "--q0 must be a finite number"),
    ("ik-rest-huge", ["ik", "planar_2r", "--xyz", "1", "0", "0", "--rest", "0", "1e300"], "--rest must be a finite"),
    ("ik-weights-negative", ["ik", "planar_2r", "--xyz", "1", "0", "0", "--weights", "-1", "1", "1", "1", "1", "1"],
     "--weights must be a finite number >= 0"),
    ("ik-weights-huge", ["ik", "planar_2r", "--xyz", "1", "0", "0", "--weights", "1e300", "1", "1", "1", "1", "1"],
     "--weights must be a finite number >= 0 and <= 1e+06"),
    ("ik-timeout-zero", ["ik", "planar_2r", "--xyz", "1", "0", "0", "--timeout", "0"], "--timeout must be a finite"),
    ("ws-seed-negative", ["workspace", "planar_2r", "--method", "random", "--seed", "-1"], "--seed must be an integer"),
    ("ws-samples-fraction", ["workspace", "planar_2r", "--samples", "2.5"], "argument --samples: expected an integer"),
    ("ws-samples-nan", ["workspace", "planar_2r", "--samples", "nan"], "argument --samples: expected an integer"),
    ("sing-seed-negative", ["singularities", "planar_2r", "--seed", "-5"], "--seed must be an integer from 0"),
    ("plan-check-step-tiny", ["plan", "planar_2r", *START_GOAL, "--check-step", "1e-300"],
     "a check step of 1e-300 m would check every grid edge at", "choose a larger --check-step"),
    ("plan-check-step-negative", ["plan", "planar_2r", *START_GOAL, "--check-step", "-1"], "--check-step must be a finite"),
    ("plan-check-step-inf", ["plan", "planar_2r", *START_GOAL, "--check-step", "inf"], "--check-step must be a finite"),
    ("plan-margin-huge", ["plan", "planar_2r", *START_GOAL, "--margin", "1e300"],
     "--margin must be a finite number >= 0 and <= 1e+06 m"),
    ("plan-margin-inf", ["plan", "planar_2r", *START_GOAL, "--margin", "inf"], "--margin must be a finite number"),
    ("plan-obstacle-huge", ["plan", "planar_2r", *START_GOAL, "--obstacle", "circle:1e300,0,1"], "within 1e+06 m"),
    ("plan-resolution-one", ["plan", "planar_2r", *START_GOAL, "--resolution", "1"], "--resolution must be at least 2"),
    ("sim-t-nan", ["simulate", "pendulum", "--q0", "0.1", "--t", "nan"], "--t must be positive and finite"),
    ("sim-dt-inf", ["simulate", "pendulum", "--q0", "0.1", "--dt", "inf"], "--dt must be positive and finite"),
    ("sim-qd0-inf", ["simulate", "pendulum", "--q0", "0.1", "--qd0", "inf"], "qd0 must be finite numbers"),
    ("sim-rtol-negative", ["simulate", "pendulum", "--q0", "0.1", "--rtol", "-1"], "--rtol must be positive"),
    ("sim-param-inf", ["simulate", "pendulum", "--q0", "0.1", "--param", "l=inf"], "--param l=inf: must be a finite"),
    ("trajopt-duration-nan", ["trajopt", "planar_2r", *FROM_TO, "--duration", "nan"], "duration must be a finite number > 0"),
    ("trajopt-duration-huge", ["trajopt", "planar_2r", *FROM_TO, "--duration", "1e300"], "duration must be within 0.001 .. 100000 s"),
    ("trajopt-duration-tiny", ["trajopt", "planar_2r", *FROM_TO, "--duration", "1e-300"], "duration must be within"),
    ("trajopt-time-weight-inf", ["trajopt", "planar_2r", *FROM_TO, "--free-time", "--time-weight", "inf"],
     "time_weight must be a finite number >= 0"),
    ("trajopt-accel-weight-huge", ["trajopt", "planar_2r", *FROM_TO, "--accel-weight", "1e300"],
     "accel_weight must be at most 1e+06"),
    ("trajopt-torque-limit-nan", ["trajopt", "planar_2r", *FROM_TO, "--torque-limit", "nan"], "torque_limit must be"),
    ("trajopt-goal-huge", ["trajopt", "pendulum", "--from", "0", "--to", "1e300"], "--to phi = 1e+300 is beyond 1e+06"),
    ("trajopt-waypoint-nan", ["trajopt", "planar_2r", *FROM_TO, "--waypoint", "0.5:nan,0,0"], "a waypoint needs s in [0, 1]"),
    ("trajopt-waypoint-huge", ["trajopt", "planar_2r", *FROM_TO, "--waypoint", "0.5:1e300,0,0"], "within 1e+06 m"),
    ("trajopt-waypoint-late", ["trajopt", "planar_2r", *FROM_TO, "--waypoint", "2:0,0,0"], "a waypoint needs s in [0, 1]"),
    ("trajopt-intervals-fraction", ["trajopt", "planar_2r", *FROM_TO, "--intervals", "2.5"],
     "argument --intervals: expected an integer"),
    ("latex-width-small", ["latex", "pendulum", "--width", "5"], "--width must be at least 10"),
    # empty paths are not "not given" (item 25)
    ("sim-out-empty", ["simulate", "pendulum", "--q0", "0.1", "--out", ""], "argument --out: empty path"),
    ("sim-generated-empty", ["simulate", "pendulum", "--q0", "0.1", "--generated", " "], "argument --generated: empty path"),
    ("trajopt-out-empty", ["trajopt", "planar_2r", *FROM_TO, "--out", ""], "argument --out: empty path"),
    ("trajopt-guess-empty", ["trajopt", "planar_2r", *FROM_TO, "--guess", ""], "argument --guess: empty path"),
    ("latex-out-empty", ["latex", "pendulum", "--out", ""], "argument --out: empty path"),
]


@pytest.mark.parametrize("argv, fragments", [pytest.param(a, f, id=i) for i, a, *f in BAD_VALUES])
def test_bad_option_values_are_one_line(argv, fragments, capsys):
    refused(argv, capsys, *fragments)


def test_a_guess_that_is_not_a_regular_file_is_refused_at_once(work, capsys):
    os.mkfifo(work / "path.csv")
    start = time.perf_counter()
    refused(["trajopt", "planar_2r", *FROM_TO, "--guess", work / "path.csv", "--out", work / "out"], capsys,
            "path.csv: cannot read --guess path: not a regular file")
    assert time.perf_counter() - start < 10  # open() of a FIFO would have blocked


# ---- simulate: non-finite inputs or results stop cleanly, nothing written (items 14, 15) ----

@pytest.mark.parametrize("extra, fragments", [
    pytest.param(["--q0", "1e308"], ["the figure of the simulation", "too large to plot; nothing written"], id="q0-1e308"),
    pytest.param(["--q0", "0.1", "--tau", "1e300"], ["kinetic energy is no longer a finite number at t = 0.001 s",
                                                     "nothing written"], id="tau-1e300"),
    pytest.param(["--q0", "0.1", "--qd0", "1e200"], ["no longer a finite number", "nothing written"], id="qd0-1e200"),
])
def test_simulate_stops_cleanly_on_values_it_cannot_represent(extra, fragments, work, capsys):
    out = work / "sim"
    out.mkdir()
    old = {"pendulum.csv": b"old csv\n", "pendulum.png": b"old png"}
    for name, data in old.items():
        (out / name).write_bytes(data)
    argv = ["simulate", "pendulum", *extra, "--t", "0.05", "--out", out]
    status, stdout, err, runtime_warnings = run(argv, capsys)
    assert status == 2 and err.count("\n") == 1 and err.startswith("derive: error: robot 'pendulum': "), err
    assert all(f in err for f in fragments), err
    assert not runtime_warnings, [str(w.message) for w in runtime_warnings]
    assert {p.name: p.read_bytes() for p in out.iterdir()} == old  # the old outputs, byte for byte


def test_simulate_api_refuses_non_finite_energies_without_warnings():
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a RuntimeWarning would raise here
        with pytest.raises(DeriveError, match="no longer a finite number"):
            simulate(robots()["pendulum"], [0.1], tau=[1e300], t_end=0.01)


def test_simulate_writes_both_files_whole_and_reports_them(monkeypatch, work, capsys):
    monkeypatch.setattr(cli_common, "PROGRESS_INTERVAL", 0.0)
    monkeypatch.setattr(simulate_module, "PROGRESS_STEPS", 100)
    monkeypatch.setattr(simulate_module, "CSV_CHUNK", 64)  # several chunks
    out = work / "sim"
    status, stdout, err, runtime_warnings = run(["simulate", "pendulum", "--q0", "0.5", "--t", "0.5", "--out", out], capsys)
    assert status == 0 and not runtime_warnings, err
    assert stdout.splitlines()[-1] == f"wrote {out / 'pendulum.csv'} and {out / 'pendulum.png'}"
    assert "simulate pendulum: 20 % (integrating, t = 0.1 of 0.5 s)" in err.splitlines()
    assert sorted(p.name for p in out.iterdir()) == ["pendulum.csv", "pendulum.png"]  # no temporary left beside
    with (out / "pendulum.csv").open() as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["t", "q_phi", "qd_phi", "qdd_phi", "tau_phi", "T", "U", "E"] and len(rows) == 502
    assert float(rows[1][1]) == 0.5 and float(rows[-1][0]) == pytest.approx(0.5)
    energy = np.array([float(r[7]) for r in rows[1:]])
    assert np.ptp(energy) < 1e-9 * abs(energy[0])  # RK4 conserves it
    assert (out / "pendulum.png").read_bytes().startswith(PNG_MAGIC)


def test_simulate_write_failure_names_the_path_and_keeps_the_old_files(work, capsys):
    out = work / "sim"
    (out / "pendulum.csv").mkdir(parents=True)  # the CSV cannot be written there
    (out / "pendulum.png").write_bytes(b"old png")
    line = refused(["simulate", "pendulum", "--q0", "0.5", "--t", "0.01", "--out", out], capsys)
    assert f"{out / 'pendulum.csv'}: cannot write CSV (is a folder); it is left as it was" in line
    assert (out / "pendulum.png").read_bytes() == b"old png"


def test_a_streamed_write_that_fails_leaves_the_old_file(work):
    target = work / "data.csv"
    target.write_text("old\n")

    def chunks():
        yield "new,"
        raise OSError(28, "No space left on device")

    with pytest.raises(DeriveError, match=f"{target}: cannot write CSV \\(No space left on device\\); it is left as it was"):
        write_chunks_atomically(target, chunks(), "CSV")
    assert target.read_text() == "old\n" and sorted(os.listdir(work)) == ["data.csv", "generated"]


def test_a_png_whose_folder_cannot_be_made_is_one_error(work):
    (work / "file").write_text("x")
    with pytest.raises(DeriveError, match=f"^{work / 'file' / 'sub' / 'w.png'}: cannot create its folder"):
        write_png(work / "file" / "sub" / "w.png", PNG_MAGIC)
    assert (work / "file").read_text() == "x"


def test_trajopt_writes_both_files_whole_and_shows_iterations(monkeypatch, work, capsys):
    monkeypatch.setattr(cli_common, "PROGRESS_INTERVAL", 0.0)
    out = work / "traj"
    status, stdout, err, _ = run(["trajopt", "planar_2r", *FROM_TO, "--intervals", "10", "--out", out], capsys)
    assert status == 0, err
    assert stdout.splitlines()[-1] == f"wrote {out / 'trajectory.csv'} and {out / 'trajectory.png'}"
    assert "trajopt planar_2r: 0 % (IPOPT iteration 1, at most 3000)" in err.splitlines()
    assert sorted(p.name for p in out.iterdir()) == ["trajectory.csv", "trajectory.png"]
    lines = (out / "trajectory.csv").read_text().splitlines()
    assert lines[0] == "t,q_theta1,q_theta2,qd_theta1,qd_theta2,qdd_theta1,qdd_theta2,tau_theta1,tau_theta2"
    data = np.array([[float(x) for x in line.split(",")] for line in lines[1:]])
    assert data.shape == (11, 9)
    np.testing.assert_allclose(data[[0, -1], 1:3], [[0, 0], [1, 1]], atol=1e-9)  # start and goal
    assert (out / "trajectory.png").read_bytes().startswith(PNG_MAGIC)


def test_trajopt_out_that_is_a_file_is_refused_before_solving(work, capsys):
    (work / "traj").write_text("mine\n")
    refused(["trajopt", "planar_2r", *FROM_TO, "--out", work / "traj"], capsys, "--out", "not a folder")
    assert (work / "traj").read_text() == "mine\n"


def test_latex_writes_tex_and_png_whole(work, capsys):
    status, stdout, err, _ = run(["latex", "pendulum", "--out", work / "doc" / "p.tex", "--png", work / "p.png"], capsys)
    assert status == 0, err
    assert err.splitlines()[-2:] == [f"wrote {work / 'doc' / 'p.tex'}", f"wrote {work / 'p.png'}"]
    assert r"\ddot{\varphi}" in (work / "doc" / "p.tex").read_text()
    assert (work / "p.png").read_bytes().startswith(PNG_MAGIC)
    assert written(work) == ["doc", "doc/p.tex", "p.png"]


# ---- --png: a file name ending in .png, and "wrote" names exactly it (item 19) ----

PNG_COMMANDS = {
    "workspace": ["workspace", "planar_2r", "--samples", "100"],
    "manipulability": ["manipulability", "planar_2r"],
    "plan": ["plan", "planar_2r", *START_GOAL, "--resolution", "10"],
    "latex": ["latex", "pendulum"],
}
BAD_PNG = [("no-suffix", "wsplot", "does not end in .png"), ("other-suffix", "w.txt", "does not end in .png"),
           ("hidden-no-suffix", ".png", "does not end in .png"), ("trailing-slash", "pics/", "is a folder"),
           ("existing-folder", "{work}", "is a folder"), ("root", "/", "is a folder"), ("empty", "", "empty path")]


@pytest.mark.parametrize("name, fragment", [pytest.param(v, f, id=i) for i, v, f in BAD_PNG])
@pytest.mark.parametrize("command", sorted(PNG_COMMANDS))
def test_png_names_that_are_not_png_files_are_refused(command, name, fragment, work, capsys):
    refused([*PNG_COMMANDS[command], "--png", name.format(work=work)], capsys, "argument --png:", fragment)


def test_wrote_names_the_png_written(work, capsys):
    png = work / "figs" / "w.PNG"
    status, stdout, err, _ = run([*PNG_COMMANDS["workspace"], "--png", png], capsys)
    assert status == 0, err
    assert stdout.splitlines()[-1] == f"wrote {png}"
    assert png.read_bytes().startswith(PNG_MAGIC) and written(work) == ["figs", "figs/w.PNG"]


# ---- temporary folders are registered, removed after use and on SIGTERM too (item 11) ----

def test_trajopt_check_generates_into_a_registered_temporary_folder(monkeypatch, tmp_path):
    """Without current generated code, the independent check generates it into a temporary folder that
    the signal handlers know of (filesystem.TEMPORARIES) and that is gone afterwards (the fixture)."""
    registered = []
    real = trajopt_module.generate

    def spy(robots_, out, **kwargs):
        registered.append(any(folder and Path(out).is_relative_to(path) for path, folder in TEMPORARIES.items()))
        return real(robots_, out, **kwargs)

    monkeypatch.setattr(trajopt_module, "generate", spy)
    robot = robots()["pendulum"]
    fd = generated_forward_dynamics(robot, params(robot), root=tmp_path / "nothing-generated")
    assert registered == [True]
    ref = NumericRobot(robot)
    q, qd, tau = np.array([0.3]), np.array([-0.7]), np.array([0.2])
    np.testing.assert_allclose(fd(q, qd, tau), ref.aba(q, qd, tau), rtol=1e-12)


def test_sigterm_during_simulate_leaves_no_temporary_folder(tmp_path, models):
    """No generated/ in the working folder: simulate generates into a temporary folder; SIGTERM while
    it exists ends the run with 143 and removes it (the handler ends with os._exit)."""
    scratch, cwd = tmp_path / "sigterm-tmp", tmp_path / "sigterm-cwd"
    scratch.mkdir()
    cwd.mkdir()
    env = {**os.environ, "TMPDIR": str(scratch), "PYTHONPATH": str(ROOT), "DERIVE_MODELS": str(models)}
    proc = subprocess.Popen([sys.executable, "-m", "derive", "simulate", "pendulum", "--q0", "0.1", "--t", "0.1"],
                            cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        while not any(p.name.startswith("derive-simulate-") for p in scratch.iterdir()):
            assert proc.poll() is None and time.monotonic() < deadline, "no temporary folder appeared"
            time.sleep(0.02)
        proc.send_signal(signal.SIGTERM)
        _, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 143, err
    assert sorted(os.listdir(scratch)) == [] and sorted(os.listdir(cwd)) == []
