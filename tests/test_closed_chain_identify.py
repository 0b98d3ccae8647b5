"""The closed-chain regressor Y_y = G^T Y(q, G yd, G ydd + Gdot yd), its base parameters, and `derive identify`
on a closed chain (docs/closed-chains.md, Identification).

- Y_y pi = tau_y to 1e-12 (symbolic Y_y against the numpy reference's constrained inverse dynamics; the
  generated Python regressor_y and base_regressor_y against the generated inverse_dynamics_y) at seeded
  closed states, for each shipped mechanism.
- The base parameter count equals the numerical rank of Y_y stacked at other seeded closed states, and is
  at most the tree's.
- The Delta moved by the generated rk4_step (PD tracking of sines, a heavier arm and a lighter plate than
  the model's) and `derive identify` on its CSV in y: the base parameters to 1e-8 without noise.
"""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np
import pytest

from derive.cli import main
from derive.reference.closure import ClosedChainReference
from derive.solvers.identify import Measurements, closed_regressor_along, identify
from derive.symbolic.base_parameters import base_parameters
from derive.symbolic.closed_regressor import assembles, closed_regressor, closed_states, stacked_rank
from test_codegen import load_python as _load_python
from test_closed_chain_code import function, manifest
from util import params, robots

CLOSED = ("fourbar", "slider_crank", "fivebar", "example2", "delta", "parallel_ankle")
BASE = {"fourbar": 15, "slider_crank": 13, "fivebar": 21, "example2": 36, "delta": 25, "parallel_ankle": 24}
"""The closed chains' base parameter counts (docs/closed-chains.md)."""
TREE = {"fourbar": 16, "slider_crank": 14, "fivebar": 22, "example2": 38, "delta": 25, "parallel_ankle": 24}
"""The spanning trees' (joint box states, derive base-parameters of the tree): the loops take some away."""


load_python = lru_cache(maxsize=None)(_load_python)
"""The generated Python module of a robot, imported once."""


@lru_cache(maxsize=None)
def derived(name: str):
    """(ClosedRegressor, ReducedChain, BaseParameters, assembly check) of a shipped mechanism."""
    cr, red, bp = closed_regressor(robots()[name])
    return cr, red, bp, assembles(cr.ccm, red, cr.reg.parameter_vector())


def closed_q(name: str, y: np.ndarray) -> np.ndarray:
    """The closed q = gamma(y) of the generated closure (Newton from the reference's z for the ankle)."""
    r = robots()[name]
    py = load_python(name)
    names = [c.name for c in r.coordinates]
    if name == "parallel_ankle":
        q = py.closure(y, [r.reference_q[names.index(c)] for c in r.dependent])[0]
    else:
        q = py.closure(y)[0]
    return np.asarray(q, dtype=float).ravel()


@pytest.mark.parametrize("name", CLOSED)
def test_regressor_times_pi_is_the_constrained_inverse_dynamics(name):
    """Y_y pi = tau_y to 1e-12: CasADi's Y_y against the numpy reference's G^T rnea at the generated closure's q;
    the generated regressor_y (pi from the manifest) and base_regressor_y (pi_b) against inverse_dynamics_y."""
    cr, red, bp, check = derived(name)
    r, m, py = robots()[name], manifest(name), load_python(name)
    f = cr.function(red)
    p = params(r)
    pi = np.array([x["value"] for x in function(m, "regressor_y")["regressor_parameters"]])
    pib = np.array([x["value"] for x in function(m, "base_regressor_y")["base_parameters"]])
    assert np.array_equal(pi, cr.reg.values()) and len(pib) == BASE[name]
    ref = ClosedChainReference(r)
    extra = (p,) if p.size else ()
    for y, yd, ydd in closed_states(r, 4, 21, check):
        tau = ref.inverse_dynamics(closed_q(name, y), yd, ydd)
        scale = max(1.0, np.abs(tau).max())
        assert np.abs(np.array(f(y, yd, ydd, p)) @ pi - tau).max() <= 1e-12 * scale
        tau_gen = np.asarray(py.inverse_dynamics_y(y, yd, ydd, *extra)).ravel()
        assert np.abs(tau_gen - tau).max() <= 1e-12 * scale
        assert np.abs(np.asarray(py.regressor_y(y, yd, ydd, *extra)) @ pi - tau_gen).max() <= 1e-12 * scale
        assert np.abs(np.asarray(py.base_regressor_y(y, yd, ydd, *extra)) @ pib - tau_gen).max() <= 1e-12 * scale


@pytest.mark.parametrize("name", CLOSED)
def test_base_parameters_are_the_rank_of_the_stacked_closed_regressor(name):
    """The count (manifest and BaseParameters) = the SVD rank of the generated regressor_y stacked at 60 other
    seeded closed states (unit columns, singular values above 1e-9 of the largest) <= the tree's count; the base
    columns reproduce every column there (Y_y = Y_b K)."""
    cr, red, bp, check = derived(name)
    r, m, py = robots()[name], manifest(name), load_python(name)
    p = params(r)
    extra = (p,) if p.size else ()
    W = np.vstack([np.asarray(py.regressor_y(y, yd, ydd, *extra)) for y, yd, ydd in closed_states(r, 60, 11, check)])
    assert bp.rank == function(m, "base_regressor_y")["rank"] == stacked_rank(W) == BASE[name]
    assert [b["column"] for b in function(m, "base_regressor_y")["base_parameters"]] == list(bp.columns)
    assert np.abs(W[:, list(bp.columns)] @ bp.K - W).max() <= 1e-9 * np.abs(W).max()
    assert BASE[name] <= TREE[name]


@pytest.mark.parametrize("name", ("fourbar", "delta"))
def test_tree_counts(name):
    """TREE (the spanning trees' counts) as base_parameters gives them."""
    assert base_parameters(robots()[name]).rank == TREE[name]


def delta_motion(p: np.ndarray, steps: int = 1000, dt: float = 0.002):
    """The Delta under the generated rk4_step from its reference configuration, PD-tracking a sum of sines
    (+-0.5 rad) about it with gravity compensated (generated inverse_dynamics_y at rest): (t, y, yd, ydd, tau),
    ydd = the generated forward_dynamics_y at each sample's state and torque (exact, whatever the step)."""
    r, py = robots()["delta"], load_python("delta")
    names = [c.name for c in r.coordinates]
    y0 = np.array([r.reference_q[names.index(c)] for c in r.independent])
    rng = np.random.default_rng(3)
    w, phase = rng.uniform(2, 9, (3, 3)), rng.uniform(0, 6, (3, 3))
    x = np.concatenate([y0, np.zeros(3)])
    xs, us = [], []
    for k in range(steps):
        target = y0 + 0.5 * np.sin(w * k * dt + phase).sum(axis=1) / 3
        u = np.asarray(py.inverse_dynamics_y(x[:3], np.zeros(3), np.zeros(3), p)).ravel()
        u = u + 30 * (target - x[:3]) - 3 * x[3:]
        xs.append(x)
        us.append(u)
        x = np.asarray(py.rk4_step(x, u, [dt], p)).ravel()
    xs, tau = np.array(xs), np.array(us)
    ydd = np.asarray(py.forward_dynamics_y(xs[:, :3], xs[:, 3:], tau, p)).reshape(steps, 3)
    return np.arange(steps) * dt, xs[:, :3], xs[:, 3:], ydd, tau


@pytest.fixture(scope="module")
def delta_data():
    """The Delta's motion with ma = 0.45 (model 0.4) and mp = 0.27 (0.3), and its true base parameters K pi."""
    r = robots()["delta"]
    cr, red, bp, _ = derived("delta")
    true = {"ma": 0.45, "mp": 0.27}
    p = np.array([true.get(x.name, x.default) for x in r.parameters])
    return (*delta_motion(p), bp.K @ cr.reg.values(true))


def test_identify_recovers_the_delta_base_parameters(delta_data):
    """The least squares on Y_y: pi_b to 1e-8 relative, residual at rounding."""
    t, y, yd, ydd, tau, pib_true = delta_data
    cr, red, bp, _ = derived("delta")
    assert y.min() > 1.0 and y.max() < 2.3  # a real swing (+-0.5 rad about the reference) that stays assembled
    result = identify(closed_regressor_along(cr, red, robots()["delta"]), bp, cr.reg.values(),
                      Measurements(t, y, yd, ydd, tau), bodies=len(cr.reg.bodies), closed=True)
    assert np.abs(result.base_values - pib_true).max() <= 1e-8 * np.abs(pib_true).max()
    assert np.all(result.residual_rms <= 1e-9 * result.tau_rms)


def test_identify_command_on_a_closed_chain(delta_data, tmp_path, capsys):
    """`derive identify delta DATA.csv` with columns in y: the report's values (6 digits) and the written model,
    which loads with its loops and has the identified base parameters."""
    t, y, yd, ydd, tau, pib_true = delta_data
    r = robots()["delta"]
    header = ",".join(["t"] + [f"{k}_{c}" for k in ("q", "qd", "qdd", "tau") for c in r.independent])
    data = tmp_path / "delta.csv"
    np.savetxt(data, np.column_stack([t, y, yd, ydd, tau]), delimiter=",", header=header, comments="", fmt="%.17g")
    out = tmp_path / "delta_identified.yaml"
    capsys.readouterr()
    assert main(["identify", "delta", str(data), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    rows = [line.split() for line in text.splitlines() if line.startswith("  ") and len(line.split()) == 5]
    assert len(rows) == BASE["delta"], text
    pib = np.array([float(row[1]) for row in rows])
    assert np.abs(pib - pib_true).max() <= 1e-5 * np.abs(pib_true).max(), text
    assert "motor1:" in text and "q_x" not in text
    from derive.description.model import load_models

    written = load_models(out)["delta_identified"]
    assert written.closed and written.independent == r.independent
    cr, red, bp = closed_regressor(written)
    assert bp.names == derived("delta")[2].names
    assert np.abs(bp.K @ cr.reg.values() - pib_true).max() <= 1e-6 * np.abs(pib_true).max()
    # --physical: each body's pseudo-inertia >= 0; the massless carriages (identified m = 0) written massless
    physical = tmp_path / "delta_physical.yaml"
    assert main(["identify", "delta", str(data), "--out", str(physical), "--physical"]) == 0
    written = load_models(physical)["delta_identified"]
    assert {link.name: float(link.mass) for link in written.links}["carriage_x"] == 0.0
    cr, red, bp = closed_regressor(written)
    # the fit is IPOPT's with the prior's pull and m >= 0 (observed 6.5e-5 relative)
    assert np.abs(bp.K @ cr.reg.values() - pib_true).max() <= 1e-3 * np.abs(pib_true).max()


def test_identify_names_a_sample_where_the_loops_do_not_close(tmp_path, capsys):
    """example2 with theta4 1 rad above its reference cannot assemble: one line naming the CSV line, nothing written."""
    r = robots()["example2"]
    cr, red, bp, check = derived("example2")
    names = [c.name for c in r.coordinates]
    y0 = np.array([r.reference_q[names.index(c)] for c in r.independent])
    far = y0 + [0.0, 1.0, 0.0]
    assert not check(far)
    header = ",".join(["t"] + [f"{k}_{c}" for k in ("q", "qd", "qdd", "tau") for c in r.independent])
    rows = [np.concatenate([[0.01 * k], y0 + 0.001 * k if k < 30 else far, np.full(9, 0.1)]) for k in range(40)]
    data = tmp_path / "example2.csv"
    np.savetxt(data, np.array(rows), delimiter=",", header=header, comments="", fmt="%.17g")
    assert main(["identify", "example2", str(data), "--out", str(tmp_path / "x.yaml")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("derive: error: identify: ") and "line 32: the loops do not close at y = " in err[-1]
    assert not (tmp_path / "x.yaml").exists()


def test_base_parameters_command_and_excite_on_a_closed_chain(capsys):
    assert main(["base-parameters", "delta"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("delta: 25 base parameters of 78 standard ones (the closed chain's, in y = motor1, motor2, "
                          "motor3)")
    assert "MR_carriage_y = m_carriage_y + Ia_y" in out
    assert main(["excite", "delta"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("derive: error: excite delta: robot 'delta' has loops") and "\n" not in err


def test_regressor_is_linear_in_the_parameters_p():
    """Y_y does not hold the masses: with ma, mp changed, the same Y_y times the new pi is the new tau_y."""
    cr, red, bp, check = derived("delta")
    r = robots()["delta"]
    true = {"ma": 0.45, "mp": 0.27}
    p = np.array([true.get(x.name, x.default) for x in r.parameters])
    tau = ca.Function("id", [red.y, cr.ccm.yd, cr.ccm.ydd, cr.ccm.sym.p], [red.inverse_dynamics])
    f = cr.function(red)
    for y, yd, ydd in closed_states(r, 3, 5, check):
        want = np.array(tau(y, yd, ydd, p)).ravel()
        assert np.abs(np.array(f(y, yd, ydd, params(r))) @ cr.reg.values(true) - want).max() <= 1e-12 * max(
            1.0, np.abs(want).max())



def test_simulate_a_closed_chain_writes_its_csv_in_y(tmp_path, capsys):
    """`derive simulate` in y: the generated rk4_step, the tree's energy at the closed q and qd = G yd (drift of
    the 1 s swing below 1e-10), the CSV's columns q_<c>, qd_<c>, qdd_<c>, tau_<c> for c in y, which identify's
    reader takes; the Newton closure (the ankle) from the reference's z."""
    from derive.solvers.identify import read_measurements
    from derive.solvers.simulate import simulate

    r = robots()["parallel_ankle"]
    traj = simulate(r, [0.25, 0.05], t_end=1.0, dt=1e-3)
    assert traj.energy_drift <= 1e-10 and traj.q.shape == (1001, 2)
    ref = ClosedChainReference(r)
    for k in (0, 500, 1000):  # the generated closure's q closes the loops; energy E = T + U of that q
        q = closed_q("parallel_ankle", traj.q[k])
        assert np.abs(ref.phi(q)).max() <= 1e-12
        assert abs(ref.energy(q, ref.projection(q) @ traj.qd[k]) - traj.energy[k]) <= 1e-12
    capsys.readouterr()
    assert main(["simulate", "delta", "--q0", "1.45", "1.75", "1.6", "--t", "0.2", "--out", str(tmp_path)]) == 0
    assert "max relative drift" in capsys.readouterr().out
    csv = tmp_path / "delta.csv"
    assert csv.read_text().splitlines()[0] == ",".join(
        ["t"] + [f"{k}_motor{i}" for k in ("q", "qd", "qdd", "tau") for i in (1, 2, 3)] + ["T", "U", "E"])
    m = read_measurements(csv, list(robots()["delta"].independent))
    assert m.q.shape == (201, 3) and np.array_equal(m.q[0], [1.45, 1.75, 1.6])
    py = load_python("delta")
    assert np.abs(np.asarray(py.forward_dynamics_y(m.q, m.qd, m.tau)).reshape(m.qdd.shape) - m.qdd).max() <= 1e-12
    assert main(["simulate", "delta", "--q0", "1.45", "1.75", "--out", str(tmp_path)]) == 2
    assert "q0 needs 3 values" in capsys.readouterr().err
