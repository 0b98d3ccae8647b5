"""`derive identify` and `derive excite`: round trips on data simulated from perturbed parameters.

Data: the UR5 with every link's mass (+-20 %) and centre of mass (~1 cm) perturbed and armature,
viscous and Coulomb friction added, moving along a sum of sines; torques from its inverse
dynamics. Without noise, the identified base parameters equal K pi_true to 1e-8 relative and the
written model reproduces them; with 1 % torque noise the identified model predicts torques of a
held-out motion to within the noise level. A CSV without qd and qdd is filtered and differentiated.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from derive.cli import main
from derive.description.model import load_models
from derive.bench.identification import perturbed as bench_perturbed
from derive.solvers.excite import fourier_basis
from derive.solvers.identify import Measurements, identify, regressor_along, torques_along
from derive.symbolic.base_parameters import base_parameters
from derive.symbolic.dynamics import NewtonEuler
from derive.symbolic.regressor import Regressor
from derive.symbolic.symbols import make_symbols


def perturbed(robot):
    return bench_perturbed(robot, armature=0.05, viscous=0.3, coulomb=0.8)


def motion(n: int, samples: int, seed: int, dt: float = 0.01):
    rng = np.random.default_rng(seed)
    t = np.arange(samples) * dt
    q, qd, qdd = (np.zeros((samples, n)) for _ in range(3))
    for j in range(n):
        for harmonic in range(1, 4):
            a, phase = rng.uniform(0.2, 0.6) / harmonic, rng.uniform(0, 6)
            w = 2 * np.pi * harmonic / 4.0 * rng.uniform(0.7, 1.3)
            q[:, j] += a * np.sin(w * t + phase)
            qd[:, j] += a * w * np.cos(w * t + phase)
            qdd[:, j] -= a * w * w * np.sin(w * t + phase)
    return t, q, qd, qdd


torques = torques_along


def write_csv(path: Path, robot, t, q, qd, qdd, tau, with_rates: bool = True) -> Path:
    names = [c.name for c in robot.coordinates]
    blocks = [("q", q)] + ([("qd", qd), ("qdd", qdd)] if with_rates else []) + [("tau", tau)]
    header = ",".join(["t"] + [f"{k}_{j}" for k, _ in blocks for j in names])
    np.savetxt(path, np.column_stack([t] + [b for _, b in blocks]), delimiter=",", header=header, comments="",
               fmt="%.17g")
    return path


@pytest.fixture(scope="module")
def ur5():
    nominal = load_models()["ur5"]
    true = perturbed(nominal)
    reg = Regressor(NewtonEuler(true, make_symbols(true)))
    bp = base_parameters(nominal)
    return nominal, true, bp, bp.K @ np.asarray(reg.values())


def identified_base(out: Path, capsys) -> np.ndarray:
    """The identified values column of the report."""
    text = capsys.readouterr().out
    rows = [line.split() for line in text.splitlines() if line.startswith("  ") and len(line.split()) == 5]
    return np.array([float(r[1]) for r in rows]), text


def test_noise_free_round_trip_recovers_the_base_parameters(ur5, tmp_path, capsys):
    nominal, true, bp, pib_true = ur5
    t, q, qd, qdd = motion(nominal.nv, 400, seed=1)
    data = write_csv(tmp_path / "data.csv", nominal, t, q, qd, qdd, torques(true, q, qd, qdd))
    out = tmp_path / "ur5_identified.yaml"
    capsys.readouterr()
    assert main(["identify", "ur5", str(data), "--out", str(out)]) == 0
    pib, text = identified_base(out, capsys)
    assert len(pib) == len(bp.names)
    # the report prints 6 significant digits: the fit itself is checked through the written model below
    assert np.abs(pib - pib_true).max() <= 1e-5 * np.abs(pib_true).max(), text
    written = load_models(out)["ur5_identified"]
    reg = Regressor(NewtonEuler(written, make_symbols(written)))
    pib_written = bp.K @ np.asarray(reg.values())
    assert np.abs(pib_written - pib_true).max() <= 1e-6 * np.abs(pib_true).max()
    t2, q2, qd2, qdd2 = motion(nominal.nv, 200, seed=9)
    assert np.abs(torques(written, q2, qd2, qdd2) - torques(true, q2, qd2, qdd2)).max() <= 1e-5 * 50


def test_identify_core_is_exact_without_noise(ur5):
    """The least squares itself: pi_b to 1e-8 relative (the CLI rounds its report)."""
    nominal, true, bp, pib_true = ur5
    t, q, qd, qdd = motion(nominal.nv, 300, seed=2)
    reg = Regressor(NewtonEuler(nominal, make_symbols(nominal)))
    result = identify(regressor_along(reg, nominal), bp, np.asarray(reg.values()),
                      Measurements(t, q, qd, qdd, torques(true, q, qd, qdd)), bodies=len(reg.bodies))
    assert np.abs(result.base_values - pib_true).max() <= 1e-8 * np.abs(pib_true).max()
    assert np.all(result.residual_rms <= 1e-9 * result.tau_rms)


def test_one_percent_noise_predicts_held_out_torques_within_the_noise(ur5, tmp_path, capsys):
    nominal, true, _, _ = ur5
    t, q, qd, qdd = motion(nominal.nv, 1500, seed=3)
    tau = torques(true, q, qd, qdd)
    rng = np.random.default_rng(4)
    noise = 0.01 * np.sqrt(np.mean(tau ** 2, axis=0))
    data = write_csv(tmp_path / "noisy.csv", nominal, t, q, qd, qdd, tau + rng.normal(size=tau.shape) * noise)
    out = tmp_path / "noisy.yaml"
    assert main(["identify", "ur5", str(data), "--out", str(out), "--physical"]) == 0
    written = load_models(out)["ur5_identified"]
    t2, q2, qd2, qdd2 = motion(nominal.nv, 400, seed=11)
    err = torques(written, q2, qd2, qdd2) - torques(true, q2, qd2, qdd2)
    assert np.all(np.sqrt(np.mean(err ** 2, axis=0)) <= noise), (np.sqrt(np.mean(err ** 2, axis=0)), noise)


def test_missing_rates_are_filtered_and_differentiated(ur5, tmp_path, capsys):
    nominal, true, _, pib_true = ur5
    t, q, qd, qdd = motion(nominal.nv, 2000, seed=6, dt=0.002)
    data = write_csv(tmp_path / "q_only.csv", nominal, t, q, qd, qdd, torques(true, q, qd, qdd), with_rates=False)
    assert main(["identify", "ur5", str(data), "--out", str(tmp_path / "d.yaml"), "--physical"]) == 0
    text = capsys.readouterr().out
    assert "qd and qdd derived from q: zero-phase Butterworth" in text
    resid = [float(line.split(";")[-1].strip(" )")) for line in text.splitlines() if "_joint: " in line]
    assert max(resid) < 0.05, text


@pytest.mark.parametrize("csv, fragment", [
    ("t,q_x\n0,1\n", "missing columns q_shoulder_pan_joint"),
    ("t,q_shoulder_pan_joint\nzero,1\n", "comma-separated numbers"),
    ("t\n", "needs a header line and samples"),
])
def test_bad_data_is_one_line(csv, fragment, tmp_path, capsys):
    path = tmp_path / "bad.csv"
    path.write_text(csv)
    assert main(["identify", "ur5", str(path), "--out", str(tmp_path / "x.yaml")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("derive: error: identify") and fragment in err[0], err
    assert not (tmp_path / "x.yaml").exists()


def test_excite_lowers_the_condition_number_within_the_limits(tmp_path, capsys):
    out = tmp_path / "exc"
    status = main(["excite", "rrprr", "--samples", "40", "--harmonics", "2", "--iterations", "30", "--out", str(out)])
    text = capsys.readouterr().out
    assert status == 0, text
    line = next(x for x in text.splitlines() if "cond(W_b)" in x)
    cond = float(line.split("cond(W_b) = ")[1].split(" ")[0])
    random_cond = float(line.split("same limits: ")[1].split(")")[0])
    assert cond < random_cond and "within every limit: yes" in line, line
    rows = np.loadtxt(out / "excitation.csv", delimiter=",", skiprows=1)
    assert rows.shape == (40, 1 + 4 * 5) and (out / "excitation.png").is_file()
    P, V, A = fourier_basis(np.array([0.0, 10.0]), 10.0, 2)  # periodic: the start and one period later agree
    assert np.allclose(P[0], P[1]) and np.allclose(V[0], V[1]) and np.allclose(A[0], A[1])


def test_base_parameters_command(capsys):
    """The planar 2R of the lecture (l1 = 1): ZZR_1 = ZZ_1 + m_2 l1^2 (+ the first armature), in text and LaTeX."""
    assert main(["base-parameters", "planar_2r"]) == 0
    text = capsys.readouterr().out
    assert text.startswith("planar_2r: 11 base parameters of 26 standard ones")
    assert "  ZZR_link1_dh = Izz_link1_dh + m_link2_dh + Ia_theta1    [1.03333]" in text
    assert main(["base-parameters", "planar_2r", "--latex"]) == 0
    latex = capsys.readouterr().out
    assert latex.startswith("\\begin{align*}") and "\\mathrm{ZZR}^{\\mathrm{link1\\_dh}} &= I_{zz}^{" in latex
