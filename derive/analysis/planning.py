"""A* search over a grid in configuration space (lecture section 2.6, Example 4).

The joint box (joint limits, as :func:`derive.analysis.workspace.joint_box`) is sampled on
a regular grid. Nodes are joined to their neighbours: "axis" connectivity (4
neighbours in 2-D, 2 nv in general) or "full" (8 in 2-D, 3^nv - 1). A step
costs its Euclidean length in joint space, and the heuristic is the Euclidean
distance to the goal, which never overestimates the remaining cost and obeys
the triangle inequality: A* returns a shortest grid path (or proves there is
none), expanding nodes in order of f = g + h.

Obstacles live in the workspace: circles (spheres in 3-D) and axis-aligned
boxes; a 2-D obstacle, given by x and y only, extends along all of z. A
configuration collides when any link, a line segment between consecutive link
frame origins from the base to the frame (:class:`derive.analysis.workspace.Arm`, no
thickness: inflate obstacles with ``margin`` for that), meets an obstacle, tested
exactly (segment-circle distance, slab test for boxes). Grid nodes are tested;
an edge between two free neighbours is taken as free, so obstacles thinner than
a grid step can be jumped: refine the grid for them.

The figure of a plan is :func:`derive.plot.planning.plot_plan`.
"""

from __future__ import annotations

import heapq
import itertools
import math
from dataclasses import dataclass, field

import numpy as np

from derive.analysis.singularity import eval_number
from derive.analysis.workspace import Arm, joint_box
from derive.description.robot import Robot
from derive.errors import DeriveError

MAX_NODES = 2_000_000


# --------------------------------------------------------------------------- grid search


@dataclass
class GridPath:
    nodes: list[tuple[int, ...]]  # grid indices from start to goal
    cost: float
    expanded: int


def neighbour_offsets(ndim: int, connectivity: str = "full") -> list[tuple[int, ...]]:
    """Offsets to the neighbours of a node: "axis" (+-1 along one axis) or "full" (any of -1, 0, 1)."""
    if connectivity == "axis":
        return [tuple(s if k == i else 0 for k in range(ndim)) for i in range(ndim) for s in (-1, 1)]
    if connectivity == "full":
        return [o for o in itertools.product((-1, 0, 1), repeat=ndim) if any(o)]
    raise DeriveError(f"connectivity '{connectivity}': expected axis (4-connected in 2-D) or full (8-connected)")


def astar(free: np.ndarray, start: tuple[int, ...], goal: tuple[int, ...], spacing=None,
          connectivity: str = "full") -> GridPath | None:
    """Shortest path on a boolean grid (True = free) from ``start`` to ``goal`` (index tuples), or None.

    Step cost and heuristic are Euclidean with the grid ``spacing`` per axis (default 1).
    Returns the node sequence, its cost and the number of expanded nodes.
    """
    free = np.asarray(free, dtype=bool)
    shape = free.shape
    h_scale = np.ones(free.ndim) if spacing is None else np.asarray(spacing, dtype=float)
    start, goal = tuple(int(i) for i in start), tuple(int(i) for i in goal)
    for name, node in (("start", start), ("goal", goal)):
        if len(node) != free.ndim or any(not 0 <= i < n for i, n in zip(node, shape)):
            raise DeriveError(f"A*: {name} {node} is outside the grid {shape}")
    if not free[start] or not free[goal]:
        return None
    steps = [(np.array(o), float(np.linalg.norm(np.array(o) * h_scale))) for o in neighbour_offsets(free.ndim, connectivity)]
    goal_arr = np.array(goal)

    def h(node) -> float:
        return float(np.linalg.norm((np.array(node) - goal_arr) * h_scale))

    g = {start: 0.0}
    parent: dict[tuple, tuple] = {}
    closed = set()
    tie = itertools.count()  # equal f: first pushed first, so the order is deterministic
    heap = [(h(start), next(tie), start)]
    while heap:
        _, _, node = heapq.heappop(heap)
        if node in closed:
            continue
        if node == goal:
            path = [node]
            while path[-1] in parent:
                path.append(parent[path[-1]])
            return GridPath(path[::-1], g[goal], len(closed) + 1)
        closed.add(node)
        base = np.array(node)
        for off, cost in steps:
            nb = tuple(int(x) for x in base + off)
            if any(not 0 <= i < n for i, n in zip(nb, shape)) or nb in closed or not free[nb]:
                continue
            cand = g[node] + cost
            if cand < g.get(nb, math.inf):
                g[nb], parent[nb] = cand, node
                heapq.heappush(heap, (cand + h(nb), next(tie), nb))
    return None


# --------------------------------------------------------------------------- obstacles


@dataclass(frozen=True)
class Circle:
    """A circle (center x, y: a cylinder along z) or a sphere (center x, y, z)."""

    center: tuple[float, ...]
    radius: float

    def hits(self, a: np.ndarray, b: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Segments a -> b (..., 3) that come within radius + margin of the center."""
        d = len(self.center)
        c = np.asarray(self.center)
        a, b = a[..., :d], b[..., :d]
        ab = b - a
        L2 = (ab * ab).sum(-1)
        t = np.clip(((c - a) * ab).sum(-1) / np.where(L2 > 0, L2, 1.0), 0.0, 1.0)
        closest = a + t[..., None] * ab
        return ((closest - c) ** 2).sum(-1) <= (self.radius + margin) ** 2

    def describe(self) -> str:
        return f"{'circle' if len(self.center) == 2 else 'sphere'} at ({', '.join(f'{x:g}' for x in self.center)}) r {self.radius:g}"


@dataclass(frozen=True)
class Box:
    """An axis-aligned box [lower, upper] in x, y (a prism along z) or x, y, z."""

    lower: tuple[float, ...]
    upper: tuple[float, ...]

    def hits(self, a: np.ndarray, b: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Segments a -> b that meet the box grown by ``margin`` (slab test: the parameter
        intervals in which the segment is inside each slab must overlap within [0, 1])."""
        d = len(self.lower)
        lo, hi = np.asarray(self.lower) - margin, np.asarray(self.upper) + margin
        a, b = a[..., :d], b[..., :d]
        ab = b - a
        tmin = np.zeros(a.shape[:-1])
        tmax = np.ones(a.shape[:-1])
        for k in range(d):
            par = np.abs(ab[..., k]) < 1e-15
            inside = (a[..., k] >= lo[k]) & (a[..., k] <= hi[k])
            safe = np.where(par, 1.0, ab[..., k])
            t1, t2 = (lo[k] - a[..., k]) / safe, (hi[k] - a[..., k]) / safe
            tmin = np.where(par, np.where(inside, tmin, 2.0), np.maximum(tmin, np.minimum(t1, t2)))
            tmax = np.where(par, np.where(inside, tmax, -1.0), np.minimum(tmax, np.maximum(t1, t2)))
        return tmin <= tmax

    def describe(self) -> str:
        return f"box [{', '.join(f'{x:g}' for x in self.lower)}] .. [{', '.join(f'{x:g}' for x in self.upper)}]"


def parse_obstacle(text: str) -> Circle | Box:
    """'circle:x,y,r', 'circle:x,y,z,r' (sphere), 'box:xmin,ymin,xmax,ymax' or 'box:xmin,ymin,zmin,xmax,ymax,zmax'."""
    kind, _, rest = text.partition(":")
    try:
        v = [eval_number(x) for x in rest.split(",")]
    except ValueError:
        v = []
    if not all(math.isfinite(x) for x in v):
        raise DeriveError(f"obstacle '{text}': every coordinate must be a finite number")
    if kind == "circle" and len(v) in (3, 4) and v[-1] > 0:
        return Circle(tuple(v[:-1]), v[-1])
    if kind == "box" and len(v) in (4, 6):
        d = len(v) // 2
        if all(v[k] < v[d + k] for k in range(d)):
            return Box(tuple(v[:d]), tuple(v[d:]))
    raise DeriveError(f"obstacle '{text}': expected circle:x,y,r | circle:x,y,z,r (r > 0) | "
                      "box:xmin,ymin,xmax,ymax | box:xmin,ymin,zmin,xmax,ymax,zmax (min < max)")


def collisions(arm: Arm, Q: np.ndarray, obstacles, margin: float = 0.0) -> np.ndarray:
    """(N,) index of the first obstacle each configuration hits, -1 when free."""
    sk = arm.skeleton(Q)
    a, b = sk[:, :-1, :], sk[:, 1:, :]
    out = np.full(sk.shape[0], -1)
    for i in reversed(range(len(obstacles))):
        out[obstacles[i].hits(a, b, margin).any(axis=1)] = i
    return out


# --------------------------------------------------------------------------- planning


@dataclass
class PlanResult:
    success: bool
    message: str
    path: np.ndarray  # (M, nv) joint-space waypoints from start to goal (empty without a path)
    length: float  # sum of Euclidean joint-space step lengths of ``path``
    expanded: int
    axes: list[np.ndarray] = field(default_factory=list)  # grid values per joint
    free: np.ndarray | None = None  # occupancy of the grid (True = free)


def plan(robot: Robot, start, goal, obstacles=(), frame: str = "tcp", resolution: int | None = None,
         connectivity: str = "full", margin: float = 0.0, arm: Arm | None = None) -> PlanResult:
    """A collision-free joint path from ``start`` to ``goal`` by A* on a grid over the joint box.

    ``resolution`` grid points per joint (default: about 40000 nodes in all). The grid path's
    first and last nodes, the ones nearest to start and goal, are replaced by start and goal.
    """
    arm = arm or Arm(robot, frame)
    lo, hi = joint_box(robot)
    start, goal = np.asarray(start, dtype=float), np.asarray(goal, dtype=float)
    n = robot.nv
    for name, q in (("start", start), ("goal", goal)):
        if q.shape != (n,):
            raise DeriveError(f"robot '{robot.name}': {name} must have {n} values, got {q.size}")
        if not np.all(np.isfinite(q)):
            raise DeriveError(f"robot '{robot.name}': {name} {q.tolist()} is not finite")
        if np.any(q < lo - 1e-12) or np.any(q > hi + 1e-12):
            raise DeriveError(f"robot '{robot.name}': {name} {q.tolist()} is outside the joint box {lo.tolist()} .. {hi.tolist()}")
    if not (math.isfinite(margin) and margin >= 0):
        raise DeriveError(f"robot '{robot.name}': the margin must be a finite number >= 0, got {margin:g}")
    per = resolution if resolution is not None else max(3, round(40000 ** (1.0 / n)))
    if per < 2 or per ** n > MAX_NODES:
        raise DeriveError(f"robot '{robot.name}': a grid of {per}^{n} nodes is not searchable (2 .. {MAX_NODES} nodes); "
                          "choose another --resolution")
    axes = [np.linspace(a, b, per) for a, b in zip(lo, hi)]
    hit = collisions(arm, np.vstack([start, goal]), list(obstacles), margin)
    for name, k in (("start", 0), ("goal", 1)):
        if hit[k] >= 0:
            raise DeriveError(f"robot '{robot.name}': the {name} configuration collides with obstacle "
                              f"{hit[k] + 1} ({obstacles[hit[k]].describe()})")
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, n)
    free = (collisions(arm, grid, list(obstacles), margin) < 0).reshape((per,) * n)
    step = (hi - lo) / (per - 1)
    snap = [tuple(int(i) for i in np.clip(np.round((q - lo) / step), 0, per - 1)) for q in (start, goal)]
    res = astar(free, snap[0], snap[1], step, connectivity)
    if res is None:
        return PlanResult(False, f"no path: the goal is not reachable from the start on the {per}^{n} grid "
                                 f"({int((~free).sum())} of {free.size} nodes in collision)",
                          np.zeros((0, n)), math.inf, 0, axes, free)
    path = np.array([[axes[k][i] for k, i in enumerate(node)] for node in res.nodes])
    path[0], path[-1] = start, goal
    if len(path) == 1:
        path = np.vstack([start, goal])
    length = float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())
    return PlanResult(True, f"path of {len(path)} waypoints, joint-space length {length:.4f} "
                            f"({res.expanded} nodes expanded of {free.size})", path, length, res.expanded, axes, free)
