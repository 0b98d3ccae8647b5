"""A robot -> URDF or MJCF text (``derive export``): the readers' mirror.

Every value is evaluated at the parameter defaults (a parameter is a name in derive only; the
file gets its number, and a comment lists the defaults used). Numbers are written as Python's
``repr`` of the double, the shortest text that reads back to the same double, so a reader that
copies numbers (``derive import-urdf`` does) gets the model back to the last bit.

URDF (what ``derive import-urdf`` reads back to the same M, g and ID):
- a link -> ``<link>`` with ``<inertial>``: mass, ``origin xyz = com, rpy = inertia_rpy`` and the
  inertia about the COM in that frame (URDF's convention is derive's);
- a joint -> ``<joint>`` with derive's ``origin`` (xyz, rpy: both URDF's Trans * Rz Ry Rx), ``axis``,
  ``<limit>``, ``<mimic>`` and ``<dynamics damping = viscous, friction = coulomb>``; a revolute joint
  without position limits is ``continuous`` (URDF's revolute needs them);
- a multi-DOF joint -> a chain of 1-DOF joints named after its coordinates (``ball_z``, ``ball_y``,
  ``ball_x``) through massless links: R = Rz Ry Rx (spherical), Rot(a1) Rot(a2) (universal, a2
  carried along by the first turn), Rot(a) then Trans(a) (cylindrical) are exactly such chains, so
  q, M and tau keep their entries and names. A helical joint (angle q, travel pitch * q along the
  same axis) is a revolute joint and a prismatic ``<joint>_slide`` that mimics it with multiplier
  pitch. Refusing them instead would make every robot with such a joint unexportable for no reason;
- a frame -> a massless link of its name on a fixed joint ``<frame>_joint`` (import-urdf turns
  such links back into frames);
- a floating base -> a massless ``world`` link and a ``floating`` joint ``root_joint`` (identity
  origin) to the root link: URDF's own spelling of a free body, read back by import-urdf as
  ``base: floating`` and by Pinocchio as a free flyer;
- what URDF has no place for (gravity other than 0 0 -9.81, rotor inertia, loop closures) is a
  comment and a note.
  URDF requires ``<limit effort velocity>`` (and lower, upper on revolute and prismatic joints):
  where the model has none the file gets the placeholders import-urdf reads as "no limit"
  (0 for effort and velocity, +-1e16 for a position), and a note says so.

MJCF (MuJoCo loads it; its mj_fullM and mj_rne match derive's M and ID):
- a link -> a ``<body>`` (pos, quat = the joint origin; the root: the world body's child, or the
  world itself if it is called ``world``) with ``<inertial pos quat mass diaginertia>`` (the
  principal axes computed here when the inertia is not diagonal);
- a joint -> ``<joint>`` elements in the child body (hinge, slide; several in one body for a
  multi-DOF joint, applied in order as MuJoCo composes them, named after the coordinates; a helical
  joint is a hinge and a slide ``<joint>_slide`` coupled by an equality), ``range``, ``armature`` =
  armature + gear_ratio^2 motor_inertia, ``damping`` = viscous, ``frictionloss`` = coulomb,
  ``actuatorfrcrange`` = +-effort (read back by ``derive import-mjcf`` as the effort limit); one
  ``<motor>`` per coordinate (gear 1: ctrl is derive's tau, ``ctrlrange`` = +-effort);
- a mimic joint -> its own joint plus ``<equality><joint joint1 joint2 polycoef="offset
  multiplier 0 0 0">`` (MuJoCo enforces it as a constraint; M and ID over the full joints
  reduce to derive's as G^T M G, G^T tau);
- a frame -> a ``<site>``; a floating base -> a ``<freejoint name="root_joint">`` in the root body
  (MuJoCo's qpos quaternion is (w, x, y, z), its free qvel the linear velocity in the world frame
  and the angular one in the body frame; derive's are (x, y, z, w) and both in the body frame);
- loops (a closed chain, docs/closed-chains.md) -> ``<equality>`` between sites (a loop frame that
  is a link gets a site ``<link>_site`` at its origin): ``point`` -> ``<connect site1 site2>``,
  ``weld`` -> ``<weld site1 site2>``; a ``planar`` loop -> ``<connect>`` (``<weld>`` with
  ``rotation``), the same constraint while the mechanism moves in its plane (refused where the two
  frames are apart along the normal, or turned, at the reference configuration); a ``distance``
  loop of length L (a massless rod with ball joints) -> the rod as a body ``<b>_rod`` on a ball
  joint at frame b (in b's link; its x axis towards frame a as the tree stands at q = 0), MuJoCo's
  least mass and moments (the floor below) all at the ball, one site ``<b>_rod_end`` at (L, 0, 0),
  and ``<connect site1="<b>_rod_end" site2="a">``: MuJoCo's connect rows carry the velocity product
  Jdot qvel (a tendon equality's do not), so MuJoCo's ydd is derive's in motion too
  (tests/test_closed_chain_mujoco.py), and the rod body's translation-only inverse weight is 5.3
  / kg for the parallel ankle where a two-site tendon's is 60 (MuJoCo's regularisation is
  proportional to it); a ``hinge`` loop is refused (MuJoCo has no hinge equality). MuJoCo's soft
  rows keep their default solref/solimp. The closed reference configuration is the ``<key
  name="reference">`` (derive import-mjcf closes the loops there; a rod's ball is turned onto frame
  a there);
- gravity -> ``<option gravity>``. MuJoCo refuses a moving body (one with a joint) whose mass or a
  principal moment is below mjMINVAL (1e-15); such a mass or moment (a thin rod's zero moment, a
  massless link between joints) is raised to 1e-12 of the robot's largest (at least 1e-14), and a
  note names the bodies: M then differs from derive's by that much.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Iterable

import numpy as np

from derive.description import expr
from derive.description.closure import Poses
from derive.description.mjcf import quat_matrix
from derive.description.robot import FREE_FLYER, IDEAL, Actuator, Frame, Joint, Limits, ModelError, Origin, Robot

URDF_GRAVITY = (0.0, 0.0, -9.81)
"""The gravity every URDF reader assumes (URDF has no element for it)."""
UNBOUNDED = 1e16
"""A position limit that means "none" where URDF or MJCF needs a number (import-urdf drops beyond 1e12)."""
MJ_MINVAL = 1e-15
"""MuJoCo's mjMINVAL: the least mass and principal moment of a body with a joint."""
FLOOR = 1e-12
"""A moving body's mass or moment below MuJoCo's least is raised to FLOOR times the robot's largest."""


@dataclass(frozen=True)
class Exported:
    """The file's text and what the format could not hold exactly (one line each, also in the file
    as comments)."""

    text: str
    notes: tuple[str, ...]


@dataclass(frozen=True)
class _Piece:
    """One 1-DOF joint of a derive joint: URDF's ``<joint>``, MJCF's ``<joint>``."""

    name: str
    kind: str  # revolute, continuous, prismatic
    axis: tuple
    limits: Limits
    actuator: Actuator
    mimic: tuple[str, float, float] | None  # (leader piece, multiplier, offset)
    coordinate: bool  # has its own entry in q (else it mimics)


# --------------------------------------------------------------------------- numbers and rotations


def _num(x: float) -> str:
    x = float(x)
    if not math.isfinite(x):
        raise ValueError(f"not finite: {x}")
    return "0" if x == 0 else repr(x)


def _vec(values: Iterable[float]) -> str:
    return " ".join(_num(v) for v in values)


def _quat_multiply(a, b) -> tuple:
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw)


def rpy_quaternion(rpy) -> tuple[float, float, float, float]:
    """(w, x, y, z) of R = Rz(yaw) Ry(pitch) Rx(roll) (URDF's rpy): q = qz(yaw) qy(pitch) qx(roll)."""
    r, p, y = (float(v) / 2 for v in rpy)
    qx, qy, qz = (math.cos(r), math.sin(r), 0.0, 0.0), (math.cos(p), 0.0, math.sin(p), 0.0), \
        (math.cos(y), 0.0, 0.0, math.sin(y))
    return _quat_multiply(_quat_multiply(qz, qy), qx)


def rpy_matrix(rpy) -> np.ndarray:
    """R = Rz(yaw) Ry(pitch) Rx(roll)."""
    r, p, y = (float(v) for v in rpy)
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def matrix_quaternion(m: np.ndarray) -> tuple[float, float, float, float]:
    """(w, x, y, z) of a rotation matrix (Shepperd: from the largest of w, x, y, z; w >= 0)."""
    t = np.trace(m)
    cands = [t, m[0, 0], m[1, 1], m[2, 2]]
    k = int(np.argmax(cands))
    if k == 0:
        s = 2.0 * math.sqrt(1.0 + t)
        q = (s / 4, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s)
    elif k == 1:
        s = 2.0 * math.sqrt(1.0 + m[0, 0] - m[1, 1] - m[2, 2])
        q = ((m[2, 1] - m[1, 2]) / s, s / 4, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s)
    elif k == 2:
        s = 2.0 * math.sqrt(1.0 - m[0, 0] + m[1, 1] - m[2, 2])
        q = ((m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, s / 4, (m[1, 2] + m[2, 1]) / s)
    else:
        s = 2.0 * math.sqrt(1.0 - m[0, 0] - m[1, 1] + m[2, 2])
        q = ((m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, s / 4)
    q = tuple(float(v) for v in q)
    return q if q[0] >= 0 else tuple(-v for v in q)


def _comment(text: str) -> str:
    """An XML comment of ``text`` ("--" may not appear inside one)."""
    text = " ".join(str(text).split())
    while "--" in text:
        text = text.replace("--", "- -")
    return f"<!-- {text.rstrip('-')} -->"


# --------------------------------------------------------------------------- the model at its defaults


class _Model:
    """The robot's numbers at the parameter defaults, its joints as 1-DOF pieces, unique new names."""

    def __init__(self, robot: Robot):
        self.robot = robot
        self.env = robot.parameter_defaults
        self.children: dict[str, list[Joint]] = {link.name: [] for link in robot.links}
        for j in robot.joints:
            self.children[j.parent].append(j)
        self.frames: dict[str, list[Frame]] = {link.name: [] for link in robot.links}
        for f in robot.frames:
            self.frames[f.link].append(f)
        self.link_names = {link.name for link in robot.links} | {f.name for f in robot.frames}
        self.joint_names = {j.name for j in robot.joints} | {c.name for c in robot.joint_coordinates}
        self.pieces = {j.name: self._pieces(j) for j in robot.joints if j.dof > 0}
        seen: dict[str, str] = {}  # a multi-DOF joint's pieces are named after its coordinates: no other joint may be
        for j in robot.joints:
            for name in [p.name for p in self.pieces[j.name]] if j.dof else [j.name]:
                if seen.setdefault(name, j.name) != j.name:
                    raise ModelError(robot.name, f"joints ({j.name})", f"'{name}' would name a joint of both "
                                     f"'{seen[name]}' and '{j.name}' in the exported file: rename one", robot.file or None)
        self.joint_names.update(seen)

    def num(self, value: Any) -> float:
        return float(expr.evaluate(value, self.env))

    def vec(self, values) -> tuple[float, ...]:
        return tuple(self.num(v) for v in values)

    def unique(self, taken: set[str], name: str) -> str:
        """``name``, or ``name`` with underscores added until it is not in ``taken`` (then taken)."""
        while name in taken:
            name += "_"
        taken.add(name)
        return name

    def _pieces(self, j: Joint) -> list[_Piece]:
        coords, acts = j.coordinates, j.actuators
        limits = j.limits if isinstance(j.limits, tuple) else (j.limits,) * max(j.dof, 1)
        mimic = (j.mimic.joint, float(j.mimic.multiplier), float(j.mimic.offset)) if j.mimic else None
        if j.type in ("revolute", "prismatic", "continuous"):
            return [_Piece(j.name, j.type, j.axis, limits[0], acts[0], mimic, mimic is None)]
        if j.type == "helical":
            pitch = self.num(j.pitch)
            leader, a, b = mimic or (j.name, 1.0, 0.0)
            slide = f"{j.name}_slide"
            while slide in self.joint_names:
                slide += "_"
            self.joint_names.add(slide)
            return [_Piece(j.name, "revolute", j.axis, limits[0], acts[0], mimic, mimic is None),
                    _Piece(slide, "prismatic", j.axis, Limits(), IDEAL, (leader, pitch * a, pitch * b), False)]
        axes = {"cylindrical": (j.axis, j.axis), "universal": (j.axis, j.axis2),
                "spherical": ((0.0, 0.0, 1.0), (0.0, 1.0, 0.0), (1.0, 0.0, 0.0))}[j.type]
        kinds = ("revolute", "prismatic") if j.type == "cylindrical" else ("revolute",) * j.dof
        return [_Piece(c.name, k, a, lim, act, None, True) for c, k, a, lim, act in zip(coords, kinds, axes, limits, acts)]

    def armature(self, a: Actuator) -> float:
        return self.num(a.armature) + self.num(a.gear_ratio) ** 2 * self.num(a.motor_inertia)

    def inertia(self, link) -> np.ndarray:
        return np.array([[self.num(x) for x in row] for row in link.inertia])

    def header(self, fmt: str) -> list[str]:
        r = self.robot
        lines = [_comment(f"robot '{r.name}' as {fmt}, written by derive export from its models.yaml entry "
                          "(conventions: derive/description/export.py)")]
        if r.description:
            lines.append(_comment(f"description: {r.description}"))
        if r.source:
            lines.append(_comment(f"source: {r.source}"))
        if r.parameters:
            values = ", ".join(f"{p.name} = {p.default!r}" for p in r.parameters)
            lines.append(_comment(f"parameters, at their defaults: {values}: every number below is evaluated there "
                                  "(the file keeps no parameter)"))
        return lines


def _placeholders(pieces: Iterable[_Piece]) -> tuple[dict[str, dict[str, float]], list[str]]:
    """piece -> URDF <limit> attributes; the pieces that got placeholders."""
    out, filled = {}, []
    for p in pieces:
        lim = p.limits
        kind = "continuous" if p.kind == "revolute" and lim.lower is None and lim.upper is None else p.kind
        attrs: dict[str, float] = {}
        if kind != "continuous":
            attrs["lower"] = -UNBOUNDED if lim.lower is None else lim.lower
            attrs["upper"] = UNBOUNDED if lim.upper is None else lim.upper
        if kind != "continuous" or lim.velocity is not None or lim.effort is not None:
            attrs["effort"] = 0.0 if lim.effort is None else lim.effort
            attrs["velocity"] = 0.0 if lim.velocity is None else lim.velocity
        if any(getattr(lim, k) is None for k in attrs):
            filled.append(p.name)
        out[p.name] = {"kind": kind, **attrs}
    return out, filled


# --------------------------------------------------------------------------- URDF


def export_urdf(robot: Robot) -> Exported:
    """The robot as a URDF document (see the module docstring) and the notes on what URDF cannot hold."""
    m = _Model(robot)
    notes: list[str] = []
    body: list[str] = []
    links = set(m.link_names)
    joints = set(m.joint_names)
    ind = "  "

    def link(name: str, mass: float = 0.0, com=(0.0, 0.0, 0.0), rpy=(0.0, 0.0, 0.0), inertia=None) -> None:
        if mass == 0 and (inertia is None or not inertia.any()):
            body.append(f'{ind}<link name="{name}"/>')
            return
        i = inertia
        body.extend([f'{ind}<link name="{name}">', f"{ind * 2}<inertial>",
                 f'{ind * 3}<origin xyz="{_vec(com)}" rpy="{_vec(rpy)}"/>', f'{ind * 3}<mass value="{_num(mass)}"/>',
                 f'{ind * 3}<inertia ixx="{_num(i[0, 0])}" ixy="{_num(i[0, 1])}" ixz="{_num(i[0, 2])}" '
                 f'iyy="{_num(i[1, 1])}" iyz="{_num(i[1, 2])}" izz="{_num(i[2, 2])}"/>',
                 f"{ind * 2}</inertial>", f"{ind}</link>"])

    def joint(name: str, kind: str, parent: str, child: str, origin: Origin | None, extra: list[str]) -> None:
        body.append(f'{ind}<joint name="{name}" type="{kind}">')
        body.append(f'{ind * 2}<parent link="{parent}"/>')
        body.append(f'{ind * 2}<child link="{child}"/>')
        if origin is not None:
            body.append(f'{ind * 2}<origin xyz="{_vec(m.vec(origin.xyz))}" rpy="{_vec(m.vec(origin.rpy))}"/>')
        body.extend(f"{ind * 2}{e}" for e in extra)
        body.append(f"{ind}</joint>")

    if robot.floating:
        world = m.unique(links, "world")
        free = m.unique(joints, FREE_FLYER)
        body.append(_comment(f"floating base: the massless link '{world}' and the floating joint '{free}' "
                             "(identity origin) to the root link"))
        link(world)
        joint(free, "floating", world, robot.root, None, [])
    for lk in robot.links:
        link(lk.name, m.num(lk.mass), m.vec(lk.com), m.vec(lk.inertia_rpy), m.inertia(lk))
    rotor: list[str] = []
    pieces_all = [p for ps in m.pieces.values() for p in ps]
    limits, filled = _placeholders(pieces_all)
    for j in robot.joints:
        if j.dof == 0:
            joint(j.name, "fixed", j.parent, j.child, j.origin, [])
            continue
        pieces = m.pieces[j.name]
        parent, origin = j.parent, j.origin
        if len(pieces) > 1:
            body.append(_comment(f"{j.type} joint '{j.name}': {len(pieces)} joints through massless links"
                                 + (f" ({pieces[1].name} = pitch * {j.name})" if j.type == "helical" else "")))
        for k, p in enumerate(pieces):
            child = j.child if k == len(pieces) - 1 else m.unique(links, f"{p.name}_link")
            if k < len(pieces) - 1:
                link(child)
            lim = limits[p.name]
            extra = [f'<axis xyz="{_vec(p.axis)}"/>']
            attrs = " ".join(f'{key}="{_num(lim[key])}"' for key in ("lower", "upper", "effort", "velocity") if key in lim)
            if attrs:
                extra.append(f"<limit {attrs}/>")
            if p.mimic is not None:
                extra.append(f'<mimic joint="{p.mimic[0]}" multiplier="{_num(p.mimic[1])}" offset="{_num(p.mimic[2])}"/>')
            viscous, coulomb = m.num(p.actuator.viscous), m.num(p.actuator.coulomb)
            if viscous or coulomb:
                extra.append(f'<dynamics damping="{_num(viscous)}" friction="{_num(coulomb)}"/>')
            arm = m.armature(p.actuator)
            if arm:
                rotor.append(f"{p.name} {arm!r}")
                extra.append(_comment(f"rotor inertia (armature + gear_ratio^2 motor_inertia) {arm!r}: URDF has no "
                                      "element for it"))
            joint(p.name, lim["kind"], parent, child, origin, extra)
            parent, origin = child, None
    for f in robot.frames:
        link(f.name)
        joint(m.unique(joints, f"{f.name}_joint"), "fixed", f.link, f.name, f.origin, [])

    gravity = m.vec(robot.gravity)
    if gravity != URDF_GRAVITY:
        notes.append(f"URDF has no gravity (readers assume {_vec(URDF_GRAVITY)} m/s^2); this robot's is "
                     f"{_vec(gravity)}: written as a comment only")
    if rotor:
        notes.append("URDF has no rotor inertia (armature): left out, in comments only, for " + ", ".join(rotor))
    if robot.loops:
        notes.append(f"URDF has no loop closures: the {len(robot.loops)} loop(s) are left out (the file is the "
                     "spanning tree; derive export --mjcf writes them as MuJoCo equalities)")
    if filled:
        notes.append("URDF requires <limit effort velocity> (and lower, upper on revolute and prismatic joints): where "
                     f"the model gives none, the placeholders 0 and +-{UNBOUNDED:g} are written (read back as no limit) "
                     "for " + ", ".join(filled))
    lines = ['<?xml version="1.0"?>', *m.header("URDF"), *(_comment("note: " + n) for n in notes)]
    lines += [f'<robot name="{robot.name}">', *body, "</robot>"]
    return Exported("\n".join(lines) + "\n", tuple(notes))


def to_urdf(robot: Robot) -> str:
    """The robot as URDF text (see :func:`export_urdf`)."""
    return export_urdf(robot).text


# --------------------------------------------------------------------------- MJCF


def _principal(inertia: np.ndarray, rpy) -> tuple[tuple[float, float, float], tuple | None]:
    """(principal moments, (w, x, y, z) of the principal axes in the link frame, None for identity)."""
    if not (inertia - np.diag(np.diag(inertia))).any():
        quat = rpy_quaternion(rpy) if any(rpy) else None
        return tuple(float(v) for v in np.diag(inertia)), quat
    eig, axes = np.linalg.eigh((inertia + inertia.T) / 2)
    if np.linalg.det(axes) < 0:
        axes[:, 0] = -axes[:, 0]
    eig = np.maximum(eig, 0.0)  # a validated tensor: negative only by rounding (within rtol 1e-9)
    eig[2] = min(eig[2], eig[0] + eig[1])
    return tuple(float(v) for v in eig), matrix_quaternion(rpy_matrix(rpy) @ axes)


@dataclass
class _MjcfLoops:
    """What a robot's loops add to its MJCF: sites and rod bodies per link, equality lines, notes."""

    sites: dict[str, list[str]]  # link -> <site .../> (no indent)
    rods: dict[str, list[tuple[str, tuple]]]  # link -> (a rod's <body> line, its ball's qpos at the reference)
    equalities: list[str]
    notes: list[str]


def quat_between(u: np.ndarray, v: np.ndarray) -> tuple[float, float, float, float]:
    """(w, x, y, z) of the least rotation taking the unit vector u to the unit vector v (a half turn about an
    axis normal to u where v = -u)."""
    w = 1.0 + float(u @ v)
    if w < 1e-12:
        axis = np.cross(u, [1.0, 0.0, 0.0] if abs(u[0]) < 0.9 else [0.0, 1.0, 0.0])
        return (0.0, *(float(x) for x in axis / np.linalg.norm(axis)))
    q = np.array([w, *np.cross(u, v)])
    return tuple(float(x) for x in q / np.linalg.norm(q))


def _mjcf_loops(robot: Robot, m: "_Model", rod_mass: float, rod_moment: float) -> _MjcfLoops:
    """The loops as MuJoCo equalities between sites (module docstring), checked at the reference configuration;
    a distance rod's body gets mass ``rod_mass`` and the moment ``rod_moment`` about every axis."""
    out = _MjcfLoops({}, {}, [], [])
    if not robot.loops:
        return out
    poses = Poses(robot)(np.array(robot.reference_q, dtype=float))
    zero = Poses(robot)(np.zeros(robot.nq))
    links = {lk.name for lk in robot.links}
    link_of = {f.name: f.link for f in robot.frames} | {a: f.link for f in robot.frames for a in f.aliases}
    bodies, joints = set(m.link_names), set(m.joint_names)
    sites = {f.name for f in robot.frames}
    link_site: dict[str, str] = {}

    def site(frame: str) -> str:
        frame = robot.frame_name(frame) if frame not in links else frame
        if frame not in links:
            return frame
        if frame not in link_site:
            link_site[frame] = m.unique(sites | bodies, f"{frame}_site")
            sites.add(link_site[frame])
            out.sites.setdefault(frame, []).append(f'<site name="{link_site[frame]}" pos="0 0 0"/>')
        return link_site[frame]

    def where(i: int) -> str:
        return f"loops[{i}]"

    for i, lp in enumerate(robot.loops):
        (Ra, pa), (Rb, pb) = poses[lp.a], poses[lp.b]
        if lp.kind == "hinge":
            raise ModelError(robot.name, where(i), "MuJoCo has no hinge equality: a hinge loop cannot be written as MJCF "
                             "(two point loops on the axis can)", robot.file or None)
        if lp.kind == "distance":
            # the rod: a body on a ball joint at frame b, in b's link, its end site at the length from the ball
            # (towards frame a as the tree stands at q = 0; the keyframe turns the ball to the reference)
            length = m.num(lp.length)
            pivot = site(lp.b)
            link = lp.b if lp.b in links else link_of[lp.b]
            (R0, p0), Rr = zero[link], poses[link][0]
            at = R0.T @ (zero[lp.b][1] - p0)  # the ball in the link frame
            toward = R0.T @ (zero[lp.a][1] - zero[lp.b][1])
            u0 = toward / np.linalg.norm(toward) if np.linalg.norm(toward) > 1e-12 else np.array([1.0, 0.0, 0.0])
            turn = quat_between(np.array([1.0, 0.0, 0.0]), u0)  # the rod's frame: its x axis along u0
            u = quat_matrix(turn).T @ Rr.T @ (poses[lp.a][1] - poses[lp.b][1])
            rod = m.unique(sites | bodies, f"{pivot}_rod")
            end = m.unique(sites | bodies | {rod}, f"{rod}_end")
            bodies.add(rod)
            sites.add(end)
            joint = m.unique(joints, rod)
            moment = _num(rod_moment)
            out.rods.setdefault(link, []).append((
                f'<body name="{rod}" pos="{_vec(at)}"' + (f' quat="{_vec(turn)}"' if turn != (1.0, 0.0, 0.0, 0.0) else "")
                + f'><joint name="{joint}" type="ball"/>'
                f'<inertial pos="0 0 0" mass="{_num(rod_mass)}" diaginertia="{moment} {moment} {moment}"/>'
                f'<site name="{end}" pos="{_num(length)} 0 0"/></body>',
                quat_between(np.array([1.0, 0.0, 0.0]), u / np.linalg.norm(u))))
            out.equalities.append(f'<connect name="loop{i}" site1="{end}" site2="{site(lp.a)}"/>')
            out.notes.append(f"{where(i)} (distance {length!r} m) is the rod body '{rod}' on a ball joint at {lp.b} "
                             f"(mass {rod_mass:.3g} kg, moments {rod_moment:.3g} kg m^2, all at the ball: derive's rod is "
                             f"massless), its end '{end}' {length!r} m from the ball held at {lp.a} by <connect>")
            continue
        if lp.kind == "planar":
            n = Ra @ np.asarray(lp.axis, dtype=float)
            apart = abs(float(n @ (pa - pb)))
            turned = float(np.linalg.norm(Ra - Rb)) if lp.rotation else 0.0
            if apart > 1e-9 or turned > 1e-9:
                raise ModelError(robot.name, where(i), f"a planar loop is a <{'weld' if lp.rotation else 'connect'}> "
                                 f"in MJCF only where its frames coincide at the reference configuration: they are "
                                 f"{apart:.3g} m apart along the normal" + (f" and turned ({turned:.3g})" if lp.rotation
                                 else ""), robot.file or None)
            out.notes.append(f"{where(i)} (planar) is a 3-D <{'weld' if lp.rotation else 'connect'}>: the same "
                             "constraint while the mechanism moves in its plane")
        tag = "weld" if lp.kind == "weld" or lp.rotation else "connect"
        out.equalities.append(f'<{tag} name="loop{i}" site1="{site(lp.a)}" site2="{site(lp.b)}"/>')
    return out


def export_mjcf(robot: Robot) -> Exported:
    """The robot as an MJCF document (see the module docstring) and the notes on what differs in MuJoCo."""
    m = _Model(robot)
    bodies = [lk.name for lk in robot.links if robot.floating or lk.name != robot.root]
    if "world" in bodies:  # MuJoCo's world body has that name; a fixed root called world is that body
        raise ModelError(robot.name, "links", "MJCF calls its world body 'world': a link of that name must be the "
                                              "root of a fixed-base robot; rename it", robot.file or None)
    notes: list[str] = []
    ind = "  "
    masses = [m.num(lk.mass) for lk in robot.links]
    moments = [float(np.abs(np.linalg.eigvalsh(m.inertia(lk))).max()) for lk in robot.links]
    floor_mass = max(FLOOR * max(masses, default=0.0), 10 * MJ_MINVAL)
    floor_moment = max(FLOOR * max(moments, default=0.0), 10 * MJ_MINVAL)
    closed = _mjcf_loops(robot, m, floor_mass, floor_moment)
    reference = dict(zip((c.name for c in robot.coordinates), robot.reference_q)) if robot.loops else {}
    key_qpos: list[str] = []  # the reference configuration in MuJoCo's qpos order
    raised: list[str] = []
    equalities: list[str] = []
    motors: list[str] = []
    velocity: list[str] = []
    placeholder: list[str] = []
    moving = {j.child for j in robot.joints if j.dof > 0} | ({robot.root} if robot.floating else set())

    def inertial(lk, depth: int) -> list[str]:
        mass, inertia = m.num(lk.mass), m.inertia(lk)
        diag, quat = _principal(inertia, m.vec(lk.inertia_rpy))
        if lk.name in moving:
            low = [k for k, d in enumerate(diag) if d < floor_moment]
            if mass < floor_mass or low:
                what = ([f"mass {mass:g} -> {floor_mass:.3g} kg"] if mass < floor_mass else []) + ([
                    f"moment{'s' * (len(low) > 1)} {', '.join(f'{diag[k]:g}' for k in low)} -> {floor_moment:.3g} kg m^2"]
                    if low else [])
                raised.append(f"{lk.name} ({', '.join(what)})")
                mass = max(mass, floor_mass)
                diag = tuple(max(d, floor_moment) for d in diag)
        elif mass == 0:
            return []
        text = f'<inertial pos="{_vec(m.vec(lk.com))}"' + (f' quat="{_vec(quat)}"' if quat else "")
        return [f'{ind * depth}{text} mass="{_num(mass)}" diaginertia="{_vec(diag)}"/>']

    def sites(link: str, depth: int) -> list[str]:
        out = []
        for f in m.frames[link]:
            rpy = m.vec(f.origin.rpy)
            quat = f' quat="{_vec(rpy_quaternion(rpy))}"' if any(rpy) else ""
            out.append(f'{ind * depth}<site name="{f.name}" pos="{_vec(m.vec(f.origin.xyz))}"{quat}/>')
        out += [f"{ind * depth}{x}" for x in closed.sites.get(link, [])]
        for line, quat in closed.rods.get(link, []):  # a rod's ball: its qpos after its link's joints (MuJoCo's order)
            out.append(f"{ind * depth}{line}")
            key_qpos.extend(_num(x) for x in quat)
        return out

    def joint_lines(j: Joint, depth: int) -> list[str]:
        out = []
        for p in m.pieces[j.name]:
            kind = "slide" if p.kind == "prismatic" else "hinge"
            attrs = f'name="{p.name}" type="{kind}" axis="{_vec(p.axis)}"'
            lim = p.limits
            if lim.lower is not None or lim.upper is not None:
                if lim.lower is None or lim.upper is None:
                    placeholder.append(p.name)
                lo = -UNBOUNDED if lim.lower is None else lim.lower
                hi = UNBOUNDED if lim.upper is None else lim.upper
                attrs += f' limited="true" range="{_num(lo)} {_num(hi)}"'
            if lim.effort is not None:  # the joint's own torque limit, where import-mjcf reads it back
                attrs += f' actuatorfrcrange="{_num(-lim.effort)} {_num(lim.effort)}"'
            arm, viscous, coulomb = m.armature(p.actuator), m.num(p.actuator.viscous), m.num(p.actuator.coulomb)
            for key, value in (("armature", arm), ("damping", viscous), ("frictionloss", coulomb)):
                if value:
                    attrs += f' {key}="{_num(value)}"'
            out.append(f"{ind * depth}<joint {attrs}/>")
            if reference:
                leader, a, b = p.mimic or (p.name, 1.0, 0.0)
                key_qpos.append(_num(a * reference[leader] + b))
            if lim.velocity is not None:
                velocity.append(f"{p.name} {lim.velocity!r}")
            if p.mimic is not None:
                leader, a, b = p.mimic
                equalities.append(f'{ind * 2}<joint name="{p.name}" joint1="{p.name}" joint2="{leader}" '
                                  f'polycoef="{_num(b)} {_num(a)} 0 0 0"/>')
            if p.coordinate:
                ctrl = "" if lim.effort is None else f' ctrllimited="true" ctrlrange="{_num(-lim.effort)} {_num(lim.effort)}"'
                motors.append(f'{ind * 2}<motor name="{p.name}" joint="{p.name}" gear="1"{ctrl}/>')
        return out

    body: list[str] = []
    root = robot.link(robot.root)
    depth = 2
    if robot.floating or root.name != "world":
        body.append(f'{ind * depth}<body name="{root.name}">')
        depth += 1
        if robot.floating:
            body.append(f'{ind * depth}<freejoint name="{m.unique(set(m.joint_names), FREE_FLYER)}"/>')
        body += inertial(root, depth)
    elif m.num(root.mass):
        body.append(f"{ind * depth}" + _comment(f"the root link 'world' is MuJoCo's world body: its mass "
                                                f"{m.num(root.mass)!r} kg moves nothing and is left out"))
    body += sites(root.name, depth)
    # depth-first, children in the model's order; an explicit stack (no recursion limit on long chains)
    stack: list[tuple[str, Any, int]] = [("open", j, depth) for j in reversed(m.children[root.name])]
    while stack:
        what, j, d = stack.pop()
        if what == "close":
            body.append(f"{ind * d}</body>")
            continue
        rpy = m.vec(j.origin.rpy)
        quat = f' quat="{_vec(rpy_quaternion(rpy))}"' if any(rpy) else ""
        body.append(f'{ind * d}<body name="{j.child}" pos="{_vec(m.vec(j.origin.xyz))}"{quat}>')
        if j.dof > 0:
            if len(m.pieces[j.name]) > 1:
                body.append(f"{ind * (d + 1)}" + _comment(f"{j.type} joint '{j.name}'"))
            body += joint_lines(j, d + 1)
        body += inertial(robot.link(j.child), d + 1)
        body += sites(j.child, d + 1)
        stack.append(("close", None, d))
        stack.extend(("open", c, d + 1) for c in reversed(m.children[j.child]))
    if robot.floating or root.name != "world":
        body.append(f"{ind * 2}</body>")

    if raised:
        notes.append(f"MuJoCo refuses a body with a joint whose mass or a principal moment is below {MJ_MINVAL:g} "
                     f"(mjMINVAL): raised to {FLOOR:g} of the robot's largest: {'; '.join(raised)}")
    if velocity:
        notes.append("MJCF has no joint velocity limit: left out, in this comment only: " + ", ".join(velocity))
    if placeholder:
        notes.append(f"MJCF ranges have two ends: a missing one is +-{UNBOUNDED:g} for " + ", ".join(placeholder))
    if equalities:
        notes.append("mimic joints are MuJoCo equality constraints (soft, solref/solimp defaults): "
                     + ", ".join(e.split('"')[1] for e in equalities))
    if robot.loops:
        notes += closed.notes
        notes.append("the loops are MuJoCo equality constraints (soft, solref/solimp defaults); the keyframe "
                     "'reference' is the closed reference configuration")
        equalities += [f"{ind * 2}{e}" for e in closed.equalities]
    lines = [f'<mujoco model="{robot.name}">', *(f"{ind}{c}" for c in m.header("MJCF")),
             *(f"{ind}" + _comment("note: " + n) for n in notes),
             f'{ind}<compiler angle="radian" autolimits="true" inertiafromgeom="false"/>',
             f'{ind}<option gravity="{_vec(m.vec(robot.gravity))}"/>', f"{ind}<worldbody>", *body, f"{ind}</worldbody>"]
    if equalities:
        lines += [f"{ind}<equality>", *equalities, f"{ind}</equality>"]
    if motors:
        lines += [f"{ind}<actuator>", *motors, f"{ind}</actuator>"]
    if key_qpos:
        lines += [f"{ind}<keyframe>", f'{ind * 2}<key name="reference" qpos="{" ".join(key_qpos)}"/>', f"{ind}</keyframe>"]
    lines.append("</mujoco>")
    return Exported("\n".join(lines) + "\n", tuple(notes))


def to_mjcf(robot: Robot) -> str:
    """The robot as MJCF text (see :func:`export_mjcf`)."""
    return export_mjcf(robot).text
