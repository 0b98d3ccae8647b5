"""A* over configuration-space grids (lecture section 2.6, Example 4) and workspace obstacles."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.sparse import lil_matrix
from scipy.sparse.csgraph import dijkstra

from derive.cli import main
from derive.errors import DeriveError
from derive.analysis.planning import (CHECK_STEP, Box, Circle, MotionCheck, astar, collisions, default_check_step,
                                      neighbour_offsets, parse_obstacle, plan)
from derive.analysis.workspace import Arm, joint_box
from derive.description.model import load_models
from derive.plot.planning import plot_plan
from util import robots, tree_robots


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
    assert res.success and res.check_step == CHECK_STEP and "checked every 0.01 m" in res.message
    assert np.array_equal(res.path[0], start) and np.array_equal(res.path[-1], goal)
    assert (collisions(arm, res.path, OBSTACLES) < 0).all()
    assert_free_along(arm, res, OBSTACLES)
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


# --------------------------------------------------------------------------- edge checks (issue 12)


def assert_free_along(arm, res, obstacles, finer: int = 10):
    """The whole path, re-checked with a step ``finer`` times smaller than the planner's, hits nothing."""
    fine = MotionCheck(arm, obstacles, 0.0, res.check_step / finer)
    assert fine.first_collision(res.path) is None
    assert fine.checked > finer * len(res.path)


def unchecked_path(res, start, goal, connectivity="full"):
    """The path the planner returned before edges were checked: A* over free nodes, ends replaced."""
    lo = np.array([a[0] for a in res.axes])
    step = np.array([a[1] - a[0] for a in res.axes])
    snap = [tuple(np.clip(np.round((np.asarray(q) - lo) / step), 0, len(res.axes[0]) - 1).astype(int)) for q in (start, goal)]
    grid = astar(res.free, snap[0], snap[1], step, connectivity)
    path = np.array([[res.axes[k][i] for k, i in enumerate(node)] for node in grid.nodes])
    path[0], path[-1] = start, goal
    return path if len(path) > 1 else np.vstack([start, goal])


def dense_collisions(arm, path, obstacles, n: int = 201) -> int:
    """Colliding points among n evenly spaced (by joint-space arc length) points of a path."""
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))])
    t = np.linspace(0.0, s[-1], n)
    Q = np.stack([np.interp(t, s, path[:, k]) for k in range(path.shape[1])], axis=1)
    return int((collisions(arm, Q, obstacles) >= 0).sum())


# Found with the node-only planner at the default resolution (5^7 / 6^6 grids): a sphere near the
# wrist at the middle of the straight motion. Its paths collided at 50, 11, 33 and 49 of 201 points.
REGRESSION = [
    ("panda", [0.04, 0.95, -1.24, -0.76, -0.65, 1.69, 1.14], [-0.32, 0.1, -1.64, -1.11, 0.13, 1.48, 1.0],
     Circle((0.32, -0.46, 0.88), 0.1)),
    ("panda", [-0.68, -0.1, -1.27, -1.75, -1.03, 1.33, 0.87], [-0.76, -0.03, 1.67, -0.74, 0.78, 1.96, -0.78],
     Circle((0.41, -0.23, 0.92), 0.1)),
    ("ur5", [0.09, 3.4, -1.34, 3.38, -1.42, -0.58], [2.47, -0.68, 0.19, -3.56, 1.91, 0.29],
     Circle((-0.02, 0.33, -0.67), 0.1)),
    ("ur5", [2.5, -3.3, 1.23, -2.53, -0.94, -1.38], [1.44, -2.42, -0.39, -3.73, -1.79, -0.59],
     Circle((0.2, -0.75, 0.39), 0.1)),
]


@pytest.mark.parametrize("name, start, goal, sphere", REGRESSION, ids=[f"{c[0]}-{i}" for i, c in enumerate(REGRESSION)])
def test_default_plans_of_spatial_arms_are_collision_free_along_the_path(name, start, goal, sphere):
    robot = robots()[name]
    arm = Arm(robot)
    res = plan(robot, start, goal, [sphere], arm=arm)
    # the old answer (edges taken as free between free nodes) collides: the case is a real regression
    assert dense_collisions(arm, unchecked_path(res, start, goal), [sphere]) > 0
    assert res.success, res.message
    assert np.array_equal(res.path[0], start) and np.array_equal(res.path[-1], goal)
    assert res.check_step == CHECK_STEP and "checked every 0.01 m" in res.message
    assert dense_collisions(arm, res.path, [sphere]) == 0
    assert_free_along(arm, res, [sphere])


def test_planar_2r_default_plan_is_collision_free_along_the_path():
    robot = robots()["planar_2r"]
    arm = Arm(robot)
    for obstacles, start, goal, resolution in ((OBSTACLES, [2.6, 0.3], [0.2, 0.4], None),
                                               ([Circle((0.9, 0.9), 0.2)], [0.2, 0.3], [1.4, 0.3], 41)):
        res = plan(robot, start, goal, obstacles, resolution=resolution, arm=arm)
        assert res.success, res.message
        assert_free_along(arm, res, obstacles)


def thin_wall_case():
    """planar_2r, 11 nodes per joint (0.628 rad apart): a small circle on link 1 at theta1 = 0.314,
    between the nodes theta1 = 0 and 0.628, blocks that angle for every theta2."""
    robot = robots()["planar_2r"]
    wall = Circle((0.95 * math.cos(math.pi / 10), 0.95 * math.sin(math.pi / 10)), 0.04)
    return robot, Arm(robot), wall


def test_edge_check_refuses_an_edge_through_a_thin_obstacle():
    robot, arm, wall = thin_wall_case()
    qa, qb = np.array([0.0, 0.0]), np.array([math.pi / 5, 0.0])
    assert (collisions(arm, np.vstack([qa, qb]), [wall]) < 0).all()  # both end nodes are free
    assert (collisions(arm, (qa + qb)[None] / 2, [wall]) == 0).all()  # the middle is not
    check = MotionCheck(arm, [wall], step=0.01)
    assert not check.free(qa, qb)[0] and not check.free(qa, qb, ends=False)[0]
    # n pieces from the bound: link 1's tip moves 1.0 * dq1, the TCP (1.0 + 0.7) * dq1
    assert check.pieces(qa, qb)[0] == math.ceil(1.7 * math.pi / 5 / 0.01)
    assert check.free(qa, qa + [0.0, 0.3])[0]  # turning theta2 only: link 1 stays clear
    # the planner: nodes on both sides are free, but no edge crosses the wall: no path (the old one jumped it)
    res = plan(robot, [-0.3, 0.2], [0.9, 0.2], [wall], resolution=11, arm=arm)
    assert not res.success and res.message.startswith("no path") and res.refused > 0
    assert dense_collisions(arm, unchecked_path(res, [-0.3, 0.2], [0.9, 0.2]), [wall]) > 0


def test_path_that_cannot_be_certified_is_refused():
    """The start's nearest grid node lies across a thin wall: the grid path exists, but the motion
    from the start onto it collides, so the planner says so (exit 1) instead of returning it."""
    robot, arm, _ = thin_wall_case()
    wall = Circle((0.97 * math.cos(0.12), 0.97 * math.sin(0.12)), 0.03)
    res = plan(robot, [0.25, 0.0], [-1.0, -0.5], [wall], resolution=11, arm=arm)
    assert not res.success and len(res.path) == 0
    assert res.message.startswith("cannot certify the path") and "start to its nearest grid node" in res.message
    assert main(["plan", "planar_2r", "--start", "0.25", "0", "--goal=-1,-0.5", "--resolution", "11",
                 "--obstacle", f"circle:{wall.center[0]},{wall.center[1]},0.03"]) == 1


@pytest.mark.parametrize("connectivity", ["axis", "full"])
def test_lazy_astar_equals_dijkstra_over_the_free_edges(connectivity):
    """Edges refused by the check are left out: the same cost as Dijkstra on the remaining graph,
    and every edge is asked about at most once."""
    rng = np.random.default_rng(3)
    for trial in range(20):
        shape = (12, 12) if trial % 2 else (6, 6, 6)
        free = rng.random(shape) > 0.2
        nodes = [tuple(i) for i in np.argwhere(free)]
        start, goal = nodes[0], nodes[-1]
        salt = int(rng.integers(1 << 30))

        def blocked(a, b):
            key = tuple(sorted((tuple(int(x) for x in a), tuple(int(x) for x in b))))
            return hash((key, salt)) % 4 == 0

        asked = []

        def edge_free(A, B):
            asked.extend(tuple(sorted((tuple(a), tuple(b)))) for a, b in zip(A.tolist(), B.tolist()))
            return np.array([not blocked(a, b) for a, b in zip(A, B)])

        index = {n: k for k, n in enumerate(nodes)}
        graph = lil_matrix((len(nodes), len(nodes)))
        for n in nodes:
            for off in neighbour_offsets(len(shape), connectivity):
                nb = tuple(np.add(n, off))
                if nb in index and not blocked(n, nb):
                    graph[index[n], index[nb]] = np.linalg.norm(off)
        best = dijkstra(graph.tocsr(), indices=index[start])[index[goal]]
        found = astar(free, start, goal, connectivity=connectivity, edge_free=edge_free, batch=1 + trial % 5)
        assert len(asked) == len(set(asked))
        if np.isinf(best):
            assert found is None
        else:
            assert found.cost == pytest.approx(best, rel=1e-12)
            assert not any(blocked(a, b) for a, b in zip(found.nodes, found.nodes[1:]))


def test_speed_bounds_bound_the_motion_of_every_skeleton_point():
    """|d p_j / d q_k| <= B[k, j] (finite differences at random configurations) for every robot,
    every joint type (examples/joint_types.yaml: spherical, universal, prismatic, cylindrical,
    helical) and both branches of a tree."""
    arms = [Arm(robots()[n]) for n in tree_robots()]  # planning moves a tree tcp; a closed chain has none
    jt = load_models(Path(__file__).resolve().parent.parent / "examples" / "joint_types.yaml")["joint_types"]
    arms += [Arm(jt, "tcp"), Arm(jt, "nut")]
    rng = np.random.default_rng(5)
    eps = 1e-6
    for arm in arms:
        lo, hi = joint_box(arm.robot)
        Q = rng.uniform(lo + 2 * eps, hi - 2 * eps, size=(40, arm.nv))
        for k in range(arm.nv):
            d = np.zeros(arm.nv)
            d[k] = eps
            rate = np.linalg.norm(arm.skeleton(Q + d) - arm.skeleton(Q - d), axis=-1) / (2 * eps)  # (N, m)
            assert (rate <= arm.speed_bounds[k] * (1 + 1e-6) + 1e-7).all(), (arm.robot.name, arm.frame, k)
        # and the bound on a whole motion holds for the displacement between its ends
        QA, QB = Q[:20], Q[20:]
        moved = np.linalg.norm(arm.skeleton(QB) - arm.skeleton(QA), axis=-1).max(axis=1)
        assert (moved <= arm.displacement_bound(QB - QA) + 1e-12).all()


def test_check_step_default_and_cli(capsys):
    assert default_check_step() == CHECK_STEP
    assert default_check_step([Circle((0.0, 0.0), 0.004)]) == pytest.approx(0.004)
    assert default_check_step([Box((0, 0, 0), (1, 0.006, 1))], margin=0.001) == pytest.approx(0.004)
    args = ["plan", "planar_2r", "--start", "2.6", "0.3", "--goal", "0.2,0.4", "--resolution", "41",
            "--obstacle", "circle:-0.1,1.45,0.22", "--obstacle", "box:1.1,-0.2,1.5,0.15"]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "collision checks: check step 0.01 m" in out and "checked every 0.01 m" in out
    assert main(args + ["--check-step", "0.002"]) == 0
    assert "collision checks: check step 0.002 m" in capsys.readouterr().out
    for bad in ("0", "-1", "nan"):
        assert main(args + ["--check-step", bad]) == 2
        assert "--check-step must be a finite length > 0 m" in capsys.readouterr().err
