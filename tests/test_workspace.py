"""Configuration space -> workspace (lecture section 2.4, figure 4): the 2R annulus, plots, CLI."""

from __future__ import annotations

import numpy as np
import pytest

from derive.cli import main
from derive.errors import DeriveError
from derive.reference import NumericRobot
from derive.analysis.workspace import Arm, joint_box, sample_configurations, workspace
from derive.plot.workspace import plot_workspace
from util import robots, tree_robots

L1, L2 = 1.0, 0.7  # planar_2r's parameter defaults


@pytest.mark.parametrize("method", ["grid", "random"])
def test_planar_2r_workspace_is_the_annulus(method):
    """Radii stay in [|L1 - L2|, L1 + L2] and come within 1e-3 of both bounds (limits +-pi)."""
    robot = robots()["planar_2r"]
    ws = workspace(robot, "tcp", 40000, method, seed=0)
    r = ws.reach
    assert r.min() >= abs(L1 - L2) - 1e-12 and r.max() <= L1 + L2 + 1e-12
    assert r.min() < abs(L1 - L2) + 1e-3 and r.max() > L1 + L2 - 1e-3
    assert ws.plane == (0, 1) and np.abs(ws.points[:, 2]).max() == 0.0
    # every annulus radius is reached: no gap in the sampled radii wider than 2 % of the width
    gaps = np.diff(np.sort(r))
    assert gaps.max() < 0.02 * (2 * min(L1, L2))


def test_grid_covers_the_joint_box_including_limits():
    robot = robots()["planar_2r"]
    Q = sample_configurations(robot, 121, "grid")
    lo, hi = joint_box(robot)
    assert Q.shape == (121, 2)
    assert np.allclose(Q.min(axis=0), lo) and np.allclose(Q.max(axis=0), hi)
    R = sample_configurations(robot, 500, "random", seed=3)
    assert np.all((R >= lo) & (R <= hi))
    with pytest.raises(DeriveError, match="grid or random"):
        sample_configurations(robot, 10, "sobol")


@pytest.mark.parametrize("name", tree_robots())
def test_batched_positions_match_the_reference_fk(name):
    robot = robots()[name]
    arm = Arm(robot, "tcp")
    Q = sample_configurations(robot, 20, "random", seed=1)
    ref = NumericRobot(robot)
    expected = np.array([ref.frame_pose(q, "tcp")[:3, 3] for q in Q])
    assert np.allclose(arm.position(Q), expected, atol=1e-12)
    sk = arm.skeleton(Q)
    assert np.allclose(sk[:, 0], 0.0) and sk.shape[1] == len(arm.chain)


def test_planar_2r_skeleton_is_base_elbow_tip():
    arm = Arm(robots()["planar_2r"], "tcp")
    sk = arm.skeleton([[np.pi / 2, -np.pi / 2]])[0]
    assert np.allclose(sk, [[0, 0, 0], [0, L1, 0], [L2, L1, 0]], atol=1e-15)


def test_workspace_plots_render(tmp_path):
    import matplotlib.image as mpimg

    for name in ("planar_2r", "ur5"):
        ws = workspace(robots()[name], "tcp", 3000, "random")
        png = plot_workspace(ws, tmp_path / f"{name}.png")
        assert png.stat().st_size > 10000
        img = mpimg.imread(png)
        assert img.ndim == 3 and img.shape[1] > 1.8 * img.shape[0]  # side by side
        assert img[..., :3].std() > 0.05  # not blank


def test_cli_workspace(tmp_path, capsys):
    png = tmp_path / "w.png"
    assert main(["workspace", "planar_2r", "--samples", "2401", "--method", "grid", "--png", str(png)]) == 0
    out = capsys.readouterr().out
    assert "distance from the base: 0.3 .. 1.7" in out and "planar in xy" in out  # 49 x 49 grid: 0 and the limits
    assert png.stat().st_size > 0
    assert main(["workspace", "planar_2r", "--frame", "elbow"]) == 2
    assert "no frame 'elbow'" in capsys.readouterr().err
