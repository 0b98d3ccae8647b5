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
exactly (segment-circle distance, slab test for boxes).

Edges are checked too, at a workspace resolution ``check_step`` (metres; default
:data:`CHECK_STEP`, or half the smallest obstacle, grown by the margin, when that is
smaller). A straight joint-space motion by dq moves the skeleton point p_j by at most
sum_k B[k, j] |dq_k| (:attr:`Arm.speed_bounds`: a turn moves a point at most at its
distance from the axis, bounded along the chain by the triangle inequality; a slide at
1), and the segments' points, convex combinations of their end points, no further. An
edge is cut into n = ceil(that bound / check_step) equal pieces and the n + 1
configurations are checked in one batch, so between checks no point of the arm moves
more than check_step: along an accepted edge every point of the arm stays within
check_step / 2 of where it was in a checked, collision-free configuration, so no link
enters an obstacle (grown by the margin) deeper than check_step / 2 (add check_step / 2
to the margin for a strict guarantee). A* evaluates edges lazily: an edge is checked
when the node it reaches is taken from the open list (in batches of the best few
candidates), so only edges the search needs are checked, and the path is the shortest
over free nodes and free edges. The path returned (start, grid nodes, goal) is verified
again at the same resolution before success is reported; if that fails, the result is
a failure that says where ("cannot certify the path: ...").

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
CHECK_STEP = 0.01  # m: default largest motion of any point of the arm between two collision checks
CHECK_CHUNK = 100_000  # configurations per batched FK + collision call
MAX_PIECES = 100_000
"""Most collision checks along one grid edge (its bound on the arm's motion / the check step): a check
step far below the arm's size would check each edge at millions of configurations."""
MAX_LENGTH = 1e6
"""Largest obstacle coordinate, radius or margin, in m: a thousand kilometres is beyond any arm, and the
squared distances of the collision tests stay finite."""


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
          connectivity: str = "full", edge_free=None, batch: int = 8) -> GridPath | None:
    """Shortest path on a boolean grid (True = free) from ``start`` to ``goal`` (index tuples), or None.

    Step cost and heuristic are Euclidean with the grid ``spacing`` per axis (default 1).
    Returns the node sequence, its cost and the number of expanded nodes.

    ``edge_free(A, B)``, given (E, ndim) index arrays of edges A[e] -> B[e] between free
    nodes, returns (E,) True where the edge is free; without it every edge between free
    neighbours is. Edges are then evaluated lazily (lazy weighted A*): an open node keeps
    its best candidate parent among the closed nodes, and the edge from that parent is
    checked only when the node is taken from the open list (in one call together with the
    next ``batch`` - 1 unchecked candidates of the list). A refused edge makes the node
    look for its next best closed parent. With a consistent heuristic a node's first
    accepted candidate carries its shortest distance over free edges, so the path is
    optimal on the graph of free nodes and free edges; no edge is checked twice, and
    start and goal in different components of the free nodes are answered without search.
    """
    free = np.asarray(free, dtype=bool)
    shape = free.shape
    ndim = free.ndim
    h_scale = np.ones(ndim) if spacing is None else np.asarray(spacing, dtype=float)
    start, goal = tuple(int(i) for i in start), tuple(int(i) for i in goal)
    for name, node in (("start", start), ("goal", goal)):
        if len(node) != ndim or any(not 0 <= i < n for i, n in zip(node, shape)):
            raise DeriveError(f"A*: {name} {node} is outside the grid {shape}")
    if not free[start] or not free[goal]:
        return None
    lazy = edge_free is not None
    offsets = np.array(neighbour_offsets(ndim, connectivity), dtype=np.int64).reshape(-1, ndim)
    if lazy and start != goal:
        from scipy.ndimage import label

        structure = np.ones((3,) * ndim, dtype=bool) if connectivity == "full" else None
        labels, _ = label(free, structure=structure)
        if labels[start] != labels[goal]:  # the checked edges are a subset: no path either
            return None
    strides = np.array([int(np.prod(shape[k + 1:])) for k in range(ndim)], dtype=np.int64)
    flat_off = offsets @ strides
    step_cost = np.linalg.norm(offsets * h_scale, axis=1)
    size = free.size
    free_flat = free.reshape(-1)
    s_flat, g_flat = int(np.dot(start, strides)), int(np.dot(goal, strides))

    def coords(node: int) -> np.ndarray:
        return np.array(np.unravel_index(node, shape))

    h = sum(((np.arange(n) - goal[k]) * h_scale[k]).reshape([-1 if i == k else 1 for i in range(ndim)]) ** 2
            for k, n in enumerate(shape))
    h = np.sqrt(np.broadcast_to(h, shape)).reshape(-1)  # the heuristic of every node

    def neighbours(node: int):
        """(flat indices, offset indices) of the in-grid neighbours of a node."""
        c = coords(node) + offsets
        inside = np.flatnonzero(((c >= 0) & (c < shape)).all(axis=1))
        return node + flat_off[inside], inside

    best = np.full(size, math.inf)  # cost of an open node's best candidate; of a closed node, its distance
    best_par = np.full(size, -1, dtype=np.int64)
    closed = np.zeros(size, dtype=bool)
    checked: dict[tuple[int, int], bool] = {}  # (parent, node) -> edge free
    tie = itertools.count()  # equal f: first pushed first, so the order is deterministic
    best[s_flat] = 0.0
    heap = [(float(h[s_flat]), next(tie), 0.0, s_flat, -1)]
    expanded = 0

    def current(e) -> bool:
        """The entry is its node's best candidate, and the node is still open."""
        return not closed[e[3]] and best[e[3]] == e[2] and best_par[e[3]] == e[4]

    def reparent(node: int) -> None:
        """After a refused edge: the node's next best closed parent, over edges not refused."""
        nbs, k = neighbours(node)
        keep = closed[nbs]
        nbs, cost = nbs[keep], best[nbs[keep]] + step_cost[k[keep]]
        best[node], best_par[node] = math.inf, -1
        for i in np.argsort(cost, kind="stable"):
            if checked.get((int(nbs[i]), node), True):
                best[node], best_par[node] = float(cost[i]), int(nbs[i])
                heapq.heappush(heap, (float(cost[i] + h[node]), next(tie), float(cost[i]), node, int(nbs[i])))
                return

    while heap:
        entry = heapq.heappop(heap)
        _, _, cost, node, par = entry
        if not current(entry):
            continue
        if lazy and par >= 0:
            if (par, node) not in checked:
                todo, held, asked = [entry], [], {(par, node)}
                while heap and len(todo) < batch:
                    e = heapq.heappop(heap)
                    if current(e):
                        held.append(e)
                        if e[4] >= 0 and (e[4], e[3]) not in checked and (e[4], e[3]) not in asked:
                            todo.append(e)
                            asked.add((e[4], e[3]))
                for e in held:
                    heapq.heappush(heap, e)
                A = np.stack(np.unravel_index([e[4] for e in todo], shape), axis=-1)
                B = np.stack(np.unravel_index([e[3] for e in todo], shape), axis=-1)
                checked.update(((e[4], e[3]), bool(v)) for e, v in zip(todo, edge_free(A, B)))
            if not checked[(par, node)]:
                reparent(node)
                continue
        closed[node] = True
        expanded += 1
        if node == g_flat:
            path = [node]
            while best_par[path[-1]] >= 0:
                path.append(int(best_par[path[-1]]))
            return GridPath([tuple(int(i) for i in coords(n)) for n in path[::-1]], cost, expanded)
        nbs, k = neighbours(node)
        cand = cost + step_cost[k]
        better = free_flat[nbs] & ~closed[nbs] & (cand < best[nbs])
        nbs, cand = nbs[better], cand[better]
        best[nbs], best_par[nbs] = cand, node
        for nb, c, f in zip(nbs.tolist(), cand.tolist(), (cand + h[nbs]).tolist()):
            heapq.heappush(heap, (f, next(tie), c, nb, node))
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
    if any(abs(x) > MAX_LENGTH for x in v):
        raise DeriveError(f"obstacle '{text}': every coordinate and radius must be within {MAX_LENGTH:g} m")
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


def obstacle_size(obstacle: Circle | Box, margin: float = 0.0) -> float:
    """The smallest extent of an obstacle grown by ``margin``: a circle's diameter, a box's shortest side."""
    if isinstance(obstacle, Circle):
        return 2.0 * (obstacle.radius + margin)
    return float(min(u - lo for lo, u in zip(obstacle.lower, obstacle.upper))) + 2.0 * margin


def default_check_step(obstacles=(), margin: float = 0.0) -> float:
    """:data:`CHECK_STEP`, or half the smallest obstacle (grown by ``margin``) when that is smaller, so an
    arm crossing an obstacle reaches a depth of at least one check step."""
    return min([CHECK_STEP] + [0.5 * obstacle_size(o, margin) for o in obstacles])


class MotionCheck:
    """Collision checks of straight joint-space motions q_a -> q_b at a workspace resolution ``step``.

    A motion is cut into n = ceil(D / step) equal pieces, D = :meth:`Arm.displacement_bound`
    of q_b - q_a (how far any point of the arm can move), and its n + 1 configurations are
    checked: between consecutive checks no point of the arm moves more than ``step``.
    All configurations of a batch of motions go through FK and the obstacle tests together
    (every 8th first, so most colliding motions are refused after an eighth of the work).
    ``checked`` counts the configurations tested.
    """

    COARSE = 8

    def __init__(self, arm: Arm, obstacles, margin: float = 0.0, step: float = CHECK_STEP):
        if not (math.isfinite(step) and step > 0):
            raise DeriveError(f"robot '{arm.robot.name}': the check step must be a finite length > 0 m, got {step:g}")
        self.arm, self.obstacles, self.margin, self.step = arm, list(obstacles), margin, float(step)
        self.checked = 0

    def pieces(self, QA, QB) -> np.ndarray:
        """(E,) number of pieces (>= 1) each motion is cut into."""
        D = self.arm.displacement_bound(np.asarray(QB, dtype=float) - np.asarray(QA, dtype=float))
        return np.maximum(1, np.ceil(D / self.step)).astype(int)

    def collide(self, Q: np.ndarray) -> np.ndarray:
        """(N,) index of the first obstacle each configuration (row of Q) hits, -1 when free."""
        if not self.obstacles:  # nothing to hit: no FK either
            return np.full(len(Q), -1)
        self.checked += len(Q)
        out = np.empty(len(Q), dtype=int)
        for k in range(0, len(Q), CHECK_CHUNK):
            out[k:k + CHECK_CHUNK] = collisions(self.arm, Q[k:k + CHECK_CHUNK], self.obstacles, self.margin)
        return out

    def _samples(self, QA, QB, n, which):
        """Configurations i / n of the way from QA[e] to QB[e] for the (e, i) selected by ``which(i, n)``."""
        counts = n + 1
        owner = np.repeat(np.arange(len(n)), counts)
        i = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
        keep = which(i, n[owner])
        owner, i = owner[keep], i[keep]
        t = (i / n[owner])[:, None]
        return owner, i, QA[owner] + t * (QB[owner] - QA[owner])

    def free(self, QA, QB, ends: bool = True) -> np.ndarray:
        """(E,) True where the motion QA[e] -> QB[e] is collision-free at every check
        (``ends=False``: the end configurations are known to be free and are not tested)."""
        QA = np.atleast_2d(np.asarray(QA, dtype=float))
        QB = np.atleast_2d(np.asarray(QB, dtype=float))
        n = self.pieces(QA, QB)
        ok = np.ones(len(n), dtype=bool)
        e = 0 if ends else 1  # configurations i = e .. n - e of n + 1
        c = self.COARSE
        # pass 1: every c-th configuration (and the last); pass 2: the others, of the motions still free
        for coarse in (True, False):
            sel = np.flatnonzero(ok)
            owner, _, Q = self._samples(QA[sel], QB[sel], n[sel],
                                        lambda i, m: (i >= e) & (i <= m - e) & (((i % c == 0) | (i == m)) == coarse))
            if len(Q):
                ok[sel[np.unique(owner[self.collide(Q) >= 0])]] = False
        return ok

    def first_collision(self, path: np.ndarray):
        """None when every segment of ``path`` is free at this resolution, else
        (segment index, configuration, obstacle index) of the first colliding check."""
        path = np.asarray(path, dtype=float)
        if len(path) < 2:
            hit = self.collide(path)
            return None if not (hit >= 0).any() else (0, path[0], int(hit[0]))
        QA, QB = path[:-1], path[1:]
        owner, _, Q = self._samples(QA, QB, self.pieces(QA, QB), lambda i, m: i >= 0)
        hit = self.collide(Q)
        bad = np.flatnonzero(hit >= 0)
        if not len(bad):
            return None
        return int(owner[bad[0]]), Q[bad[0]], int(hit[bad[0]])


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
    check_step: float = CHECK_STEP  # m: no point of the arm moves more than this between collision checks
    checked: int = 0  # configurations tested for collision (nodes, edge and path checks)
    refused: int = 0  # grid edges between free nodes refused by the edge check

    @property
    def resolution(self) -> str:
        """The checking resolution, in words."""
        return (f"check step {self.check_step:.3g} m (no point of the arm moves further between two checked "
                f"configurations); {self.checked} configurations checked, {self.refused} grid "
                f"edge{'' if self.refused == 1 else 's'} refused")


def plan(robot: Robot, start, goal, obstacles=(), frame: str = "tcp", resolution: int | None = None,
         connectivity: str = "full", margin: float = 0.0, arm: Arm | None = None,
         check_step: float | None = None, progress=None) -> PlanResult:
    """A collision-free joint path from ``start`` to ``goal`` by A* on a grid over the joint box.

    ``resolution`` grid points per joint (default: about 40000 nodes in all). Nodes and the
    edges A* uses are checked (:class:`MotionCheck`, ``check_step`` m, default
    :func:`default_check_step`). The grid path runs between the nodes nearest to start and
    goal; start and goal are joined to it, replacing those nodes where the direct motion is
    free, and the whole path is verified at ``check_step`` before success is reported.
    ``progress(done, total)`` is called as the grid's nodes are checked.
    """
    arm = arm or Arm(robot, frame)
    obstacles = list(obstacles)
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
    if not (math.isfinite(margin) and 0 <= margin <= MAX_LENGTH):
        raise DeriveError(f"robot '{robot.name}': the margin must be a finite number >= 0 (at most {MAX_LENGTH:g} m), "
                          f"got {margin:g}")
    step_m = default_check_step(obstacles, margin) if check_step is None else float(check_step)
    check = MotionCheck(arm, obstacles, margin, step_m)
    per = resolution if resolution is not None else max(3, round(40000 ** (1.0 / n)))
    if per < 2 or per ** n > MAX_NODES:
        raise DeriveError(f"robot '{robot.name}': a grid of {per}^{n} nodes is not searchable (2 .. {MAX_NODES} nodes); "
                          "choose another --resolution")
    axes = [np.linspace(a, b, per) for a, b in zip(lo, hi)]
    step = (hi - lo) / (per - 1)
    pieces = float(arm.displacement_bound(step)[0]) / check.step  # the longest (diagonal) grid edge
    if pieces > MAX_PIECES:
        raise DeriveError(f"robot '{robot.name}': a check step of {check.step:g} m would check every grid edge at "
                          f"{pieces:.3g} configurations (more than {MAX_PIECES}); choose a larger --check-step "
                          "or a larger --resolution")
    hit = collisions(arm, np.vstack([start, goal]), obstacles, margin)
    for name, k in (("start", 0), ("goal", 1)):
        if hit[k] >= 0:
            raise DeriveError(f"robot '{robot.name}': the {name} configuration collides with obstacle "
                              f"{hit[k] + 1} ({obstacles[hit[k]].describe()})")
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, n)
    free = np.empty(len(grid), dtype=bool)
    for k in range(0, len(grid), CHECK_CHUNK):
        free[k:k + CHECK_CHUNK] = check.collide(grid[k:k + CHECK_CHUNK]) < 0
        if progress:
            progress(min(k + CHECK_CHUNK, len(grid)), len(grid))
    free = free.reshape((per,) * n)
    snap = [tuple(int(i) for i in np.clip(np.round((q - lo) / step), 0, per - 1)) for q in (start, goal)]
    refused = [0]

    def edge_free(A: np.ndarray, B: np.ndarray) -> np.ndarray:
        ok = check.free(lo + A * step, lo + B * step, ends=False)
        refused[0] += int((~ok).sum())
        return ok

    def result(success: bool, message: str, path=None, length=math.inf, expanded=0) -> PlanResult:
        return PlanResult(success, message, np.zeros((0, n)) if path is None else path, length, expanded, axes, free,
                          check.step, check.checked, refused[0])

    # edges per batched check: about 2048 configurations (few for long edges: a batch is partly speculative)
    batch = int(np.clip(2048 // check.pieces(lo, lo + step)[0], 8, 256))
    res = astar(free, snap[0], snap[1], step, connectivity, edge_free=edge_free, batch=batch)
    if res is None:
        return result(False, f"no path: the goal is not reachable from the start on the {per}^{n} grid "
                             f"({int((~free).sum())} of {free.size} nodes in collision, {refused[0]} "
                             f"edge{'' if refused[0] == 1 else 's'} refused)")
    nodes = np.array([[axes[k][i] for k, i in enumerate(node)] for node in res.nodes])
    path = _join_ends(check, start, nodes, goal)
    bad = check.first_collision(path)
    if bad is not None:
        seg, q, ob = bad
        where = ("start to its nearest grid node" if seg == 0 and len(path) > 2 else
                 "goal's nearest grid node to the goal" if seg == len(path) - 2 and len(path) > 2 else
                 f"waypoint {seg} to {seg + 1}")
        return result(False, f"cannot certify the path: its segment from the {where} collides with obstacle {ob + 1} "
                             f"({obstacles[ob].describe()}) at q = [{', '.join(f'{x:.4g}' for x in q)}] "
                             f"(check step {check.step:.3g} m); refine --resolution", expanded=res.expanded)
    length = float(np.linalg.norm(np.diff(path, axis=0), axis=1).sum())
    return result(True, f"path of {len(path)} waypoints, joint-space length {length:.4f}, checked every {check.step:.3g} m "
                        f"({res.expanded} nodes expanded of {free.size})", path, length, res.expanded)


def _join_ends(check: MotionCheck, start: np.ndarray, nodes: np.ndarray, goal: np.ndarray) -> np.ndarray:
    """start + grid nodes + goal, the first (last) node replaced by start (goal) where the direct
    motion to the second (from the last-but-one) node is free at the check resolution."""
    path = [start] + list(nodes) + [goal]
    if len(path) > 2 and np.array_equal(path[0], path[1]):
        path.pop(1)
    if len(path) > 2 and np.array_equal(path[-1], path[-2]):
        path.pop(-2)
    if len(path) > 2 and check.free(path[0], path[2])[0]:
        path.pop(1)
    if len(path) > 2 and check.free(path[-3], path[-1])[0]:
        path.pop(-2)
    return np.array(path)
