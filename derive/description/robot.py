"""The robot description: validated, frozen dataclasses (what models.yaml, DH tables and URDF become).

No CAS lives here. Numeric fields hold a float or a parameter expression string
(see :mod:`derive.description.expr`); the symbolic side and the numeric reference each
evaluate them in their own algebra.

Conventions (URDF's):
- a joint's ``origin`` places the joint frame in the parent link frame as
  ``Trans(xyz) * Rz(yaw) * Ry(pitch) * Rx(roll)``; the joint then moves along or
  about ``axis`` given in the joint frame, and the child link frame is the moved
  joint frame;
- a link's inertia is about its centre of mass, expressed in the inertial frame,
  which sits at ``com`` in the link frame rotated by ``inertia_rpy``;
- the root link (the only link that is no joint's child) is the world frame;
  gravity is a vector in that frame.
"""

from __future__ import annotations

import keyword
import math
import re
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from derive.description.joints import COORDINATE_SUFFIXES, JOINT_TYPES, motion_type, wrap_angle

from derive.errors import DeriveError

C_KEYWORDS = frozenset(
    "auto break case char const continue default do double else enum extern float for goto if inline int "
    "long register restrict return short signed sizeof static struct switch typedef union unsigned void "
    "volatile while _Bool _Complex _Imaginary real".split()
)
_IDENT = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")

Value = Any  # float | str (parameter expression)
Vec3 = tuple  # tuple[Value, Value, Value]


class ModelError(DeriveError):
    """Bad model input: one line naming the robot, the field and the problem."""

    def __init__(self, robot: str | None, field_path: str, problem: str, source: str | None = None):
        self.robot, self.field, self.problem, self.source = robot, field_path, problem, source
        where = f"robot '{robot}'" if robot else "models file"
        if source:
            where = f"{source}: {where}" if robot else f"models file {source}"
        text = f"{where}: {field_path}: {problem}" if field_path else f"{where}: {problem}"
        # one line whatever the names hold (a URDF name may carry &#10; or a line separator)
        super().__init__("".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in text))

    def in_file(self, source: str | None) -> "ModelError":
        """The same error, naming the file it came from (if known)."""
        return self if self.source or not source else ModelError(self.robot, self.field, self.problem, source)


@dataclass(frozen=True)
class Parameter:
    name: str
    default: float


@dataclass(frozen=True)
class Origin:
    """Pose of a child frame in its parent frame: Trans(xyz) * RPY(rpy)."""

    xyz: Vec3 = (0.0, 0.0, 0.0)
    rpy: Vec3 = (0.0, 0.0, 0.0)


VISUAL_SHAPES = ("mesh", "box", "cylinder", "sphere", "capsule")
"""What a link's ``visual`` draws: a mesh file or a primitive shape."""


@dataclass(frozen=True)
class Visual:
    """One piece of a link's looks (URDF ``<visual>``, MJCF ``<geom>``), for ``derive view`` only.

    ``shape`` one of :data:`VISUAL_SHAPES`; ``mesh`` the file as models.yaml spells it (relative to the
    models file, absolute, or ``example-robot-data:<path under robots/>``); ``size`` box edges (x, y, z),
    cylinder and capsule (radius, length along z), sphere (radius,); placed at ``origin`` in the link
    frame, scaled by ``scale`` along its own axes, coloured ``color`` (r, g, b, a in 0..1; None: the
    mesh's own, else grey). No part of the dynamics or of the generated code (not in the model hash).
    """

    shape: str
    mesh: str = ""
    size: tuple[float, ...] = ()
    origin: Origin = Origin()
    scale: tuple[float, float, float] = (1.0, 1.0, 1.0)
    color: tuple[float, float, float, float] | None = None


@dataclass(frozen=True)
class Link:
    name: str
    mass: Value = 0.0
    com: Vec3 = (0.0, 0.0, 0.0)
    inertia: tuple = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    inertia_rpy: Vec3 = (0.0, 0.0, 0.0)
    visual: tuple[Visual, ...] = field(default=(), compare=False)  # the looks: derive view only, not the dynamics


@dataclass(frozen=True)
class Limits:
    lower: float | None = None
    upper: float | None = None
    velocity: float | None = None
    effort: float | None = None


@dataclass(frozen=True)
class Actuator:
    """Drive and friction of one coordinate; all zero by default (an ideal joint).

    The reflected rotor inertia ``armature + gear_ratio**2 * motor_inertia`` (kg m^2 for a
    turn, kg for a slide) adds to M's diagonal, as Pinocchio's ``model.armature``; friction
    ``viscous * qd + coulomb * sign(qd)`` adds to the joint torque (URDF's ``<dynamics
    damping friction>``). Values are numbers or parameter expressions. A mimic joint's actuator
    acts on its own motion (see :attr:`Robot.mimic_actuators`).
    """

    armature: Value = 0.0
    gear_ratio: Value = 1.0
    motor_inertia: Value = 0.0
    viscous: Value = 0.0
    coulomb: Value = 0.0

    @property
    def ideal(self) -> bool:
        """No armature and no friction (the default)."""
        return self == Actuator()


IDEAL = Actuator()


@dataclass(frozen=True)
class Coordinate:
    """One entry of q: ``name`` (a C identifier), its ``joint`` and that joint's ``type``.

    ``unit`` is "rad" for angles (revolute, continuous, helical and the turns of multi-DOF
    joints) and "m" for lengths (prismatic, the slide of a cylindrical joint).
    """

    name: str
    joint: str
    type: str
    unit: str
    limits: Limits = Limits()
    actuator: Actuator = IDEAL

    @property
    def continuous(self) -> bool:
        """An unbounded turn (a continuous joint): q and q + 2 pi are one configuration."""
        return self.type == "continuous"


@dataclass(frozen=True)
class Mimic:
    """A joint that follows another: q_this = multiplier * q_joint + offset (URDF's ``<mimic>``).
    The mimic joint has no entry in q; its motion and inertia enter the dynamics through the
    chain rule (M = G^T M_full G, tau = G^T tau_full with G = d q_full / d q), and so do its own
    actuator's armature and friction (G^T D G)."""

    joint: str
    multiplier: float = 1.0
    offset: float = 0.0


class MimicCycle(DeriveError):
    """Mimic joints that follow each other round in a circle: none of them reaches a coordinate."""

    def __init__(self, joints: list[str]):
        self.joints = joints
        super().__init__(f"the mimic joints {', '.join(repr(j) for j in joints)} follow each other in a cycle")


def compose_mimics(mimics: dict[str, Mimic]) -> dict[str, tuple[Mimic, tuple[str, ...]]]:
    """Each mimic joint as one mimic of the first joint of its chain that mimics nothing, with the chain.

    q_C = m2 q_B + o2 and q_B = m1 q_A + o1 give q_C = m2 (m1 q_A + o1) + o2 = (m2 m1) q_A + (m2 o1 + o2),
    for chains of any length (the chain rule of a linear map: G stays constant). ``mimics`` maps a joint to
    its own mimic; the result maps it to ``(composed mimic, (the joints it passes through, in order, ending
    with the root))``: a direct mimic comes back unchanged, with a chain of one. Whether the root has a
    coordinate is the caller's to judge. Raises :class:`MimicCycle` (the joints of the cycle, in the order
    they follow each other) if a chain comes back onto itself (a joint mimicking itself is a cycle of one).
    """
    out: dict[str, tuple[Mimic, tuple[str, ...]]] = {}
    for start in mimics:
        path = [start]  # start, the joint it follows, ...
        while path[-1] in mimics and path[-1] not in out:
            nxt = mimics[path[-1]].joint
            if nxt in path:
                raise MimicCycle(path[path.index(nxt):])
            path.append(nxt)
        # compose from the far end back to start (memoised: each joint is resolved once)
        for k in range(len(path) - 2, -1, -1):
            own = mimics[path[k]]
            if path[k + 1] in out:
                inner, chain = out[path[k + 1]]
                out[path[k]] = (Mimic(inner.joint, own.multiplier * inner.multiplier,
                                      own.multiplier * inner.offset + own.offset), (path[k + 1],) + chain)
            else:
                out[path[k]] = (own, (own.joint,))
    return out


@dataclass(frozen=True)
class Joint:
    """A joint (see :data:`JOINT_TYPES`).

    ``limits`` is one Limits for a joint of at most 1 DOF and a tuple, one per
    coordinate, otherwise. A spherical joint ignores ``axis``: it turns about the
    z, y, x axes of its joint frame.
    """

    name: str
    type: str
    parent: str
    child: str
    origin: Origin = Origin()
    axis: tuple = (1.0, 0.0, 0.0)  # URDF's default
    limits: Limits | tuple[Limits, ...] = Limits()
    pitch: Value | None = None  # helical only: m of travel per rad
    axis2: tuple | None = None  # universal only
    mimic: Mimic | None = None  # a 1-DOF joint driven by another one's coordinate
    actuator: Actuator | tuple[Actuator, ...] | None = None  # like limits: one, or one per coordinate

    @property
    def dof(self) -> int:
        return JOINT_TYPES[self.type]

    @property
    def constraints(self) -> int:
        """Constraints the joint puts on its child's 6 DOF (Table 1): 6 - dof."""
        return 6 - self.dof

    @property
    def coordinates(self) -> tuple[Coordinate, ...]:
        """The joint's entries of q, in order (none for a fixed or a mimic joint)."""
        if self.mimic is not None:
            return ()
        actuators = self.actuators
        if self.dof <= 1:
            unit = "m" if self.type == "prismatic" else "rad"
            return (Coordinate(self.name, self.name, self.type, unit, self.limits, actuators[0]),) * self.dof
        return tuple(Coordinate(f"{self.name}_{s}", self.name, self.type, "m" if s == "trans" else "rad", lim, act)
                     for s, lim, act in zip(COORDINATE_SUFFIXES[self.type], self.limits, actuators))

    @property
    def actuators(self) -> tuple[Actuator, ...]:
        """One Actuator per coordinate (IDEAL where none is given)."""
        n = max(self.dof, 1)
        if self.actuator is None:
            return (IDEAL,) * n
        return self.actuator if isinstance(self.actuator, tuple) else (self.actuator,) * n

    @property
    def summary(self) -> str:
        """E.g. ``ball (spherical, 3 DOF, 3 constraints: ball_z, ball_y, ball_x)``, as Table 1 counts them."""
        names = [c.name for c in self.coordinates]
        coords = f": {', '.join(names)}" if names and names != [self.name] else ""
        return f"{self.name} ({self.type}, {self.dof} DOF, {self.constraints} constraints{coords})"

    @property
    def gimbal_lock(self) -> str | None:
        """Where the joint's coordinates are singular, as text; None if nowhere.

        Only the spherical joint has such configurations: with ZYX Euler angles
        (a, b, c) the angular velocity is w = E(b, c) [da; db; dc] with
        det E = cos(b) (up to sign), so at b = +-pi/2 the first and last axes align: one
        rotation of the joint is reached by no rate, the rates [da; db; dc] along
        (1, 0, +-1) move nothing, and M (singular there) cannot be solved for qdd.
        """
        if self.type != "spherical":
            return None
        y = f"{self.name}_y"
        return (f"cos({y}) = 0, i.e. {y} = pi/2 + k pi (+-pi/2 within [-pi, pi]): "
                f"the z and x turns of '{self.name}' align")


BUNDLE_QUANTITIES = ("mass_matrix", "bias", "gravity", "coriolis_matrix", "inverse_dynamics", "forward_dynamics",
                     "inverse_dynamics_fext", "forward_dynamics_fext", "com", "com_jacobian", "centroidal_map",
                     "regressor", "base_regressor")
"""What a control-tick bundle may hold: these generated functions' outputs, and per frame F
those of :data:`BUNDLE_FRAME_QUANTITIES` (``fk_F``, ``jacobian_F``, ...)."""
BUNDLE_FRAME_QUANTITIES = ("fk", "jacobian", "jdot_qd", "frame_acceleration")
FUNCTION_QUANTITIES = ("fk", "jacobian", "jdot_qd", "frame_acceleration", "fk_jacobian", "fk_all", "mass_matrix",
                       "coriolis_matrix", "gravity", "bias", "inverse_dynamics", "inverse_dynamics_derivatives",
                       "forward_dynamics", "inverse_dynamics_fext", "forward_dynamics_fext", "com", "com_jacobian",
                       "centroidal_map", "ode_rhs", "ode_jac_x", "ode_jac_u", "regressor", "base_regressor", "bundle",
                       "rk4_step", "ik", "manipulability", "closure", "velocity_map", "mass_matrix_y", "bias_y",
                       "inverse_dynamics_y", "forward_dynamics_y", "constraint_forces", "regressor_y", "base_regressor_y",
                       "motor_to_joint_position", "motor_to_joint_velocity", "motor_to_joint_torque",
                       "joint_to_motor_position", "joint_to_motor_velocity", "joint_to_motor_torque",
                       "contact_dynamics", "contact_dynamics_baumgarte", "contact_dynamics_derivatives",
                       "impulse_dynamics", "impulse_dynamics_derivatives", "contact_inverse_dynamics",
                       "centroidal_map_dot_qd", "com_acceleration", "centroidal_inertia")
"""The quantities of the generated functions (``<robot>_<quantity>[_<frame>]``), what models.yaml's
``generate: {quantities: [...]}`` may choose from."""
MOTOR_MAP_QUANTITIES = ("motor_to_joint_position", "motor_to_joint_velocity", "motor_to_joint_torque",
                        "joint_to_motor_position", "joint_to_motor_velocity", "joint_to_motor_torque")
"""The motor <-> joint maps of a closed chain with ``outputs`` (its independent coordinates y are the motors,
the outputs the joints it is used in: a parallel ankle's pitch and roll)."""
CLOSED_CHAIN_QUANTITIES = ("closure", "velocity_map", "mass_matrix_y", "bias_y", "inverse_dynamics_y",
                           "forward_dynamics_y", "constraint_forces", "regressor_y", "base_regressor_y") + MOTOR_MAP_QUANTITIES
"""Those of :data:`FUNCTION_QUANTITIES` that only a robot with loops has (in its independent coordinates)."""
CONTACT_QUANTITIES = ("contact_dynamics", "contact_dynamics_baumgarte", "contact_dynamics_derivatives", "impulse_dynamics",
                      "impulse_dynamics_derivatives", "contact_inverse_dynamics")
"""Those of :data:`FUNCTION_QUANTITIES` that only a robot with ``contacts:`` has (one function per contact set;
``contact_dynamics_baumgarte`` per set of point contacts only, ``contact_inverse_dynamics`` per set of at least
6 rows on a floating base)."""
CONTACT_NEEDS_INVERSE_MASS = CONTACT_QUANTITIES[:5]
"""Those of :data:`CONTACT_QUANTITIES` that solve with M^-1 (left out where M(q) is singular)."""
CENTROIDAL_QUANTITIES = ("centroidal_map_dot_qd", "com_acceleration", "centroidal_inertia")
"""Those of :data:`FUNCTION_QUANTITIES` that only a robot with ``contacts:`` has (the centroidal terms of legged control)."""
CONTACT_KINDS = {"point": 3, "surface": 6}
"""Contact kind -> rows of its constraint: a point holds the frame origin's position (3), a surface the
frame's whole pose (6)."""

BIG_FRAMES = 8
"""A robot with more named frames than this is big (the committed arms have at most 5; a Gen3 with a
2F-85 and a wrist camera has 17, iCub 23, ANYmal C 65): without models.yaml's ``generate: {frames: ...}``
its per-frame functions go to :attr:`Robot.default_frames` only, not to every named frame."""
BIG_NV = 30
"""A robot with more velocities than this is big as well, and without ``generate: {quantities: ...}``
it also leaves out :data:`LEAN_LEFT_OUT`: with a floating base or mimic joints (no analytic derivatives,
no ABA) those are unrolled in O(nv^3) or worse and made 80 % of the Unitree H1-2's 1.4 million
operations and 76 MB of Python (344 s to generate, 20 s to import)."""
LEAN_LEFT_OUT = ("coriolis_matrix", "inverse_dynamics_derivatives", "ode_rhs", "ode_jac_x", "ode_jac_u", "rk4_step",
                 "regressor", "base_regressor", "contact_dynamics_derivatives", "impulse_dynamics_derivatives")
"""What a robot of more than :data:`BIG_NV` velocities leaves out by default: C (the bias h = C qd + g
stays), dID/dx, the ODE, its Jacobians and RK4 (forward dynamics stays: qdd = FD(q, qd, tau)) and the
identification regressors (and a robot with contacts their derivatives). ``generate: {quantities: all}`` brings
them back."""


@dataclass(frozen=True)
class Bundle:
    """A control-tick function: the outputs of several generated functions of (q, qd, ...) in one
    pass that computes every shared transform, sine and cosine once (``<robot>_bundle_<name>``)."""

    name: str
    quantities: tuple[str, ...]


@dataclass(frozen=True)
class Contact:
    """A contact of models.yaml's ``contacts:``: a link or named frame held by the ground (or a wall).

    ``kind`` "point" (:data:`CONTACT_KINDS`): the frame origin's classical acceleration is zero, the
    force [fx, fy, fz] acts at the origin, world-aligned. "surface": the frame's spatial acceleration
    (world-aligned, at the origin) is zero, the wrench [force; torque] acts at the origin, world-aligned
    (Pinocchio's CONTACT_3D and CONTACT_6D, LOCAL_WORLD_ALIGNED)."""

    frame: str
    kind: str = "point"

    @property
    def rows(self) -> int:
        return CONTACT_KINDS[self.kind]


@dataclass(frozen=True)
class ContactSet:
    """A set of contacts active together (a stance): one generated function per set and quantity
    (``<robot>_contact_dynamics_<name>``); its frames in the order of the force vector lambda."""

    name: str
    frames: tuple[str, ...]


@dataclass(frozen=True)
class Frame:
    """A named frame rigidly attached to a link, e.g. the tool centre point.

    ``aliases``: other names of the same frame (an imported URDF's own name of the link that became
    ``tcp``), usable wherever a frame is asked for; the generated code keeps one set of functions
    under ``name`` and spells the aliases as references to them."""

    name: str
    link: str
    origin: Origin = Origin()
    aliases: tuple[str, ...] = ()


LOOP_KINDS = {"point": 3, "hinge": 5, "weld": 6, "planar": 2, "distance": 1}
"""Closure kind -> rows of its residual phi (a planar loop with ``rotation`` has 3)."""


def loop_basis(n) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """(u, v): with the unit vector n a right-handed orthonormal frame (u, v, n), u x v = n.

    u is the coordinate axis e least aligned with n (the first of the smallest |n_i|) with its n
    part removed, normalised; v = n x u. The symbolic side and the reference both take u, v from here,
    so their residuals are the same functions of q.
    """
    n = [float(x) for x in n]
    i = min(range(3), key=lambda k: (abs(n[k]), k))
    e = [1.0 if k == i else 0.0 for k in range(3)]
    u = [e[k] - n[i] * n[k] for k in range(3)]
    norm = math.sqrt(sum(x * x for x in u))
    u = [x / norm for x in u]
    v = [n[1] * u[2] - n[2] * u[1], n[2] * u[0] - n[0] * u[2], n[0] * u[1] - n[1] * u[0]]
    return tuple(u), tuple(v)


@dataclass(frozen=True)
class Loop:
    """A loop closure: frames ``a`` and ``b`` (links or named frames) must coincide as ``kind`` says.

    With (R_a, p_a), (R_b, p_b) the frames' world poses, d = p_a - p_b, and (u, v) = loop_basis(axis)
    for the axis n given in frame a's axes, the residual phi (zero when closed) is

    - point (3, a ball joint): d;
    - hinge (5, a revolute joint about n): [d; (R_a u).(R_b n); (R_a v).(R_b n)];
    - weld (6, rigid): [d; (R_a e_y).(R_b e_z); (R_a e_z).(R_b e_x); (R_a e_x).(R_b e_y)];
    - planar (2, a revolute joint of a mechanism moving in the plane normal to n): [(R_a u).d; (R_a v).d],
      with ``rotation`` (3, rigid in the plane) also (R_a u).(R_b v);
    - distance (1, a rod of ``length`` L with ball joints at both ends): (d.d - L^2) / (2 L).

    The orientation rows vanish also for some flipped frames (R_b n = -R_a n); validation requires
    the unflipped closure at the reference configuration.
    """

    a: str
    b: str
    kind: str
    axis: tuple | None = None  # hinge axis or planar normal, unit, in frame a's axes
    length: Value | None = None  # distance only
    rotation: bool = False  # planar only: the relative turn about n is closed too

    @property
    def rows(self) -> int:
        """Entries of the loop's residual."""
        return LOOP_KINDS[self.kind] + (1 if self.rotation else 0)

    @property
    def basis(self) -> tuple[tuple, tuple]:
        """(u, v) of :func:`loop_basis` for the hinge axis or the planar normal."""
        return loop_basis(self.axis)

    @property
    def summary(self) -> str:
        """E.g. ``coupler_tip = rocker_tip (planar, normal [0, 0, 1], 2 rows)``."""
        extra = ""
        if self.kind == "hinge":
            extra = f", axis [{', '.join(f'{float(x):g}' for x in self.axis)}]"
        elif self.kind == "planar":
            extra = f", normal [{', '.join(f'{float(x):g}' for x in self.axis)}]" + (", with rotation" if self.rotation else "")
        elif self.kind == "distance":
            extra = f", length {self.length}"
        return f"{self.a} = {self.b} ({self.kind}{extra}, {self.rows} rows)"


FREE_FLYER = "root_joint"
"""Name of the free-flyer joint a floating base adds above the root link (Pinocchio's name)."""
BASE_POSITION = ("base_x", "base_y", "base_z", "base_qx", "base_qy", "base_qz", "base_qw")
"""A floating base's 7 entries of q: the root link's origin in the world (m), then its orientation
as a unit quaternion (x, y, z, w) (Pinocchio's ``JointModelFreeFlyer``)."""
BASE_VELOCITY = ("base_vx", "base_vy", "base_vz", "base_wx", "base_wy", "base_wz")
"""A floating base's 6 entries of v (= qd): the linear velocity of the root link's origin and its
angular velocity, both in the root link's frame (Pinocchio's LOCAL convention)."""
BASES = ("fixed", "floating")
SMOOTHING = 1e-2
"""Default eps (rad/s or m/s) of the smooth Coulomb friction tanh(qd / eps): within 1 % of sign(qd)
above 2.6 eps (0.026 rad/s)."""


@dataclass(frozen=True)
class Robot:
    """A kinematic tree. ``joints`` are in topological order (parents first).

    ``base`` "fixed": the root link is the world. "floating": a free-flyer joint
    (:data:`FREE_FLYER`) places the root link in the world, with q = [BASE_POSITION, joints]
    (nq = nv + 1) and v = [BASE_VELOCITY, joints].
    """

    name: str
    links: tuple[Link, ...]
    joints: tuple[Joint, ...]
    frames: tuple[Frame, ...] = ()
    gravity: Vec3 = (0.0, 0.0, -9.81)
    parameters: tuple[Parameter, ...] = ()
    description: str = ""
    source: str = ""
    base: str = "fixed"
    wrenches: tuple[str, ...] | None = None  # frames taking external wrenches; None: "tcp" if there is one
    coulomb_smoothing: float | None = None  # eps of tanh(qd / eps) in the ODE's Coulomb friction; None: SMOOTHING
    bundles: tuple[Bundle, ...] | None = None  # control-tick functions; None: the defaults (control_bundles)
    contacts: tuple[Contact, ...] = ()  # frames that may touch the ground (models.yaml's contacts:)
    contact_sets: tuple[ContactSet, ...] | None = None  # stances; None: one set "all" of every contact
    generate_frames: tuple[str, ...] | None = None  # frames given per-frame functions; None: the named frames
    generate_quantities: tuple[str, ...] | None = None  # quantities generated (and what they call); None: all
    loops: tuple[Loop, ...] = ()  # loop closures of the tree (a closed chain); () for a tree
    independent: tuple[str, ...] | None = None  # with loops: the independent coordinates y, in q's order
    independent_chosen: bool = False  # with loops: y was chosen by pivoting on K (models.yaml gave none)
    reference: tuple[tuple[str, float], ...] = ()  # with loops: models.yaml's starting values of coordinates
    loop_rows: tuple[int, ...] | None = None  # with loops: the rows of the stacked phi kept (independent rows)
    reference_q: tuple[float, ...] | None = field(default=None, compare=False)  # the closed reference q (solved)
    outputs: tuple[str, ...] | None = None  # with loops: the joints the motors y drive (motor <-> joint maps)
    file: str = field(default="", compare=False)  # the models file it was read from ("" if none): for messages only

    @property
    def closed(self) -> bool:
        """The robot has loop closures: a closed chain in the tree's coordinates q = (y, z)."""
        return bool(self.loops)

    @property
    def dependent(self) -> tuple[str, ...]:
        """With loops: the dependent coordinates z (q's entries not in y), in q's order."""
        return tuple(c.name for c in self.coordinates if c.name not in (self.independent or ()))

    @property
    def mimic_actuators(self) -> tuple[tuple[Joint, Actuator], ...]:
        """(mimic joint, its actuator) for every mimic joint with a non-ideal actuator. A mimic joint has no
        coordinate: its drive and friction act on its own motion q_m = a q_J + b, i.e. through G on its
        leader's coordinate J: armature and viscous friction a^2 times theirs (G^T D G), the Coulomb force
        a f_c sign(a qd_J) (= |a| f_c sign(qd_J))."""
        return tuple((j, j.actuators[0]) for j in self.joints
                     if j.mimic is not None and j.actuator is not None and not j.actuators[0].ideal)

    @property
    def actuated(self) -> bool:
        """Any coordinate or mimic joint with armature or friction (else every function is that of ideal joints)."""
        return any(not c.actuator.ideal for c in self.joint_coordinates) or bool(self.mimic_actuators)

    @property
    def smoothing(self) -> float:
        """eps of the smooth Coulomb friction tanh(qd / eps) of forward dynamics, the ODE and trajopt."""
        return SMOOTHING if self.coulomb_smoothing is None else self.coulomb_smoothing

    @property
    def floating(self) -> bool:
        return self.base == "floating"

    @property
    def wrench_frames(self) -> tuple[str, ...]:
        """The frames (links or named frames) at which the generated ``*_fext`` dynamics take
        external wrenches: the model's ``wrenches`` list, by default the ``tcp`` frame if any."""
        if self.wrenches is not None:
            return self.wrenches
        return ("tcp",) if any(f.name == "tcp" for f in self.frames) else ()

    @property
    def stances(self) -> tuple[ContactSet, ...]:
        """The contact sets that get the contact functions: models.yaml's ``contact_sets``, by default one
        set ``all`` of every contact (none without contacts)."""
        if self.contact_sets is not None:
            return self.contact_sets
        return (ContactSet("all", tuple(c.frame for c in self.contacts)),) if self.contacts else ()

    def contact(self, frame: str) -> Contact:
        return next(c for c in self.contacts if c.frame == frame)

    @property
    def centroidal(self) -> bool:
        """Whether the robot gets the centroidal terms (:data:`CENTROIDAL_QUANTITIES`): where it has contacts."""
        return bool(self.contacts)

    @property
    def control_bundles(self) -> tuple[Bundle, ...]:
        """The model's ``bundles``, by default two: ``control`` = M, the bias h = C qd + g, and of the
        ``tcp`` frame (if any) its pose, Jacobian and J'qd, plus the Jacobian and J'qd of every other
        wrench frame and every frame of ``contacts:``; ``computed_torque`` (with a tcp) = tau for a given qdd, and the
        tcp's pose, Jacobian and the acceleration that qdd gives it."""
        if self.bundles is not None:
            return self.bundles
        tcp = any(f.name == "tcp" for f in self.frames)
        control = ["mass_matrix", "bias"] + (["fk_tcp", "jacobian_tcp", "jdot_qd_tcp"] if tcp else [])
        held = tuple(dict.fromkeys(self.wrench_frames + tuple(c.frame for c in self.contacts)))  # wrench and contact frames
        control += [f"{q}_{f}" for f in held if f != "tcp" for q in ("jacobian", "jdot_qd")]
        out = [Bundle("control", tuple(control))]
        if tcp:
            out.append(Bundle("computed_torque", ("inverse_dynamics", "fk_tcp", "jacobian_tcp",
                                                  "frame_acceleration_tcp")))
        return tuple(out)

    @property
    def root(self) -> str:
        children = {j.child for j in self.joints}
        return next(link.name for link in self.links if link.name not in children)

    @property
    def moving_joints(self) -> tuple[Joint, ...]:
        """Joints with degrees of freedom, in the order of q."""
        return tuple(j for j in self.joints if j.dof > 0)

    @property
    def joint_coordinates(self) -> tuple[Coordinate, ...]:
        """The joints' entries of q (and of v), one per DOF: a joint's coordinates are consecutive,
        joints in tree order; a floating base's entries come before them in q and v."""
        return tuple(c for j in self.joints for c in j.coordinates)

    @property
    def base_coordinates(self) -> tuple[Coordinate, ...]:
        """A floating base's 7 entries of q (none for a fixed base)."""
        if not self.floating:
            return ()
        return tuple(Coordinate(n, FREE_FLYER, "freeflyer", "m" if i < 3 else "1") for i, n in enumerate(BASE_POSITION))

    @property
    def coordinates(self) -> tuple[Coordinate, ...]:
        """The entries of q: the floating base's 7 (if any), then the joints' coordinates."""
        return self.base_coordinates + self.joint_coordinates

    @property
    def velocity_names(self) -> tuple[str, ...]:
        """The entries of v (qd, qdd and tau): the floating base's 6 (if any), then the joints' coordinates."""
        return (BASE_VELOCITY if self.floating else ()) + tuple(c.name for c in self.joint_coordinates)

    def joint_box(self, angle: float = math.pi, length: float = 1.0) -> tuple[tuple[float, ...], tuple[float, ...]]:
        """(lower, upper) of each entry of q: its limits, or +-``angle`` (rad) / +-``length`` (m)
        where a limit is missing (``math.inf`` for an unbounded box). A continuous joint has none:
        +-pi (the default) covers each of its configurations once."""
        coords = self.coordinates
        lower = tuple(-(angle if c.unit == "rad" else length) if c.limits.lower is None else c.limits.lower for c in coords)
        upper = tuple((angle if c.unit == "rad" else length) if c.limits.upper is None else c.limits.upper for c in coords)
        return lower, upper

    @property
    def continuous_indices(self) -> tuple[int, ...]:
        """Indices in q of the continuous joints' angles (what :meth:`wrap` wraps): those whose
        configuration repeats every 2 pi, i.e. all but a leader that a mimic joint follows other than
        as a turn by an integer multiple (a rack, a screw or a half-rate turn: 2 pi would move it)."""
        aperiodic = {j.mimic.joint for j in self.joints if j.mimic is not None
                     and (motion_type(j.type) != "revolute"
                          or float(j.mimic.multiplier) != round(float(j.mimic.multiplier)))}
        return tuple(i for i, c in enumerate(self.coordinates) if c.continuous and c.joint not in aperiodic)

    def wrap(self, q):
        """q (..., nq) with the continuous joints' angles wrapped to (-pi, pi]: the same configuration
        (:func:`derive.description.joints.wrap_angle`); the other entries as they are, a copy."""
        out = np.array(q, dtype=float, copy=True)
        index = list(self.continuous_indices)
        if index:
            out[..., index] = wrap_angle(out[..., index])
        return out

    def gimbal_locked(self, q, tol: float = 1e-6) -> tuple[str, ...]:
        """Names of the spherical joints in gimbal lock at ``q``: |cos(<joint>_y)| <= tol."""
        index = {c.name: i for i, c in enumerate(self.coordinates)}
        return tuple(j.name for j in self.joints
                     if j.type == "spherical" and abs(math.cos(q[index[f"{j.name}_y"]])) <= tol)

    @property
    def nq(self) -> int:
        """Entries of q: nv, plus 1 for a floating base's quaternion."""
        return self.nv + (1 if self.floating else 0)

    @property
    def nv(self) -> int:
        """Entries of v = qd, of qdd and of tau: the joints' DOF, plus 6 for a floating base."""
        return len(self.joint_coordinates) + (6 if self.floating else 0)

    def require_fixed_base(self, what: str) -> None:
        """Raise a one-line error if the robot has a floating base, which ``what`` does not handle."""
        if self.floating:
            raise ModelError(self.name, "base", f"{what} handles fixed-base robots only; this one has a floating base")

    @property
    def parameter_defaults(self) -> dict[str, float]:
        return {p.name: p.default for p in self.parameters}

    def link(self, name: str) -> Link:
        return next(link for link in self.links if link.name == name)

    def parent_joint(self, link_name: str) -> Joint | None:
        return next((j for j in self.joints if j.child == link_name), None)

    @property
    def link_names(self) -> tuple[str, ...]:
        """Every link in tree order: the root, then each joint's child."""
        return (self.root,) + tuple(j.child for j in self.joints)

    @property
    def frame_names(self) -> tuple[str, ...]:
        """Every frame FK can place: links first (tree order), then named frames (aliases not included)."""
        return self.link_names + tuple(f.name for f in self.frames)

    @property
    def leaves(self) -> tuple[str, ...]:
        """The leaves of the kinematic tree: links that are no joint's parent (feet, hands, finger
        tips, a head), in tree order."""
        parents = {j.parent for j in self.joints}
        return tuple(link for link in self.link_names if link not in parents)

    @property
    def big(self) -> bool:
        """More than :data:`BIG_FRAMES` named frames or more than :data:`BIG_NV` velocities."""
        return len(self.frames) > BIG_FRAMES or self.nv > BIG_NV

    @property
    def default_frames(self) -> tuple[str, ...]:
        """A big robot's frames with per-frame functions when models.yaml chooses none: the ``tcp``,
        the wrench (contact) frames, then the leaves of the tree, each once."""
        tcp = ("tcp",) if any(f.name == "tcp" for f in self.frames) else ()
        return tuple(dict.fromkeys(tcp + self.wrench_frames + tuple(c.frame for c in self.contacts) + self.leaves))

    @property
    def function_frames(self) -> tuple[str, ...]:
        """The frames (named frames or links) that get the generated per-frame functions (``fk_<frame>``,
        ``jacobian_<frame>``, ...): models.yaml's ``generate: {frames: [...]}``; without it every named
        frame, or for a :attr:`big` robot :attr:`default_frames`. Every link's pose is in ``fk_all``
        whatever the choice."""
        if self.generate_frames is not None:
            return self.generate_frames
        return self.default_frames if self.big else tuple(f.name for f in self.frames)

    @property
    def function_quantities(self) -> tuple[str, ...] | None:
        """The quantities generated (None: all): models.yaml's ``generate: {quantities: [...]}``; without
        it all, or above :data:`BIG_NV` velocities all but :data:`LEAN_LEFT_OUT`."""
        if self.generate_quantities is not None or self.nv <= BIG_NV:
            return self.generate_quantities
        return tuple(q for q in FUNCTION_QUANTITIES if q not in LEAN_LEFT_OUT)

    @property
    def selection(self) -> dict[str, str]:
        """Why these frames and quantities, in words, where a default for big robots or models.yaml's
        ``generate:`` chose them ({} for a small robot without ``generate:``, which gets every named frame
        and every quantity): what manifest.json's ``selection``, ``derive info`` and the importer say."""
        out = {}
        why = f"more than {BIG_FRAMES} named frames ({len(self.frames)})" if len(self.frames) > BIG_FRAMES else \
            f"more than {BIG_NV} velocities ({self.nv})"
        if self.generate_frames is not None:
            out["frames"] = "generate.frames"
        elif self.big:
            out["frames"] = (f"default for a big robot ({why}): the tcp, the wrench frames and the leaves of the tree "
                             "(links with no child); generate: {frames: all} gives every link and named frame")
        if self.generate_quantities is not None:
            out["quantities"] = "generate.quantities, and what they call"
        elif self.nv > BIG_NV:
            out["quantities"] = (f"default for more than {BIG_NV} velocities ({self.nv}): all but "
                                 f"{', '.join(q for q in LEAN_LEFT_OUT if self.contacts or q not in CONTACT_QUANTITIES)}; "
                                 "generate: {quantities: all} gives them")
        return out

    @property
    def frame_aliases(self) -> dict[str, str]:
        """{alias: frame name} of every named frame's aliases."""
        return {a: f.name for f in self.frames for a in f.aliases}

    def frame_name(self, name: str) -> str:
        """The frame ``name`` stands for: itself, or the frame it is an alias of."""
        return self.frame_aliases.get(name, name)


def model_data(robot: Robot) -> dict:
    """The validated model as plain data (what its content hash is taken of).

    Joint fields only some types have (``pitch``, ``axis2``) appear only where set,
    so models without such joints keep the hash they had before those types existed.
    """
    data = asdict(robot)
    del data["file"]  # where the model was read from is no part of it
    del data["reference_q"]  # solved from the model by Newton: its last bits may differ between machines
    for link in data["links"]:  # the looks move no generated number: a new mesh regenerates nothing
        del link["visual"]
    if not data["loops"]:  # trees keep the hash they had before loops existed
        for key in ("loops", "independent", "independent_chosen", "reference", "loop_rows"):
            del data[key]
    if data["base"] == "fixed":  # fixed-base models keep the hash they had before floating bases existed
        del data["base"]
    for key in ("wrenches", "coulomb_smoothing", "bundles", "generate_frames", "generate_quantities", "outputs", "contact_sets"):
        if data[key] is None:
            del data[key]
    if not data["contacts"]:  # models without contacts keep the hash they had before contacts existed
        del data["contacts"]
    for frame in data["frames"]:  # models without aliases keep the hash they had before aliases existed
        if not frame["aliases"]:
            del frame["aliases"]
    for joint in data["joints"]:
        for key in ("pitch", "axis2", "mimic", "actuator"):
            if joint[key] is None:
                del joint[key]
    return data


MAX_NAME = 64
"""Longest name of a robot, joint, link, frame or parameter: C99 guarantees 63 significant
characters of an identifier, and generated file names join several names."""

RESERVED_ROBOT_NAMES = {
    # Python modules the generated module imports or that users import beside it
    **{m: f"the Python module '{m}'" for m in ("numpy", "math", "derive", "jax", "casadi", "sympy", "scipy")},
    # C standard headers: generated/<robot>/c/<robot>.h would shadow them (and math.h wins over math.py)
    **{h: f"<{h}.h> of the C standard library" for h in (
        "assert", "complex", "ctype", "errno", "fenv", "float", "inttypes", "iso646", "limits", "locale", "math",
        "setjmp", "signal", "stdalign", "stdarg", "stdatomic", "stdbool", "stddef", "stdint", "stdio", "stdlib",
        "stdnoreturn", "string", "tgmath", "threads", "time", "uchar", "wchar", "wctype")},
}
"""Robot names (compared case-insensitively) whose generated header or module would shadow another."""
RESERVED_PREFIX = "derive_"  # the support files: derive_real.h, derive_ik.h, derive_linalg.h, ...


def import_command(source: Any) -> str | None:
    """The ``derive import-urdf ...`` command recorded in a robot's ``source`` (what import-urdf writes:
    ``"<file>, imported by `derive import-urdf ...`"``), or None."""
    parts = str(source or "").split("`")
    return next((p for p in parts[1::2] if p.startswith("derive import-urdf ")), None)


def shown(name: Any, width: int = 40) -> str:
    """A name for an error message: at most ``width`` characters."""
    text = str(name)
    return text if len(text) <= width else text[: width - 3] + "..."


def identifier(robot: str | None, where: str, name: Any) -> str:
    """``name`` if it is a C and Python identifier of at most MAX_NAME characters and no reserved word."""
    if not isinstance(name, str) or not _IDENT.match(name):
        raise ModelError(robot and shown(robot), where, f"'{shown(name)}' is not a C identifier (letters, digits, _; not "
                         "starting with a digit)")
    if len(name) > MAX_NAME:
        raise ModelError(robot and shown(robot), where, f"'{shown(name)}' is longer than {MAX_NAME} characters")
    if name in C_KEYWORDS or keyword.iskeyword(name):
        raise ModelError(robot, where, f"'{name}' is a reserved word in C or Python")
    return name


def robot_name(name: Any) -> str:
    """A robot's name: an identifier that names no C header or Python module it would shadow."""
    name = identifier(shown(name) if isinstance(name, str) else None, "name", name)
    shadowed = RESERVED_ROBOT_NAMES.get(name.lower())
    if shadowed:
        raise ModelError(name, "name", f"'{name}' is reserved: the generated {name}.h / {name}.py would shadow {shadowed}")
    if name.lower().startswith(RESERVED_PREFIX):
        raise ModelError(name, "name", f"names starting with '{RESERVED_PREFIX}' are reserved for derive's support files")
    return name
