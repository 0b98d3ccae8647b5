"""Degrees of freedom by Grübler's formula (lecture eq. 9), for robots and closed chains.

    DOF = m (N - 1 - J) + sum_i f_i

m = 3 for planar, 6 for spatial mechanisms; N links including the ground; J
joints, where a joint joining k links counts as k - 1 joints; f_i the freedoms
of joint i (Table 1: revolute, prismatic, helical 1; cylindrical, universal 2;
spherical 3; fixed 0). The formula assumes independent constraints: it is a
lower bound when constraints are redundant (e.g. parallel four-bar linkages).

A mechanism file is YAML::

    name: example2
    space: planar                 # planar (m = 3) | spatial (m = 6)
    links: [ground, a, b, c]      # names, the first is the ground; or a count N (0 = ground)
    joints:
      - {type: revolute, links: [ground, a]}
      - {type: revolute, links: [a, b, c]}    # joins three links: counts as 2 joints

A robot of models.yaml is a tree (m = 6, N = links, J = joints) and gets
DOF = sum of its joint freedoms = nv.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping


from derive.description.files import load_yaml, read_text
from derive.description.joints import JOINT_TYPES
from derive.errors import DeriveError

JOINT_DOF = JOINT_TYPES  # the lecture's Table 1, as the model parser knows it
"""The lecture's Table 1 (plus the rigid 'fixed' joint)."""
PLANAR_JOINTS = ("revolute", "continuous", "prismatic", "fixed")
SPACES = {"planar": 3, "spatial": 6}


@dataclass(frozen=True)
class MechanismJoint:
    type: str
    links: tuple[str, ...]
    freedoms: int | None = None  # a loop closure's f (its kind names no joint type: a distance rod's 5)

    @property
    def count(self) -> int:
        """How many two-link joints this joint stands for (k links -> k - 1)."""
        return len(self.links) - 1

    @property
    def dof(self) -> int:
        return JOINT_DOF[self.type] if self.freedoms is None else self.freedoms


@dataclass(frozen=True)
class Mechanism:
    name: str
    space: str
    links: tuple[str, ...]  # links[0] is the ground
    joints: tuple[MechanismJoint, ...]
    description: str = ""

    @property
    def m(self) -> int:
        return SPACES[self.space]

    @property
    def n_links(self) -> int:
        return len(self.links)

    @property
    def n_joints(self) -> int:
        return sum(j.count for j in self.joints)

    @property
    def freedoms(self) -> int:
        return sum(j.dof * j.count for j in self.joints)

    @property
    def dof(self) -> int:
        return grubler(self.m, self.n_links, [j.dof for j in self.joints for _ in range(j.count)])

    @property
    def loops(self) -> int:
        """Independent closed loops, J - N + 1 (0 for a serial chain or tree)."""
        return self.n_joints - self.n_links + 1


def grubler(m: int, n_links: int, joint_dofs: list[int]) -> int:
    """m (N - 1 - J) + sum f_i, eq. 9, with J = len(joint_dofs) two-link joints."""
    return m * (n_links - 1 - len(joint_dofs)) + sum(joint_dofs)


# --------------------------------------------------------------------------- input


def parse_mechanism(data: Any, source: str = "<mechanism>") -> Mechanism:
    """A validated Mechanism from the YAML structure described in the module docstring."""
    def error(where: str, problem: str) -> DeriveError:
        return DeriveError(f"mechanism {source}: {where}: {problem}")

    if not isinstance(data, Mapping):
        raise error("file", "expected a mapping with space, links and joints")
    unknown = set(data) - {"name", "description", "space", "links", "joints"}
    if unknown:
        raise error(sorted(unknown)[0], "unknown field (expected name, description, space, links, joints)")
    space = data.get("space", "spatial")
    if space not in SPACES:
        raise error("space", f"'{space}' is neither planar (m = 3) nor spatial (m = 6)")
    raw_links = data.get("links")
    if isinstance(raw_links, bool) or not isinstance(raw_links, (int, list)):
        raise error("links", "expected a count N (ground included) or a list of names (ground first)")
    links = tuple(str(i) for i in range(raw_links)) if isinstance(raw_links, int) else tuple(str(x) for x in raw_links)
    if len(links) < 2:
        raise error("links", f"need the ground and at least one more link, got {len(links)}")
    if len(set(links)) != len(links):
        raise error("links", f"duplicate link name '{next(x for x in links if links.count(x) > 1)}'")
    raw_joints = data.get("joints")
    if not isinstance(raw_joints, list) or not raw_joints:
        raise error("joints", "missing or not a non-empty list")
    joints = []
    for i, raw in enumerate(raw_joints):
        where = f"joints[{i}]"
        if not isinstance(raw, Mapping) or set(raw) - {"type", "links", "name"} or "type" not in raw or "links" not in raw:
            raise error(where, "expected {type: ..., links: [a, b, ...]} (optional name)")
        jtype = raw["type"]
        if jtype not in JOINT_DOF:
            raise error(f"{where}.type", f"unknown joint type '{jtype}' (known: {', '.join(JOINT_DOF)})")
        if space == "planar" and jtype not in PLANAR_JOINTS:
            raise error(f"{where}.type", f"a {jtype} joint does not move in a plane (planar: {', '.join(PLANAR_JOINTS)})")
        jl = raw["links"]
        if not isinstance(jl, list) or len(jl) < 2:
            raise error(f"{where}.links", "a joint joins at least two links")
        jl = tuple(str(x) for x in jl)
        for x in jl:
            if x not in links:
                raise error(f"{where}.links", f"unknown link '{x}' (links: {', '.join(links)})")
        if len(set(jl)) != len(jl):
            raise error(f"{where}.links", "lists a link twice")
        joints.append(MechanismJoint(jtype, jl))
    mech = Mechanism(str(data.get("name", Path(source).stem)), space, links, tuple(joints),
                     str(data.get("description", "")).strip())
    _check_connected(mech, error)
    return mech


def _check_connected(mech: Mechanism, error) -> None:
    reached, frontier = {mech.links[0]}, [mech.links[0]]
    while frontier:
        link = frontier.pop()
        for j in mech.joints:
            if link in j.links:
                for other in j.links:
                    if other not in reached:
                        reached.add(other)
                        frontier.append(other)
    loose = [x for x in mech.links if x not in reached]
    if loose:
        raise error("links", f"link '{loose[0]}' is not connected to the ground '{mech.links[0]}' through the joints")


def read_yaml(path: Path) -> Any:
    """The YAML structure of a mechanism file; DeriveError (one line) if unreadable or malformed
    (size, text, duplicate keys, alias expansion and nesting are limited as for models files)."""
    if not path.exists():
        raise DeriveError(f"mechanism {path}: no such file")
    return load_yaml(read_text(path, "mechanism file"), f"mechanism {path}")


def load_mechanism(path: str | Path) -> Mechanism:
    path = Path(path)
    return parse_mechanism(read_yaml(path), str(path))


LOOP_JOINTS = {"point": ("spherical", None), "hinge": ("revolute", None), "weld": ("fixed", None),
               "distance": ("distance rod", 5), "planar": ("revolute", None)}
"""Loop kind -> the joint it stands for in Grübler's count (type, f): a distance rod (two ball joints and
a rod, without the rod's idle spin) removes one freedom; a planar loop with rotation is a weld."""


def mechanism_from_robot(robot) -> Mechanism:
    """A models.yaml robot as a mechanism: its links, one two-link joint per joint, and one per loop closure
    (joining the links that carry the loop's two frames). Planar (m = 3) when every loop is planar, else
    spatial (m = 6)."""
    robot.require_fixed_base("the Gruebler count")
    links = (robot.root,) + tuple(x.name for x in robot.links if x.name != robot.root)
    joints = [MechanismJoint(j.type, (j.parent, j.child)) for j in robot.joints]
    link_of = {f.name: f.link for f in robot.frames} | {a: f.link for f in robot.frames for a in f.aliases}
    for lp in robot.loops:
        jtype, freedoms = LOOP_JOINTS[lp.kind]
        if lp.kind == "planar" and lp.rotation:
            jtype = "fixed"
        joints.append(MechanismJoint(jtype, (link_of.get(lp.a, lp.a), link_of.get(lp.b, lp.b)), freedoms))
    planar = bool(robot.loops) and all(lp.kind == "planar" for lp in robot.loops)
    return Mechanism(robot.name, "planar" if planar else "spatial", links, tuple(joints), robot.description)


def closed_report(robot, mech: Mechanism) -> str:
    """Mobility from the rank of the constraint Jacobian K at the reference configuration, next to Grübler."""
    rows = sum(lp.rows for lp in robot.loops)
    r = len(robot.loop_rows)
    mobility = robot.nq - r
    lines = [f"  loops: {'; '.join(lp.summary for lp in robot.loops)}",
             f"mobility = nq - rank K = {robot.nq} - {r} = {mobility} (K: {rows} x {robot.nq} at the reference "
             "configuration)"]
    if mobility == mech.dof:
        lines.append(f"  agrees with Grübler's count ({mech.dof})")
    else:
        lines.append(f"  differs from Grübler's count ({mech.dof}) by {mobility - mech.dof}: "
                     + (f"{rows - r} of the {rows} closure rows are redundant (an over-constrained mechanism, e.g. a "
                        "planar linkage closed by spatial loops)" if mobility > mech.dof else
                        "the loops remove more freedoms than Grübler counts"))
    lines.append(f"  independent y = ({', '.join(robot.independent)}), dependent z = ({', '.join(robot.dependent)})"
                 + (" (chosen by pivoting on K)" if robot.independent_chosen else ""))
    return "\n".join(lines)


# --------------------------------------------------------------------------- report


def report(mech: Mechanism, nv: int | None = None) -> str:
    """The formula with the numbers put in, one joint type per line."""
    counts = Counter()
    for j in mech.joints:
        counts[j.type] += j.count
    multi = sum(1 for j in mech.joints if j.count > 1)
    lines = [f"{mech.name}: {mech.space} (m = {mech.m}), N = {mech.n_links} links (ground '{mech.links[0]}' included), "
             f"J = {mech.n_joints} joints" + (f" ({multi} joining more than two links, counted k - 1 times)" if multi else "")]
    for jtype in JOINT_DOF:
        if counts[jtype]:
            lines.append(f"  {jtype:<12} x{counts[jtype]:<3} f = {JOINT_DOF[jtype]}")
    lines.append(f"DOF = m (N - 1 - J) + sum f_i = {mech.m} ({mech.n_links} - 1 - {mech.n_joints}) + {mech.freedoms} = {mech.dof}")
    if mech.loops:
        lines.append(f"  {mech.loops} independent closed loop(s); the count assumes independent loop constraints")
    if nv is not None and not mech.loops:  # a tree has N - 1 = J: the formula reduces to the sum of the freedoms
        lines.append(f"  tree (no loops): DOF = sum of joint freedoms = {mech.freedoms}; the model's nv = {nv}")
    if mech.dof <= 0:
        lines.append("  DOF <= 0: a structure (statically " + ("determinate" if mech.dof == 0 else "indeterminate") + "), "
                     "unless some constraints are redundant")
    return "\n".join(lines)
