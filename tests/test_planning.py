"""A* over configuration-space grids (lecture section 2.6, Example 4) and workspace obstacles."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.sparse import lil_matrix
from scipy.sparse.csgraph import dijkstra

from derive.cli import main
from derive.errors import DeriveError
from derive.analysis.planning import Box, Circle, astar, collisions, neighbour_offsets, parse_obstacle, plan
from derive.analysis.workspace import Arm, joint_box
from derive.plot.planning import plot_plan
from util import robots


def test_empty_grid_optimal_lengths():
    free = np.ones((20, 20), dtype=bool)
    full = astar(free, (0, 0), (19, 10), connectivity="full")
    assert full.cost == pytest.approx(10 * math.sqrt(2) + 9)  # 10 diagonal + 9 straight steps
    axis = astar(free, (0, 0), (19, 10), connectivity="axis")
    assert axis.cost == pytest.approx(29)  # Manhattan
    assert astar(free, (3, 4), (3, 4)).cost == 0.0
    spaced = astar(free, (0, 0), (19, 0), spacing=(0.5, 2.0))
    assert spaced.cost == pytest.approx(9.5)


def test_wall_with_a_gap_gives_the_known_detour():
    """The lecture's picture: a wall between start and goal, one opening at the top."""
    free = np.ones((20, 20), dtype=bool)
    free[10, :18] = False  # wall along y at x = 10, open for y = 18, 19
    path = astar(free, (0, 0), (19, 0), connectivity="axis")
    assert path.cost == pytest.approx(19 + 2 * 18)
    assert all(free[n] for n in path.nodes)
    assert all(np.abs(np.subtract(a, b)).sum() == 1 for a, b in zip(path.nodes, path.nodes[1:]))
    path8 = astar(free, (0, 0), (19, 0), connectivity="full")
    # 8-connected: octile distances (0,0) -> (10,18) through the gap -> (19,0)
    assert path8.cost == pytest.approx((10 * math.sqrt(2) + 8) + (9 * math.sqrt(2) + 9))


@pytest.mark.parametrize("connectivity", ["axis", "full"])
def test_astar_equals_dijkstra_on_random_grids(connectivity):
    """Optimality: the same cost as Dijkstra (scipy) on 30 random 2-D and 3-D obstacle grids."""
    rng = np.random.default_rng(0)
    for trial in range(30):
        shape = (15, 15) if trial % 2 else (7, 7, 7)
        free = rng.random(shape) > 0.3
        nodes = [tuple(i) for i in np.argwhere(free)]
        start, goal = nodes[0], nodes[-1]
        index = {n: k for k, n in enumerate(nodes)}
        graph = lil_matrix((len(nodes), len(nodes)))
        for n in nodes:
            for off in neighbour_offsets(len(shape), connectivity):
                nb = tuple(np.add(n, off))
                if nb in index:
                    graph[index[n], index[nb]] = np.linalg.norm(off)
        best = dijkstra(graph.tocsr(), indices=index[start])[index[goal]]
        found = astar(free, start, goal, connectivity=connectivity)
        if np.isinf(best):
            assert found is None
        else:
            assert found.cost == pytest.approx(best, rel=1e-12)


def test_enclosed_goal_has_no_path():
    free = np.ones((15, 15), dtype=bool)
    free[8:13, 8] = free[8:13, 12] = free[8, 8:13] = free[12, 8:13] = False  # a closed square
    assert astar(free, (0, 0), (10, 10)) is None
    assert astar(free, (0, 0), (10, 10), connectivity="axis") is None
    free[8, 10] = True  # open a door
    assert astar(free, (0, 0), (10, 10)) is not None
    with pytest.raises(DeriveError, match="outside the grid"):
        astar(free, (0, 0), (15, 0))


def test_segment_obstacle_tests():
    a, b = np.array([[0.0, 0, 0]]), np.array([[2.0, 0, 0]])
    assert Circle((1.0, 0.5), 0.5).hits(a, b)[0] and not Circle((1.0, 0.6), 0.5).hits(a, b)[0]
    assert Circle((3.0, 0.0), 1.0).hits(a, b)[0] and not Circle((3.1, 0.0), 1.0).hits(a, b)[0]  # end cap
    assert Circle((1.0, 0.6), 0.5).hits(a, b, margin=0.2)[0]
    assert Circle((1.0, 0.0, 5.0), 1.0).hits(a, b)[0] == False  # noqa: E712  (a sphere above the segment)
    assert Box((0.5, -1), (0.7, 1)).hits(a, b)[0]  # crossing
    assert Box((0.5, -1, -1), (0.7, 1, 1)).hits(a, b)[0]
    assert not Box((2.1, -1), (3, 1)).hits(a, b)[0]
    assert Box((-1, -1), (3, 1)).hits(a, b)[0]  # segment inside
    assert not Box((0.5, 0.1), (0.7, 1)).hits(a, b)[0]  # parallel, outside the slab
    assert parse_obstacle("circle:1,pi/2,0.3") == Circle((1.0, math.pi / 2), 0.3)
    assert parse_obstacle("box:0,0,1,2") == Box((0.0, 0.0), (1.0, 2.0))
    for bad in ("circle:1,2", "box:1,1,0,0", "cone:1,2,3", "circle:1,2,-1"):
        with pytest.raises(DeriveError, match="obstacle"):
            parse_obstacle(bad)


OBSTACLES = [Circle((-0.1, 1.45), 0.22), Box((1.1, -0.2), (1.5, 0.15))]


def test_planar_2r_plan_is_collision_free_and_ends_at_start_and_goal():
    robot = robots()["planar_2r"]
    arm = Arm(robot)
    start, goal = np.array([2.6, 0.3]), np.array([0.2, 0.4])
    res = plan(robot, start, goal, OBSTACLES, resolution=101, arm=arm)
    assert res.success
    assert np.array_equal(res.path[0], start) and np.array_equal(res.path[-1], goal)
    assert (collisions(arm, res.path, OBSTACLES) < 0).all()
    assert res.length >= np.linalg.norm(goal - start) - 1e-12
    assert res.length == pytest.approx(np.linalg.norm(np.diff(res.path, axis=0), axis=1).sum())
    # the straight joint-space line is blocked (that is why the path bends)
    line = start + np.linspace(0, 1, 200)[:, None] * (goal - start)
    assert (collisions(arm, line, OBSTACLES) >= 0).any()
    free_res = plan(robot, start, goal, [], resolution=101, arm=arm)
    assert free_res.length == pytest.approx(np.linalg.norm(goal - start), rel=0.05)
    assert res.length > free_res.length


def test_link_obstacle_splitting_the_configuration_space_gives_no_path():
    """A circle on link 1's sweep at theta1 = -pi/2 blocks that angle for every theta2; joint
    limits (no wrap-around) then cut the configuration space in two."""
    robot = robots()["planar_2r"]
    res = plan(robot, [-2.5, 0.5], [0.0, 0.5], [Circle((0.0, -0.5), 0.2)], resolution=81)
    assert not res.success and res.message.startswith("no path") and len(res.path) == 0
    assert not res.free[np.argmin(np.abs(res.axes[0] + np.pi / 2)), :].any()


def test_plan_rejects_colliding_or_out_of_range_endpoints():
    robot = robots()["planar_2r"]
    with pytest.raises(DeriveError, match="start configuration collides with obstacle 1"):
        plan(robot, [0.0, 0.0], [1.0, 1.0], [Circle((1.0, 0.0), 0.1)])
    with pytest.raises(DeriveError, match="outside the joint box"):
        plan(robot, [4.0, 0.0], [1.0, 1.0])
    with pytest.raises(DeriveError, match="not searchable"):
        mid = np.mean(joint_box(robots()["panda"]), axis=0)
        plan(robots()["panda"], mid, mid, resolution=30)


def test_plan_png_and_cli(tmp_path, capsys):
    import matplotlib.image as mpimg

    png = tmp_path / "plan.png"
    args = ["plan", "planar_2r", "--start", "2.6", "0.3", "--goal", "0.2,0.4", "--resolution", "101",
            "--obstacle", "circle:-0.1,1.45,0.22", "--obstacle", "box:1.1,-0.2,1.5,0.15", "--png", str(png)]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "path length:" in out and png.stat().st_size > 10000
    img = mpimg.imread(png)
    assert img.ndim == 3 and img.shape[1] > 1.8 * img.shape[0] and img[..., :3].std() > 0.05
    nopath = tmp_path / "nopath.png"
    assert main(["plan", "planar_2r", "--start=-2.5,0.5", "--goal", "0", "0.5", "--resolution", "61",
                 "--obstacle", "circle:0,-0.5,0.2", "--png", str(nopath)]) == 1
    assert "no path" in capsys.readouterr().out and nopath.stat().st_size > 0
    assert main(["plan", "planar_2r", "--start", "0", "0", "--goal", "1", "1", "--obstacle", "blob:1"]) == 2
    assert "obstacle 'blob:1'" in capsys.readouterr().err
    res = plan(robots()["rrprr"], np.zeros(5), np.full(5, 0.1), [], resolution=4)
    plot_plan(robots()["rrprr"], res, np.zeros(5), np.full(5, 0.1), [], tmp_path / "rrprr.png")
    assert (tmp_path / "rrprr.png").stat().st_size > 0
