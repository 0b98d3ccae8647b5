"""What ``derive view`` draws, from models.yaml alone: p_world = world_T_f(q) p_f.

Every primitive hangs on one frame f (a link, or a named frame such as ``tcp``) at constant local
coordinates p_f; a configuration q gives every frame's pose world_T_f (4x4, world z up), and the
drawing is those primitives carried to the world. :class:`Geometry` holds the local part (built
once per robot), :class:`Kinematics` the poses (the generated ``fk_all`` where the robot's current
generated Python is at hand, else the numpy reference), :func:`place` the world coordinates:

- the skeleton: a segment from each joint's parent frame origin to its child frame origin (the
  joint origins, as a stick figure draws them), and from a link's origin to each named frame on it;
- joint axes: a segment of ``axis_length`` along each joint's axis (and ``axis2``) from its origin;
- frames: every link and named frame as an RGB triad (x red, y green, z blue);
- CoM spheres: a steel ball (7850 kg/m^3) of the link's mass at its centre of mass, radius
  (3 m / (4 pi rho))^(1/3);
- equivalent-inertia boxes: the uniform box of the link's mass with the same principal moments,
  edge a_k = sqrt(6 (I_i + I_j - I_k) / m) along principal axis k (a negative radicand, a rod's
  rounding, drawn as 0), centred at the CoM.

Pure numpy: viser (:mod:`derive.view.server`) and the HTML page (:mod:`derive.view.page`) only draw it.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from derive.codegen.generate import model_hash
from derive.description import expr
from derive.description.robot import Robot
from derive.errors import DeriveError
from derive.reference.rnea import NumericRobot, rpy_matrix
from derive.runtime.python import candidates, generated
from derive.solvers.identify import read_measurements

STEEL = 7850.0
"""kg/m^3 of the CoM spheres: a steel ball of the link's mass."""
AXIS_SHARE, FRAME_SHARE = 0.12, 0.06
"""Joint-axis and frame-triad lengths as shares of the robot's size (:attr:`Geometry.size`)."""
AXIS_JOINTS = ("revolute", "continuous", "prismatic", "helical", "cylindrical", "universal")
"""Joint types drawn with their axis (a spherical joint has none: its frame shows the turn)."""


@dataclass(frozen=True)
class Geometry:
    """The primitives of one robot in their frames' coordinates (indices into ``frames``).

    ``segments`` (S, 2) frame pairs of the skeleton; ``axes`` (A,) frame and ``axis_dirs`` (A, 3) unit
    joint axes in that frame, named ``axis_names``; per body with mass (B,): ``body_frames``,
    ``masses``, ``coms`` (B, 3) and ``box_rotations`` (B, 3, 3), ``box_sizes`` (B, 3) in the body's
    frame; ``size`` (m) the robot's extent at its initial q, which scales axes and triads.
    """

    robot: str
    frames: tuple[str, ...]
    segments: np.ndarray
    axes: np.ndarray
    axis_dirs: np.ndarray
    axis_names: tuple[str, ...]
    body_frames: np.ndarray
    masses: np.ndarray
    coms: np.ndarray
    box_rotations: np.ndarray
    box_sizes: np.ndarray
    size: float = 1.0
    up: tuple[float, float, float] = (0.0, 0.0, 1.0)

    @property
    def com_radii(self) -> np.ndarray:
        """Radius (m) of each CoM sphere: a steel ball of the link's mass."""
        return np.cbrt(3.0 * self.masses / (4.0 * math.pi * STEEL))

    @property
    def axis_length(self) -> float:
        return AXIS_SHARE * self.size

    @property
    def frame_length(self) -> float:
        return FRAME_SHARE * self.size


@dataclass(frozen=True)
class Placed:
    """One configuration's drawing in world coordinates (m): ``segments`` (S, 2, 3), ``axes`` (A, 2, 3)
    from the joint origin along its axis, ``frames`` (F, 4, 4) the poses, ``coms`` (B, 3),
    ``box_centres`` (B, 3) and ``box_rotations`` (B, 3, 3) (columns: the box edges' directions)."""

    segments: np.ndarray
    axes: np.ndarray
    frames: np.ndarray
    coms: np.ndarray
    box_centres: np.ndarray
    box_rotations: np.ndarray


def equivalent_box(mass: float, inertia: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(R, edges) of the uniform box with ``mass`` and the inertia (3x3, about the CoM): inertia =
    R diag(I_k) R^T with I_k = m (a_i^2 + a_j^2) / 12, so a_k = sqrt(6 (I_i + I_j - I_k) / m); R a
    proper rotation (det +1) whose columns are the principal axes."""
    moments, R = np.linalg.eigh(0.5 * (inertia + inertia.T))
    if np.linalg.det(R) < 0:
        R[:, 2] = -R[:, 2]
    if mass <= 0:
        return R, np.zeros(3)
    total = moments.sum()
    edges = np.sqrt(np.clip(6.0 * (total - 2.0 * moments) / mass, 0.0, None))
    return R, edges


def initial_q(robot: Robot) -> np.ndarray:
    """The configuration shown first: 0 clipped into each joint's limits (identity base pose)."""
    lower, upper = robot.joint_box()
    joints = np.clip(0.0, lower, upper)
    if robot.floating:
        return np.concatenate([[0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0], joints[7:]])
    return joints


def geometry(robot: Robot, kinematics: "Kinematics | None" = None) -> Geometry:
    """The primitives of ``robot`` (see the module docstring), at its parameters' default values."""
    env = dict(robot.parameter_defaults)

    def num(value) -> float:
        return float(expr.evaluate(value, env))

    frames = tuple(robot.frame_names)
    index = {name: k for k, name in enumerate(frames)}
    segments = [(index[j.parent], index[j.child]) for j in robot.joints]
    segments += [(index[f.link], index[f.name]) for f in robot.frames]
    axes, dirs, names = [], [], []
    for joint in robot.joints:
        if joint.type not in AXIS_JOINTS:
            continue
        for k, axis in enumerate((joint.axis, joint.axis2) if joint.type == "universal" else (joint.axis,)):
            a = np.array([num(v) for v in axis], dtype=float)
            axes.append(index[joint.child])
            dirs.append(a / np.linalg.norm(a))
            names.append(joint.name if joint.type != "universal" else f"{joint.name}_{k + 1}")
    body_frames, masses, coms, rotations, sizes = [], [], [], [], []
    for link in robot.links:
        mass = num(link.mass)
        if mass <= 0:
            continue
        turn = rpy_matrix(*[num(v) for v in link.inertia_rpy])
        inertia = turn @ np.array([[num(x) for x in row] for row in link.inertia]) @ turn.T
        R, edges = equivalent_box(mass, inertia)
        body_frames.append(index[link.name])
        masses.append(mass)
        coms.append([num(v) for v in link.com])
        rotations.append(R)
        sizes.append(edges)
    geo = Geometry(robot.name, frames, np.array(segments, dtype=int).reshape(-1, 2), np.array(axes, dtype=int),
                   np.array(dirs, dtype=float).reshape(-1, 3), tuple(names), np.array(body_frames, dtype=int),
                   np.array(masses, dtype=float), np.array(coms, dtype=float).reshape(-1, 3),
                   np.array(rotations, dtype=float).reshape(-1, 3, 3), np.array(sizes, dtype=float).reshape(-1, 3))
    kin = kinematics or Kinematics(robot)
    origins = kin.poses(initial_q(robot))[:, :3, 3]
    extent = float(np.max(np.ptp(origins, axis=0))) if len(origins) else 0.0
    gravity = np.array([num(v) for v in robot.gravity], dtype=float)
    up = tuple(-gravity / np.linalg.norm(gravity)) if np.linalg.norm(gravity) > 0 else (0.0, 0.0, 1.0)
    return Geometry(**{**geo.__dict__, "size": max(extent, 0.1), "up": tuple(float(x) for x in up)})


def upright(up) -> np.ndarray:
    """The rotation (3x3) that turns ``up`` (a unit vector) to +z by the shortest turn (about x by pi
    for -z): how the page shows a robot whose gravity is not along -z, a planar arm in x-y, upright."""
    u = np.asarray(up, dtype=float)
    c = float(u[2])
    if c < -1 + 1e-12:
        return np.diag([1.0, -1.0, -1.0])
    k = np.cross(u, [0.0, 0.0, 1.0])
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + K + K @ K / (1 + c)


def place(geo: Geometry, poses: np.ndarray) -> Placed:
    """The primitives of ``geo`` in the world at the frame poses ``poses`` (F, 4, 4): p = world_T_f p_f."""
    origins = poses[:, :3, 3]
    R = poses[:, :3, :3]
    seg = origins[geo.segments] if len(geo.segments) else np.zeros((0, 2, 3))
    start = origins[geo.axes] if len(geo.axes) else np.zeros((0, 3))
    tip = start + geo.axis_length * np.einsum("aij,aj->ai", R[geo.axes], geo.axis_dirs) if len(geo.axes) else start
    body = geo.body_frames
    coms = origins[body] + np.einsum("bij,bj->bi", R[body], geo.coms) if len(body) else np.zeros((0, 3))
    rot = R[body] @ geo.box_rotations if len(body) else np.zeros((0, 3, 3))
    return Placed(seg, np.stack([start, tip], axis=1), poses, coms, coms, rot)


def _current_module(robot: Robot, folder: str | Path | None):
    """The generated Python of ``robot`` if it was generated from this very model (manifest's model
    hash), else None: code of an older model would draw another robot."""
    path = next((p for p in candidates(robot.name, folder) if p.is_file()), None)
    if path is None:
        return None
    try:
        manifest = json.loads((path.parent.parent / "manifest.json").read_text())
    except (OSError, ValueError):
        return None
    if manifest.get("model_hash") != model_hash(robot)[:16]:
        return None
    return generated(robot.name, folder)


class Kinematics:
    """world_T_f(q) of every frame of ``robot.frame_names`` (F, 4, 4), and the IK of the frames that have one.

    The links' poses come from the generated ``fk_all`` (every link in one pass) when the robot's
    generated Python is current (./generated, else the shipped generated/), else from the numpy
    reference (:class:`~derive.reference.rnea.NumericRobot`); a named frame is its link's pose
    times its constant offset. ``source`` says which.
    """

    def __init__(self, robot: Robot, folder: str | Path | None = None):
        self.robot = robot
        self.reference = NumericRobot(robot)
        self.names = tuple(robot.frame_names)
        self.links = len(robot.link_names)
        self.module = _current_module(robot, folder)
        self.fk_all = getattr(self.module, "fk_all", None)
        self.source = "generated fk_all" if self.fk_all is not None else "numpy reference"
        at = self.reference.fk(self.reference.neutral())
        self.offsets = [(robot.link_names.index(f.link), np.linalg.inv(at[f.link]) @ at[f.name]) for f in robot.frames]

    def poses(self, q) -> np.ndarray:
        """(F, 4, 4) world_T_f at q (nq), frames in ``robot.frame_names`` order."""
        q = np.asarray(q, dtype=float)
        if self.fk_all is not None:
            links = np.asarray(self.fk_all(q), dtype=float).reshape(self.links, 4, 4)
        else:
            fk = self.reference.fk(q)
            links = np.array([fk[name] for name in self.names[:self.links]])
        named = [links[k] @ offset for k, offset in self.offsets]
        return np.concatenate([links, np.array(named).reshape(-1, 4, 4)])

    @property
    def ik_frames(self) -> tuple[str, ...]:
        """Frames with a generated ``ik_<frame>`` (none without current generated code)."""
        if self.module is None:
            return ()
        return tuple(f for f in self.names if callable(getattr(self.module, f"ik_{f}", None)))

    def ik(self, frame: str, target: np.ndarray, q0) -> tuple[np.ndarray, np.ndarray, int]:
        """(q, residual [m, rad], status: 0 solved, 1 not converged, 2 bad target) of the generated
        ``ik_<frame>`` from q0 towards world_T_frame = ``target``."""
        q, residual, status = getattr(self.module, f"ik_{frame}")(np.asarray(target, dtype=float), np.asarray(q0, dtype=float))
        return np.asarray(q, dtype=float), np.asarray(residual, dtype=float), int(status)


@dataclass(frozen=True)
class Trajectory:
    """A motion to play: times ``t`` (N,) in s and configurations ``q`` (N, nq)."""

    t: np.ndarray
    q: np.ndarray


def read_trajectory(robot: Robot, path: str | Path) -> Trajectory:
    """t and q of a trajectory CSV (t, q_<joint>, qd_<joint>, qdd_<joint>, tau_<joint>: what simulate,
    trajopt and excite write and identify reads), read by identify's reader; a one-line DeriveError
    naming the file otherwise."""
    if robot.floating:
        raise DeriveError(f"view {robot.name}: {path}: trajectories of a floating base are not read yet "
                          "(the CSV has no base pose columns)")
    data = read_measurements(path, list(robot.velocity_names), what="view")
    if len(data.t) > 1 and np.any(np.diff(data.t) < 0):
        raise DeriveError(f"view: {path}: column t goes back in time (the samples must be in time order)")
    return Trajectory(np.asarray(data.t, dtype=float), np.asarray(data.q, dtype=float))


def frames_to_show(trajectory: Trajectory, most: int = 600) -> np.ndarray:
    """Indices of the samples drawn when playing ``trajectory``: all, or ``most`` evenly spread in time
    (first and last included), so a long log still makes a small page."""
    n = len(trajectory.t)
    if n <= most:
        return np.arange(n)
    wanted = np.linspace(trajectory.t[0], trajectory.t[-1], most)
    return np.unique(np.clip(np.searchsorted(trajectory.t, wanted), 0, n - 1))
