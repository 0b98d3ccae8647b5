"""URDF -> a models.yaml robot entry (``derive import-urdf``).

Only :mod:`xml.etree` and numpy. The result is a plain dict ready for YAML that
:func:`derive.description.model.parse_robot` accepts:

- ``revolute``/``continuous``/``prismatic``/``fixed`` joints are kept (a continuous
  joint without position limits: its <limit> gives velocity and effort only); ``planar``
  is refused; ``floating`` only
  as the one joint from a massless root link (a ``world``) to the base, with an
  identity origin: the root is dropped and the base floats (as ``--floating``);
- by default the whole tree is imported: every moving joint, in Pinocchio's order
  (depth-first, siblings by joint name, as urdfdom keeps them), which the entry's
  joint list follows so that q has Pinocchio's order too. A moving branch that
  carries no mass at all is dropped (a massless body at a leaf would make the mass
  matrix singular) and named in the entry's description;
- ``tip`` names the link that becomes the frame ``tcp`` (none without it); the
  path to it is kept even where it carries no mass. A tip fused onto its moving
  body by fixed joints keeps its own name as an alias of ``tcp`` (``aliases:``):
  ``tool_frame`` and ``tcp`` then name the same frame everywhere;
- ``chain`` imports the root-to-``chain`` path only (``tcp`` at that link):
  moving branches off it are dropped if they carry no mass and refused otherwise
  (lock them);
- ``lock`` turns joints into fixed ones at a given position (default 0); the
  lock motion is folded into the fixed transform;
- a moving joint with ``<mimic joint= multiplier= offset=>`` becomes a models.yaml
  ``mimic`` joint (no entry in q) when the joint it follows keeps its coordinate;
  a mimic of a mimic is composed into one mimic of the chain's root (q_C = m2 (m1 q_A
  + o1) + o2, chains of any length; a cycle is refused, naming its joints); otherwise
  (the root locked, dropped, fixed or unknown) it must be locked (``mimic`` on a fixed
  joint is ignored). Its own ``<dynamics>`` stays its actuator (G^T D G in the
  coordinates, as MuJoCo applies it);
- fixed joints are merged: the child's mass properties are added to the parent
  (parallel-axis theorem) and the child survives as a named frame on its moving
  ancestor. The URDF root link always stays (but a world dropped above a
  floating joint): the world frame, or with ``floating`` (``base: floating``) the
  free-flying body (Pinocchio's ``JointModelFreeFlyer`` above the root link);
- inertias are re-expressed in the link frame (no ``inertia_rpy``).

Numbers are read as urdfdom reads them (C-locale decimals, :mod:`derive.description.numbers`:
no ``1_0``, no other digits than ASCII, no hex, inf or nan) and bounded like a models file's
(at most 1e12 in magnitude; a nonzero one below FLT_MIN, or an axis component below 2^-63 of
the axis, is rounding residue: read as 0 with a warning; a position limit beyond 1e12 is an
exporter's "unbounded": dropped with a warning). Every error names the file. Numbers that come
straight from the URDF are copied exactly; only composed or merged values are computed. Of those, only what is the rounding
of an exact angle is snapped: a composed angle exact to rounding (within
:data:`derive.description.angles.EXACT` = 1e-14 rad of a multiple of pi/2) becomes
that multiple, a vector component within a few ulps of the vector's length (e.g.
0.1 * cos(pi/2) = 6e-18) becomes 0. Nothing else moves, so the imported model
reproduces the URDF as written to 1e-14 (relative).

Right angles rounded by the file's author (1.5708, 3.1416, 1.57079632679: within
NEAR = 1e-4 rad of k pi/2 but not exact, :mod:`derive.description.angles`) are kept as
written, and one warning line lists them (the entry's joint origins and frames, where
they land, and the links' inertial origins). ``snap_angles=TOL`` (``--snap-angles TOL``)
makes every constant angle within TOL of k pi/2 exactly k pi/2: the URDF's joint and
inertial origins before anything is composed, then the composed origins; the entry's
``source`` command carries the option, so a re-import reproduces it.

What exporters write that carries no information is read as absent, with a
one-line warning on stderr: ``<limit>`` attributes that are all zero (or a zero
velocity or effort) and ``<mimic>`` on a fixed joint (ignored, as Pinocchio does).
Inertias are also judged against the robot's scale: a tensor that is itself
rounding noise (e.g. -2e-22 kg m^2 where the largest link has 0.1 kg m^2) is
clamped to the nearest physical one; real errors are still refused (naming the way
forward: ``--fix-inertia`` repairs them with a warning per link). The joints must form a
tree: a cycle is a one-line error naming the file and the cycle. ``--out`` appends to a
models file atomically (:func:`append_entry`).
"""

from __future__ import annotations

import dataclasses
import importlib.metadata
import json
import keyword
import math
import os
import re
import sys
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable, Mapping

import numpy as np
import yaml

from derive.description.angles import EXACT, NEAR, quarter, snapped, spelled
from derive.description.files import InputFileError, read_bytes, read_text
from derive.description.inertia import inertia_problem, nearest_physical
from derive.description.model import parse_models, parse_robot
from derive.description.numbers import (MAX_MAGNITUDE, MIN_MAGNITUDE, axis_component_problem, decimal, decimals,
                                       magnitude_problem, tiny, unit_vector)
from derive.description.xacro_expand import XacroError, assignments, is_xacro, package_folders
from derive.description.xacro_expand import command_options as xacro_command
from derive.description.xacro_expand import expand as expand_xacro
from derive.description.robot import (C_KEYWORDS, Mimic, MimicCycle, ModelError, compose_mimics, identifier,
                                      import_command, shown)
from derive.filesystem import write_atomically

ERD = "example-robot-data"
ERD_PREFIX = ERD + ":"
SNAP_ULPS = 4  # composed vector components within this many ulps of the vector's length are snapped to 0
MAX_SNAP = 0.1  # --snap-angles at most this (rad): beyond, real angles would be taken for right angles
NOISE = 1e-12  # inertia noise floor, relative to the robot's largest inertia (see _clamp_inertia_noise)
GRAVITY = [0.0, 0.0, -9.81]


# --------------------------------------------------------------------------- locating files


def example_robot_data_dir() -> Path | None:
    """``<site-packages>/cmeel.prefix/share/example-robot-data/robots`` of the installed package, or None."""
    for entry in sys.path:
        candidate = Path(entry or ".") / "cmeel.prefix" / "share" / ERD / "robots"
        if candidate.is_dir():
            return candidate
    return None


def example_robot_data_version() -> str | None:
    try:
        return importlib.metadata.version(ERD)
    except importlib.metadata.PackageNotFoundError:
        return None


def resolve_urdf(file: str | Path, robot: str | None = None) -> tuple[Path, str, str]:
    """``file`` -> (path to read, portable spelling for commands, origin for ``source``).

    ``example-robot-data:<path under robots/>`` names a URDF of the installed
    example-robot-data package; a plain path inside that package is spelled the
    same way, so the generated entry does not depend on where the venv lives.
    """
    text = str(file)
    erd = example_robot_data_dir()
    if text.startswith(ERD_PREFIX):
        rel = text[len(ERD_PREFIX):].lstrip("/")
        if erd is None:
            raise ModelError(robot or c_identifier(Path(text).stem), text,
                             f"the {ERD} package is not installed (pip install {ERD})")
        path = erd / rel
    else:
        path = Path(text)
        rel = None
        if erd is not None:
            try:
                rel = path.resolve().relative_to(erd.resolve()).as_posix()
            except (ValueError, OSError):
                rel = None
    if rel is None:
        return path, text, path.name
    version = example_robot_data_version()
    origin = f"{ERD} {version} {rel}" if version else f"{ERD} {rel}"
    return path, ERD_PREFIX + rel, origin


# --------------------------------------------------------------------------- names


def c_identifier(name: str) -> str:
    """A URDF name made a C identifier: other characters -> '_', no leading digit, no keyword."""
    out = re.sub(r"[^A-Za-z0-9_]", "_", name) or "_"
    if out[0].isdigit():
        out = "_" + out
    if out in C_KEYWORDS or keyword.iskeyword(out):
        out += "_"
    return out


# --------------------------------------------------------------------------- transforms


def rpy_matrix(rpy) -> np.ndarray:
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    return np.array([
        [cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
        [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
        [-sp, cp * sr, cp * cr],
    ])


def matrix_rpy(m: np.ndarray) -> tuple[float, float, float]:
    """R = Rz(yaw) Ry(pitch) Rx(roll) -> (roll, pitch, yaw), pitch in [-pi/2, pi/2].

    Yaw first, then roll and pitch from Rz(yaw)^T R, so the angles reproduce R to
    rounding even at or near pitch = +-pi/2 (where roll and yaw are not unique).
    """
    yaw = math.atan2(m[1, 0], m[0, 0])
    cy, sy = math.cos(yaw), math.sin(yaw)
    roll = math.atan2(sy * m[0, 2] - cy * m[1, 2], cy * m[1, 1] - sy * m[0, 1])
    pitch = math.atan2(-m[2, 0], cy * m[0, 0] + sy * m[1, 0])
    return roll, pitch, yaw


def axis_angle(axis, angle: float) -> np.ndarray:
    k = np.array(unit_vector(axis), dtype=float)  # robust for any nonzero finite axis (1e200 included)
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * kx + (1.0 - math.cos(angle)) * kx @ kx


_EPS = float(np.finfo(float).eps)


def _snap_angle(a: float) -> float:
    """A computed angle exact to rounding (within EXACT = 1e-14 of k pi/2) -> exactly k pi/2 (0.0 for k = 0).

    Only the rounding of an exact angle is removed (composing two exact right angles
    leaves a few ulps): 1e-12 rad off a multiple of pi/2 is the URDF's own spelling and stays.
    """
    return snapped(a, EXACT)


def _snap_vector(v) -> list[float]:
    """Components within a few ulps of the vector's length -> 0 (rounding of an exact rotation)."""
    v = [float(x) for x in v]
    tiny = SNAP_ULPS * _EPS * math.sqrt(math.fsum(x * x for x in v))
    return [0.0 if abs(x) <= tiny else x for x in v]


@dataclass(frozen=True)
class Pose:
    """A rigid transform that remembers the URDF numbers it was read from.

    ``xyz``/``rpy`` are exact copies while the pose is a single URDF origin (or
    the identity); composing two non-identity poses computes them.
    """

    xyz: tuple = (0.0, 0.0, 0.0)
    rpy: tuple = (0.0, 0.0, 0.0)
    rot: Any = field(default=None, compare=False)  # 3x3, when known more exactly than rpy

    @property
    def is_identity(self) -> bool:
        return all(v == 0 for v in self.xyz) and all(v == 0 for v in self.rpy) and (
            self.rot is None or np.array_equal(self.rot, np.eye(3)))

    @property
    def R(self) -> np.ndarray:
        return self.rot if self.rot is not None else rpy_matrix(self.rpy)

    @property
    def p(self) -> np.ndarray:
        return np.array(self.xyz, dtype=float)

    def __mul__(self, other: "Pose") -> "Pose":
        if other.is_identity:
            return self
        if self.is_identity:
            return other
        R = self.R @ other.R
        p = self.p + self.R @ other.p
        return Pose.from_matrix(R, p)

    @staticmethod
    def from_matrix(R: np.ndarray, p) -> "Pose":
        return Pose(tuple(_snap_vector(p)), tuple(_snap_angle(v) for v in matrix_rpy(R)), R)


# --------------------------------------------------------------------------- URDF reading


@dataclass
class _Inertial:
    mass: float = 0.0
    com: tuple = (0.0, 0.0, 0.0)
    rpy: tuple = (0.0, 0.0, 0.0)
    inertia: dict = field(default_factory=lambda: {k: 0.0 for k in ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")})

    def matrix(self) -> np.ndarray:
        i = self.inertia
        return np.array([[i["ixx"], i["ixy"], i["ixz"]], [i["ixy"], i["iyy"], i["iyz"]], [i["ixz"], i["iyz"], i["izz"]]])


@dataclass
class _Joint:
    name: str
    type: str
    parent: str
    child: str
    origin: Pose
    axis: tuple
    limits: dict
    mimic: tuple[str, float, float] | None  # (joint, multiplier, offset)
    dynamics: tuple[float, float] = (0.0, 0.0)  # <dynamics damping= friction=>: viscous, Coulomb


def _printable(text: str) -> str:
    """``text`` for a one-line message: characters that do not print (tabs, line or paragraph separators,
    controls) as their escapes."""
    return "".join(c if c.isprintable() else c.encode("unicode_escape").decode("ascii") for c in text)


class _Reader:
    """Reads the elements of one URDF; every error and warning names the file (``path``, as shown)."""

    def __init__(self, robot: str, path: str):
        self.robot, self.path = robot, path

    def error(self, where: str, problem: str) -> ModelError:
        return ModelError(self.robot, where, problem, self.path)

    def floats(self, where: str, el: ET.Element | None, attr: str, n: int, default: tuple,
               huge: bool = False) -> tuple:
        """The ``n`` numbers of attribute ``attr`` of ``el`` (``default`` if either is missing).

        Read as urdfdom reads them (:func:`derive.description.numbers.decimal`) and bounded like every
        number of a model (:func:`derive.description.numbers.magnitude_problem`): a nonzero number below
        FLT_MIN is flushed to 0 with a warning (rounding residue), a non-finite or too large one refused;
        with ``huge`` too large ones are returned as read (limits: the caller drops them).
        """
        text = None if el is None else el.get(attr)
        if text is None:
            return default
        snippet = f'<{el.tag} {attr}="{_printable(shown(text, 60))}">'
        parts = decimals(text)
        vals = []
        for token in parts:
            value = decimal(token)
            if value is None:
                raise self.error(where, f"{snippet}: '{_printable(shown(token))}' is not a number (URDF numbers are decimals "
                                        "such as 0.25, -1.5e-3)")
            vals.append(value)
        if len(vals) != n:
            raise self.error(where, f"{snippet}: expected {'a number' if n == 1 else f'{n} numbers'}, "
                                    f"got {len(vals)}")
        for i, value in enumerate(vals):
            if tiny(value):
                self.warn(where, f"{snippet}: {value:g} is below the smallest normal float ({MIN_MAGNITUDE:.3g}): "
                                 "read as 0")
                vals[i] = 0.0
                continue
            problem = magnitude_problem(value)
            if problem and not (huge and math.isfinite(value)):
                raise self.error(where, f"{snippet}: {problem}")
        return tuple(vals)

    def number(self, where: str, el: ET.Element | None, attr: str, default: float | None = None,
               huge: bool = False) -> float | None:
        return self.floats(where, el, attr, 1, (default,), huge)[0]

    def origin(self, where: str, el: ET.Element | None) -> Pose:
        if el is None:
            return Pose()
        return Pose(self.floats(where + ".xyz", el, "xyz", 3, (0.0, 0.0, 0.0)),
                    self.floats(where + ".rpy", el, "rpy", 3, (0.0, 0.0, 0.0)))

    def inertial(self, name: str, el: ET.Element | None) -> _Inertial:
        out = _Inertial()
        if el is None:
            return out
        where = f"links[{name}].inertial"
        out.mass = self.number(where + ".mass", el.find("mass"), "value", 0.0)
        if out.mass < 0:
            raise self.error(where + ".mass", f"must be >= 0, got {out.mass}")
        origin = self.origin(where + ".origin", el.find("origin"))
        out.com, out.rpy = origin.xyz, origin.rpy
        inertia = el.find("inertia")
        if inertia is not None:
            out.inertia = {k: self.number(f"{where}.inertia.{k}", inertia, k, 0.0) for k in out.inertia}
        return out

    def joint(self, el: ET.Element) -> _Joint:
        name = el.get("name")
        if not name:
            raise self.error("joints", "a <joint> has no name")
        where = f"joints[{name}]"
        jtype = el.get("type")
        if jtype == "planar":
            raise self.error(where, "planar joints are not supported (revolute, continuous, prismatic and fixed joints; "
                                    "a floating joint only from a massless root link to the base, as the floating base)")
        if jtype not in ("revolute", "continuous", "prismatic", "fixed", "floating"):
            raise self.error(where + ".type", f"unknown joint type {jtype!r} (known: revolute, continuous, prismatic, fixed, "
                                              "floating)")
        ends = {}
        for key in ("parent", "child"):
            sub = el.find(key)
            if sub is None or not sub.get("link"):
                raise self.error(f"{where}.{key}", "missing")
            ends[key] = sub.get("link")
        axis = self.floats(where + ".axis", el.find("axis"), "xyz", 3, (1.0, 0.0, 0.0))
        small = axis_component_problem(axis)
        while small:  # a component no computation can see (a turn below 1e-19 rad): 0, as rounding residue
            i, why = small
            self.warn(where + ".axis", f'<axis xyz="{_printable(shown(el.find("axis").get("xyz"), 60))}">: '
                                       f"{why.split('; write 0')[0]}: read as 0")
            axis = tuple(0.0 if k == i else a for k, a in enumerate(axis))
            small = axis_component_problem(axis)
        one_dof = jtype not in ("fixed", "floating")
        if one_dof and unit_vector(axis) is None:
            raise self.error(where + ".axis", "must not be the zero vector")
        limits = self.limits(where + ".limit", el.find("limit"), jtype) if one_dof else {}
        # <mimic> on a fixed joint couples nothing: ignored, as Pinocchio and urdfdom do (talos' grippers)
        mimic = el.find("mimic") if one_dof else None
        if mimic is not None:
            mimic = (mimic.get("joint") or "?", self.number(where + ".mimic.multiplier", mimic, "multiplier", 1.0),
                     self.number(where + ".mimic.offset", mimic, "offset", 0.0))
        dyn = el.find("dynamics") if one_dof else None
        dynamics = (0.0, 0.0)
        if dyn is not None:
            dynamics = tuple(self.number(f"{where}.dynamics.{k}", dyn, k, 0.0) for k in ("damping", "friction"))
            for k, v in zip(("damping", "friction"), dynamics):
                if not v >= 0:
                    raise self.error(f"{where}.dynamics.{k}", f"must be >= 0, got {v:g}")
        return _Joint(name, jtype, ends["parent"], ends["child"],
                      self.origin(where + ".origin", el.find("origin")), axis, limits, mimic, dynamics)

    def limits(self, where: str, lim: ET.Element | None, jtype: str) -> dict:
        """The numbers of a moving joint's <limit>, without the exporters' placeholders.

        URDF exporters (SolidWorks' sw_urdf_exporter, for one) write
        ``<limit lower="0" upper="0" effort="0" velocity="0"/>`` for "not given". All
        written values zero (lower = upper = 0 and no effort or velocity) is read as no
        limits; a zero velocity or effort next to real position limits is dropped (a
        joint that may not move or push is no joint). Others write "unbounded" as a huge
        number (iris: ``lower="-1e+16" upper="1e+16"``): a limit beyond MAX_MAGNITUDE
        (1e12) is dropped too. Each drop prints one warning line. Negative velocities or
        efforts stay, for the model's validation to refuse.
        """
        if lim is None:
            return {}
        keys = ("velocity", "effort") if jtype == "continuous" else ("lower", "upper", "velocity", "effort")  # continuous: no position limits
        raw = {key: self.number(f"{where}.{key}", lim, key, huge=True) for key in keys}
        limits = {k: v for k, v in raw.items() if v is not None}
        huge = [k for k, v in limits.items() if abs(v) > MAX_MAGNITUDE]
        if huge:
            self.warn(where, f"{' = '.join(f'{k} = {limits[k]:g}' for k in huge)}: beyond {MAX_MAGNITUDE:g}, an "
                             f"exporter's placeholder for no limit: imported without {' and '.join(huge)} limit")
            for k in huge:
                del limits[k]
        if limits and all(v == 0 for v in limits.values()):
            self.warn(where, f"{' = '.join(limits)} = 0 is an exporter's placeholder: imported without limits")
            return {}
        zero = [k for k in ("velocity", "effort") if limits.get(k) == 0]
        if zero:
            self.warn(where, f"{' = '.join(zero)} = 0 is an exporter's placeholder: imported without {' and '.join(zero)} limit")
            for k in zero:
                del limits[k]
        return limits

    def warn(self, where: str, problem: str) -> None:
        print(_printable(f"warning: {self.path}: {where}: {problem}"), file=sys.stderr)

    def visuals(self, name: str, el: ET.Element, folder: Path, packages: Mapping[str, Path],
                materials: Mapping[str, tuple], missing) -> list[dict]:
        """The ``<visual>`` elements of link ``name`` (in the link frame): {shape: value, origin: Pose,
        scale, color}, a mesh's file resolved (:func:`mesh_file`). Shapes URDF does not know are skipped
        with a warning; nothing here stops an import."""
        out = []
        for k, vis in enumerate(el.findall("visual")):
            where = f"links[{name}].visual[{k}]"
            geometry = vis.find("geometry")
            shape = next(iter(geometry), None) if geometry is not None else None
            if shape is None or shape.tag not in ("mesh", "box", "cylinder", "sphere", "capsule"):
                self.warn(where, f"no mesh, box, cylinder, sphere or capsule in its <geometry>"
                                 f"{f' (<{shape.tag}>)' if shape is not None else ''}: not shown by derive view")
                continue
            item: dict = {}
            if shape.tag == "mesh":
                filename = shape.get("filename") or ""
                if not filename:
                    self.warn(where + ".mesh", "no filename: not shown by derive view")
                    continue
                item["mesh"] = mesh_file(filename, folder, packages, missing)
            elif shape.tag == "box":
                item["box"] = list(self.floats(where + ".box", shape, "size", 3, (0.0, 0.0, 0.0)))
            elif shape.tag == "sphere":
                item["sphere"] = self.number(where + ".sphere", shape, "radius", 0.0)
            else:
                item[shape.tag] = [self.number(f"{where}.{shape.tag}", shape, key, 0.0) for key in ("radius", "length")]
            sizes = item.get("box") or item.get("cylinder") or item.get("capsule") or [item.get("sphere", 1.0)]
            if not all(v > 0 for v in sizes):
                self.warn(where, f"<{shape.tag}> of size {' '.join(f'{v:g}' for v in sizes)}: not shown by derive view")
                continue
            item["origin"] = self.origin(where + ".origin", vis.find("origin"))
            scale = self.floats(where + ".mesh.scale", shape, "scale", 3, (1.0, 1.0, 1.0)) if shape.tag == "mesh" \
                else (1.0, 1.0, 1.0)
            if any(v == 0 for v in scale):
                self.warn(where + ".mesh.scale", "a zero scale: not shown by derive view")
                continue
            if scale != (1.0, 1.0, 1.0):
                item["scale"] = list(scale)
            material = vis.find("material")
            if material is not None:
                color = material.find("color")
                rgba = self.floats(where + ".material.color", color, "rgba", 4, ()) if color is not None else \
                    materials.get(material.get("name") or "", ())
                if rgba and all(0 <= v <= 1 for v in rgba):
                    item["color"] = list(rgba)
            out.append(item)
        return out


def _package_folder(package: str, folder: Path, packages: Mapping[str, Path]) -> Path | None:
    """Where ROS package ``package`` lies: ``--package-path``, else a folder of that name at or beside
    an ancestor of the URDF's folder (a ROS workspace's layout), else ROS_PACKAGE_PATH or share/ under
    AMENT_PREFIX_PATH."""
    if package in packages:
        return Path(packages[package])
    for up in [folder, *folder.parents]:
        if up.name == package:
            return up
        if (up / package).is_dir():
            return up / package
    for var, below in (("ROS_PACKAGE_PATH", ""), ("AMENT_PREFIX_PATH", "share")):
        for root in filter(None, os.environ.get(var, "").split(os.pathsep)):
            if (Path(root) / below / package).is_dir():
                return Path(root) / below / package
    return None


def mesh_file(filename: str, folder: Path, packages: Mapping[str, Path] = {}, warn=None) -> str:
    """A URDF mesh ``filename`` as models.yaml keeps it: ``package://NAME/...`` resolved (:func:`_package_folder`),
    ``file://`` and paths relative to the URDF's ``folder`` made absolute; a file of the installed
    example-robot-data spelled ``example-robot-data:<path under robots/>``. A file that is not there is
    kept as written and ``warn`` (if given) is called with the problem: the viewer skips it."""
    text = filename.strip()
    path: Path | None
    if text.startswith("package://"):
        package, _, rest = text[len("package://"):].lstrip("/").partition("/")  # talos' package:///NAME/...
        found = _package_folder(package, folder, packages)
        path = found / rest if found is not None else None
        if path is None:
            if warn:
                warn(f"{text}: package '{package}' not found (--package-path {package}=DIR)")
            return text
    elif text.startswith("file://"):
        path = Path(text[len("file://"):])
    else:
        path = folder / text
    path = Path(os.path.normpath(path.absolute()))
    if not path.is_file():
        if warn:
            warn(f"{text}: no such file ({path})")
        return text if text.startswith("package://") else path.as_posix()
    erd = example_robot_data_dir()
    if erd is not None:
        try:
            return ERD_PREFIX + path.resolve().relative_to(erd.resolve()).as_posix()
        except (ValueError, OSError):
            pass
    return path.as_posix()


def _stem(path: Path) -> str:
    """The file name without ``.xacro`` and ``.urdf`` (``arm.urdf.xacro`` -> ``arm``)."""
    name = path.name
    for suffix in (".xacro", ".urdf"):
        if name.endswith(suffix) and len(name) > len(suffix):
            name = name[:-len(suffix)]
    return name


def _read(path: Path, robot: str | None, shown: str | None = None, xacro_args: Mapping[str, str] | None = None,
          packages: Mapping[str, Path] | None = None, visuals: dict[str, list[dict]] | None = None
          ) -> tuple[str, dict[str, _Inertial], list[_Joint], bool]:
    """(URDF robot name, links in file order, joints in file order, whether the file was xacro); warnings
    name the file as ``shown``. A xacro file is expanded first (:mod:`derive.description.xacro_expand`).
    ``visuals``, if given, receives each link's ``<visual>`` elements (:meth:`_Reader.visuals`)."""
    who = robot or c_identifier(_stem(path))
    try:
        text = read_bytes(path, "URDF")
    except InputFileError as exc:
        raise ModelError(who, "", str(exc)) from None
    xacro = is_xacro(path, text)
    if xacro:
        text = expand_xacro(path, text, shown or str(path), xacro_args, packages)
    elif xacro_args or packages:
        raise XacroError(f"{shown or path}: {'--arg' if xacro_args else '--package-path'} is for xacro files; this "
                         "one is plain URDF (no .xacro name, no xacro element or substitution)")
    expanded = " (as xacro expands it)" if xacro else ""
    try:
        root = ET.fromstring(text)
    except (RecursionError, MemoryError):
        raise ModelError(who, str(path), f"XML nested too deeply{expanded}") from None
    except ET.ParseError as exc:
        line, col = exc.position
        msg = str(exc).split(":")[0]
        raise ModelError(who, f"{path} line {line}, column {col + 1}{expanded}", f"malformed XML: {msg}") from None
    if root.tag != "robot":
        hint = " (an MJCF file: derive import-mjcf FILE)" if root.tag == "mujoco" else ""
        raise ModelError(who, str(path), f"not a URDF: the root element is <{root.tag}>, not <robot>{hint}{expanded}")
    urdf_name = root.get("name") or _stem(path)
    reader = _Reader(robot or c_identifier(urdf_name), shown or str(path))
    links: dict[str, _Inertial] = {}
    for el in root.findall("link"):
        name = el.get("name")
        if not name:
            raise reader.error("links", "a <link> has no name")
        if name in links:
            raise reader.error(f"links[{name}]", "duplicate link name")
        links[name] = reader.inertial(name, el.find("inertial"))
    if visuals is not None:
        materials = {}
        for mat in root.findall("material"):
            color = mat.find("color")
            if mat.get("name") and color is not None:
                materials[mat.get("name")] = reader.floats(f"materials[{mat.get('name')}].color", color, "rgba", 4, ())
        missing: list[str] = []
        for el in root.findall("link"):
            found = reader.visuals(el.get("name"), el, path.parent, packages or {}, materials, missing.append)
            if found:
                visuals[el.get("name")] = found
        if missing:
            reader.warn("visual", f"{len(missing)} mesh file{'s' * (len(missing) > 1)} not found, kept as written "
                                  f"(derive view skips {'them' if len(missing) > 1 else 'it'}): {missing[0]}"
                                  + (f"; and {len(missing) - 1} more" if len(missing) > 1 else ""))
    joints = [reader.joint(el) for el in root.findall("joint")]
    return urdf_name, links, joints, xacro


# --------------------------------------------------------------------------- import


def parse_lock(lock: str | Iterable[str] | Mapping[str, float] | None, robot: str | None = None) -> dict[str, tuple[float, str]]:
    """``"a,b=0.3"`` or ``["a", "b=0.3"]`` or ``{"b": 0.3}`` -> {name: (value, spelling)}."""
    if lock is None:
        return {}
    def bounded(name: str, v: float, text: str) -> float:
        if not math.isfinite(v):
            raise ModelError(robot, f"lock[{name}]", f"the value {shown(text)!r} is not finite")
        problem = magnitude_problem(v)
        if problem:
            raise ModelError(robot, f"lock[{name}]", f"the value {problem}")
        return float(v)

    if isinstance(lock, Mapping):
        return {str(k): (bounded(str(k), float(v), str(v)), f"{k}={v}") for k, v in lock.items()}
    items = lock.split(",") if isinstance(lock, str) else list(lock)
    out: dict[str, tuple[float, str]] = {}
    for item in items:
        item = str(item).strip()
        if not item:
            continue
        name, eq, value = item.partition("=")
        name, value = name.strip(), value.strip()
        if value.lower().lstrip("+-") in ("inf", "infinity", "nan"):
            v = float(value)
        else:
            v = decimal(value) if eq else 0.0  # a C-locale decimal, as in the URDF (no 1_0, no other digits)
        if v is None:
            raise ModelError(robot, f"lock[{name}]", f"the value {shown(value)!r} is not a number")
        out[name] = (bounded(name, v, value), f"{name}={value}" if eq else name)
    return out


def _find_cycle(links: Mapping[str, Any], parent_joint: Mapping[str, _Joint]) -> list[_Joint]:
    """The joints of a cycle of the parent relation (each the parent joint of the next's parent link), or [].

    Walks up from every link once (linear time): a walk that reaches a root or an
    earlier walk's link is fine; one that comes back onto itself has found a cycle.
    """
    done: set[str] = set()
    for start in links:
        walk: dict[str, None] = {}
        link: str | None = start
        while link is not None and link not in done and link not in walk:
            walk[link] = None
            j = parent_joint.get(link)
            link = None if j is None else j.parent
        if link is not None and link in walk:
            cycle = list(walk)[list(walk).index(link):]  # child to parent
            return [parent_joint[n] for n in reversed(cycle)]
        done.update(walk)
    return []


def _lock_spelling(j: _Joint) -> str:
    """``name`` (lock at 0) or ``name=value`` with the limit nearest 0 when 0 is outside the joint's limits."""
    lo, hi = j.limits.get("lower"), j.limits.get("upper")
    value = 0.0
    if lo is not None and lo > 0:
        value = lo
    elif hi is not None and hi < 0:
        value = hi
    return j.name if value == 0 else f"{j.name}={value!r}"


def _command(spelling: str, tip: str | None, chain: str | None, floating: bool, lock: dict, name: str | None,
             friction: bool = True, fix_inertia: bool = False, xacro: str = "",
             snap_angles: float | None = None, visuals: bool = True) -> str:
    """The ``derive import-urdf`` command line that reproduces an import (``xacro``: its --arg and
    --package-path options)."""
    cmd = f"derive import-urdf {spelling}{xacro}"
    if chain is not None:
        cmd += f" --chain {chain}"
    elif tip is not None:
        cmd += f" --tip {tip}"
    if floating:
        cmd += " --floating"
    if lock:
        cmd += " --lock " + ",".join(s for _, s in lock.values())
    if name:
        cmd += f" --name {name}"
    if not friction:
        cmd += " --no-friction"
    if fix_inertia:
        cmd += " --fix-inertia"
    if snap_angles is not None:
        cmd += f" --snap-angles {snap_angles!r}"
    if not visuals:
        cmd += " --no-visuals"
    return cmd


def relock_command(source: str, joints: Iterable[str]) -> str | None:
    """The ``derive import-urdf`` command of an imported robot's ``source`` with ``joints`` added to its
    ``--lock`` list (the way forward when a coordinate moves no mass); None if it was not imported so."""
    command = import_command(source)
    if command is None:
        return None
    joints = [j for j in joints if j]
    match = re.search(r" --lock (\S+)", command)
    if match:
        return command[:match.end()] + "," + ",".join(joints) + command[match.end():]
    return command + " --lock " + ",".join(joints)


def _visual_entry(origin: Pose, item: Mapping) -> dict:
    """A models.yaml ``visual`` item: the shape, then only what differs from the defaults."""
    out = {k: v for k, v in item.items() if k in ("mesh", "box", "cylinder", "sphere", "capsule")}
    if any(origin.xyz):
        out["xyz"] = list(origin.xyz)
    if any(origin.rpy):
        out["rpy"] = list(origin.rpy)
    out.update({k: item[k] for k in ("scale", "color") if k in item})
    return out


def _inertia_dict(m: np.ndarray) -> dict:
    m = (m + m.T) / 2.0
    tiny = SNAP_ULPS * _EPS * float(np.abs(m).max())  # rounding residue of rotating an exact zero
    m = np.where(np.abs(m) <= tiny, 0.0, m)
    return {"ixx": float(m[0, 0]), "ixy": float(m[0, 1]), "ixz": float(m[0, 2]),
            "iyy": float(m[1, 1]), "iyz": float(m[1, 2]), "izz": float(m[2, 2])}


def _snap_origin(origin: Pose, tol: float) -> Pose:
    """A URDF origin (as read: ``rpy`` exact, no matrix) with its angles within ``tol`` of k pi/2 made k pi/2."""
    rpy = tuple(snapped(a, tol) for a in origin.rpy)
    return origin if rpy == origin.rpy else Pose(origin.xyz, rpy)


def _merge_mass(robot: str, body: str, parts: list[tuple[str, Pose, _Inertial]], noise: float = 0.0) -> dict:
    """Mass properties of a body made of ``parts`` (URDF link, its pose in the body frame, its inertial).

    A massless part's inertia must be zero; entries up to ``noise`` (kg m^2) are rounding noise and ignored.
    """
    kept = []
    for name, pose, inr in parts:
        if inr.mass == 0:
            if any(abs(v) > noise for v in inr.inertia.values()):
                where = f"links[{body}].inertia" if name == body else f"links[{name}].inertia (merged into '{body}')"
                raise ModelError(robot, where, "a massless link must have zero inertia")
            continue
        kept.append((pose, inr))
    parts = kept
    if not parts:
        return {}
    if len(parts) == 1:
        pose, inr = parts[0]
        if pose.is_identity and all(v == 0 for v in inr.rpy):  # exact copy
            return {"mass": inr.mass, "com": list(inr.com), "inertia": dict(inr.inertia)}
    masses = [inr.mass for _, inr in parts]
    coms = [pose.p + pose.R @ np.array(inr.com) for pose, inr in parts]
    inertias = [(pose.R @ rpy_matrix(inr.rpy)) @ inr.matrix() @ (pose.R @ rpy_matrix(inr.rpy)).T for pose, inr in parts]
    if len(parts) == 1:
        return {"mass": masses[0], "com": _snap_vector(coms[0]), "inertia": _inertia_dict(inertias[0])}
    total = math.fsum(masses)
    com = sum(m * c for m, c in zip(masses, coms)) / total
    inertia = np.zeros((3, 3))
    for m, c, I in zip(masses, coms, inertias):
        d = c - com
        inertia += I + m * (float(d @ d) * np.eye(3) - np.outer(d, d))
    return {"mass": total, "com": _snap_vector(com), "inertia": _inertia_dict(inertia)}


def _clamp_inertia_noise(inertia: dict, mass: float, floor: float) -> dict:
    """``inertia`` unchanged if it is physical; the nearest physical tensor if it misses by at most ``floor``.

    Model validation (:func:`derive.description.inertia.inertia_problem`) judges a
    tensor against its own trace (rtol 1e-9), so rounding noise is accepted on any
    link with a real inertia. It fails only where the tensor itself is noise-sized,
    e.g. -2e-22 kg m^2 entries (icub's legs) on a link whose true inertia is zero:
    nothing is left to be relative to. The importer judges such a link against an
    absolute floor, NOISE (1e-12) times the robot's largest inertia, and then, so
    that the entry validates as written, clamps it: negative principal moments -> 0,
    the largest lowered to the triangle inequality's bound. The change is below the
    floor, i.e. below 1e-12 of the robot's inertia scale, so dynamics still match the
    URDF (and Pinocchio) to 1e-12. Anything that misses by more (a clearly negative
    moment, a clear triangle violation, a massless link with inertia) is left as
    written for the validation to refuse. Physical tensors are never touched: a
    value copied from the URDF stays exactly that value.
    """
    m = np.array([[inertia["ixx"], inertia["ixy"], inertia["ixz"]],
                  [inertia["ixy"], inertia["iyy"], inertia["iyz"]],
                  [inertia["ixz"], inertia["iyz"], inertia["izz"]]], dtype=float)
    if inertia_problem(m, mass) is None:
        return inertia
    if mass == 0:
        miss = float(np.abs(m).max())
    else:
        eig, axes = np.linalg.eigh(m)
        miss = max(-eig[0], eig[2] - eig[0] - eig[1], 0.0)
    if not math.isfinite(miss) or miss > floor:
        return inertia  # a real error: the model validation says what is wrong
    if mass == 0:
        clamped = np.zeros((3, 3))
    else:
        e = np.maximum(eig, 0.0)
        e[2] = min(e[2], e[0] + e[1])
        clamped = axes @ np.diag(e) @ axes.T
    out = _inertia_dict(clamped)
    m = np.array([[out["ixx"], out["ixy"], out["ixz"]], [out["ixy"], out["iyy"], out["iyz"]],
                  [out["ixz"], out["iyz"], out["izz"]]])
    return out if inertia_problem(m, mass) is None else inertia


def import_urdf(path: str | Path, tip: str | None = None, lock: Any = (), name: str | None = None,
                chain: str | None = None, floating: bool = False, friction: bool = True,
                fix_inertia: bool = False, xacro_args: Any = None, package_paths: Any = None,
                snap_angles: float | None = None, visuals: bool = True) -> dict:
    """Read a URDF and return one models.yaml robot entry (a plain dict).

    ``path`` may be ``example-robot-data:<path under robots/>``. By default the
    whole tree is imported: every moving joint (depth-first, siblings by joint
    name: Pinocchio's order) except the locked ones, and except moving
    branches that carry no mass at all (a massless body at a leaf would make the
    mass matrix singular): those are dropped and named in the entry's
    description. ``tip`` only names the link that becomes the frame ``tcp`` (no
    ``tcp`` frame without it); the path to it is kept even if massless.

    ``chain`` names a link instead: only the root-to-``chain`` path may move (the
    ``tcp`` frame sits at ``chain``); moving branches off it are dropped if they
    carry no mass and refused otherwise (lock them). ``tip``, if given as well,
    must be the same link.

    ``lock`` names joints to make fixed, as ``"a,b=0.3"``, ``["a", "b=0.3"]`` or
    ``{"b": 0.3}`` (value in rad or m, default 0). ``floating`` gives the entry
    ``base: floating``: the URDF root link becomes a free-flying body, as
    ``pinocchio.buildModelFromUrdf(path, pinocchio.JointModelFreeFlyer())``. A URDF
    whose root is a massless link joined to the rest by a single ``floating``
    joint with an identity origin (``world`` -> ``base``) is read the same way:
    the root is dropped and its child is the floating base. A moving joint's
    ``<dynamics damping= friction=>`` becomes its ``actuator: {viscous, coulomb}``
    (where non-zero) unless ``friction`` is False; a mimic joint keeps its own too
    (acting on its own motion, they reach its leader's coordinate through the mimic
    map G: G^T D G). ``name`` defaults to the URDF robot name made a C identifier.

    ``fix_inertia`` repairs impossible inertias instead of refusing them, with one
    warning per link on stderr: a massless link's inertia becomes zero, any other
    the nearest physical one (:func:`derive.description.inertia.nearest_physical`).

    A xacro file (a ``.xacro`` name, or xacro elements or substitutions in it) is expanded first with the ``xacro`` package
    (:mod:`derive.description.xacro_expand`): ``xacro_args`` are its arguments (``{"NAME": "VALUE"}`` or
    ``["NAME=VALUE", ...]``), ``package_paths`` the folders of the ROS packages its ``$(find NAME)`` and
    ``package://NAME`` name (``{"NAME": DIR}`` or ``["NAME=DIR", ...]``); the entry's ``source`` records them.

    Constant angles are kept as written; those within 1e-4 rad of a multiple of pi/2
    without being one to rounding are listed in one warning line. ``snap_angles``
    (a tolerance in rad, at most 0.1) makes every constant angle within it of k pi/2
    exactly k pi/2 (recorded in the entry's ``source`` command as ``--snap-angles``).

    ``visuals`` (default True) keeps each link's ``<visual>`` elements as its ``visual:`` list (meshes
    and shapes for ``derive view``; no part of the dynamics): a link merged through fixed joints
    brings its visuals along, placed in its body's frame; a mesh file is resolved now
    (:func:`mesh_file`: ``package://`` through ``package_paths`` or the URDF's ancestors) and kept
    absolute (``derive import-urdf --out`` writes it relative to the models file). False (``--no-visuals``)
    leaves them out.

    Raises :class:`derive.description.model.ModelError` on any problem; it names
    the URDF and, for data defects, the way forward (a xacro expansion:
    :class:`derive.description.xacro_expand.XacroError`, naming the file).
    """
    return import_urdf_named(path, tip, lock, name, chain=chain, floating=floating, friction=friction,
                             fix_inertia=fix_inertia, xacro_args=xacro_args, package_paths=package_paths,
                             snap_angles=snap_angles, visuals=visuals)[1]


def _fix_inertias(reader: "_Reader", links: dict[str, _Inertial], floor: float) -> list[str]:
    """``--fix-inertia``: every link's impossible inertia replaced in place (one warning per link); the
    names of the links repaired. Rounding noise (within ``floor``, which the import clamps silently
    anyway) is left alone.
    """
    fixed = []
    for name, inr in links.items():
        m = inr.matrix()
        if inertia_problem(m, inr.mass) is None:
            continue
        if inr.mass == 0:
            if not any(abs(v) > floor for v in inr.inertia.values()):
                continue
            inr.inertia = {k: 0.0 for k in inr.inertia}
            fixed.append(name)
            reader.warn(f"links[{name}].inertial.inertia", "a massless link must have zero inertia: set to zero "
                                                            "(--fix-inertia)")
            continue
        if inertia_problem(_matrix(_clamp_inertia_noise(dict(inr.inertia), inr.mass, floor)), inr.mass) is None:
            continue
        problem = inertia_problem(m, inr.mass)
        inr.inertia = _inertia_dict(nearest_physical(m, inr.mass))
        fixed.append(name)
        shown_values = ", ".join(f"{k}={v:.6g}" for k, v in inr.inertia.items())
        reader.warn(f"links[{name}].inertial.inertia", f"{problem}: replaced by the nearest physical inertia "
                                                        f"({shown_values}) (--fix-inertia)")
    return fixed


def _matrix(i: Mapping[str, float]) -> np.ndarray:
    return np.array([[i["ixx"], i["ixy"], i["ixz"]], [i["ixy"], i["iyy"], i["iyz"]], [i["ixz"], i["iyz"], i["izz"]]],
                    dtype=float)


def _flush_tiny(node: Any) -> Any:
    """The entry with every computed number below FLT_MIN in magnitude made 0 (rounding residue of
    composing or merging; the URDF's own numbers were flushed, with a warning, when read)."""
    if isinstance(node, dict):
        return {k: _flush_tiny(v) for k, v in node.items()}
    if isinstance(node, list):
        return [_flush_tiny(v) for v in node]
    if isinstance(node, float) and tiny(node):
        return 0.0
    return node


def import_urdf_named(path: str | Path, tip: str | None = None, lock: Any = (), name: str | None = None,
                      chain: str | None = None, floating: bool = False, friction: bool = True,
                      fix_inertia: bool = False, xacro_args: Any = None, package_paths: Any = None,
                      snap_angles: float | None = None, visuals: bool = True) -> tuple[str, dict]:
    """Like :func:`import_urdf`, returning ``(robot name, entry)``."""
    if name is not None:
        identifier(name, "name", name)
    file, spelling, origin_text = resolve_urdf(path, name)
    try:
        xacro_args = assignments(xacro_args, "--arg", "VALUE")
        package_text = assignments(package_paths, "--package-path", "DIR")  # as given, for the command
        packages = package_folders(package_text)
    except XacroError as exc:
        raise XacroError(f"{spelling}: {exc}") from None
    looks: dict[str, list[dict]] | None = {} if visuals else None
    urdf_name, links, joints, xacro = _read(file, name, spelling, xacro_args, packages, looks)
    robot = name or c_identifier(urdf_name)
    floating_flag = bool(floating)

    def error(where: str, problem: str) -> ModelError:
        return ModelError(robot, where, problem, spelling)

    if snap_angles is not None:
        if isinstance(snap_angles, bool) or not isinstance(snap_angles, (int, float)) or not 0 < snap_angles <= MAX_SNAP:
            raise error("snap_angles", f"must be a tolerance in rad, 0 < TOL <= {MAX_SNAP:g} (e.g. 1e-4), got "
                        f"{shown(str(snap_angles))}")
        snap_angles = float(snap_angles)
        joints = [dataclasses.replace(j, origin=_snap_origin(j.origin, snap_angles)) for j in joints]
        for inr in links.values():
            inr.rpy = tuple(snapped(a, snap_angles) for a in inr.rpy)

    repaired: list[str] = []
    if fix_inertia:
        largest = max((abs(float(np.trace(inr.matrix()))) for inr in links.values()), default=0.0)
        repaired = _fix_inertias(_Reader(robot, spelling), links, NOISE * largest)

    # ---- tree structure
    parent_joint: dict[str, _Joint] = {}
    seen_joints: set[str] = set()
    for j in joints:
        if j.name in seen_joints:
            raise error(f"joints[{j.name}]", "duplicate joint name")
        seen_joints.add(j.name)
        for key, link in (("parent", j.parent), ("child", j.child)):
            if link not in links:
                raise error(f"joints[{j.name}].{key}", f"unknown link '{link}'")
        if j.child in parent_joint:
            raise error(f"joints[{j.name}].child", f"link '{j.child}' already has parent joint '{parent_joint[j.child].name}'")
        parent_joint[j.child] = j
    if not links:
        raise error("links", "the xacro file expands to no <link> (does it only define macros?)" if xacro
                    else "the URDF has no <link>")
    roots = [n for n in links if n not in parent_joint]
    cycle = _find_cycle(links, parent_joint)
    if cycle:
        where = f" detached from the root link '{roots[0]}'" if len(roots) == 1 else "" if roots else ", so no link is the root"
        raise error("joints", f"the joints {', '.join(repr(j.name) for j in cycle)} form a cycle through the links "
                    f"{', '.join(repr(j.child) for j in cycle)}{where}; a URDF must be a tree")
    if len(roots) != 1:
        raise error("links", f"links {', '.join(repr(r) for r in roots)} have no parent joint; exactly one root link is allowed")
    root = roots[0]
    children: dict[str, list[_Joint]] = {n: [] for n in links}
    for j in joints:
        children[j.parent].append(j)
    tree = [root]  # every link, parents first (no cycle, one root: all links hang off the root)
    for link in tree:
        tree.extend(j.child for j in children[link])
    behind: dict[str, float] = {}  # mass of a link and everything below it
    for link in reversed(tree):
        behind[link] = links[link].mass + math.fsum(behind[j.child] for j in children[link])

    try:
        locks = parse_lock(lock, robot)
    except ModelError as exc:
        raise exc.in_file(spelling) from None
    by_name = {j.name: j for j in joints}
    for jname, (value, _) in locks.items():
        j = by_name.get(jname)
        if j is None:
            moving = [x.name for x in joints if x.type != "fixed"]
            raise error(f"lock[{jname}]", f"unknown joint (moving joints: {', '.join(moving)})")
        if j.type == "fixed":
            raise error(f"lock[{jname}]", "the joint is fixed already")
        if j.type == "floating" and value != 0:
            raise error(f"lock[{jname}]", f"a floating joint is locked at its origin only (--lock {jname}), got {value:g}")
        lo, hi = j.limits.get("lower"), j.limits.get("upper")
        if (lo is not None and value < lo) or (hi is not None and value > hi):
            raise error(f"lock[{jname}]", f"{value} is outside the joint limits [{lo}, {hi}] "
                        f"(e.g. --lock {_lock_spelling(j)})")

    def moves(j: _Joint) -> bool:
        return j.type != "fixed" and j.name not in locks

    # ---- floating joints: only world -> base, read as a floating base
    world_joint: _Joint | None = None
    for j in joints:
        if j.type != "floating" or j.name in locks:
            continue
        inr = links[j.parent]
        at_root = j.parent == root and len(children[root]) == 1 and inr.mass == 0 and not any(inr.inertia.values())
        if not at_root:
            raise error(f"joints[{j.name}]", "floating joints are not supported but as the only joint of a massless root "
                        f"link (the world) to the base, which becomes the floating base; lock it (--lock {j.name}) "
                        "to make it fixed")
        if not j.origin.is_identity:
            raise error(f"joints[{j.name}].origin", "a floating joint read as the floating base must have the identity "
                        f"origin (it only offsets the base coordinates); remove it, or lock it (--lock {j.name})")
        world_joint = j
    world = None
    if world_joint is not None:
        world, root, floating = root, world_joint.child, True

    # ---- what moves: the whole tree, or the root-to-tip path (chain)
    key = "tip"
    if chain is not None:
        if tip is not None and tip != chain:
            raise error("tip", f"'{tip}' is not the --chain link '{chain}'; --chain puts the frame 'tcp' at its link "
                        "(give --chain alone)")
        tip, key = chain, "chain"
    if tip is not None and tip not in links:
        raise error(key, f"unknown link '{tip}' (links: {', '.join(links)})")
    if tip is not None and tip == world:
        raise error(key, f"'{tip}' is the world above the floating joint '{world_joint.name}'; choose a link of the robot")

    def lock_list(names: Iterable[str]) -> str:
        """``--lock`` text that keeps the user's locks and adds ``names`` (moving joints) at usable values."""
        out = {n: s for n, (_, s) in locks.items()}
        for n in names:
            if n not in out and n in by_name and by_name[n].type != "fixed":
                out[n] = _lock_spelling(by_name[n])
        return ",".join(out.values())

    on_path = set()
    link = tip
    while link is not None:
        on_path.add(link)
        link = parent_joint[link].parent if link != root else None

    # Kept joints in Pinocchio's order: depth-first, siblings by joint name (urdfdom keeps a link's child
    # joints in a std::map by name, not in file order). Written in this order, the entry's joints give
    # q in this order too (parse_robot: depth-first, file order among siblings).
    order: list[_Joint] = []
    off_path: list[tuple[_Joint, float]] = []  # chain: moving joints of branches with mass that miss the tip
    dropped: list[str] = []  # whole tree: moving joints of massless branches
    for link in children:
        children[link].sort(key=lambda j: j.name)  # str order = UTF-8 byte order, std::string's
    stack = list(reversed(children[root]))
    while stack:
        j = stack.pop()
        if moves(j) and j.child not in on_path:
            if chain is not None:
                if behind[j.child] > 0:
                    off_path.append((j, behind[j.child]))
                continue  # a massless branch is dropped
            if behind[j.child] == 0:
                dropped.append(j.name)  # nothing to move: a massless body would make M singular
                continue
        order.append(j)
        stack.extend(reversed(children[j.child]))
    kept = {j.name for j in order if moves(j)}
    # A mimic of a mimic is one mimic of the chain's root (q_C = m2 (m1 q_A + o1) + o2); the chain runs
    # through moving joints only: a locked or fixed one ends it (and is judged below, as the root).
    try:
        composed = compose_mimics({j.name: Mimic(*j.mimic) for j in joints
                                   if j.mimic is not None and moves(j) and j.mimic[0] != j.name})
    except MimicCycle as exc:
        pairs = ", ".join(f"{a} mimics {b}" for a, b in zip(exc.joints, exc.joints[1:] + exc.joints[:1]))
        raise error(f"joints[{exc.joints[0]}].mimic", f"{exc} ({pairs}): none of them has a coordinate; lock them "
                    f"(--lock {lock_list(exc.joints)}) or remove one <mimic>") from None
    stuck: list[tuple[_Joint, str, str]] = []  # a mimic joint follows a joint that keeps its own coordinate
    for j in order:
        if j.mimic is None or not moves(j):
            continue
        if j.name not in composed:  # it mimics itself
            target, through = j, (j.name,)
        else:  # not `chain`: that is the --chain argument, still needed for the notes and the command
            leader, through = composed[j.name]
            target = by_name.get(leader.joint)
        problem = ("an unknown joint" if target is None else "itself" if target is j else
                   "a fixed joint" if target.type == "fixed" else "a locked joint" if target.name in locks else
                   "a joint of a dropped massless branch" if target.name not in kept else None)
        if problem:
            stuck.append((j, "".join(f", which mimics '{x}'" for x in through[1:]), problem))
    if stuck:
        j, via, problem = stuck[0]
        others = f" (and {len(stuck) - 1} more mimic joint{'s' * (len(stuck) > 2)} alike)" if len(stuck) > 1 else ""
        raise error(f"joints[{j.name}].mimic", f"mimics '{j.mimic[0]}'{via}, {problem}{others}: lock "
                    f"{'them' if others else 'it'} (--lock {lock_list(m.name for m, _, _ in stuck)})")
    if off_path:
        # every joint that would still move mass off the path once the branch tops are locked, so that
        # the suggested command works as given
        to_lock = []
        for top, _ in off_path:
            below = [top]
            for x in below:
                if x is top or (moves(x) and behind[x.child] > 0):
                    to_lock.append(x.name)
                below.extend(children[x.child])
        j, mass = off_path[0]
        raise error(f"joints[{j.name}]", f"moves a branch with mass ({mass:g} kg) that does not lead to the tip "
                    f"'{tip}'; lock it (--lock {lock_list(to_lock)}) or choose another tip")
    if not floating and not any(moves(j) for j in order):
        raise error("joints", "no moving joint is left to import (a fixed-base robot needs one); a single rigid body "
                    "imports as a floating base (--floating)")

    # ---- merge fixed joints: body (surviving link) and pose in the body frame of every link
    body: dict[str, str] = {root: root}
    pose: dict[str, Pose] = {root: Pose()}
    out_joints: list[dict] = []
    for j in order:
        origin = j.origin
        if j.name in locks:
            value = locks[j.name][0]
            if value != 0:
                if j.type in ("revolute", "continuous"):
                    motion = Pose.from_matrix(axis_angle(j.axis, value), (0.0, 0.0, 0.0))
                else:
                    motion = Pose(tuple(_snap_vector(np.array(unit_vector(j.axis)) * value)))
                origin = origin * motion
        placed = pose[j.parent] * origin
        if moves(j):
            body[j.child], pose[j.child] = j.child, Pose()
            entry = {"name": j.name, "type": j.type, "parent": body[j.parent], "child": j.child,
                     "origin": {"xyz": list(placed.xyz), "rpy": list(placed.rpy)}, "axis": list(j.axis)}
            if j.limits:
                entry["limits"] = dict(j.limits)
            if j.mimic is not None:
                leader = composed[j.name][0]  # a mimic of a mimic: of the chain's root
                entry["mimic"] = {"joint": leader.joint, "multiplier": leader.multiplier, "offset": leader.offset}
            if friction and any(j.dynamics):  # URDF damping and friction: viscous and Coulomb friction
                # (a mimic joint's act on its own motion: through G on its leader's coordinate, G^T D G)
                entry["actuator"] = {k: v for k, v in zip(("viscous", "coulomb"), j.dynamics) if v}
            out_joints.append(entry)
        else:
            body[j.child], pose[j.child] = body[j.parent], placed

    survivors = [root] + [j.child for j in order if moves(j)]
    out_links = []
    # inertia noise floor: NOISE times the largest inertia of the robot, as written and as merged
    largest = max((abs(float(np.trace(inr.matrix()))) for inr in links.values()), default=0.0)
    for s in survivors:
        parts = [(n, pose[n], links[n]) for n in body if body[n] == s]
        try:
            out_links.append({"name": s, **_merge_mass(robot, s, parts, NOISE * largest)})
        except ModelError as exc:
            raise ModelError(robot, exc.field, f"{exc.problem}: give it a mass in the URDF, or import with "
                             "--fix-inertia (sets a massless link's inertia to zero, with a warning)", spelling) from None
    for link in out_links:
        if "inertia" in link:
            i = link["inertia"]
            largest = max(largest, abs(i["ixx"] + i["iyy"] + i["izz"]))
    for link in out_links:
        if "inertia" in link:
            link["inertia"] = _clamp_inertia_noise(link["inertia"], link["mass"], NOISE * largest)
    for link in out_links:  # the looks of every URDF link merged into it, in its frame
        placed_visuals = [_visual_entry(pose[n] * item["origin"], item) for n in body if body[n] == link["name"]
                          for item in (looks or {}).get(n, ())]
        if placed_visuals:
            link["visual"] = placed_visuals

    frames = []
    if tip is not None:  # a tip fused onto its moving body keeps its own name as an alias of tcp (a moving link keeps it anyway)
        frames.append({"name": "tcp", "link": body[tip], "xyz": list(pose[tip].xyz), "rpy": list(pose[tip].rpy),
                       **({"aliases": [tip]} if body[tip] != tip and tip != "tcp" else {})})
    for n in body:
        if body[n] != n and n != tip:
            frames.append({"name": n, "link": body[n], "xyz": list(pose[n].xyz), "rpy": list(pose[n].rpy)})

    # ---- constant angles near k pi/2: snapped as asked (composed ones too), the others listed
    placed_angles = [(f"joints[{j['name']}].origin.rpy", j["origin"]["rpy"]) for j in out_joints]
    placed_angles += [(f"frames[{f['name']}].rpy", f["rpy"]) for f in frames]
    if snap_angles is not None:
        for _, rpy in placed_angles:
            rpy[:] = [snapped(a, snap_angles) for a in rpy]
    near = [(f"{where}[{i}]", a) for where, rpy in placed_angles for i, a in enumerate(rpy)]
    near += [(f"links[{n}].inertial.origin.rpy[{i}]", a) for n, inr in links.items() if inr.mass != 0
             for i, a in enumerate(inr.rpy)]
    near = [(where, a) for where, a in near if quarter(a, NEAR) is not None and quarter(a, EXACT) is None]
    if near:
        _Reader(robot, spelling).warn(
            "angles", f"{len(near)} constant angle{'s are' if len(near) > 1 else ' is'} within {NEAR:g} rad of a multiple of pi/2 "
            f"without being one (kept as written; --snap-angles {NEAR:g} makes "
            f"{'it' if len(near) == 1 else 'them'} exact): " + ", ".join(f"{w} = {spelled(a)}" for w, a in near))

    # ---- names -> C identifiers
    renamed: dict[str, str] = {}

    def ident(kind: str, n: str) -> str:
        new = c_identifier(n)
        if renamed.setdefault(new, n) != n:
            raise error(kind, f"'{n}' and '{renamed[new]}' both become the identifier '{new}'")
        return new

    for link in out_links:
        link["name"] = ident("links", link["name"])
    for i, f in enumerate(frames):
        f["name"] = "tcp" if tip is not None and i == 0 else ident("frames", f["name"])
        f["link"] = c_identifier(f["link"])
        if "aliases" in f:
            f["aliases"] = [ident("frames", a) for a in f["aliases"]]
    if tip is not None and "tcp" in renamed:
        raise error(key, f"the URDF already has a link called '{renamed['tcp']}'; it would clash with the frame 'tcp'")
    renamed_joints: dict[str, str] = {}
    for j in out_joints:
        new = c_identifier(j["name"])
        if renamed_joints.setdefault(new, j["name"]) != j["name"]:
            raise error("joints", f"'{j['name']}' and '{renamed_joints[new]}' both become the identifier '{new}'")
        j["name"], j["parent"], j["child"] = new, c_identifier(j["parent"]), c_identifier(j["child"])
        if "mimic" in j:
            j["mimic"]["joint"] = c_identifier(j["mimic"]["joint"])

    notes = []
    if chain is not None:
        notes.append(f"chain to {tip}")
    elif tip is not None:
        notes.append(f"tip {tip}")
    if world_joint is not None:
        notes.append(f"floating base {root}: the floating joint {world_joint.name} from {world}")
    elif floating:
        notes.append(f"floating base {root}")
    if locks:
        notes.append("locked " + ", ".join(f"{n} = {v:g}" for n, (v, _) in locks.items()))
    if repaired:
        notes.append("repaired the inertia of " + ", ".join(repaired))
    if dropped:
        notes.append("dropped the massless moving " + ("branches " if len(dropped) > 1 else "branch ") + ", ".join(dropped))
    if snap_angles is not None:
        notes.append(f"constant angles within {snap_angles:g} rad of a multiple of pi/2 made exact")
    description = f"{urdf_name} imported from {'xacro' if xacro else 'URDF'}" + (f" ({'; '.join(notes)})" if notes else "")
    command = _command(spelling, tip, chain, floating_flag, locks, name if name and name != c_identifier(urdf_name) else None,
                       friction or not any(any(j.dynamics) for j in order), bool(repaired),
                       xacro_command(xacro_args, package_text), snap_angles, visuals)
    entry = {
        "description": description,
        "source": f"{origin_text}, imported by `{command}`",
        **({"base": "floating"} if floating else {}),
        "gravity": list(GRAVITY),
        "links": out_links,
        "joints": out_joints,
        "frames": frames,
    }
    entry = _flush_tiny(entry)
    try:
        parse_robot(robot, entry)  # the entry must load as it is
    except ModelError as exc:
        problem, hint = exc.problem, ""
        if exc.field.endswith(".inertia"):
            problem = problem.split("; re-import it")[0]
            hint = (": correct the link's <inertial> in the URDF, or import with --fix-inertia (the nearest "
                    "physical inertia, with a warning)")
        raise ModelError(robot, exc.field, f"{problem} (in the imported entry){hint}", spelling) from None
    return robot, entry



# --------------------------------------------------------------------------- YAML text


_PLAIN = re.compile(r"^[A-Za-z_][A-Za-z0-9_.\-]*$")
_YAML_WORDS = {"y", "n", "yes", "no", "on", "off", "true", "false", "null", "~"}


def _scalar(v: Any) -> str:
    if isinstance(v, bool) or v is None:
        raise TypeError(f"unexpected value {v!r}")
    if isinstance(v, (int, float)):
        v = float(v)
        if not math.isfinite(v):
            raise ValueError(f"not finite: {v}")
        text = repr(v)
        if "e" in text and "." not in text:  # YAML 1.1 floats need a dot: 1e-05 -> 1.0e-05
            mant, exp = text.split("e")
            text = f"{mant}.0e{exp}"
        if "e" in text and text.split("e")[1][0] not in "+-":
            text = text.replace("e", "e+")
        return text
    s = str(v)
    if _PLAIN.match(s) and s.lower() not in _YAML_WORDS:
        return s

    return json.dumps(s)


def _flow(v: Any) -> str:
    if isinstance(v, Mapping):
        return "{" + ", ".join(f"{k}: {_flow(x)}" for k, x in v.items()) + "}"
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_flow(x) for x in v) + "]"
    return _scalar(v)


def _block_scalar(v: Any) -> str:
    """A scalar as a block-context mapping value: plain when YAML reads it back unchanged."""
    if isinstance(v, str) and v == v.strip() and "\n" not in v and " #" not in v and not v.startswith(("\"", "'")):
        try:
            if yaml.safe_load(f"k: {v}") == {"k": v}:
                return v
        except (yaml.YAMLError, ValueError, OverflowError):  # e.g. a date that is no date
            pass
    return _flow(v)


def _item(d: Mapping, indent: str, width: int = 120) -> list[str]:
    """One list item: a flow mapping if it fits on a line, else a block mapping of flow values."""
    line = f"{indent}- {_flow(d)}"
    if len(line) <= width:
        return [line]
    out = []
    for i, (k, v) in enumerate(d.items()):
        out.append(f"{indent}{'- ' if i == 0 else '  '}{k}: {_flow(v)}")
    return out


def dump_entry(name: str, entry: Mapping, indent: str = "  ", generator: str = "derive import-urdf") -> str:
    """Deterministic YAML text of one robot entry, to sit under ``robots:`` of models.yaml."""
    source = str(entry.get("source", ""))
    command = source.split("`")[1] if source.count("`") >= 2 else None
    origin = source.split(", imported by")[0].split(", identified by")[0] or "a URDF"
    lines = [f"{indent}# {name}: generated by `{generator}` from {origin}; do not edit by hand."]
    if command:
        lines.append(f"{indent}# Regenerate with: {command}")
    lines.append(f"{indent}{name}:")
    body = indent + "  "
    for key, value in entry.items():
        if isinstance(value, list) and value and all(isinstance(x, Mapping) for x in value):
            lines.append(f"{body}{key}:")
            for x in value:
                lines.extend(_item(x, body + "  "))
        else:
            lines.append(f"{body}{key}: {_block_scalar(value)}")
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- command


def append_entry(models_path: str | Path, name: str, entry: Mapping, replace: bool = False,
                 generator: str = "derive import-urdf") -> str:
    """Append ``entry`` under ``robots:`` of a models file; an existing robot of that name is refused,
    or with ``replace`` rewritten in place (:func:`_entry_lines`: its lines and the generated comments
    above it; the other robots, comments and the order stay as they were).

    The new text is validated first and then written all at once (:func:`derive.filesystem.write_atomically`:
    a temporary file beside it, fsync'ed and renamed over it): on any failure (a full disk, a kill) the file
    is byte-identical to what it was, or still absent, and the error names it. Returns what it did:
    "appended" or "replaced".
    """
    path = Path(models_path)
    if not path.exists() and not path.is_symlink():  # a new models file
        new_text = "# derive robot models (fields: the documentation's models.yaml reference, docs/reference/schema.md)\nrobots:\n" + dump_entry(name, entry, generator=generator)
        parse_models(new_text, source=str(path))
        write_atomically(path, new_text, "models file")
        return "appended"
    text = read_text(path, "models file")
    existing = parse_models(text, source=str(path))
    if name in existing:
        if not replace:
            raise ModelError(name, f"{path} robots", "already exists; pass --replace to replace it in place, or pick "
                                                     "another --name")
        lines = text.splitlines(keepends=True)
        first, last, column = _entry_lines(text, name, str(path))
        new_text = "".join(lines[:first]) + dump_entry(name, entry, indent=" " * column, generator=generator) \
            + "".join(lines[last + 1:])
        robots = parse_models(new_text, source=str(path))
        if list(robots) != list(existing):
            raise ModelError(name, str(path), "cannot replace the entry in place safely (its text spans other keys)")
        write_atomically(path, new_text, "models file")
        return "replaced"
    new_text = text + ("" if text.endswith("\n") else "\n") + "\n" + dump_entry(name, entry, generator=generator)
    robots = parse_models(new_text, source=str(path))
    if name not in robots or list(robots)[:-1] != list(existing):
        raise ModelError(name, str(path), "'robots:' is not the last top-level key; cannot append safely")
    write_atomically(path, new_text, "models file")
    return "appended"


def _entry_lines(text: str, name: str, source: str) -> tuple[int, int, int]:
    """(first line, last line, column of its key) of robot ``name``'s entry under ``robots:``, lines
    counted from 0: its key, its value, and right above the key the comments derive wrote with it
    ("# <name>: generated by ..." and "# Regenerate with: ..."); other comments stay."""
    root = yaml.compose(text, Loader=yaml.SafeLoader)
    robots = next((v for k, v in root.value if k.value == "robots"), None) if isinstance(root, yaml.MappingNode) else None
    pair = next(((k, v) for k, v in getattr(robots, "value", ()) if k.value == name), None)
    if not isinstance(robots, yaml.MappingNode) or pair is None or robots.flow_style:
        raise ModelError(name, source, "cannot find the entry's text to replace (a flow-style or aliased 'robots:')")
    key, value = pair

    def last(node) -> int:  # the last line holding a character of node
        if isinstance(node, yaml.MappingNode) and not node.flow_style:
            return max((last(x) for pair in node.value for x in pair), default=node.start_mark.line)
        if isinstance(node, yaml.SequenceNode) and not node.flow_style:
            return max((last(x) for x in node.value), default=node.start_mark.line)
        end = node.end_mark
        return end.line if end.column > 0 else end.line - 1

    lines = text.splitlines()
    first = key.start_mark.line
    while first > 0 and re.match(rf"\s*# ({re.escape(name)}: generated by |Regenerate with: )", lines[first - 1]):
        first -= 1
    return first, max(last(value), key.start_mark.line), key.start_mark.column
