"""Singularities, redundancy and manipulability (lecture sections 4.1-4.3, eq. 24, 30, figure 9)."""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

import derive
from derive.cli import main
from derive.errors import DeriveError
from derive.analysis.manipulability import Manipulability, ellipsoid, measures, symbolic
from derive.codegen.catalogue import manipulability_function as template_function
from derive.reference import NumericRobot
from derive.analysis.singularity import TaskJacobian, analyse, find_singularities, free_coordinates, redundancy
from derive.plot.manipulability import plot_manipulability
from util import robots, sx_model

L1, L2 = 1.0, 0.7


def planar_2r_J(q):
    """Eq. 24."""
    t1, t2 = q
    return np.array([[-L1 * np.sin(t1) - L2 * np.sin(t1 + t2), -L2 * np.sin(t1 + t2)],
                      [L1 * np.cos(t1) + L2 * np.cos(t1 + t2), L2 * np.cos(t1 + t2)]])


def test_planar_2r_task_is_the_2x2_jacobian_of_eq24():
    tj = TaskJacobian(robots()["planar_2r"])
    assert tj.rows == (0, 1) and tj.moving_rows == (0, 1, 5)
    rng = np.random.default_rng(0)
    for q in rng.uniform(-np.pi, np.pi, (10, 2)):
        assert np.allclose(tj(q), planar_2r_J(q), atol=1e-14)
    assert TaskJacobian(robots()["planar_2r"], task="full").rows == (0, 1, 5)
    assert TaskJacobian(robots()["planar_2r"], task="x,y,z").rows == (0, 1, 2)  # explicit rows are kept
    with pytest.raises(DeriveError, match="task 'xy'"):
        TaskJacobian(robots()["planar_2r"], task="xy")


@pytest.mark.parametrize("t1", [0.0, 0.7, -2.0])
def test_planar_2r_stretched_is_singular_with_mu3_zero_and_1d_null_space(t1):
    """theta2 = 0: rank 1, mu3 = 0, mu1 = mu2 = inf, null space spanned by one joint velocity."""
    tj = TaskJacobian(robots()["planar_2r"])
    q = np.array([t1, 0.0])
    info = analyse(tj(q), q)
    assert info.singular and info.rank == 1
    assert info.null_space.shape == (2, 1)
    assert np.abs(tj(q) @ info.null_space).max() < 1e-15
    # the lost direction is radial: the stretched arm cannot move along itself
    assert abs(abs(info.lost_directions[:, 0] @ [np.cos(t1), np.sin(t1)]) - 1) < 1e-12
    mu = Manipulability(robots()["planar_2r"]).at(q).mu
    assert mu[2] < 1e-15 and np.isinf(mu[0]) and np.isinf(mu[1])


def test_measures_match_eq30_and_mu3_is_l1_l2_sin_theta2():
    rng = np.random.default_rng(0)
    man = Manipulability(robots()["planar_2r"])
    for q in rng.uniform(-np.pi, np.pi, (20, 2)):
        J = planar_2r_J(q)
        lam = np.linalg.eigvalsh(J @ J.T)
        lmin, lmax = lam[0], lam[-1]
        info = man.at(q)
        assert np.allclose(info.mu, [np.sqrt(lmax / lmin), lmax / lmin, np.sqrt(lmax * lmin)], rtol=1e-10)
        assert info.mu[2] == pytest.approx(L1 * L2 * abs(np.sin(q[1])), rel=1e-12)
        semi, axes = info.semi_axes, info.axes
        assert np.allclose(semi**2, lam[::-1], rtol=1e-10)  # sqrt of the eigenvalues of J J^T
        assert np.allclose(J @ J.T @ axes, axes * semi**2, atol=1e-12)  # eigenvectors


@pytest.mark.parametrize("name", ["planar_2r", "ur5"])
def test_batched_measures_equal_single_ones(name):
    man = Manipulability(robots()[name])
    Q = np.random.default_rng(1).uniform(-3, 3, (7, robots()[name].nv))
    assert np.allclose(man.batch(Q), [man.at(q).mu for q in Q], rtol=1e-12)


def test_mu3_is_yoshikawa_for_3d_tasks_and_position_orientation_parts():
    man = Manipulability(robots()["panda"])
    ref = NumericRobot(robots()["panda"])
    q = np.random.default_rng(2).uniform(-1.5, 1.5, 7)
    J = ref.jacobian(q, "tcp")
    info = man.at(q)
    assert info.mu[2] == pytest.approx(np.sqrt(np.linalg.det(J[:3] @ J[:3].T)), rel=1e-10)
    for part, rows in (("position", slice(0, 3)), ("orientation", slice(3, 6))):
        _, semi, axes = info.parts[part]
        lam, vec = np.linalg.eigh(J[rows] @ J[rows].T)
        assert np.allclose(semi, np.sqrt(lam[::-1]), rtol=1e-10)
        assert np.allclose(np.abs(axes.T @ vec[:, ::-1]), np.eye(3), atol=1e-8)
    # a 1-DOF pendulum cannot span its 2-D position task: singular everywhere
    assert np.array_equal(measures(np.array([[1.0], [0.5]])), [np.inf, np.inf, 0.0])
    s, U = ellipsoid(np.array([[3.0, 0.0], [0.0, 0.0]]))
    assert np.allclose(s, [3, 0]) and U.shape == (2, 2)


def test_symbolic_measures_of_planar_2r():
    m = derive.load("planar_2r")
    L1s, L2s = m.params[0], m.params[1]
    t2 = m.q[1]
    out = symbolic(m)
    assert sp.simplify(out["mu3"] ** 2 - (L1s * L2s * sp.sin(t2)) ** 2) == 0
    assert out["mu3"].subs(t2, 0) == 0
    vals = {L1s: L1, L2s: L2, m.q[0]: 0.4, t2: 1.1}
    lam = np.linalg.eigvalsh(planar_2r_J([0.4, 1.1]) @ planar_2r_J([0.4, 1.1]).T)
    assert float(out["mu2"].subs(vals)) == pytest.approx(lam[1] / lam[0], rel=1e-12)
    assert float(out["mu1"].subs(vals)) == pytest.approx(np.sqrt(lam[1] / lam[0]), rel=1e-12)


def test_generated_manipulability_spec():
    """Generated for frames that can span their task; the C/Python values are checked against
    this reference in test_codegen (quantity 'manipulability')."""
    t = template_function(sx_model("planar_2r"), "tcp")
    assert t.name == "planar_2r_manipulability_tcp" and t.calls == (("jacobian", "jacobian_tcp"),)
    assert dict(t.context)["rows"] == (0, 1) and t.outputs == (("mu", (3, 1)),)
    assert template_function(sx_model("pendulum"), "tcp") is None  # nv = 1 < k = 2
    assert dict(template_function(sx_model("ur5"), "tcp").context)["rows"] == (0, 1, 2)


def test_redundancy_classification():
    text = redundancy(TaskJacobian(robots()["panda"]))
    assert "kinematically redundant for the 3-D task (x,y,z): nv = 7 > 3" in text
    assert "intrinsically redundant: nv = 7 > 6" in text
    assert "not kinematically redundant" in redundancy(TaskJacobian(robots()["ur5"], task="full"))
    assert "not intrinsically redundant: nv = 2 <= 3" in redundancy(TaskJacobian(robots()["planar_2r"]))
    assert "never be spanned" in redundancy(TaskJacobian(robots()["pendulum"]))
    rng = np.random.default_rng(0)
    tj = TaskJacobian(robots()["panda"])
    info = analyse(tj(rng.uniform(-1, 1, 7)))
    assert info.rank == 3 and info.null_space.shape == (7, 4)


def test_search_finds_the_2r_singularities_theta2_0_and_pi():
    tj = TaskJacobian(robots()["planar_2r"])
    assert free_coordinates(tj) == (0,)  # rotating the whole arm changes no singular value
    found, free = find_singularities(tj, starts=12, seed=0)
    q2 = sorted(round(abs(c.q[1]), 9) for c in found)
    assert q2 == [0.0, round(np.pi, 9)]
    for c in found:
        assert c.singular_values[-1] < 1e-12
    # theta2 = pi lies outside planar_2r's limits (+-3.14159)
    assert [c.within_limits for c in sorted(found, key=lambda c: abs(c.q[1]))] == [True, False]


def test_search_on_a_spatial_arm_returns_rank_deficient_configurations():
    tj = TaskJacobian(robots()["rrprr"])
    found, _ = find_singularities(tj, starts=6, seed=1)
    assert found
    for c in found:
        s = np.linalg.svd(tj(c.q), compute_uv=False)
        assert s[-1] < 1e-7 * s[0]


def test_manipulability_plot_renders(tmp_path):
    import matplotlib.image as mpimg

    for name in ("planar_2r", "ur5"):
        png = plot_manipulability(Manipulability(robots()[name]), tmp_path / f"{name}.png", samples=2000)
        img = mpimg.imread(png)
        assert png.stat().st_size > 10000 and img.ndim == 3 and img[..., :3].std() > 0.05
    with pytest.raises(DeriveError, match="position task"):
        plot_manipulability(Manipulability(robots()["ur5"], task="orientation"), tmp_path / "x.png")


def test_cli_manipulability_and_singularities(tmp_path, capsys):
    png = tmp_path / "m.png"
    assert main(["manipulability", "planar_2r", "--q", "0", "0", "--q", "0.3,pi/2", "--png", str(png)]) == 0
    out = capsys.readouterr().out
    assert "q = [0, 0]: mu1 = inf, mu2 = inf, mu3 = 0" in out
    assert "mu3 = 0.7\n" in out  # L1 L2 sin(pi/2)
    assert png.stat().st_size > 0
    assert main(["singularities", "planar_2r", "--q", "0.3", "0"]) == 0
    out = capsys.readouterr().out
    assert "rank 1 of 2 (SINGULAR)" in out and out.count("null space:") == 1
    assert main(["singularities", "planar_2r", "--starts", "8"]) == 0
    out = capsys.readouterr().out
    assert "singular at q = [0, 0]" in out and "singular at q = [0, 3.14159]" in out
    assert main(["singularities", "planar_2r", "--q", "1,2,3"]) == 2
    assert "expected 2 values" in capsys.readouterr().err
