"""Configuration space and workspace (lecture section 2.4, figure 4).

The configuration space is the box of joint values q (within the joint limits;
revolute joints without limits span [-pi, pi], prismatic ones [-1, 1] m; a continuous
joint spans (-pi, pi], each of its configurations once). The
workspace is its image under forward kinematics, x = FK(q) (eq. 11, 23): the
positions the frame reaches in at least one configuration. It is sampled on a
grid or at random; FK is the derived CasADi expression, evaluated for all
samples at once.

The arm's skeleton, the origins of the link frames from the root to a frame,
is evaluated the same way: drawings and the planner's collision checks use it.
:attr:`Arm.speed_bounds` bounds how fast each skeleton point moves per unit of each
joint coordinate, anywhere in the joint box (the planner's edge checks use it).
The figure of both spaces is :func:`derive.plot.workspace.plot_workspace`.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property
from typing import Callable

import casadi as ca
import numpy as np

from derive.description import expr
from derive.description.robot import Robot
from derive.errors import DeriveError
from derive.symbolic.kinematics import Kinematics, joint_motions
from derive.symbolic.symbols import make_symbols

AXIS_NAMES = "xyz"
MAX_SAMPLES = 10_000_000
"""Most configurations a workspace samples: FK costs microseconds each, so 1e7 of them take minutes."""
KEPT_SAMPLES = 200_000
"""Samples a :class:`Workspace` keeps (for the figures and :meth:`Manipulability.batch`); beyond that a
seeded random subset is kept, while the extents and the reach cover every sample."""
CHUNK = 65_536
"""Configurations sampled and mapped through FK at a time: memory stays bounded whatever the count."""


def joint_box(robot: Robot) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) of q as arrays: the limits of each coordinate, else [-pi, pi] (angles) or [-1, 1] m."""
    lo, hi = robot.joint_box()
    return np.array(lo), np.array(hi)


def sample_count(robot: Robot, n: int, method: str = "grid") -> int:
    """How many configurations :func:`sample_configurations` returns for ``n``: n, or round(n^(1/nv))^nv on a grid."""
    if method == "random":
        return n
    if method != "grid":
        raise DeriveError(f"sampling method '{method}': expected grid or random")
    return _grid_points(robot, n) ** robot.nv


def _grid_points(robot: Robot, n: int) -> int:
    return max(2, round(n ** (1.0 / robot.nv)))


def sample_configurations(robot: Robot, n: int, method: str = "grid", seed: int = 0) -> np.ndarray:
    """About ``n`` configurations (rows) in the joint box: a regular grid of round(n^(1/nv))
    points per joint (limits included; a continuous joint's in (-pi, pi], -pi being pi), or
    ``n`` uniform random samples."""
    total = sample_count(robot, n, method)
    if total <= 0:
        return np.zeros((0, robot.nv))
    return np.vstack(list(_sample_chunks(robot, n, method, seed, total)))


def _sample_chunks(robot: Robot, n: int, method: str, seed: int, chunk: int | None = None):
    """The configurations of :func:`sample_configurations`, ``chunk`` (default :data:`CHUNK`) rows at a
    time, in the same order (numpy's generator draws the same stream in pieces as at once)."""
    chunk = chunk or CHUNK
    lo, hi = joint_box(robot)
    total = sample_count(robot, n, method)
    if method == "random":
        rng = np.random.default_rng(seed)
        for start in range(0, total, chunk):
            yield robot.wrap(rng.uniform(lo, hi, size=(min(chunk, total - start), robot.nv)))  # [-pi, pi) -> (-pi, pi]
        return
    per = _grid_points(robot, n)
    turns = [i in robot.continuous_indices for i in range(robot.nv)]
    axes = np.array([np.linspace(a, b, per + 1)[1:] if turn else np.linspace(a, b, per)  # (nv, per)
                     for a, b, turn in zip(lo, hi, turns)])
    for start in range(0, total, chunk):
        index = np.unravel_index(np.arange(start, min(start + chunk, total)), (per,) * robot.nv)  # C order, as meshgrid "ij"
        yield np.column_stack([axes[k][i] for k, i in enumerate(index)])


class Arm:
    """Batched kinematics of one frame of a robot: the frame's position and the arm's skeleton.

    ``skeleton(Q)`` returns, per configuration, the origins of the root, of every link
    on the way to the frame and of the frame itself (points that coincide for every q,
    such as a DH model's intermediate frames, are dropped): the arm drawn as line segments.
    """

    BLOCK = 4096  # configurations per CasADi call

    def __init__(self, robot: Robot, frame: str = "tcp"):
        robot.require_fixed_base("the workspace and planning tools")
        self.robot, self.frame = robot, frame
        self._maps: dict[int, ca.Function] = {}
        sym = make_symbols(robot)
        kin = Kinematics(robot, sym)
        if frame not in kin.poses:
            raise DeriveError(f"robot '{robot.name}': no frame '{frame}' (frames: {', '.join(kin.poses)})")
        chain = [frame]
        link = next((f.link for f in robot.frames if f.name == frame), frame)
        if link != frame:
            chain.append(link)
        while (j := robot.parent_joint(chain[-1])) is not None:
            chain.append(j.parent)
        chain.reverse()
        points = ca.horzcat(*[kin.poses[name].p for name in chain])  # 3 x len(chain)
        self._p = np.array([p.default for p in robot.parameters])
        f = ca.Function("skeleton", [sym.q, sym.p], [points])
        self.nv = robot.nv
        probes = [np.array(f(q, self._p)) for q in sample_configurations(robot, 3, "random", seed=12345)]
        keep = [0]
        for k in range(1, len(chain)):
            if max(np.linalg.norm(P[:, k] - P[:, keep[-1]]) for P in probes) > 1e-12:
                keep.append(k)
            elif k == len(chain) - 1:  # the chain ends at the frame itself, not at a point equal to it
                keep[-1 if len(keep) > 1 else len(keep):] = [k]
        self.chain = [chain[k] for k in keep]
        self._f = ca.Function("skeleton", [sym.q, sym.p], [points[:, keep]])
        self.speed_bounds = _speed_bounds(robot, chain)[:, keep]

    def displacement_bound(self, dQ) -> np.ndarray:
        """(N,) upper bound on how far any skeleton point (hence any point of the segments
        between them) moves along the straight joint-space line q -> q + dq, for each row dq
        of dQ, with both ends in the joint box: max over points j of sum_k B[k, j] |dq_k|."""
        dQ = np.atleast_2d(np.asarray(dQ, dtype=float))
        return (np.abs(dQ) @ self.speed_bounds).max(axis=1)

    def skeleton(self, Q) -> np.ndarray:
        """(N, m, 3) origins along the chain for N configurations (rows of Q)."""
        Q = np.atleast_2d(np.asarray(Q, dtype=float))
        if Q.shape[1] != self.nv:
            raise DeriveError(f"robot '{self.robot.name}': q must have {self.nv} entries, got {Q.shape[1]}")
        m = len(self.chain)
        out = np.empty((Q.shape[0], m, 3))
        for start in range(0, Q.shape[0], self.BLOCK):  # bounded memory for big samples
            block = Q[start:start + self.BLOCK]
            n = block.shape[0]
            size = max(64, 1 << (n - 1).bit_length())  # maps of a few sizes, built once (building one costs)
            if size not in self._maps:
                self._maps[size] = self._f.map(size)
            if size > n:
                block = np.vstack([block, np.zeros((size - n, self.nv))])
            res = self._maps[size](block.T, self._p).full()  # 3 x (m * size); the parameters are broadcast
            out[start:start + n] = res.reshape(3, size, m)[:, :n].transpose(1, 2, 0)
        return out

    def position(self, Q) -> np.ndarray:
        """(N, 3) positions of the frame."""
        return self.skeleton(Q)[:, -1, :]


def _speed_bounds(robot: Robot, chain: list[str]) -> np.ndarray:
    """(nv, len(chain)) B with |d p_j / d q_k| <= B[k, j] for every q in the joint box, where p_j
    is the origin of ``chain[j]`` (links from the root, possibly ending at a named frame).

    A turn q_k (revolute, or one turn of a universal/spherical joint; each is a rotation about a
    unit axis through the joint frame's origin o_k) moves p_j at |a_k x (p_j - o_k)| <= |p_j - o_k|;
    a slide at 1; a helical joint at |p_j - o_k| + |pitch|. |p_j - o_k| is at most the sum of the
    lengths of the translations met from o_k to p_j (triangle inequality; rotations keep
    lengths): the joint origins' |xyz|, a frame's |xyz| and max |q| over the box of every slide.
    Coordinates off the chain, or after p_j on it, do not move p_j (B = 0).
    """
    env = {p.name: float(p.default) for p in robot.parameters}

    def length(xyz) -> float:
        return float(np.linalg.norm([float(expr.evaluate(v, env)) for v in xyz]))

    lo, hi = robot.joint_box()
    index = {c.name: i for i, c in enumerate(robot.coordinates)}
    links = {link.name for link in robot.links}
    pieces: list[tuple] = [("point", 0)]  # ("len", metres) | ("coord", k, kind, |pitch|) | ("point", j)
    for j, name in enumerate(chain[1:], start=1):
        joint = robot.parent_joint(name) if name in links else None
        if joint is None:  # a named frame on its link
            frame = next(f for f in robot.frames if f.name == name)
            pieces.append(("len", length(frame.origin.xyz)))
        else:
            pieces.append(("len", length(joint.origin.xyz)))
            for m in joint_motions(joint):
                k = index[m.coordinate]
                travel = max(abs(lo[k]), abs(hi[k]))
                pitch = abs(float(expr.evaluate(m.pitch, env))) if m.kind == "helical" else 0.0
                pieces.append(("coord", k, m.kind, pitch))
                if m.kind == "prismatic":
                    pieces.append(("len", travel))
                elif m.kind == "helical":
                    pieces.append(("len", pitch * travel))
        pieces.append(("point", j))
    B = np.zeros((robot.nv, len(chain)))
    for s, piece in enumerate(pieces):
        if piece[0] != "coord":
            continue
        _, k, kind, pitch = piece
        reach = 0.0
        for later in pieces[s + 1:]:
            if later[0] == "len":
                reach += later[1]
            elif later[0] == "point":
                B[k, later[1]] = 1.0 if kind == "prismatic" else reach + pitch
    return B


@dataclass
class Workspace:
    """Samples of the configuration space and their images: ``points[i] = FK(q[i])``.

    ``q`` and ``points`` hold at most :data:`KEPT_SAMPLES` of the ``count`` samples (all of them
    when there are no more); ``lower``, ``upper`` (the box of the points) and ``reach_range``
    (least and greatest distance from the base) cover every sample.
    """

    robot: Robot
    frame: str
    q: np.ndarray  # (N, nv)
    points: np.ndarray  # (N, 3)
    base: np.ndarray  # (3,), the root's origin
    count: int = 0  # samples mapped through FK (0: len(q))
    lower: np.ndarray | None = None  # (3,) smallest coordinates over every sample (None: of points)
    upper: np.ndarray | None = None
    reach_range: tuple[float, float] | None = None

    def __post_init__(self):
        self.count = self.count or len(self.q)
        if self.lower is None:
            self.lower, self.upper = self.points.min(axis=0), self.points.max(axis=0)
        if self.reach_range is None:
            self.reach_range = (float(self.reach.min()), float(self.reach.max()))

    @cached_property
    def plane(self) -> tuple[int, ...]:
        """Axes along which the points move (all three unless the robot is planar)."""
        extent = self.upper - self.lower
        return tuple(i for i in range(3) if extent[i] > 1e-9 * max(extent.max(), 1e-300))

    @property
    def reach(self) -> np.ndarray:
        """Distance of every kept sample from the base origin."""
        return np.linalg.norm(self.points - self.base, axis=1)

    def summary(self) -> str:
        lo, hi = self.lower, self.upper
        box = ", ".join(f"{AXIS_NAMES[i]} in [{lo[i]:.4g}, {hi[i]:.4g}]" for i in range(3))
        kind = "planar in " + "".join(AXIS_NAMES[i] for i in self.plane) if len(self.plane) < 3 else "spatial"
        return (f"{self.robot.name}/{self.frame}: {self.count} configurations -> workspace ({kind})\n"
                f"  {box}\n  distance from the base: {self.reach_range[0]:.4g} .. {self.reach_range[1]:.4g}")


def workspace(robot: Robot, frame: str = "tcp", n: int = 40000, method: str = "grid", seed: int = 0,
              arm: Arm | None = None, keep: int = KEPT_SAMPLES,
              progress: Callable[[int, int], None] | None = None) -> Workspace:
    """Sample the configuration space (:func:`sample_configurations`) and map the samples through FK.

    The samples go through FK :data:`CHUNK` at a time, so memory stays bounded; at most ``keep``
    of them are kept (a seeded random subset when there are more), the extents cover all.
    ``progress(done, total)`` is called after every chunk. At most :data:`MAX_SAMPLES` samples.
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise DeriveError(f"robot '{robot.name}': the number of samples must be an integer >= 1, got {n!r}")
    total = sample_count(robot, n, method)
    if n > MAX_SAMPLES:
        raise DeriveError(f"robot '{robot.name}': {n} samples are more than {MAX_SAMPLES} (FK of each costs "
                          "microseconds: hours of work); sample fewer")
    arm = arm or Arm(robot, frame)
    kept = None if total <= keep else np.sort(np.random.default_rng(seed).choice(total, keep, replace=False))
    Qs, Ps = [], []
    lower, upper = np.full(3, np.inf), np.full(3, -np.inf)
    rmin, rmax, done, base = np.inf, -np.inf, 0, None
    for Q in _sample_chunks(robot, n, method, seed):
        sk = arm.skeleton(Q)
        P = sk[:, -1, :]
        base = sk[0, 0, :] if base is None else base
        lower, upper = np.minimum(lower, P.min(axis=0)), np.maximum(upper, P.max(axis=0))
        r = np.linalg.norm(P - base, axis=1)
        rmin, rmax = min(rmin, float(r.min())), max(rmax, float(r.max()))
        if kept is None:
            Qs.append(Q)
            Ps.append(P)
        else:
            pick = kept[(kept >= done) & (kept < done + len(Q))] - done
            Qs.append(Q[pick])
            Ps.append(P[pick])
        done += len(Q)
        if progress:
            progress(done, total)
    return Workspace(robot, frame, np.vstack(Qs), np.vstack(Ps), base, total, lower, upper, (rmin, rmax))
