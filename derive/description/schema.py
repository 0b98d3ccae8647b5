"""The fields of models.yaml: one table per mapping, the keys the parser accepts and what each means.

The parser (:mod:`derive.description.model`, :mod:`derive.description.dh`) checks every mapping's
keys against :data:`SECTIONS` and nothing else, and the documentation's schema page is rendered
from the same table, so the two cannot drift apart. A new field is one entry here plus its
parsing. Conventions are URDF's (see :mod:`derive.description.robot`): ``origin`` places a frame
by ``Trans(xyz) Rz(yaw) Ry(pitch) Rx(roll)``, inertias are about the centre of mass.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Section:
    """One mapping of models.yaml: where it appears, what it is, and its keys (key -> meaning)."""

    name: str
    where: str
    doc: str
    fields: dict[str, str]

    @property
    def keys(self) -> frozenset[str]:
        return frozenset(self.fields)


_SECTIONS = (
    Section("file", "the top level of the file", "A models file holds one mapping.", {
        "robots": "mapping robot name -> robot (C and Python identifier, at most 64 characters)",
    }),
    Section("robot", "robots.<name>", "One robot: a kinematic tree of links and joints (or a DH table).", {
        "description": "free text, shown by `derive info`",
        "source": "where the numbers come from (for an imported robot: the command that reproduces it)",
        "parameters": "mapping symbol -> default number; generated code takes their values as the input `p`",
        "gravity": "gravity vector in the root (world) frame; default [0, 0, -9.81]",
        "links": "list of links (see link); the root link, no joint's child, is the world",
        "joints": "list of joints (see joint)",
        "dh": "a Denavit-Hartenberg table instead of links and joints (see dh)",
        "frames": "list of named frames fixed to links (see frame)",
        "base": "`fixed` (default) or `floating`: a free flyer places the root link in the world",
        "wrenches": "frames taking external wrenches in the `_fext` functions (default: tcp, where there is one)",
        "coulomb_smoothing": "eps of the smooth Coulomb friction coulomb tanh(qd / eps) in forward dynamics "
                             "(rad/s or m/s; default 0.01)",
        "bundles": "control-tick functions (see bundle; default: control and computed_torque)",
        "generate": "which functions to generate (see generate; default: all)",
        "loops": "closures of a closed kinematic chain: two frames that must coincide (see loop)",
        "independent": "with loops: the independent coordinates y (default: chosen by pivoting on the "
                       "constraint Jacobian, actuated joints first; `derive info` states the choice)",
        "reference": "with loops: mapping coordinate -> value, the start of the closure solve that fixes the "
                     "assembly (coordinates not listed start at 0)",
        "outputs": "with loops: the joints the independent coordinates (the motors) drive, as many as they, "
                   "e.g. a parallel ankle's [pitch, roll]: motor <-> joint maps for position, velocity and "
                   "torque are generated",
        "contacts": "links or frames that may touch the ground (see contact): each contact set gets the contact and "
                    "impulse dynamics, the robot the centroidal terms (see the contacts guide)",
        "contact_sets": "mapping stance name -> list of contact frames active together (default: one set `all` of "
                        "every contact); one generated function per set",
    }),
    Section("link", "robots.<name>.links[i]", "A rigid body. Mass properties are about the centre of mass.", {
        "name": "C identifier, unique among links and frames (beyond letter case)",
        "mass": "kg, >= 0; number, parameter or expression such as \"m1/2\" (default 0)",
        "com": "centre of mass [x, y, z] in the link frame (default [0, 0, 0])",
        "inertia": "inertia about the COM: diagonal [ixx, iyy, izz], a symmetric 3x3 list, or "
                   "{ixx, ixy, ixz, iyy, iyz, izz}; positive semi-definite, triangle inequality",
        "inertia_rpy": "orientation [roll, pitch, yaw] of the inertial frame in the link frame (default 0)",
        "visual": "list of the link's looks (see visual): meshes and shapes `derive view` draws; no part of the "
                  "dynamics or the generated code",
    }),
    Section("visual", "links[i].visual[k]", "One mesh or primitive shape fixed to the link, for `derive view` only "
            "(import-urdf and import-mjcf write them). Exactly one of mesh, box, cylinder, sphere, capsule.", {
                "mesh": "a mesh file (STL, OBJ or DAE; the `viewer` extra reads it): relative to the models file's "
                        "folder, absolute, or example-robot-data:<path under robots/>",
                "box": "edge lengths [x, y, z] (m), centred on the visual's origin",
                "cylinder": "[radius, length] (m), along the visual's z, centred",
                "sphere": "radius (m)",
                "capsule": "[radius, length] (m): a cylinder of that length along z with hemispherical ends",
                "xyz": "position of the visual's origin in the link frame (m; default 0)",
                "rpy": "its orientation [roll, pitch, yaw] in the link frame (rad; default 0)",
                "scale": "[sx, sy, sz] along the visual's axes (default [1, 1, 1]; a mesh in mm: 0.001)",
                "color": "[r, g, b] or [r, g, b, a], each 0..1 (default: the mesh's own colour, else grey)",
            }),
    Section("joint", "robots.<name>.joints[i]", "Joins a parent link to a child link.", {
        "name": "C identifier; a 1-DOF joint's coordinate (q's entry) takes this name",
        "type": "revolute, continuous, prismatic, helical, cylindrical, universal, spherical or fixed",
        "parent": "the parent link's name",
        "child": "the child link's name (each link has at most one parent joint)",
        "origin": "the joint frame in the parent link frame (see origin)",
        "axis": "unit axis in the joint frame (normalised; default [1, 0, 0] as URDF); not for spherical",
        "axis2": "universal joints only: the second axis, perpendicular to axis",
        "pitch": "helical joints only: m/rad, != 0 (< 0 left-handed)",
        "limits": "position/velocity/effort limits (see limits); a multi-DOF joint takes one mapping for "
                  "all coordinates or a list, one per coordinate",
        "mimic": "this 1-DOF joint follows another: q_m = multiplier q_J + offset (see mimic)",
        "actuator": "rotor inertia and friction per coordinate (see actuator); one mapping or a list",
    }),
    Section("origin", "joints[i].origin", "A pose: Trans(xyz) Rz(yaw) Ry(pitch) Rx(roll), as URDF.", {
        "xyz": "translation [x, y, z] (m; default 0)",
        "rpy": "roll, pitch, yaw (rad; default 0)",
    }),
    Section("inertia", "links[i].inertia (mapping form)", "The entries of the inertia tensor; missing ones are 0.", {
        "ixx": "kg m^2", "iyy": "kg m^2", "izz": "kg m^2", "ixy": "kg m^2", "ixz": "kg m^2", "iyz": "kg m^2",
    }),
    Section("limits", "joints[i].limits, dh.rows[i].limits", "Optional; a continuous joint takes velocity and effort "
            "only.", {
                "lower": "lowest position (rad or m); <= upper",
                "upper": "highest position (rad or m)",
                "velocity": "largest |qd| (> 0)",
                "effort": "largest |tau| (> 0)",
            }),
    Section("mimic", "joints[i].mimic", "A 1-DOF joint without its own coordinate; a mimic of a mimic is composed "
            "into one mimic of the chain's root.", {
                "joint": "the leader joint (1-DOF)",
                "multiplier": "a in q_m = a q_J + b (default 1)",
                "offset": "b in q_m = a q_J + b (default 0)",
            }),
    Section("actuator", "joints[i].actuator", "All zero by default (an ideal joint). Values may be parameter "
            "expressions.", {
                "armature": "rotor inertia added to M's diagonal (kg m^2), >= 0",
                "gear_ratio": "N in armature + N^2 motor_inertia (default 1), != 0",
                "motor_inertia": "the motor's rotor inertia (kg m^2), >= 0",
                "viscous": "viscous friction f_v qd, >= 0",
                "coulomb": "Coulomb friction f_c sign(qd) (smoothed by tanh in forward dynamics), >= 0",
            }),
    Section("frame", "robots.<name>.frames[i]", "A named frame fixed to a link (a TCP, a camera, a foot).", {
        "name": "C identifier (tcp is the IK frame); gets fk_/jacobian_/... functions",
        "link": "the link it is fixed to",
        "xyz": "position in the link frame (default 0)",
        "rpy": "orientation in the link frame (default 0)",
        "aliases": "other names of this frame, usable wherever a frame is asked for",
    }),
    Section("bundle", "robots.<name>.bundles[i]", "A control tick: several quantities in one pass.", {
        "name": "C identifier: the function is bundle_<name>",
        "quantities": "mass_matrix, bias, gravity, ... and fk_F, jacobian_F, jdot_qd_F, frame_acceleration_F",
    }),
    Section("loop", "robots.<name>.loops[i]", "A loop closure: the two frames coincide in the way its kind says "
            "(see the closed-chains guide).", {
                "frames": "[a, b]: two link or frame names",
                "kind": "point (3 rows), hinge (5, with axis), weld (6), planar (2, with normal; 3 with rotation: true) "
                        "or distance (1, with length)",
                "axis": "hinge: the hinge axis, in frame a's axes",
                "normal": "planar: the plane's normal, in frame a's axes",
                "length": "distance: the rod's length (m)",
                "rotation": "planar: true also closes the rotation within the plane (default false)",
            }),
    Section("contact", "robots.<name>.contacts[i]", "A contact: the frame is held by the environment while in "
            "contact (Pinocchio's rigid contact models, LOCAL_WORLD_ALIGNED).", {
                "frame": "a link or named frame (its origin is the contact point)",
                "kind": "`point` (default; 3 rows: the origin does not accelerate, force [fx, fy, fz]) or `surface` "
                        "(6 rows: the frame does not move, wrench [force; torque]), world-aligned at the origin",
            }),
    Section("generate", "robots.<name>.generate", "Optional; without it every function is generated.", {
        "frames": "links and frames that get the per-frame functions, or `all` (default: the named frames; "
                  "a big robot, more than 8 named frames or nv above 30: the tcp, the wrench frames and the leaves)",
        "quantities": "only these kinds of function (and the functions they call), or `all` (default: all; above "
                      "nv 30 the O(nv^3) ones are left out: see the large-robots guide)",
    }),
    Section("parameter", "any numeric field, as a mapping", "An inline parameter: declares the symbol and its "
            "default where it is used.", {
                "param": "the parameter's name (a C identifier)",
                "default": "its default value (a number)",
            }),
    Section("dh", "robots.<name>.dh", "A serial chain as a DH table. Standard: T_i = Rz(theta_i) Tz(d_i) Tx(a_i) "
            "Rx(alpha_i); modified: T_i = Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(theta_i) Tz(d_i).", {
                "convention": "standard or modified",
                "base": "the root link's name (default base)",
                "rows": "list of rows (see dh_row), one per joint",
            }),
    Section("dh_row", "robots.<name>.dh.rows[i]", "One joint of a DH table; the mass properties are in DH frame i.", {
        "joint": "the joint's (and coordinate's) name",
        "type": "revolute, continuous or prismatic (q adds to theta or to d)",
        "a": "link length (m)",
        "alpha": "link twist (rad)",
        "d": "link offset (m)",
        "theta": "joint angle offset (rad)",
        "link": "the name of DH frame i's link",
        "mass": "as link.mass",
        "com": "as link.com, in DH frame i",
        "inertia": "as link.inertia, in DH frame i",
        "inertia_rpy": "as link.inertia_rpy",
        "limits": "as joint.limits",
    }),
)

SECTIONS: dict[str, Section] = {s.name: s for s in _SECTIONS}
"""Section name -> the keys the parser accepts in that mapping of models.yaml, with their meaning."""


def keys(section: str) -> frozenset[str]:
    """The keys the parser accepts in ``section`` (a name of :data:`SECTIONS`)."""
    return SECTIONS[section].keys
