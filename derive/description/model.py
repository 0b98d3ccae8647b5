"""models.yaml -> validated robots: loading, parsing and the checks every model passes.

No CAS lives here. Numeric fields hold a float or a parameter expression string
(see :mod:`derive.description.expr`); the symbolic side and the numeric reference each
evaluate them in their own algebra. The dataclasses and conventions are in
:mod:`derive.description.robot`. Every number, as written and as evaluated, is 0 or has a
magnitude in [FLT_MIN, 1e12] (:mod:`derive.description.numbers`, shared with the URDF reader);
an axis component is 0 or at least 2^-63 of the axis's largest.
"""

from __future__ import annotations

import dataclasses
import math
import os
from pathlib import Path
from typing import Any, Iterable, Mapping

import numpy as np

from derive.description import expr
from derive.description.closure import CHART_TOL, CLOSED_TOL, Closure, close
from derive.description.dh import dh_to_tree
from derive.description.files import load_yaml, read_text
from derive.description.inertia import inertia_problem
from derive.description.joints import JOINT_TYPES
from derive.description.numbers import axis_component_problem, decimal, magnitude_problem, unit_vector
from derive.description.robot import (BASES, BUNDLE_FRAME_QUANTITIES, BUNDLE_QUANTITIES, CONTACT_KINDS, FUNCTION_QUANTITIES, Actuator, Bundle, Contact, ContactSet, robot_name, Frame, Joint, Limits, Link, LOOP_KINDS, Loop, Mimic, MimicCycle, ModelError, Origin, Parameter, Robot, Value, Vec3, VISUAL_SHAPES, Visual,
                                      compose_mimics, identifier, import_command, shown)
from derive.description.schema import keys
from derive.resources import EXAMPLE_MODELS


# --------------------------------------------------------------------------- loading


MODELS_FILE = "models.yaml"


def local_models_path() -> Path | None:
    """The models file the user named without ``--models``: $DERIVE_MODELS, else ./models.yaml; None if neither."""
    env = os.environ.get("DERIVE_MODELS")
    if env:
        return Path(env)
    local = Path.cwd() / MODELS_FILE
    return local if local.is_file() else None


def default_models_path() -> Path:
    """The models file read when none is given: $DERIVE_MODELS, else ./models.yaml, else the shipped
    example robots (pendulum, planar_2r, rrprr, cartpole, ur5, panda)."""
    return local_models_path() or EXAMPLE_MODELS


def load_models(path: str | Path | None = None) -> dict[str, Robot]:
    """Read and validate every robot of a models file, in the file's order.

    ``path`` None means :func:`default_models_path`; an empty path is an error, never the default.
    """
    path = Path(path) if path is not None and str(path) != "" else (default_models_path() if path is None else path)
    text = read_text(path, "models file")
    return parse_models(text, source=str(path))


def parse_models(text: str, source: str | None = None) -> dict[str, Robot]:
    """Validate every robot of a models file's text; a ModelError names ``source``, the robot and the field."""
    data = load_yaml(text, f"models file {source}" if source else "models text")
    if not isinstance(data, Mapping) or not isinstance(data.get("robots"), Mapping):
        raise ModelError(None, "robots", "the file must hold a mapping 'robots: {name: {...}}'", source)
    try:
        _check_keys(None, "", data, keys("file"))
    except ModelError as exc:
        raise exc.in_file(source) from None
    if not data["robots"]:
        raise ModelError(None, "robots", "no robots in the file", source)
    robots: dict[str, Robot] = {}
    folded: dict[str, str] = {}
    for name, spec in data["robots"].items():
        try:
            robot = parse_robot(str(name), spec)
        except ModelError as exc:
            raise exc.in_file(source) from None
        if source:
            robot = dataclasses.replace(robot, file=str(source))
        other = folded.get(robot.name.lower())
        if other is not None:
            raise ModelError(robot.name, "name", f"differs from robot '{other}' only by case: their files and "
                             "macros would clash on case-insensitive file systems", source)
        folded[robot.name.lower()] = robot.name
        robots[robot.name] = robot
    return robots


def load_robot(name: str, path: str | Path | None = None) -> Robot:
    models = load_models(path)
    if name not in models:
        source = Path(path) if path else default_models_path()
        raise ModelError(name, "robots", f"no such robot in {source} (known: {', '.join(models)})")
    return models[name]


# --------------------------------------------------------------------------- parsing


def _check_keys(robot: str | None, where: str, data: Mapping, allowed: Iterable[str]) -> None:
    allowed = set(allowed)
    for key in data:
        if key not in allowed:
            raise ModelError(robot, f"{where}{key}", f"unknown field (expected one of: {', '.join(sorted(allowed))})")


class _Parser:
    """Parses one robot; collects inline parameters as it goes."""

    def __init__(self, name: str, spec: Any):
        self.name = robot_name(name)
        if not isinstance(spec, Mapping):
            raise ModelError(name, "", "a robot must be a mapping with links and joints (or dh)")
        self.spec = spec
        self.params: dict[str, float] = {}

    def error(self, where: str, problem: str) -> ModelError:
        return ModelError(self.name, where, problem)

    # ---- values ----
    def value(self, where: str, raw: Any) -> Value:
        if isinstance(raw, Mapping):
            self.check_keys(where + ".", raw, keys("parameter"))
            if "param" not in raw or "default" not in raw:
                raise self.error(where, "a parameter needs both 'param' and 'default'")
            pname = identifier(self.name, where + ".param", raw["param"])
            default = self.number(where + ".default", raw["default"])
            if pname in self.params and self.params[pname] != default:
                raise self.error(where, f"parameter '{pname}' declared twice with different defaults")
            self.params[pname] = default
            return pname
        if isinstance(raw, bool) or raw is None:
            raise self.error(where, f"expected a number or parameter expression, got {raw!r}")
        if isinstance(raw, (int, float)):
            problem = magnitude_problem(raw)
            if problem:
                raise self.error(where, problem)
            return float(raw)
        if isinstance(raw, str):
            try:
                expr.parse(raw)
            except expr.ExpressionError as exc:
                raise self.error(where, str(exc)) from None
            return raw.strip()
        raise self.error(where, f"expected a number or parameter expression, got {type(raw).__name__}")

    def number(self, where: str, raw: Any) -> float:
        """A plain number (no parameter), within the bounds of :mod:`derive.description.numbers`."""
        if isinstance(raw, str):  # YAML 1.1 reads 1e-3 (no dot) as a string: a C-locale decimal, nothing more
            value = decimal(raw.strip())
            if value is None:
                raise self.error(where, f"expected a finite number, got {shown(raw)!r}")
            raw = value
        if isinstance(raw, bool) or not isinstance(raw, (int, float)):
            raise self.error(where, f"expected a finite number, got {raw!r}")
        problem = magnitude_problem(raw)
        if problem:
            raise self.error(where, problem)
        return float(raw)

    def vec3(self, where: str, raw: Any, default: Vec3 = (0.0, 0.0, 0.0)) -> Vec3:
        if raw is None:
            return default
        if not isinstance(raw, (list, tuple)) or len(raw) != 3:
            raise self.error(where, f"expected a list of 3 values, got {raw!r}")
        return tuple(self.value(f"{where}[{i}]", v) for i, v in enumerate(raw))

    def check_keys(self, where: str, data: Any, allowed: Iterable[str]) -> None:
        if not isinstance(data, Mapping):
            raise self.error(where.rstrip("."), f"expected a mapping, got {data!r}")
        _check_keys(self.name, where, data, allowed)

    def origin(self, where: str, raw: Any) -> Origin:
        if raw is None:
            return Origin()
        self.check_keys(where + ".", raw, keys("origin"))
        return Origin(self.vec3(where + ".xyz", raw.get("xyz")), self.vec3(where + ".rpy", raw.get("rpy")))

    def inertia(self, where: str, raw: Any) -> tuple:
        if raw is None:
            return Link.__dataclass_fields__["inertia"].default
        if isinstance(raw, Mapping):
            self.check_keys(where + ".", raw, keys("inertia"))
            v = {k: self.value(f"{where}.{k}", raw.get(k, 0.0)) for k in ("ixx", "iyy", "izz", "ixy", "ixz", "iyz")}
            return ((v["ixx"], v["ixy"], v["ixz"]), (v["ixy"], v["iyy"], v["iyz"]), (v["ixz"], v["iyz"], v["izz"]))
        if isinstance(raw, (list, tuple)) and len(raw) == 3 and all(isinstance(r, (list, tuple)) and len(r) == 3 for r in raw):
            rows = tuple(tuple(self.value(f"{where}[{i}][{k}]", v) for k, v in enumerate(r)) for i, r in enumerate(raw))
            for i in range(3):
                for k in range(i + 1, 3):
                    if rows[i][k] != rows[k][i]:
                        raise self.error(where, f"not symmetric: [{i}][{k}] = {rows[i][k]!r} but [{k}][{i}] = {rows[k][i]!r}")
            return rows
        if isinstance(raw, (list, tuple)) and len(raw) == 3:  # diagonal
            d = [self.value(f"{where}[{i}]", v) for i, v in enumerate(raw)]
            return ((d[0], 0.0, 0.0), (0.0, d[1], 0.0), (0.0, 0.0, d[2]))
        raise self.error(where, "expected a 3x3 matrix, a diagonal [ixx, iyy, izz] or {ixx: .., ixy: .., ...}")

    def limits(self, where: str, raw: Any) -> Limits:
        if raw is None:
            return Limits()
        self.check_keys(where + ".", raw, keys("limits"))
        vals = {k: (None if raw.get(k) is None else self.number(f"{where}.{k}", raw[k])) for k in ("lower", "upper", "velocity", "effort")}
        if vals["lower"] is not None and vals["upper"] is not None and vals["lower"] > vals["upper"]:
            raise self.error(where, f"lower ({vals['lower']}) is above upper ({vals['upper']})")
        for k in ("velocity", "effort"):
            if vals[k] is not None and vals[k] <= 0:
                raise self.error(f"{where}.{k}", f"must be positive, got {vals[k]}")
        return Limits(**vals)

    def link(self, where: str, raw: Any) -> Link:
        self.check_keys(where + ".", raw, keys("link"))
        if "name" not in raw:
            raise self.error(where + ".name", "missing")
        return Link(
            name=identifier(self.name, where + ".name", raw["name"]),
            mass=self.value(where + ".mass", raw.get("mass", 0.0)),
            com=self.vec3(where + ".com", raw.get("com")),
            inertia=self.inertia(where + ".inertia", raw.get("inertia")),
            inertia_rpy=self.vec3(where + ".inertia_rpy", raw.get("inertia_rpy")),
            visual=self.visuals(where + ".visual", raw.get("visual")),
        )

    def numbers(self, where: str, raw: Any, n: int | tuple[int, ...], positive: bool = False) -> tuple[float, ...]:
        """A list of ``n`` plain numbers (``n`` a tuple: any of those counts); ``positive``: each > 0."""
        counts = (n,) if isinstance(n, int) else n
        if not isinstance(raw, (list, tuple)) or len(raw) not in counts:
            want = " or ".join(str(c) for c in counts)
            raise self.error(where, f"expected a list of {want} numbers, got {shown(repr(raw), 60)}")
        out = tuple(self.number(f"{where}[{i}]", v) for i, v in enumerate(raw))
        for i, v in enumerate(out):
            if positive and not v > 0:
                raise self.error(f"{where}[{i}]", f"must be positive, got {v:g}")
        return out

    def visuals(self, where: str, raw: Any) -> tuple[Visual, ...]:
        """A link's ``visual`` list (see :class:`~derive.description.robot.Visual`); plain numbers only."""
        if raw is None:
            return ()
        if not isinstance(raw, list):
            raise self.error(where, "expected a list of visuals ({mesh: FILE} or {box: [x, y, z]}, ...)")
        out = []
        for k, item in enumerate(raw):
            at = f"{where}[{k}]"
            self.check_keys(at + ".", item, keys("visual"))
            shapes = [s for s in VISUAL_SHAPES if s in item]
            if len(shapes) != 1:
                raise self.error(at, f"needs exactly one of {', '.join(VISUAL_SHAPES)}, got "
                                     f"{', '.join(shapes) if shapes else 'none'}")
            shape, value = shapes[0], item[shapes[0]]
            mesh, size = "", ()
            if shape == "mesh":
                if not isinstance(value, str) or not value.strip():
                    raise self.error(f"{at}.mesh", f"expected a file name, got {shown(repr(value), 60)}")
                mesh = value
            elif shape == "box":
                size = self.numbers(f"{at}.box", value, 3, positive=True)
            elif shape == "sphere":
                size = (self.number(f"{at}.sphere", value),)
                if not size[0] > 0:
                    raise self.error(f"{at}.sphere", f"must be a positive radius, got {size[0]:g}")
            else:
                size = self.numbers(f"{at}.{shape}", value, 2, positive=True)
            scale = self.numbers(f"{at}.scale", item["scale"], 3) if "scale" in item else (1.0, 1.0, 1.0)
            for i, v in enumerate(scale):
                if v == 0:
                    raise self.error(f"{at}.scale[{i}]", "must not be 0")
            color = None
            if "color" in item:
                color = self.numbers(f"{at}.color", item["color"], (3, 4))
                for i, v in enumerate(color):
                    if not 0 <= v <= 1:
                        raise self.error(f"{at}.color[{i}]", f"must be from 0 to 1, got {v:g}")
                color = color + (1.0,) * (4 - len(color))
            xyz = self.numbers(f"{at}.xyz", item["xyz"], 3) if "xyz" in item else (0.0, 0.0, 0.0)
            rpy = self.numbers(f"{at}.rpy", item["rpy"], 3) if "rpy" in item else (0.0, 0.0, 0.0)
            out.append(Visual(shape, mesh, size, Origin(xyz, rpy), scale, color))
        return tuple(out)

    def unit_vector(self, where: str, raw: Any) -> tuple:
        """A nonzero 3-vector of numbers, normalised (kept as written when already unit); robust for any
        components within the bounds (:func:`derive.description.numbers.unit_vector`)."""
        if not isinstance(raw, (list, tuple)) or len(raw) != 3:
            raise self.error(where, f"expected 3 numbers, got {shown(raw)!r}")
        v = [self.number(f"{where}[{i}]", a) for i, a in enumerate(raw)]
        small = axis_component_problem(v)
        if small:
            raise self.error(f"{where}[{small[0]}]", small[1])
        unit = unit_vector(v)
        if unit is None:
            raise self.error(where, "must not be the zero vector")
        return unit

    def joint(self, where: str, raw: Any) -> Joint:
        self.check_keys(where + ".", raw, keys("joint"))
        for key in ("name", "type", "parent", "child"):
            if key not in raw:
                raise self.error(f"{where}.{key}", "missing")
        jtype = raw["type"]
        if not isinstance(jtype, str) or jtype not in JOINT_TYPES:
            raise self.error(f"{where}.type", f"unknown joint type '{jtype}' (known: {', '.join(JOINT_TYPES)})")
        name = identifier(self.name, where + ".name", raw["name"])
        if jtype == "spherical" and "axis" in raw:
            raise self.error(f"{where}.axis", "a spherical joint turns about z, y, x of its joint frame "
                                              "(ZYX Euler angles); orient them with origin.rpy instead")
        axis = self.unit_vector(f"{where}.axis", raw.get("axis", [1.0, 0.0, 0.0]))
        for key, owner in (("pitch", "helical"), ("axis2", "universal")):
            if key in raw and jtype != owner:
                raise self.error(f"{where}.{key}", f"only a {owner} joint has '{key}' (this one is {jtype})")
            if key not in raw and jtype == owner:
                raise self.error(f"{where}.{key}", f"missing: a {owner} joint needs '{key}'")
        pitch = self.value(f"{where}.pitch", raw["pitch"]) if jtype == "helical" else None
        axis2 = None
        if jtype == "universal":
            axis2 = self.unit_vector(f"{where}.axis2", raw["axis2"])
            cos = sum(a * b for a, b in zip(axis, axis2))
            if abs(abs(cos) - 1) < 1e-9:
                raise self.error(f"{where}.axis2", f"{list(axis2)} is parallel to axis {list(axis)}: that is one revolute joint")
            if abs(cos) > 1e-9:
                raise self.error(f"{where}.axis2", f"must be perpendicular to axis {list(axis)} (cos of the angle = {cos:.3g})")
        return Joint(
            name=name,
            type=jtype,
            parent=str(raw["parent"]),
            child=str(raw["child"]),
            origin=self.origin(where + ".origin", raw.get("origin")),
            axis=axis,
            limits=self.joint_limits(where + ".limits", raw.get("limits"), JOINT_TYPES[jtype], jtype),
            pitch=pitch,
            axis2=axis2,
            mimic=self.mimic(f"{where}.mimic", raw["mimic"], jtype) if "mimic" in raw else None,
            actuator=self.joint_actuator(f"{where}.actuator", raw["actuator"], JOINT_TYPES[jtype], "mimic" in raw)
            if raw.get("actuator") is not None else None,
        )

    def actuator(self, where: str, raw: Any) -> Actuator:
        if not isinstance(raw, Mapping):
            raise self.error(where, "expected a mapping {armature, gear_ratio, motor_inertia, viscous, coulomb}")
        self.check_keys(where + ".", raw, keys("actuator"))
        return Actuator(**{k: self.value(f"{where}.{k}", v) for k, v in raw.items()})

    def joint_actuator(self, where: str, raw: Any, dof: int, mimic: bool) -> Actuator | tuple[Actuator, ...]:
        """One mapping for all coordinates, or a list with one per coordinate (as limits).

        A mimic joint (1 DOF, no coordinate) has one mapping: its own drive and friction, acting on its
        own motion q_m = a q_J + b and so entering its leader's coordinate through G (G^T D G)."""
        if dof == 0:
            raise self.error(where, "only a moving joint has an actuator (this one is fixed)")
        if mimic and not isinstance(raw, Mapping):
            raise self.error(where, "a mimic joint has one actuator mapping {armature, gear_ratio, motor_inertia, "
                                    "viscous, coulomb} (its own motion)")
        if isinstance(raw, list):
            if len(raw) != dof:
                raise self.error(where, f"expected {dof} actuators (one per coordinate), got {len(raw)}")
            return tuple(self.actuator(f"{where}[{i}]", r) for i, r in enumerate(raw))
        return self.actuator(where, raw)

    def mimic(self, where: str, raw: Any, jtype: str) -> Mimic:
        if JOINT_TYPES[jtype] != 1:
            raise self.error(where, f"only a 1-DOF joint can mimic another (this one is {jtype})")
        if not isinstance(raw, Mapping):
            raise self.error(where, "expected a mapping {joint: NAME, multiplier: A, offset: B}")
        self.check_keys(where + ".", raw, keys("mimic"))
        if "joint" not in raw:
            raise self.error(f"{where}.joint", "missing")
        return Mimic(identifier(self.name, f"{where}.joint", raw["joint"]),
                     self.number(f"{where}.multiplier", raw.get("multiplier", 1.0)),
                     self.number(f"{where}.offset", raw.get("offset", 0.0)))

    def joint_limits(self, where: str, raw: Any, dof: int, jtype: str = "") -> Limits | tuple[Limits, ...]:
        """One mapping for a 1-DOF joint; for a multi-DOF joint a list (one per coordinate) or one mapping for all.

        A continuous joint takes velocity and effort only: position limits are refused rather than
        ignored, since they would silently change its joint box, IK and trajopt bounds."""
        if dof <= 1:
            limits = self.limits(where, raw)
            if jtype == "continuous":
                for key in ("lower", "upper"):
                    if getattr(limits, key) is not None:
                        raise self.error(f"{where}.{key}", "a continuous joint has no position limits (velocity and "
                                                           "effort may be given): drop it, or make the joint revolute")
            return limits
        if isinstance(raw, list):
            if len(raw) != dof:
                raise self.error(where, f"expected {dof} limits (one per coordinate), got {len(raw)}")
            return tuple(self.limits(f"{where}[{i}]", r) for i, r in enumerate(raw))
        return (self.limits(where, raw),) * dof

    def frame(self, where: str, raw: Any) -> Frame:
        self.check_keys(where + ".", raw, keys("frame"))
        for key in ("name", "link"):
            if key not in raw:
                raise self.error(f"{where}.{key}", "missing")
        aliases = raw.get("aliases") or []
        if not isinstance(aliases, list):
            raise self.error(where + ".aliases", "expected a list of names")
        return Frame(
            name=identifier(self.name, where + ".name", raw["name"]),
            link=str(raw["link"]),
            origin=Origin(self.vec3(where + ".xyz", raw.get("xyz")), self.vec3(where + ".rpy", raw.get("rpy"))),
            aliases=tuple(identifier(self.name, f"{where}.aliases[{k}]", a) for k, a in enumerate(aliases)),
        )

    # ---- robot ----
    def robot(self) -> Robot:
        spec = self.spec
        self.check_keys("", spec, keys("robot"))
        base = spec.get("base", "fixed")
        if base not in BASES:
            raise self.error("base", f"expected one of {', '.join(BASES)}, got {shown(base)!r}")
        params = spec.get("parameters") or {}
        if not isinstance(params, Mapping):
            raise self.error("parameters", "expected a mapping name: default")
        for pname, default in params.items():
            identifier(self.name, f"parameters.{pname}", pname)
            self.params[pname] = self.number(f"parameters.{pname}", default)
        if "dh" in spec:
            if "links" in spec or "joints" in spec:
                raise self.error("dh", "give either a dh table or links and joints, not both")

            links, joints = dh_to_tree(self, spec["dh"])
        else:
            for key in ("links", "joints"):
                if not isinstance(spec.get(key), list):
                    raise self.error(key, "missing or not a list")
            links = [self.link(f"links[{i}]", raw) for i, raw in enumerate(spec["links"])]
            joints = [self.joint(f"joints[{i}]", raw) for i, raw in enumerate(spec["joints"])]
        frames_raw = spec.get("frames") or []
        if not isinstance(frames_raw, list):
            raise self.error("frames", "expected a list")
        frames = [self.frame(f"frames[{i}]", raw) for i, raw in enumerate(frames_raw)]
        gravity = self.vec3("gravity", spec.get("gravity"), default=(0.0, 0.0, -9.81))
        robot = Robot(
            name=self.name,
            links=tuple(links),
            joints=tuple(self.topological(links, joints)),
            frames=tuple(frames),
            gravity=gravity,
            parameters=tuple(Parameter(k, v) for k, v in self.params.items()),
            description=str(spec.get("description", "")).strip(),
            source=str(spec.get("source", "")).strip(),
            base=base,
            wrenches=self.wrenches(spec),
            bundles=self.bundles(spec),
            coulomb_smoothing=None if spec.get("coulomb_smoothing") is None else self.number(
                "coulomb_smoothing", spec["coulomb_smoothing"]),
        )
        if robot.coulomb_smoothing is not None and robot.coulomb_smoothing <= 0:
            raise self.error("coulomb_smoothing", f"must be > 0 (rad/s or m/s), got {robot.coulomb_smoothing:g}")
        if robot.nv == 0:
            raise self.error("joints", "no moving joint: a robot needs at least one degree of freedom")
        self.check_names(robot)
        self.check_values(robot)
        robot = self.resolve_mimics(robot)
        known = robot.frame_names + tuple(robot.frame_aliases)
        for i, frame in enumerate(robot.wrench_frames):
            if frame not in known:
                raise self.error(f"wrenches[{i}]", f"unknown frame '{shown(frame)}' (links and frames: {', '.join(known)})")
        if robot.wrenches:  # an alias stands for its frame: the generated *_fext take the frame's name
            wrenches = tuple(map(robot.frame_name, robot.wrenches))
            if len(set(wrenches)) != len(wrenches):
                raise self.error("wrenches", "a frame is listed twice (by its name and an alias)")
            robot = dataclasses.replace(robot, wrenches=wrenches)
        if "generate" in spec:
            robot = dataclasses.replace(robot, generate_frames=self.generate_frames(spec["generate"], robot),
                                        generate_quantities=self.generate_quantities(spec["generate"]))
        if "all" in robot.function_frames:  # fk_<frame> would be fk_all, every link's pose
            raise self.error("generate.frames" if robot.generate_frames else "frames", "the frame name 'all' is reserved: "
                             "fk_all is the pose of every link; rename the frame or leave it out of generate.frames")
        if "loops" in spec or "independent" in spec or "reference" in spec or "outputs" in spec:
            robot = self.loops(spec, robot)
        if "contacts" in spec or "contact_sets" in spec:
            robot = self.contacts(spec, robot, known)
        for i, bundle in enumerate(robot.bundles or ()):
            for k, quantity in enumerate(bundle.quantities):
                self.check_bundle_quantity(f"bundles[{i}].quantities[{k}]", quantity, known)
                if quantity.endswith("_fext") and not robot.wrench_frames:
                    raise self.error(f"bundles[{i}].quantities[{k}]", f"'{quantity}' needs frames taking external "
                                     "wrenches: list them in wrenches: (by default the frame tcp, where there is one)")
        return robot

    # ---- contacts ----
    def contacts(self, spec: Mapping, robot: Robot, known: tuple[str, ...]) -> Robot:
        """``contacts:`` (a list of {frame, kind}) and ``contact_sets:`` (a mapping name -> list of those
        frames); an alias stands for its frame."""
        raw = spec.get("contacts")
        if not isinstance(raw, list) or not raw:
            raise self.error("contacts", "expected a non-empty list of {frame, kind}" if "contacts" in spec else
                             "missing: contact_sets name frames of contacts: list them in contacts:")
        if robot.closed:
            raise self.error("contacts", "contacts on a robot with loops are not supported (a tree only)")
        contacts: list[Contact] = []
        for i, entry in enumerate(raw):
            where = f"contacts[{i}]"
            self.check_keys(where + ".", entry, keys("contact"))
            if "frame" not in entry:
                raise self.error(where + ".frame", "missing")
            frame = entry["frame"]
            if frame not in known:
                raise self.error(where + ".frame", f"unknown frame '{shown(frame)}' (links and frames: {', '.join(known)})")
            kind = entry.get("kind", "point")
            if kind not in CONTACT_KINDS:
                raise self.error(where + ".kind", f"unknown contact kind '{shown(kind)}' (known: {', '.join(CONTACT_KINDS)})")
            frame = robot.frame_name(frame)
            if any(c.frame == frame for c in contacts):
                raise self.error(where + ".frame", f"'{frame}' is listed twice (by its name or an alias)")
            if frame == robot.root and not robot.floating:
                raise self.error(where + ".frame", f"'{frame}' is the fixed base: it cannot move, so it takes no contact")
            contacts.append(Contact(frame, kind))
        names = [c.frame for c in contacts]
        sets_raw = spec.get("contact_sets")
        sets = None
        if sets_raw is not None:
            if not isinstance(sets_raw, Mapping) or not sets_raw:
                raise self.error("contact_sets", "expected a mapping name -> list of contact frames")
            sets = []
            for name, frames in sets_raw.items():
                where = f"contact_sets.{name}"
                identifier(self.name, where, name)
                if not isinstance(frames, list) or not frames:
                    raise self.error(where, "expected a non-empty list of contact frames")
                chosen: list[str] = []
                for k, frame in enumerate(frames):
                    resolved = robot.frame_name(frame) if isinstance(frame, str) else frame
                    if resolved not in names:
                        raise self.error(f"{where}[{k}]", f"'{shown(frame)}' is not a contact (contacts: {', '.join(names)})")
                    if resolved in chosen:
                        raise self.error(f"{where}[{k}]", f"'{frame}' is listed twice (by its name or an alias)")
                    chosen.append(resolved)
                rows = sum(c.rows for c in contacts if c.frame in chosen)
                if rows > robot.nv:
                    raise self.error(where, f"{rows} constraint rows for {robot.nv} velocities: the contacts are redundant")
                sets.append(ContactSet(str(name), tuple(chosen)))
            sets = tuple(sets)
        else:
            rows = sum(c.rows for c in contacts)
            if rows > robot.nv:
                raise self.error("contacts", f"{rows} constraint rows for {robot.nv} velocities: the contacts are "
                                 "redundant together; name the stances in contact_sets")
        return dataclasses.replace(robot, contacts=tuple(contacts), contact_sets=sets)

    # ---- loop closures ----
    def loop(self, where: str, raw: Any, known: tuple[str, ...]) -> Loop:
        self.check_keys(where + ".", raw, keys("loop"))
        for key in ("frames", "kind"):
            if key not in raw:
                raise self.error(f"{where}.{key}", "missing")
        frames = raw["frames"]
        if not isinstance(frames, list) or len(frames) != 2:
            raise self.error(f"{where}.frames", f"expected two link or frame names [a, b], got {shown(frames)!r}")
        for k, name in enumerate(frames):
            if name not in known:
                raise self.error(f"{where}.frames", f"unknown frame '{shown(name)}' (links and frames: {', '.join(known)})")
        if frames[0] == frames[1]:
            raise self.error(f"{where}.frames", f"'{frames[0]}' twice: a loop joins two different frames")
        kind = raw["kind"]
        if kind not in LOOP_KINDS:
            raise self.error(f"{where}.kind", f"unknown loop kind '{shown(kind)}' (known: {', '.join(LOOP_KINDS)})")
        own = {"hinge": "axis", "planar": "normal", "distance": "length"}
        for key in ("axis", "normal", "length"):
            if key in raw and own.get(kind) != key:
                raise self.error(f"{where}.{key}", f"a {kind} loop has no '{key}'" + (
                    f" (a {kind} loop takes '{own[kind]}')" if kind in own else ""))
        if kind in own and own[kind] not in raw:
            raise self.error(f"{where}.{own[kind]}", f"missing: a {kind} loop needs '{own[kind]}'")
        if "rotation" in raw and (kind != "planar" or not isinstance(raw["rotation"], bool)):
            raise self.error(f"{where}.rotation", "only a planar loop takes 'rotation', true or false")
        axis = self.unit_vector(f"{where}.{own[kind]}", raw[own[kind]]) if kind in ("hinge", "planar") else None
        length = None
        if kind == "distance":
            length = self.value(f"{where}.length", raw["length"])
            value = float(expr.evaluate(length, self.params))
            if not value > 0:
                raise self.error(f"{where}.length", f"must be > 0 (m), got {value:g}")
        return Loop(frames[0], frames[1], kind, axis, length, bool(raw.get("rotation", False)))

    def loops(self, spec: Mapping, robot: Robot) -> Robot:
        """``loops:``, ``independent:`` and ``reference:``: the closures, checked numerically at the reference
        configuration (:func:`derive.description.closure.close`): they must close there, none may be redundant,
        and the independent coordinates must be a chart (K_z invertible)."""
        raw = spec.get("loops")
        if not isinstance(raw, list) or not raw:
            raise self.error("loops", "expected a non-empty list of {frames: [a, b], kind: ...}"
                             + ("" if "loops" in spec else " (independent, reference and outputs need loops)"))
        if robot.floating:
            raise self.error("loops", "closed chains need a fixed base here; this robot has a floating base")
        known = robot.frame_names + tuple(robot.frame_aliases)
        loops = tuple(self.loop(f"loops[{i}]", item, known) for i, item in enumerate(raw))
        names = [c.name for c in robot.coordinates]
        independent = None
        if spec.get("independent") is not None:
            ind = spec["independent"]
            if not isinstance(ind, list) or not ind:
                raise self.error("independent", "expected a non-empty list of coordinate names")
            for k, name in enumerate(ind):
                if name not in names:
                    raise self.error(f"independent[{k}]", f"unknown coordinate '{shown(name)}' (coordinates: "
                                     f"{', '.join(names)})")
            if len(set(ind)) != len(ind):
                raise self.error("independent", "a coordinate is listed twice")
            independent = tuple(ind)
        reference: dict[str, float] = {}
        if spec.get("reference") is not None:
            ref = spec["reference"]
            if not isinstance(ref, Mapping):
                raise self.error("reference", "expected a mapping {coordinate: value}")
            for name, value in ref.items():
                if name not in names:
                    raise self.error(f"reference.{shown(name)}", f"unknown coordinate (coordinates: {', '.join(names)})")
                reference[name] = self.number(f"reference.{name}", value)
        robot = dataclasses.replace(robot, loops=loops)
        closed = close(robot, independent, reference)
        n = len(names)
        mobility = n - closed.rank
        if mobility == 0:
            raise self.error("loops", f"the loops leave no degree of freedom: rank K = {closed.rank} = nq at the "
                             "reference configuration (a structure)")
        if independent is not None and len(independent) != mobility:
            raise self.error("independent", f"{len(independent)} coordinate(s) given, but the loops leave nq - rank K "
                             f"= {n} - {closed.rank} = {mobility} degree(s) of freedom")
        if closed.chart_sigma <= CHART_TOL:
            ys = ", ".join(closed.independent)
            raise self.error("independent", f"({ys}) is not a valid chart at the reference configuration: K_z is "
                             f"singular there (smallest singular value / largest = {closed.chart_sigma:.3g}); choose "
                             "other independent coordinates or another reference")
        if closed.residual > CLOSED_TOL:
            cl_rows = 0
            worst, where = -1.0, 0
            from_q = closed.q
            phi = Closure(robot).phi(np.array(from_q))
            for i, lp in enumerate(loops):
                value = float(np.max(np.abs(phi[cl_rows:cl_rows + lp.rows])))
                if value > worst:
                    worst, where = value, i
                cl_rows += lp.rows
            raise self.error(f"loops[{where}].frames", f"'{loops[where].a}' and '{loops[where].b}' do not close at the "
                             f"reference configuration: residual max |phi| = {worst:.3g} after Newton's method from "
                             "reference: (unlisted coordinates 0); check the lengths, or give reference values nearer "
                             "a closed configuration")
        if closed.flipped:
            i = closed.flipped[0]
            raise self.error(f"loops[{i}].frames", f"'{loops[i].a}' and '{loops[i].b}' close turned half a turn against "
                             "each other at the reference configuration; give reference values nearer the intended one")
        if closed.redundant is not None:
            i = closed.redundant
            raise self.error(f"loops[{i}]", f"redundant: it constrains nothing the other loops do not (rank K = "
                             f"{closed.rank} with or without it)")
        robot = dataclasses.replace(robot, independent=closed.independent, independent_chosen=closed.chosen,
                                    reference=tuple(reference.items()), loop_rows=closed.rows,
                                    reference_q=closed.q)
        if spec.get("outputs") is not None:
            robot = dataclasses.replace(robot, outputs=self.outputs(spec["outputs"], robot))
        return robot

    def outputs(self, raw: Any, robot: Robot) -> tuple[str, ...]:
        """``outputs:`` the joints the motors y drive (a parallel ankle's pitch and roll): as many coordinates
        as y, forming a chart at the reference configuration (d outputs / dy = G's output rows invertible)."""
        names = [c.name for c in robot.coordinates]
        ny = len(robot.independent)
        if not isinstance(raw, list) or not raw:
            raise self.error("outputs", "expected a non-empty list of coordinate names")
        for k, name in enumerate(raw):
            if name not in names:
                raise self.error(f"outputs[{k}]", f"unknown coordinate '{shown(name)}' (coordinates: {', '.join(names)})")
        if len(set(raw)) != len(raw):
            raise self.error("outputs", "a coordinate is listed twice")
        if len(raw) != ny:
            raise self.error("outputs", f"{len(raw)} coordinate(s) given, but the mechanism has {ny} degree(s) of "
                             f"freedom (independent: {', '.join(robot.independent)})")
        if list(raw) == list(robot.independent):
            raise self.error("outputs", "the same as independent: the motor <-> joint maps would be the identity; "
                             "leave outputs out")
        # d(outputs)/dy = G's output rows is invertible where K_w (K's columns of the coordinates w not in
        # outputs, kept rows) is: K_o od + K_w wd = 0 then gives wd, y among w, from od
        K = Closure(robot).jacobian(np.array(robot.reference_q))[list(robot.loop_rows)]
        w = [i for i, c in enumerate(names) if c not in raw]
        s = np.linalg.svd(K[:, w], compute_uv=False)
        sigma = float(s[-1] / max(np.linalg.norm(K, 2), 1e-300))
        if sigma <= CHART_TOL:
            raise self.error("outputs", f"({', '.join(raw)}) is not a valid chart at the reference configuration: "
                             f"d(outputs)/dy is singular there (K's columns of the other coordinates: smallest "
                             f"singular value / |K| = {sigma:.3g}); the motors cannot set these joints independently")
        return tuple(raw)

    def resolve_mimics(self, robot: Robot) -> Robot:
        """``robot`` with every mimic of a mimic composed into one mimic of its chain's root
        (:func:`derive.description.robot.compose_mimics`), as the URDF importer composes them; each joint
        keeps its own actuator. The root must be a 1-DOF joint with its own coordinate; a cycle is refused.
        """
        joints = {j.name: j for j in robot.joints}
        try:
            composed = compose_mimics({j.name: j.mimic for j in robot.joints if j.mimic is not None})
        except MimicCycle as exc:
            if len(exc.joints) == 1:
                raise self.error(f"joints ({exc.joints[0]}).mimic.joint", "a joint can only mimic a 1-DOF joint with "
                                 "its own coordinate, not itself") from None
            raise self.error(f"joints ({exc.joints[0]}).mimic.joint", f"{exc}: one of them must follow a joint with "
                             "its own coordinate") from None
        for name, (mimic, chain) in composed.items():
            where = f"joints ({name}).mimic.joint"
            via = f" (through {', '.join(repr(x) for x in chain[:-1])})" if len(chain) > 1 else ""
            target = joints.get(mimic.joint)
            if target is None:
                raise self.error(where, f"unknown joint '{shown(mimic.joint)}'{via}")
            if target.dof != 1:
                raise self.error(where, f"a joint can only mimic a 1-DOF joint with its own coordinate, not "
                                 f"'{target.name}', a {target.type} joint{via}")
            for key, value in (("multiplier", mimic.multiplier), ("offset", mimic.offset)):
                problem = magnitude_problem(value)
                if problem and len(chain) > 1:
                    raise self.error(f"joints ({name}).mimic.{key}", f"composed through {', '.join(chain[:-1])}: "
                                     f"{problem}")
        if not any(len(chain) > 1 for _, chain in composed.values()):
            return robot
        return dataclasses.replace(robot, joints=tuple(
            dataclasses.replace(j, mimic=composed[j.name][0]) if j.name in composed else j for j in robot.joints))

    def bundles(self, spec: Mapping) -> tuple[Bundle, ...] | None:
        raw = spec.get("bundles")
        if raw is None:
            return None
        if not isinstance(raw, list):
            raise self.error("bundles", "expected a list of {name, quantities}")
        out = []
        for i, item in enumerate(raw):
            where = f"bundles[{i}]"
            if not isinstance(item, Mapping):
                raise self.error(where, "expected a mapping with name and quantities")
            self.check_keys(where + ".", item, keys("bundle"))
            for key in ("name", "quantities"):
                if key not in item:
                    raise self.error(f"{where}.{key}", "missing")
            name = identifier(self.name, f"{where}.name", item["name"])
            quantities = item["quantities"]
            if not isinstance(quantities, list) or not quantities:
                raise self.error(f"{where}.quantities", "expected a non-empty list of quantities")
            if len(set(map(str, quantities))) != len(quantities):
                raise self.error(f"{where}.quantities", "a quantity is listed twice")
            out.append(Bundle(name, tuple(identifier(self.name, f"{where}.quantities[{k}]", q)
                                          for k, q in enumerate(quantities))))
        if len({b.name for b in out}) != len(out):
            raise self.error("bundles", "two bundles have the same name")
        return tuple(out)

    def check_bundle_quantity(self, where: str, quantity: str, frames: Iterable[str]) -> None:
        frames = tuple(frames)
        if quantity in BUNDLE_QUANTITIES or any(quantity == f"{prefix}_{frame}" for prefix in BUNDLE_FRAME_QUANTITIES
                                                for frame in frames):
            return
        raise self.error(where, f"unknown quantity '{shown(quantity)}': one of {', '.join(BUNDLE_QUANTITIES)}, or "
                                f"{', '.join(p + '_<frame>' for p in BUNDLE_FRAME_QUANTITIES)} for a link or frame "
                                f"({', '.join(frames)})")

    def generate_frames(self, raw: Any, robot: Robot) -> tuple[str, ...] | None:
        """``generate: {frames: [...]}``: the links and named frames (an alias stands for its frame)
        that get the per-frame functions, in the order given; ``frames: all``: every link and named frame
        (:attr:`Robot.frame_names`); None where ``frames`` is not given."""
        self.check_keys("generate.", raw, keys("generate"))
        frames = raw.get("frames")
        if frames is None:
            return None
        if frames == "all":
            return robot.frame_names
        if not isinstance(frames, list):
            raise self.error("generate.frames", "expected a list of link or frame names, or all")
        known = robot.frame_names + tuple(robot.frame_aliases)
        out: list[str] = []
        for i, name in enumerate(frames):
            if name not in known:
                raise self.error(f"generate.frames[{i}]", f"unknown frame '{shown(name)}' (links and frames: "
                                 f"{', '.join(known)})")
            if robot.frame_name(name) in out:
                raise self.error(f"generate.frames[{i}]", f"'{name}' is listed twice (by its name or an alias)")
            out.append(robot.frame_name(name))
        return tuple(out)

    def generate_quantities(self, raw: Mapping) -> tuple[str, ...] | None:
        """``generate: {quantities: [...]}``: the kinds of generated function kept (each of
        :data:`FUNCTION_QUANTITIES`; what they call comes along); ``quantities: all``: every one, also for a
        robot of more than :data:`~derive.description.robot.BIG_NV` velocities; None where not given."""
        quantities = raw.get("quantities")
        if quantities is None:
            return None
        if quantities == "all":
            return FUNCTION_QUANTITIES
        if not isinstance(quantities, list) or not quantities:
            raise self.error("generate.quantities", "expected a non-empty list of quantities, or all")
        for i, q in enumerate(quantities):
            if q not in FUNCTION_QUANTITIES:
                raise self.error(f"generate.quantities[{i}]", f"unknown quantity '{shown(q)}' (one of "
                                 f"{', '.join(FUNCTION_QUANTITIES)})")
        if len(set(quantities)) != len(quantities):
            raise self.error("generate.quantities", "a quantity is listed twice")
        return tuple(quantities)

    def wrenches(self, spec: Mapping) -> tuple[str, ...] | None:
        raw = spec.get("wrenches")
        if raw is None:
            return None
        if not isinstance(raw, list):
            raise self.error("wrenches", "expected a list of frame names")
        if len(set(map(str, raw))) != len(raw):
            raise self.error("wrenches", "a frame is listed twice")
        return tuple(identifier(self.name, f"wrenches[{i}]", f) for i, f in enumerate(raw))

    def topological(self, links: list[Link], joints: list[Joint]) -> list[Joint]:
        names = [link.name for link in links]
        if not names:
            raise self.error("links", "a robot needs at least one link")
        parent_of: dict[str, Joint] = {}
        for i, j in enumerate(joints):
            if j.parent not in names:
                raise self.error(f"joints[{i}].parent", f"unknown link '{j.parent}'")
            if j.child not in names:
                raise self.error(f"joints[{i}].child", f"unknown link '{j.child}'")
            if j.child == j.parent:
                raise self.error(f"joints[{i}]", f"joins link '{j.child}' to itself")
            if j.child in parent_of:
                raise self.error(
                    f"joints[{i}].child",
                    f"link '{j.child}' already has parent joint '{parent_of[j.child].name}' "
                    "(closed chains are not supported here; see 'derive dof' for mechanisms)",
                )
            parent_of[j.child] = j
        roots = [n for n in names if n not in parent_of]
        if not roots:
            raise self.error("joints", "the joints form a cycle: no link is left as the root")
        if len(roots) > 1:
            raise self.error("joints", f"links {', '.join(repr(r) for r in roots)} have no parent joint; exactly one root link is allowed")
        children: dict[str, list[Joint]] = {n: [] for n in names}
        for j in joints:
            children[j.parent].append(j)
        ordered: list[Joint] = []
        stack = list(reversed(children[roots[0]]))  # depth-first, file order among siblings (import-urdf writes URDF siblings sorted by joint name, as Pinocchio orders them)
        while stack:
            j = stack.pop()
            ordered.append(j)
            stack.extend(reversed(children[j.child]))
        if len(ordered) != len(joints):
            stuck = [j.name for j in joints if j not in ordered]
            raise self.error("joints", f"the joints {', '.join(stuck)} form a cycle detached from the root '{roots[0]}'")
        return ordered

    def check_names(self, robot: Robot) -> None:
        seen: dict[str, str] = {}
        groups = [("links", [x.name for x in robot.links]), ("joints", [x.name for x in robot.joints]),
                  ("frames", [x.name for x in robot.frames] + [a for x in robot.frames for a in x.aliases])]
        for group, names in groups:
            local: set[str] = set()
            for n in names:
                if n in local:
                    raise self.error(group, f"duplicate name '{n}'")
                local.add(n)
        for group, names in (groups[0], groups[2]):  # links, frames and aliases share fk_<name>
            for n in names:
                if n in seen:
                    raise self.error(group, f"name '{n}' is used by both {seen[n]} and {group}")
                seen[n] = group
        # q's entries name the symbols of q, qd, qdd, tau and the generated code's inputs
        owner: dict[str, str] = {p.name: "a parameter" for p in robot.parameters}
        owner.update({n: "a coordinate of the floating base" for n in robot.velocity_names[:6] + tuple(
            c.name for c in robot.base_coordinates)} if robot.floating else {})
        for j in robot.joints:
            for c in j.coordinates:
                identifier(self.name, f"joints ({j.name}) coordinate", c.name)
                if c.name in owner:
                    raise self.error(f"joints ({j.name})", f"coordinate name '{c.name}' is already {owner[c.name]}")
                owner[c.name] = f"a coordinate of joint '{c.joint}'"
        for i, f in enumerate(robot.frames):
            if f.link not in {x.name for x in robot.links}:
                raise self.error(f"frames[{i}].link", f"unknown link '{f.link}'")
        reserved = {"q", "qd", "qdd", "tau", "p", "x", "u"}
        for p in robot.parameters:
            if p.name in reserved:
                raise self.error(f"parameters.{p.name}", f"'{p.name}' is reserved for the state and input vectors")
            if p.name in expr.CONSTANTS or p.name in expr.FUNCTIONS:
                raise self.error(f"parameters.{p.name}", f"'{p.name}' is reserved in expressions (a constant or function)")
        # the symbols of the sympy view and the LaTeX: a coordinate c gives c, dc, ddc and tau_c
        symbols: dict[str, str] = {p.name: f"parameter '{p.name}'" for p in robot.parameters}
        base = {n: "root_joint" for n in robot.velocity_names[:6]} if robot.floating else {}
        joint_of = {c.name: c.joint for c in robot.coordinates} | base
        spelled = [(c.name, c.joint, c.name, "coordinate") for c in robot.base_coordinates]
        for v in robot.velocity_names:
            spelled += [(v, joint_of[v], v, "coordinate")] * (v not in base) + [(sym, joint_of[v], v, what) for sym, what in (
                (f"d{v}", "velocity"), (f"dd{v}", "acceleration"), (f"tau_{v}", "torque"))]
        for sym, joint, name, what in spelled:
            if sym in symbols and symbols[sym] != f"coordinate '{name}'":
                raise self.error(f"joints ({joint})", f"the {what} symbol '{sym}' of coordinate '{name}' is "
                                 f"already the symbol of {symbols[sym]}: rename one")
            symbols[sym] = f"coordinate '{name}'" if what == "coordinate" else f"the {what} of '{name}'"
        # frame and link names become file and function names: they must differ beyond case
        folded: dict[str, str] = {}
        for group, names in groups:
            if group == "joints":
                continue
            for n in names:
                if n.lower() in folded and folded[n.lower()] != n:
                    raise self.error(group, f"'{n}' differs from '{folded[n.lower()]}' only by case: their generated "
                                     "files would clash on case-insensitive file systems")
                folded[n.lower()] = n

    def check_values(self, robot: Robot) -> None:
        """Evaluate every expression at the parameter defaults and check physics."""
        env = robot.parameter_defaults

        def num(where: str, v: Value) -> float:
            try:
                out = float(expr.evaluate(v, env))
            except (expr.ExpressionError, ZeroDivisionError, ValueError, OverflowError) as exc:
                raise self.error(where, f"{v!r}: {exc}") from None
            if not math.isfinite(out):
                raise self.error(where, f"{v!r} evaluates to {out}")
            problem = magnitude_problem(out)
            if problem:
                raise self.error(where, f"{v!r} = {problem}" if isinstance(v, str) else problem)
            return out

        for i, link in enumerate(robot.links):
            where = f"links[{i}] ({link.name})"
            mass = num(where + ".mass", link.mass)
            if mass < 0:
                raise self.error(where + ".mass", f"must be >= 0, got {mass}")
            for k in range(3):
                num(f"{where}.com[{k}]", link.com[k])
                num(f"{where}.inertia_rpy[{k}]", link.inertia_rpy[k])
            inertia = [[num(f"{where}.inertia[{r}][{c}]", link.inertia[r][c]) for c in range(3)] for r in range(3)]
            problem = inertia_problem(inertia, mass)
            if problem:
                command = import_command(robot.source)
                if command and "--fix-inertia" not in command:  # an imported robot: the importer can repair it
                    problem += f"; re-import it with the inertia repaired: {command} --fix-inertia"
                raise self.error(where + ".inertia", problem)
        for i, j in enumerate(robot.joints):
            for k in range(3):
                num(f"joints ({j.name}).origin.xyz[{k}]", j.origin.xyz[k])
                num(f"joints ({j.name}).origin.rpy[{k}]", j.origin.rpy[k])
            acting = [(c.name, c.actuator) for c in j.coordinates] + ([(j.name, j.actuators[0])] if j.mimic else [])
            for cname, a in acting:
                where = f"joints ({j.name}).actuator" + (f" ({cname})" if cname != j.name else "")
                for key in ("armature", "motor_inertia", "viscous", "coulomb"):
                    if num(f"{where}.{key}", getattr(a, key)) < 0:
                        raise self.error(f"{where}.{key}", f"must be >= 0, got {num(where, getattr(a, key)):g}")
                if num(f"{where}.gear_ratio", a.gear_ratio) == 0:
                    raise self.error(f"{where}.gear_ratio", "must not be 0")
            if j.pitch is not None and num(f"joints ({j.name}).pitch", j.pitch) == 0:
                raise self.error(f"joints ({j.name}).pitch", "must not be 0 (a helical joint of pitch 0 is a revolute joint)")
        for k in range(3):
            num(f"gravity[{k}]", robot.gravity[k])
        for f in robot.frames:
            for k in range(3):
                num(f"frames ({f.name}).xyz[{k}]", f.origin.xyz[k])
                num(f"frames ({f.name}).rpy[{k}]", f.origin.rpy[k])


def check_values(robot: Robot) -> None:
    """The physical checks of models.yaml (masses, inertias, finite values) on a Robot, e.g. one
    whose parameter defaults were replaced; raises ModelError."""
    _Parser(robot.name, {}).check_values(robot)


def parse_robot(name: str, spec: Any) -> Robot:
    """The validated Robot of one entry of a models file (``spec``: its parsed YAML). The same entry
    parsed again in a process is the same (immutable) Robot, not derived again: a closed chain's
    assembly, solved here, is most of the parse, and tools, notebooks and tests read one models file
    many times. A refusal is raised every time."""
    try:
        key = (name, _canonical(spec))
    except RecursionError:  # nested deeper than any robot: the parser says what is wrong with it
        return _Parser(name, spec).robot()
    robot = _PARSED.get(key)
    if robot is None:
        robot = _Parser(name, spec).robot()
        if len(_PARSED) >= _PARSED_MAX:
            _PARSED.pop(next(iter(_PARSED)))
        _PARSED[key] = robot
    return robot


_PARSED: dict = {}
_PARSED_MAX = 256


def _canonical(value: Any):
    """A hashable image of parsed YAML that tells apart whatever the parser may: types (1, 1.0, True and
    "1"), the sign of a zero, and the order of a mapping's keys (a robot's parameters keep theirs)."""
    if isinstance(value, Mapping):
        return ("map", tuple((_canonical(k), _canonical(v)) for k, v in value.items()))
    if isinstance(value, (list, tuple)):
        return (type(value).__name__, tuple(_canonical(v) for v in value))
    if isinstance(value, float):
        return ("float", repr(value))
    return (type(value).__name__, value if isinstance(value, (str, int, type(None))) else repr(value))
