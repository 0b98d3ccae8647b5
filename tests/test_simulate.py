"""Simulation with the generated forward dynamics: energy conservation, integrators, CLI, example."""

from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import derive
from derive.cli import main
from derive.inspect.linearize import linearize
from derive.solvers.simulate import simulate
from util import robots, tree_robots

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.parametrize("name, q0", [("pendulum", [1.0]), ("planar_2r", [1.0, 0.5])])
def test_energy_is_conserved_over_10_s_with_rk4(name, q0):
    """No torque, no friction, RK4 at 1e-3 s for 10 s: relative drift <= 1e-6 (measured 3e-13 and 2e-8)."""
    traj = simulate(robots()[name], q0, t_end=10.0, dt=1e-3)
    assert traj.t.shape == (10001,) and traj.t[-1] == pytest.approx(10.0)
    assert traj.energy_drift <= 1e-6, f"{name}: drift {traj.energy_drift:.2e}"
    assert np.ptp(traj.kinetic) > 1.0, "the arm actually swings"


@pytest.mark.parametrize("name", tree_robots())  # a closed chain: its rk4_step in y, test_closed_chain_code.py
def test_every_robot_conserves_energy_and_work(name):
    """With a constant torque E - tau . (q - q0) is conserved (1 s, seeded start)."""
    robot = robots()[name]
    rng = np.random.default_rng(0)
    traj = simulate(robot, 0.3 * rng.uniform(-1, 1, robot.nv), 0.5 * rng.normal(size=robot.nv),
                    tau=0.2 * rng.normal(size=robot.nv), t_end=1.0)
    assert traj.energy_drift <= 1e-6, f"{name}: drift {traj.energy_drift:.2e}"


def test_adaptive_integrators_agree_with_rk4():
    robot = robots()["planar_2r"]
    ref = simulate(robot, [1.0, 0.5], t_end=2.0, dt=1e-3)
    for method in ("RK45", "DOP853", "LSODA", "Radau"):
        traj = simulate(robot, [1.0, 0.5], t_end=2.0, dt=1e-3, method=method)
        assert traj.q.shape == ref.q.shape
        assert np.abs(traj.q - ref.q).max() < 1e-6, method
        assert traj.energy_drift < 1e-6, method


def test_small_swings_follow_example7():
    """phi(t) = phi0 cos(sqrt(b/a) t) for small phi0, with a and b of eq. 21 at the default parameters."""
    m = derive.load("pendulum")
    lin = linearize(m, [0])
    at = {p: d.default for p, d in zip(m.params, m.robot.parameters)}
    omega = float((lin.K[0, 0] / lin.M[0, 0]).subs(at)) ** 0.5
    phi0 = 1e-3
    traj = simulate(m.robot, [phi0], t_end=3.0, dt=1e-3)
    # the neglected sin(phi) - phi shifts the frequency by phi0^2/16 = 6e-8: 6e-10 rad after 3 s (measured 4.9e-10)
    assert np.abs(traj.q[:, 0] - phi0 * np.cos(omega * traj.t)).max() < 1e-5 * phi0


def test_parameters_change_the_motion():
    robot = robots()["pendulum"]
    short = simulate(robot, [0.5], t_end=1.0, params={"l": 0.5})
    long = simulate(robot, [0.5], t_end=1.0)
    assert np.abs(short.q - long.q).max() > 0.1 and short.energy_drift < 1e-6


def test_cli_writes_csv_and_png(tmp_path, capsys):
    import matplotlib.image

    out = tmp_path / "sim"
    assert main(["simulate", "planar_2r", "--q0", "1", "0.5", "--t", "1", "--tau", "0.5", "0", "--out", str(out)]) == 0
    text = capsys.readouterr().out
    assert "max relative drift" in text and "energy E - tau.(q - q0)" in text
    with (out / "planar_2r.csv").open() as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["t", "q_theta1", "q_theta2", "qd_theta1", "qd_theta2", "qdd_theta1", "qdd_theta2",
                       "tau_theta1", "tau_theta2", "T", "U", "E"]
    assert len(rows) == 1002 and float(rows[1][1]) == 1.0 and float(rows[-1][0]) == pytest.approx(1.0)
    assert matplotlib.image.imread(out / "planar_2r.png").shape[0] > 300


@pytest.mark.parametrize("argv, message", [
    (["simulate", "pendulum", "--q0", "1", "2"], "robot 'pendulum': q0 needs 1 value (one per joint), got 2"),
    (["simulate", "pendulum", "--q0", "1", "--param", "length=2"], "robot 'pendulum' has no parameter(s) length"),
    (["simulate", "pendulum", "--q0", "1", "--param", "l"], "--param expects NAME=VALUE, got 'l'"),
    (["simulate", "pendulum", "--q0", "1", "--dt", "0"], "must be positive"),
    (["simulate", "nosuch", "--q0", "1"], "no such robot"),
])
def test_cli_errors_are_one_line(argv, message, capsys, tmp_path):
    assert main([*argv, "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("derive: error:") and message in err[-1]


def test_missing_generated_code_is_explained(tmp_path, capsys):
    assert main(["simulate", "pendulum", "--q0", "1", "--generated", str(tmp_path), "--out", str(tmp_path)]) == 2
    assert "no generated code at" in capsys.readouterr().err


def test_example_tour_runs(tmp_path):
    """examples/pendulum_tour.py as a new user runs it, from an empty folder."""
    run = subprocess.run([sys.executable, str(ROOT / "examples" / "pendulum_tour.py")], cwd=tmp_path,
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    out = tmp_path / "pendulum_tour_out"
    for name in ("pendulum.tex", "pendulum_equations.png", "pendulum.csv", "pendulum_simulation.png"):
        assert (out / name).stat().st_size > 500, name
    assert r"\ddot{\varphi}" in (out / "pendulum.tex").read_text()
    assert "z' = [z1, -2*g*l*z0*(m_r + 2*m_s)/(4*I_r + 4*I_s + l**2*m_r + 4*l**2*m_s)]" in run.stdout
    if "no C compiler" not in run.stdout:  # the C rk4_step predicts what Python simulated
        assert float(run.stdout.rsplit("max difference", 1)[1]) < 1e-9
