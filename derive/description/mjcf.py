"""MJCF -> a models.yaml robot entry (``derive import-mjcf``), read from MuJoCo's compiled model.

MuJoCo's own compiler (the optional ``mujoco`` package: ``pip install 'derive-robotics[mjcf]'``)
reads the file, so defaults and classes, ``<include>``, ``<frame>``, ``compiler angle/eulerseq``,
every orientation spelling (quat, euler, axisangle, xyaxes, zaxis) and ``inertiafromgeom`` mean
exactly what they mean to MuJoCo; this module reads the compiled ``mjModel`` arrays. URDF is never
read through MuJoCo (its URDF reader fuses the fixed base away): a ``<robot>`` file is refused.

Conventions (what the entry is, against MuJoCo's qpos and qvel):

- Every MuJoCo body is a derive link or frame with MuJoCo's body frame: a body with joints is the
  link its last joint moves; a body without joints (welded to its parent) is merged into its
  parent's link (mass by the parallel-axis theorem) and stays a named frame. With a fixed base the
  root link is ``world``.
- ``hinge`` -> revolute, ``slide`` -> prismatic: q = qpos (MuJoCo turns by qpos - ref, so the joint
  origin holds the turn by -ref). Joints of one body apply in file order, each about its anchor
  ``pos`` in the body frame: body = Trans(p) Rot(a, q) Trans(-p). A joint whose anchor is off the
  body origin, and every joint but a body's last, moves a massless link ``<body>_<joint>`` whose
  frame is the joint frame at the anchor; the body frame sits on it at Trans(-p).
- ``ball`` -> spherical: derive's q are the ZYX Euler angles (z, y, x) of MuJoCo's quaternion,
  R = Rz(z) Ry(y) Rx(x), and qd their rates: MuJoCo's qvel (the body-frame angular velocity) is
  w = E qd with E = [[-sy, 0, 1], [cy sx, cx, 0], [cy cx, -sx, 0]] (gimbal lock at cos y = 0). A
  ball's armature and damping act on w, not on Euler rates: dropped with a warning.
- ``free`` (a top-level body only) -> ``base: floating``: q = [x, y, z, qx, qy, qz, qw] where MuJoCo
  has qpos = [x, y, z, qw, qx, qy, qz]; v = [R^T v_world, w_body] where MuJoCo has qvel =
  [v_world, w_body] (v_world the world-frame velocity of the body origin, R the body orientation).
  ``floating=False`` welds a free body to the world at its initial pose; ``floating=True`` on a
  file without a free joint floats its one top-level body (which must have no joints).
- Limits: ``range`` -> lower, upper; a symmetric ``actuatorfrcrange`` -> effort; an end beyond
  1e12 in magnitude (an exporter's "no limit", derive export's for a one-sided range) is left out
  with a warning, as import-urdf does.
- Inertials: ``body_mass``, ``body_ipos`` and the principal ``body_inertia`` turned from
  ``body_iquat`` into the link frame (no ``inertia_rpy``); a massless body's rotational inertia
  counts (MuJoCo's M holds it).
- Named sites become frames on their body's link (unnamed sites are left out).
- The visible geoms (groups 0 to 2, MuJoCo's viewer's default; not fully transparent) become their
  link's ``visual:`` list (``derive view`` only; ``visuals=False`` / ``--no-visuals`` leaves them
  out): box, sphere, cylinder and capsule with their full sizes, an ellipsoid as a unit sphere
  scaled by its radii, a mesh as its file (absolute; relative to the models file with ``--out``) and
  ``scale``, placed as written: MuJoCo's compiler moves a mesh's vertices to its inertial frame
  (``mesh_pos``, ``mesh_quat``) and the geom the other way, which the import undoes. Colour: the
  geom's material's ``rgba``, else its own. Planes, height fields and meshes without a file are
  left out.
- ``dof_armature``, ``dof_damping`` and ``dof_frictionloss`` -> the joint's ``actuator``
  ``{armature, viscous, coulomb}`` (MuJoCo applies frictionloss as a soft constraint, derive as
  f_c sign(qd)); a joint actuator's ``gear`` -> ``gear_ratio`` (a record only: derive's tau stays
  the joint torque, MuJoCo's motor ctrl = tau / gear). ``actuators=False`` leaves all of it out.
- ``equality joint`` with polycoef (c0, c1, 0, 0, 0): joint1 becomes a mimic of joint2,
  q1 - ref1 = c0 + c1 (q2 - ref2); a non-linear polynomial, a joint fixed to a constant and the
  other kinds (flex, other tendon couplings) are refused in one line.
- ``equality connect``, ``weld`` and a two-site ``tendon`` close kinematic loops
  (docs/closed-chains.md); each becomes a ``loops:`` entry between two frames. A named site is the
  loop's frame itself; otherwise new frames ``<name>_a`` (body1's link) and ``<name>_b`` (body2's),
  ``<name>`` the equality's name or ``loop<k>``.
  connect -> ``point``: with bodies, frame a at ``anchor`` in body1 and frame b at the point MuJoCo
  computes in body2 at qpos0 (its ``eq_data[3:6]``); with sites, the two sites.
  weld -> ``weld``: with bodies, frame a at (``relpose``, given or the one MuJoCo computes at qpos0)
  in body1 and frame b at ``anchor`` in body2 (MuJoCo's p1 + R1 relpos = p2 + R2 anchor, R1 relquat =
  R2); with sites, the two sites. torquescale 0 (no rotation held) is refused: write a connect.
  tendon (a spatial tendon through exactly two sites, no tendon2, polycoef (c0, 0, 0, 0, 0)) ->
  ``distance`` between the two sites, length = MuJoCo's tendon_length0 + c0 (a massless rod with
  ball joints); other tendon couplings are refused. derive export's rod (a body ``<site>_rod`` on
  one ball joint at its origin, where its parent has the site ``<site>``, with one site, its end,
  held by a site connect at another site; no child bodies) -> ``distance`` between that other site
  and ``<site>``, length = the end's distance from the ball; the rod body (its mass and moments
  MuJoCo's least) and its ball are left out.
  ``solref``, ``solimp`` and ``torquescale`` weigh MuJoCo's soft rows; derive's closure is exact, so
  they are not kept. An inactive one (``active="false"``) is left out with a warning.
  ``reference:`` is the qpos of the keyframe ``keyframe=`` (``--keyframe``; by default the one named
  ``reference`` where there is one, as derive export writes it), else MuJoCo's qpos0 (the hinge and
  slide ``ref``): derive closes the loops there (``independent:`` from ``independent=``, else
  derive's pivoting); loops that do not close there are one line. Closed chains need a fixed base
  (``--fixed`` welds a free body).
- Gravity is ``opt.gravity`` (0 where the gravity flag is disabled); joint stiffness and
  gravity compensation have no derive counterpart and are dropped with a warning.
"""

from __future__ import annotations

import math
import os
import sys
import xml.etree.ElementTree as ET
from pathlib import Path
from typing import Any

import numpy as np

from derive.description.files import InputFileError, read_bytes
from derive.description.model import parse_robot
from derive.description.numbers import MAX_MAGNITUDE
from derive.description.robot import ModelError, identifier
from derive.description.urdf import Pose, c_identifier
from derive.errors import DeriveError

EXTRA = "pip install 'derive-robotics[mjcf]'"
GENERATOR = "derive import-mjcf"


class MjcfError(DeriveError):
    """An MJCF file that cannot be imported; one line naming the file (and the element)."""


def load_mujoco(path: str | Path):
    """The ``mujoco`` module, or a one-line error naming the extra that installs it."""
    try:
        import mujoco
    except ImportError:
        raise MjcfError(f"{path}: reading MJCF needs MuJoCo's compiler, the mujoco package: {EXTRA}") from None
    return mujoco


# --------------------------------------------------------------------------- transforms


def quat_matrix(quat) -> np.ndarray:
    """R of MuJoCo's unit quaternion (w, x, y, z)."""
    w, x, y, z = (float(v) for v in quat)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _h(rot: np.ndarray, pos) -> np.ndarray:
    t = np.eye(4)
    t[:3, :3], t[:3, 3] = rot, np.asarray(pos, dtype=float)
    return t


def _axis_rotation(axis, angle: float) -> np.ndarray:
    k = np.asarray(axis, dtype=float)
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * kx + (1.0 - math.cos(angle)) * kx @ kx


def _origin(t: np.ndarray) -> dict:
    """{xyz, rpy} of a 4x4 pose (angles within a few ulps of k pi/2 snapped, as the URDF reader does)."""
    pose = Pose.from_matrix(t[:3, :3], t[:3, 3])
    return {"xyz": [float(v) for v in pose.xyz], "rpy": [float(v) for v in pose.rpy]}


def _is_identity(t: np.ndarray) -> bool:
    return bool(np.array_equal(t, np.eye(4)))


def _clean(v: float) -> float:
    """-0.0 -> 0.0 (YAML text stays tidy); other values unchanged."""
    return 0.0 if v == 0 else float(v)


# --------------------------------------------------------------------------- reading


def _root_tag(path: Path, spelling: str, robot: str) -> tuple[str, str | None]:
    """(root element tag, its ``model`` attribute) without reading the file through MuJoCo."""
    try:
        data = read_bytes(path, "MJCF")
    except InputFileError as exc:
        raise MjcfError(str(exc)) from None
    try:
        root = ET.fromstring(data)
    except (RecursionError, MemoryError):
        raise ModelError(robot, "", "XML nested too deeply", spelling) from None
    except ET.ParseError as exc:
        line, col = exc.position
        raise ModelError(robot, f"line {line}, column {col + 1}", f"malformed XML: {str(exc).split(':')[0]}",
                         spelling) from None
    return root.tag, root.get("model")


def _compile(mujoco, path: Path, spelling: str, robot: str):
    try:
        return mujoco.MjModel.from_xml_path(str(path))
    except (ValueError, RuntimeError, OSError) as exc:  # MuJoCo's compiler: several lines, one kept per clause
        text = "; ".join(line.strip() for line in str(exc).splitlines() if line.strip())
        raise ModelError(robot, "", f"MuJoCo's compiler refused it: {text}", spelling) from None


def import_mjcf(path: str | Path, name: str | None = None, floating: bool | None = None,
                actuators: bool = True, independent: list[str] | None = None, keyframe: str | None = None,
                visuals: bool = True) -> dict:
    """Read an MJCF file through MuJoCo's compiler and return one models.yaml robot entry (a plain dict).

    ``floating`` None: as the file says (a free joint -> ``base: floating``); True / False to
    choose (module docstring). ``actuators`` False leaves armature, damping, frictionloss and
    gears out. ``name`` defaults to the MJCF ``model`` name made a C identifier. ``independent``: the
    independent coordinates of a closed chain (``connect``/``weld`` equalities; default: derive's
    pivoting); ``keyframe``: the keyframe whose qpos is its reference configuration (default: the one named
    ``reference`` where there is one, else qpos0). ``visuals`` False leaves out the visible geoms (each
    link's ``visual:`` list, module docstring). Raises a one-line :class:`~derive.errors.DeriveError`
    naming the file and the element.
    """
    return import_mjcf_named(path, name, floating, actuators, independent, keyframe, visuals)[1]


def import_mjcf_named(path: str | Path, name: str | None = None, floating: bool | None = None,
                      actuators: bool = True, independent: list[str] | None = None,
                      keyframe: str | None = None, visuals: bool = True) -> tuple[str, dict]:
    """Like :func:`import_mjcf`, returning ``(robot name, entry)``."""
    if name is not None:
        identifier(name, "name", name)
    spelling = str(path)
    file = Path(path)
    fallback = name or c_identifier(file.stem)
    tag, model_name = _root_tag(file, spelling, fallback)
    if tag != "mujoco":
        hint = " (a URDF: derive import-urdf FILE)" if tag == "robot" else ""
        raise ModelError(fallback, "", f"not an MJCF file: the root element is <{tag}>, not <mujoco>{hint}", spelling)
    mujoco = load_mujoco(spelling)
    default = c_identifier(model_name or file.stem)
    robot = name or default
    m = _compile(mujoco, file, spelling, robot)
    importer = _Importer(mujoco, m, robot, spelling, floating, actuators, default, independent, keyframe)
    importer.folder = file.absolute().parent if visuals else None
    return robot, importer.entry()


class _Importer:
    def __init__(self, mujoco, m, robot: str, spelling: str, floating: bool | None, actuators: bool, default: str,
                 independent: list[str] | None = None, keyframe: str | None = None):
        self.mj, self.m, self.robot, self.spelling, self.default_name = mujoco, m, robot, spelling, default
        self.independent = list(independent) if independent else None
        self.keyframe = keyframe
        kinds = mujoco.mjtJoint
        # plain ints: the arrays hold numpy integers, which pybind's enums do not compare with
        self.FREE, self.BALL, self.SLIDE, self.HINGE = (int(k) for k in (kinds.mjJNT_FREE, kinds.mjJNT_BALL,
                                                                          kinds.mjJNT_SLIDE, kinds.mjJNT_HINGE))
        self.floating_arg, self.with_actuators = floating, actuators
        self.notes: list[str] = []
        self.folder: Path | None = None  # the MJCF's folder, where its relative mesh files are; None: no visuals

    def error(self, where: str, problem: str) -> ModelError:
        return ModelError(self.robot, where, problem, self.spelling)

    def warn(self, where: str, problem: str) -> None:
        print(f"warning: {self.spelling}: {where}: {problem}", file=sys.stderr)

    # ---- names (MuJoCo's, made C identifiers; unnamed ones numbered)
    def body_name(self, b: int) -> str:
        return "world" if b == 0 else c_identifier(self.m.body(b).name or f"body{b}")

    def joint_name(self, j: int) -> str:
        return c_identifier(self.m.joint(j).name or f"{self.body_name(int(self.m.jnt_bodyid[j]))}_joint{j}")

    def body_where(self, b: int) -> str:
        return f"<body name=\"{self.m.body(b).name}\">" if self.m.body(b).name else f"body {b}"

    def joint_where(self, j: int) -> str:
        return f"<joint name=\"{self.m.joint(j).name}\">" if self.m.joint(j).name else f"joint {j}"

    def body_joints(self, b: int) -> list[int]:
        start = int(self.m.body_jntadr[b])
        return list(range(start, start + int(self.m.body_jntnum[b]))) if start >= 0 else []

    # ---- the base
    def choose_base(self) -> tuple[bool, int]:
        """(floating?, the root body: 0 = the world for a fixed base)."""
        m, mj = self.m, self.mj
        free = [j for j in range(m.njnt) if int(m.jnt_type[j]) == self.FREE]
        top = [b for b in range(1, m.nbody) if m.body_parentid[b] == 0]
        if len(free) > 1:
            raise self.error(self.joint_where(free[1]), f"a second free joint ({len(free)} in all): derive models "
                             "one tree with at most one floating base")
        floating = bool(free) if self.floating_arg is None else self.floating_arg
        if not floating:
            if free:
                self.notes.append(f"the free body {self.body_name(int(m.jnt_bodyid[free[0]]))} welded to the world at "
                                  "its initial pose")
            return False, 0
        if free:
            root = int(m.jnt_bodyid[free[0]])
            if len(self.body_joints(root)) > 1:
                raise self.error(self.body_where(root), "a free joint together with other joints in one body")
            dof = int(m.jnt_dofadr[free[0]])
            if self.with_actuators and any(float(x) for x in np.concatenate(
                    [m.dof_armature[dof:dof + 6], m.dof_damping[dof:dof + 6], m.dof_frictionloss[dof:dof + 6]])):
                self.warn(self.joint_where(free[0]), "the free joint's armature, damping and frictionloss have no "
                                                     "counterpart on derive's floating base: left out")
        else:
            if len(top) != 1:
                raise self.error("worldbody", f"--floating needs one top-level body to float, the file has {len(top)}")
            root = top[0]
            if self.body_joints(root):
                raise self.error(self.body_where(root), f"--floating: it is joined to the world by "
                                 f"{self.joint_where(self.body_joints(root)[0])}; only a body without joints can float")
        dropped = []
        for b in top:
            if b == root:
                continue
            subtree = [c for c in range(b, m.nbody) if self.under(c, b)]
            moving = [j for c in subtree for j in self.body_joints(c)]
            if moving:
                raise self.error(self.joint_where(moving[0]), f"moves a body of another tree than the floating base "
                                 f"'{self.body_name(root)}': derive models one tree")
            dropped.append(self.body_name(b))
        if dropped or m.body_mass[0] > 0:
            self.notes.append("dropped what is fixed to the world" + (f" ({', '.join(dropped)})" if dropped else ""))
        self.notes.append(f"floating base {self.body_name(root)}")
        return True, root

    def under(self, b: int, top: int) -> bool:
        while b > 0:
            if b == top:
                return True
            b = int(self.m.body_parentid[b])
        return False

    # ---- the entry
    def entry(self) -> dict:
        m, mj = self.m, self.mj
        floating, root = self.choose_base()
        for e in range(m.neq):
            self.check_equality(e)
        mimic = self.mimics()
        self.rods = self.find_rods()

        link_of: dict[int, str] = {root: self.body_name(root)}
        at: dict[int, np.ndarray] = {root: np.eye(4)}
        links: list[str] = [self.body_name(root)]
        joints: list[dict] = []
        frames: list[dict] = []
        parts: dict[str, list[tuple[np.ndarray, int]]] = {self.body_name(root): [(np.eye(4), root)]}

        for b in range(1, m.nbody):
            parent = int(m.body_parentid[b])
            if b == root or parent not in link_of or b in self.rods:
                continue  # the floating root is placed; what hangs off the world is dropped with a floating base;
                # a distance rod's body is its loop (self.loops)
            pose = at[parent] @ _h(quat_matrix(m.body_quat[b]), m.body_pos[b])
            body = self.body_name(b)
            moving = [j for j in self.body_joints(b) if int(m.jnt_type[j]) != self.FREE]
            link = link_of[parent]
            for k, j in enumerate(moving):
                joint, link, pose = self.joint(j, link, pose, body, last=k == len(moving) - 1, mimic=mimic.get(j))
                joints.append(joint)
                links.append(link)
                parts[link] = []
            link_of[b], at[b] = link, pose
            parts[link].append((pose, b))
            if link != body:
                frames.append({"name": body, "link": link, **_origin(pose)})
        for s in range(m.nsite):
            b = int(m.site_bodyid[s])
            if not m.site(s).name or b not in link_of or b in self.rods:
                continue
            pose = at[b] @ _h(quat_matrix(m.site_quat[s]), m.site_pos[s])
            frames.append({"name": c_identifier(m.site(s).name), "link": link_of[b], **_origin(pose)})
        if floating and any(m.site_bodyid[s] == 0 and m.site(s).name for s in range(m.nsite)):
            self.notes.append("the world's sites left out")
        loops = self.loops(link_of, at, frames, links)
        if self.independent and not loops:
            raise self.error("--independent", "only a closed chain (an equality connect or weld) has independent "
                                              "coordinates; this file has none")
        closed = self.closure_fields(loops, joints)

        out_links = [{"name": n, **self.merged(n, parts[n])} for n in links]
        if self.folder is not None:
            for link in out_links:
                looks = [item for pose, b in parts[link["name"]] for item in self.visuals(pose, b)]
                if looks:
                    link["visual"] = looks
        self.check_names(out_links, joints, frames)
        gravity = [0.0, 0.0, 0.0] if m.opt.disableflags & mj.mjtDisableBit.mjDSBL_GRAVITY else \
            [_clean(g) for g in m.opt.gravity]
        if any(m.body_gravcomp[1:]):
            self.warn("body gravcomp", "gravity compensation is not modelled by derive: left out")
        notes = "; ".join(self.notes)
        command = f"{GENERATOR} {self.spelling}" + {None: "", True: " --floating", False: " --fixed"}[self.floating_arg] \
            + ("" if self.with_actuators else " --no-actuators") + (f" --name {self.robot}" if self.robot != self.default_name else "") \
            + (f" --independent {','.join(self.independent)}" if self.independent else "") \
            + (f" --keyframe {self.keyframe}" if self.keyframe is not None else "")
        entry = {
            "description": f"{self.robot} imported from MJCF" + (f" ({notes})" if notes else ""),
            "source": f"{Path(self.spelling).name}, imported by `{command}`",
            **({"base": "floating"} if floating else {}),
            "gravity": gravity,
            "links": out_links,
            "joints": joints,
            "frames": frames,
            **closed,
        }
        try:
            parse_robot(self.robot, entry)
        except ModelError as exc:
            raise ModelError(self.robot, exc.field, f"{exc.problem} (in the imported entry)", self.spelling) from None
        return entry

    def joint(self, j: int, parent: str, pose: np.ndarray, body: str, last: bool, mimic: dict | None
              ) -> tuple[dict, str, np.ndarray]:
        """(entry of MuJoCo joint j, the link it moves, the body frame's pose in that link).

        ``pose``: the body frame (as moved by the body's earlier joints) in the link ``parent``.
        """
        m, mj = self.m, self.mj
        kind = int(m.jnt_type[j])
        axis = [_clean(v) for v in m.jnt_axis[j]]
        ref = float(m.qpos0[m.jnt_qposadr[j]]) if kind in (self.HINGE, self.SLIDE) else 0.0
        anchor = np.zeros(3) if kind == self.SLIDE else np.array(m.jnt_pos[j], dtype=float)
        if kind == self.HINGE:
            zero = _h(_axis_rotation(axis, -ref), np.zeros(3)) if ref else np.eye(4)
        elif kind == self.SLIDE:
            zero = _h(np.eye(3), -ref * np.array(axis)) if ref else np.eye(4)
        else:
            zero = np.eye(4)
        origin = pose @ _h(np.eye(3), anchor) @ zero
        rest = _h(np.eye(3), -anchor)  # the body frame in the joint's child frame
        name = self.joint_name(j)
        child = body if last and _is_identity(rest) else f"{body}_{name}"
        jtype = {self.HINGE: "revolute", self.SLIDE: "prismatic",
                 self.BALL: "spherical"}[kind]
        entry: dict[str, Any] = {"name": name, "type": jtype, "parent": parent, "child": child,
                                 "origin": _origin(origin)}
        if jtype != "spherical":
            entry["axis"] = axis
            limits = {}
            if m.jnt_limited[j]:
                limits["lower"], limits["upper"] = (float(v) for v in m.jnt_range[j])
            if m.jnt_actfrclimited[j]:
                lo, hi = (float(v) for v in m.jnt_actfrcrange[j])
                if lo == -hi and hi > 0:
                    limits["effort"] = hi
            # a range has two ends: exporters (derive export's too) write a missing one as a huge number
            huge = [k for k, v in limits.items() if abs(v) > MAX_MAGNITUDE]
            if huge:
                self.warn(self.joint_where(j), f"{', '.join(f'{k} {limits[k]:g}' for k in huge)}: beyond "
                          f"{MAX_MAGNITUDE:g}, a placeholder for no limit: imported without it")
                for k in huge:
                    del limits[k]
            if limits:
                entry["limits"] = limits
        elif m.jnt_limited[j]:
            self.warn(self.joint_where(j), "a ball joint's cone limit has no counterpart in ZYX angles: left out")
        if mimic is not None:
            entry["mimic"] = mimic
        if m.jnt_stiffness[j]:
            self.warn(self.joint_where(j), f"stiffness {m.jnt_stiffness[j]:g} left out (derive has no joint springs)")
        actuator = self.actuator(j, jtype)
        if actuator:
            entry["actuator"] = actuator
        return entry, child, rest

    def actuator(self, j: int, jtype: str) -> dict:
        m, mj = self.m, self.mj
        dof = int(m.jnt_dofadr[j])
        values = {"armature": float(m.dof_armature[dof]), "viscous": float(m.dof_damping[dof]),
                  "coulomb": float(m.dof_frictionloss[dof])}
        gears = [float(m.actuator_gear[a][0]) for a in range(m.nu) if m.actuator_trnid[a][0] == j
                 and int(m.actuator_trntype[a]) in (int(mj.mjtTrn.mjTRN_JOINT), int(mj.mjtTrn.mjTRN_JOINTINPARENT))]
        if jtype == "spherical":
            if any(float(x) for x in np.concatenate([m.dof_armature[dof:dof + 3], m.dof_damping[dof:dof + 3],
                                                     m.dof_frictionloss[dof:dof + 3]])) and self.with_actuators:
                self.warn(self.joint_where(j), "a ball joint's armature, damping and frictionloss act on its angular "
                                               "velocity, not on derive's ZYX angle rates: left out")
            return {}
        if not self.with_actuators:
            return {}
        out = {k: v for k, v in values.items() if v}
        if len(set(gears)) == 1 and gears[0] not in (0.0, 1.0):
            out["gear_ratio"] = gears[0]
        return out

    # ---- loop closures (equality connect and weld)
    def loops(self, link_of: dict[int, str], at: dict[int, np.ndarray], frames: list[dict],
              links: list[str]) -> list[dict]:
        """models.yaml ``loops:`` of the active connect, weld and two-site tendon equalities; the frames they
        need appended to ``frames`` (module docstring)."""
        m, mj = self.m, self.mj
        connect, weld, tendon = (int(k) for k in (mj.mjtEq.mjEQ_CONNECT, mj.mjtEq.mjEQ_WELD, mj.mjtEq.mjEQ_TENDON))
        site = int(mj.mjtObj.mjOBJ_SITE)
        taken = set(links) | {f["name"] for f in frames}
        out: list[dict] = []
        for e in range(m.neq):
            kind = int(m.eq_type[e])
            if kind not in (connect, weld, tendon):
                continue
            label = m.equality(e).name
            where = f"<equality name=\"{label}\">" if label else f"equality {e}"
            if not m.eq_active0[e]:
                self.warn(where, "inactive at the start (active=\"false\"): left out")
                continue
            data = np.array(m.eq_data[e], dtype=float)
            o1, o2 = int(m.eq_obj1id[e]), int(m.eq_obj2id[e])
            loop: dict[str, Any] = {"kind": {connect: "point", weld: "weld", tendon: "distance"}[kind]}
            rod = next((r for r in self.rods.values() if r[1] == e), None)
            if rod is not None:  # a distance rod's body: the loop joins the other site and the ball's
                pivot, _, end = rod
                if int(m.site_bodyid[o2]) not in link_of or int(m.body_parentid[m.site_bodyid[o1]]) not in link_of:
                    raise self.error(where, "joins a body which is not on the floating base's tree (closed chains need "
                                            "a fixed base: --fixed)")
                out.append({"frames": [c_identifier(m.site(o2).name), pivot], "kind": "distance",
                            "length": float(np.linalg.norm(m.site_pos[end]))})
                continue
            if kind == tendon:
                ends = self.tendon_sites(where, o1, o2, data)
                loop["length"] = float(m.tendon_length0[o1] + data[0])
            elif int(m.eq_objtype[e]) == site:
                ends = [o1, o2]
            if kind == tendon or int(m.eq_objtype[e]) == site:
                poses = [(int(m.site_bodyid[s]), _h(quat_matrix(m.site_quat[s]), m.site_pos[s]),
                          c_identifier(m.site(s).name) if m.site(s).name else None) for s in ends]
            elif kind == connect:
                poses = [(o1, _h(np.eye(3), data[0:3]), None), (o2, _h(np.eye(3), data[3:6]), None)]
            else:
                quat = data[6:10]
                poses = [(o1, _h(quat_matrix(quat / np.linalg.norm(quat)), data[3:6]), None),
                         (o2, _h(np.eye(3), data[0:3]), None)]
            if kind == weld and not data[10] > 0:
                raise self.error(where, f"torquescale {data[10]:g} leaves the rotation free: write it as <connect>")
            for b, _, _ in poses:
                if b not in link_of:
                    raise self.error(where, f"joins {self.body_where(b)}, which is not on the floating base's tree "
                                            "(closed chains need a fixed base: --fixed)")
            base = c_identifier(label) if label else f"loop{len(out)}"
            names = []
            for side, (b, pose, named) in zip("ab", poses):
                if named is not None:  # a named site is a frame already
                    names.append(named)
                    continue
                name = f"{base}_{side}"
                while name in taken:
                    name += "_"
                taken.add(name)
                names.append(name)
                frames.append({"name": name, "link": link_of[b], **_origin(at[b] @ pose)})
            out.append({"frames": names, **loop})
        return out

    def find_rods(self) -> dict[int, tuple[str, int, int]]:
        """The distance rods as derive export writes them: body -> (the ball's site name, the connect, the end site).

        A rod is a body named ``<site>_rod`` (underscores may follow) with one ball joint at its origin, no child
        bodies and one site, its end, which a site ``<connect>`` (site1) holds at a named site (site2); its parent
        has the site ``<site>`` at the rod's origin, the ball. It stands for a massless rod: its mass and
        moments (MuJoCo's least) are left out, and the loop is ``distance`` between site2 and ``<site>``, the
        length the end's distance from the ball."""
        m, mj = self.m, self.mj
        out: dict[int, tuple[str, int, int]] = {}
        for e in range(m.neq):
            if int(m.eq_type[e]) != int(mj.mjtEq.mjEQ_CONNECT) or int(m.eq_objtype[e]) != int(mj.mjtObj.mjOBJ_SITE):
                continue
            end, other = int(m.eq_obj1id[e]), int(m.eq_obj2id[e])
            b = int(m.site_bodyid[end])
            name = m.body(b).name.rstrip("_")
            joints = self.body_joints(b)
            if (b in out or not name.endswith("_rod") or not m.site(other).name or len(joints) != 1
                    or int(m.jnt_type[joints[0]]) != self.BALL or np.any(m.jnt_pos[joints[0]])
                    or int(np.sum(m.site_bodyid == b)) != 1 or any(int(m.body_parentid[c]) == b for c in range(m.nbody))):
                continue
            pivot, parent = name[:-len("_rod")], int(m.body_parentid[b])
            ball = [s for s in range(m.nsite) if m.site(s).name == pivot and int(m.site_bodyid[s]) == parent]
            if ball and np.allclose(m.site_pos[ball[0]], m.body_pos[b], rtol=0, atol=1e-12):
                out[b] = (c_identifier(pivot), e, end)
        return out

    def tendon_sites(self, where: str, t1: int, t2: int, data: np.ndarray) -> list[int]:
        """The two sites of a tendon equality that is a distance loop: a spatial tendon through exactly two sites
        held at a constant length (no tendon2, polycoef c1..c4 = 0); anything else is refused in one line."""
        m, mj = self.m, self.mj
        start, count = int(m.tendon_adr[t1]), int(m.tendon_num[t1])
        wraps = [(int(m.wrap_type[w]), int(m.wrap_objid[w])) for w in range(start, start + count)]
        if t2 >= 0 or any(data[1:5]) or len(wraps) != 2 or any(k != int(mj.mjtWrap.mjWRAP_SITE) for k, _ in wraps):
            raise self.error(where, "<tendon> equality constraints are supported only as a distance loop: a spatial "
                             "tendon through exactly two sites held at a constant length (no tendon2, polycoef "
                             "c1 = c2 = c3 = c4 = 0)")
        return [w for _, w in wraps]

    def closure_fields(self, loops: list[dict], joints: list[dict]) -> dict:
        """``loops:``, ``independent:`` and ``reference:``: the configuration of the keyframe ``self.keyframe``
        (by default the one named ``reference``, where there is one: derive export writes it), else MuJoCo's
        qpos0; a ball's quaternion as its ZYX angles. Mimic joints have no entry."""
        if not loops:
            return {}
        m, mj = self.m, self.mj
        names = [m.key(k).name for k in range(m.nkey)]
        wanted = self.keyframe if self.keyframe is not None else ("reference" if "reference" in names else None)
        if wanted is not None and wanted not in names:
            raise self.error(f"<key name=\"{wanted}\">", "no keyframe of that name (keyframes: "
                             f"{', '.join(n or '(unnamed)' for n in names) or 'none'})")
        qpos = np.array(m.qpos0 if wanted is None else m.key(names.index(wanted)).qpos, dtype=float)
        if wanted is not None:
            self.notes.append(f"loops closed at the keyframe '{wanted}'")
        mimics = {x["name"] for x in joints if "mimic" in x}
        reference = {}
        for j in range(m.njnt):
            if int(m.jnt_bodyid[j]) in self.rods:
                continue  # a distance rod's ball
            kind, a, name = int(m.jnt_type[j]), int(m.jnt_qposadr[j]), self.joint_name(j)
            if kind in (self.HINGE, self.SLIDE) and name not in mimics:
                values = {name: float(qpos[a])}
            elif kind == self.BALL:
                R = quat_matrix(qpos[a:a + 4] / np.linalg.norm(qpos[a:a + 4]))
                values = {f"{name}_z": math.atan2(R[1, 0], R[0, 0]),
                          f"{name}_y": math.asin(max(-1.0, min(1.0, -R[2, 0]))),
                          f"{name}_x": math.atan2(R[2, 1], R[2, 2])}
            else:
                continue
            reference.update({k: _clean(v) for k, v in values.items() if v})
        return {"loops": loops, **({"independent": self.independent} if self.independent else {}),
                **({"reference": reference} if reference else {})}

    # ---- equality constraints
    def check_equality(self, e: int) -> None:
        m, mj = self.m, self.mj
        kind = int(m.eq_type[e])
        label = m.equality(e).name
        where = f"<equality name=\"{label}\">" if label else f"equality {e}"
        spelled = {int(v): k.removeprefix("mjEQ_").lower() for k, v in mj.mjtEq.__members__.items()}.get(kind, str(kind))
        if kind in (int(mj.mjtEq.mjEQ_CONNECT), int(mj.mjtEq.mjEQ_WELD), int(mj.mjtEq.mjEQ_TENDON)):
            return  # a loop closure: self.loops
        if kind != int(mj.mjtEq.mjEQ_JOINT):
            raise self.error(where, f"<{spelled}> equality constraints are not supported")
        if not m.eq_active0[e]:
            return
        j1, j2 = int(m.eq_obj1id[e]), int(m.eq_obj2id[e])
        coef = [float(c) for c in m.eq_data[e][:5]]
        if j2 < 0:
            raise self.error(where, f"holds {self.joint_where(j1)} at a constant: remove the joint (or the constraint)")
        if any(coef[2:]):
            raise self.error(where, f"polycoef {' '.join(f'{c:g}' for c in coef)} is not linear: only q1 = c0 + c1 q2 "
                                    "couplings (mimic joints) are supported")
        for j in (j1, j2):
            if int(m.jnt_type[j]) not in (self.HINGE, self.SLIDE):
                raise self.error(where, f"couples {self.joint_where(j)}, which is no hinge or slide")
        if coef[1] == 0:
            raise self.error(where, f"polycoef c1 = 0 holds {self.joint_where(j1)} at a constant: remove the joint")

    def mimics(self) -> dict[int, dict]:
        """MuJoCo joint id -> models.yaml ``mimic`` for the active linear joint couplings."""
        m, mj = self.m, self.mj
        out: dict[int, dict] = {}
        for e in range(m.neq):
            if int(m.eq_type[e]) != int(mj.mjtEq.mjEQ_JOINT):
                continue
            if not m.eq_active0[e]:
                label = m.equality(e).name
                self.warn(f"<equality name=\"{label}\">" if label else f"equality {e}", "inactive at the start "
                          "(active=\"false\"): left out")
                continue
            j1, j2 = int(m.eq_obj1id[e]), int(m.eq_obj2id[e])
            c0, c1 = (float(c) for c in m.eq_data[e][:2])
            ref1, ref2 = float(m.qpos0[m.jnt_qposadr[j1]]), float(m.qpos0[m.jnt_qposadr[j2]])
            # q1 - ref1 = c0 + c1 (q2 - ref2), and derive's q is MuJoCo's qpos
            out[j1] = {"joint": self.joint_name(j2), "multiplier": c1, "offset": _clean(ref1 + c0 - c1 * ref2)}
        return out

    # ---- looks
    def visuals(self, pose: np.ndarray, b: int) -> list[dict]:
        """The visible geoms of body ``b`` as ``visual`` items in its link's frame (``pose``: the body's)."""
        m, kinds = self.m, self.mj.mjtGeom
        out = []
        for g in range(m.ngeom):
            if int(m.geom_bodyid[g]) != b or int(m.geom_group[g]) > 2:
                continue
            kind = int(m.geom_type[g])
            rgba = m.mat_rgba[m.geom_matid[g]] if m.geom_matid[g] >= 0 else m.geom_rgba[g]
            if rgba[3] <= 0:
                continue
            size = [float(v) for v in m.geom_size[g]]
            place = _h(quat_matrix(m.geom_quat[g]), m.geom_pos[g])
            item: dict = {}
            if kind == int(kinds.mjGEOM_BOX):
                item["box"] = [2 * v for v in size]
            elif kind == int(kinds.mjGEOM_SPHERE):
                item["sphere"] = size[0]
            elif kind in (int(kinds.mjGEOM_CYLINDER), int(kinds.mjGEOM_CAPSULE)):
                item["cylinder" if kind == int(kinds.mjGEOM_CYLINDER) else "capsule"] = [size[0], 2 * size[1]]
            elif kind == int(kinds.mjGEOM_ELLIPSOID):
                item.update(sphere=1.0, scale=size)
            elif kind == int(kinds.mjGEOM_MESH):
                mesh = int(m.geom_dataid[g])
                at = int(m.mesh_pathadr[mesh])
                file = m.paths[at:].split(b"\0", 1)[0].decode() if at >= 0 else ""
                if not file:
                    self.warn(f"geom {g}", "a mesh without a file (inline vertices): not kept for derive view")
                    continue
                path = Path(file) if Path(file).is_absolute() else self.folder / file
                if not path.is_file():
                    self.warn(f"geom {g}", f"mesh file {file}: not found ({path}): kept, derive view skips it")
                item["mesh"] = Path(os.path.normpath(path)).as_posix()
                # the compiler moved the vertices to the mesh's inertial frame and the geom the other way: undone
                place = place @ np.linalg.inv(_h(quat_matrix(m.mesh_quat[mesh]), m.mesh_pos[mesh]))
                scale = [float(v) for v in m.mesh_scale[mesh]]
                if scale != [1.0, 1.0, 1.0]:
                    item["scale"] = scale
            else:
                continue  # a plane, a height field, an SDF: no part of a robot's looks
            origin = _origin(pose @ place)
            item.update({k: v for k, v in origin.items() if any(v)})
            item["color"] = [round(float(c), 6) for c in rgba]
            out.append({k: item[k] for k in sorted(item, key=["mesh", "box", "cylinder", "sphere", "capsule", "xyz",
                                                                "rpy", "scale", "color"].index)})
        return out

    # ---- mass
    def merged(self, link: str, parts: list[tuple[np.ndarray, int]]) -> dict:
        """{mass, com, inertia} of the MuJoCo bodies in ``parts`` (pose of each body frame in the link frame)."""
        m = self.m
        # a massless body with rotational inertia counts (MuJoCo's M holds it: bolt's feet)
        kept = [(pose, b) for pose, b in parts if m.body_mass[b] > 0 or np.any(m.body_inertia[b] > 0)]
        if not kept:
            return {}
        masses, coms, inertias = [], [], []
        for pose, b in kept:
            rot = pose[:3, :3] @ quat_matrix(m.body_iquat[b])
            masses.append(float(m.body_mass[b]))
            coms.append(pose[:3, :3] @ m.body_ipos[b] + pose[:3, 3])
            inertias.append(rot @ np.diag(m.body_inertia[b]) @ rot.T)
        total = math.fsum(masses)
        # without mass the inertia is a pure moment, the same about every point: the first body's com
        com = sum(mass * c for mass, c in zip(masses, coms)) / total if len(kept) > 1 and total > 0 else coms[0]
        inertia = np.zeros((3, 3))
        for mass, c, inr in zip(masses, coms, inertias):
            d = c - com
            inertia += inr + mass * (float(d @ d) * np.eye(3) - np.outer(d, d))
        inertia = (inertia + inertia.T) / 2
        tiny = 4 * np.finfo(float).eps * float(np.abs(inertia).max())  # rounding residue of turning an exact zero
        inertia = np.where(np.abs(inertia) <= tiny, 0.0, inertia)
        return {"mass": total, "com": [_clean(v) for v in com],
                "inertia": {"ixx": _clean(inertia[0, 0]), "iyy": _clean(inertia[1, 1]), "izz": _clean(inertia[2, 2]),
                            "ixy": _clean(inertia[0, 1]), "ixz": _clean(inertia[0, 2]), "iyz": _clean(inertia[1, 2])}}

    def check_names(self, links: list[dict], joints: list[dict], frames: list[dict]) -> None:
        """Links and frames share one namespace in derive (fk_<name>), MuJoCo's bodies and sites do not."""
        seen: dict[str, str] = {}
        for kind, items in (("body", links), ("body or site", frames)):
            for item in items:
                if item["name"] in seen:
                    raise self.error(f"{kind} '{item['name']}'", f"the name is also that of a {seen[item['name']]}: "
                                     "derive names links and frames in one namespace; rename one in the MJCF")
                seen[item["name"]] = "body" if kind == "body" else kind
        named: set[str] = set()
        for joint in joints:
            if joint["name"] in named:
                raise self.error(f"joint '{joint['name']}'", "two joints have this name (as a C identifier)")
            named.add(joint["name"])
