"""Denavit-Hartenberg tables -> links and joints of a kinematic tree.

Standard DH (Spong; the lecture's eq. 25), row i between frames i-1 and i:
    T_i = Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i)
Modified DH (Craig), row i:
    T_i = Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(theta_i) Tz(d_i)
For a revolute row, q_i adds to theta_i; for a prismatic row, q_i adds to d_i; a continuous
row is a revolute one without position limits (a continuous joint).

Each row becomes a moving joint plus, where one URDF origin cannot hold the
constant part, a massless helper link ``<link>_dh`` and a fixed joint. The row's
``link`` is the DH frame i and carries the row's mass properties, which are
therefore given in DH frame i.
"""

from __future__ import annotations

from typing import Any

from derive.description.schema import keys
from derive.description.robot import Joint, Limits, Link, Origin, identifier

Z = (0.0, 0.0, 1.0)


def dh_to_tree(p: Any, raw: Any) -> tuple[list[Link], list[Joint]]:
    """Convert a ``dh:`` block (parsed by the model parser ``p``) to links and joints."""
    p.check_keys("dh.", raw, keys("dh"))
    convention = raw.get("convention")
    if convention not in ("standard", "modified"):
        raise p.error("dh.convention", f"must be 'standard' or 'modified', got {convention!r}")
    rows = raw.get("rows")
    if not isinstance(rows, list) or not rows:
        raise p.error("dh.rows", "missing or empty")
    base = identifier(p.name, "dh.base", raw.get("base", "base"))
    links = [Link(name=base)]
    joints: list[Joint] = []
    parent = base
    for i, row in enumerate(rows):
        where = f"dh.rows[{i}]"
        p.check_keys(where + ".", row, keys("dh_row"))
        for key in ("joint", "type", "link"):
            if key not in row:
                raise p.error(f"{where}.{key}", "missing")
        jtype = row["type"]
        if not isinstance(jtype, str) or jtype not in ("revolute", "continuous", "prismatic"):
            raise p.error(f"{where}.type", f"a DH row is 'revolute', 'continuous' or 'prismatic', got {jtype!r}")
        a, alpha, d, theta = (p.value(f"{where}.{k}", row.get(k, 0.0)) for k in ("a", "alpha", "d", "theta"))
        link = p.link(where, {k: row[k] for k in ("mass", "com", "inertia", "inertia_rpy") if k in row} | {"name": row["link"]})
        helper = Link(name=f"{link.name}_dh")
        limits = p.joint_limits(where + ".limits", row.get("limits"), 1, jtype)
        jname = identifier(p.name, f"{where}.joint", row["joint"])

        def joint(name: str, kind: str, par: str, child: str, xyz=(0.0, 0.0, 0.0), rpy=(0.0, 0.0, 0.0),
                  lim: Limits = Limits()) -> Joint:
            return Joint(name=name, type=kind, parent=par, child=child, origin=Origin(tuple(xyz), tuple(rpy)), axis=Z, limits=lim)

        if convention == "standard":
            # Rz(theta) Tz(d) motion first, then the constant Tz(d) Tx(a) Rx(alpha) to DH frame i.
            if jtype != "prismatic":
                joints.append(joint(jname, jtype, parent, helper.name, rpy=(0.0, 0.0, theta), lim=limits))
                joints.append(joint(f"{jname}_dh", "fixed", helper.name, link.name, xyz=(a, 0.0, d), rpy=(alpha, 0.0, 0.0)))
            else:
                joints.append(joint(jname, "prismatic", parent, helper.name, xyz=(0.0, 0.0, d), rpy=(0.0, 0.0, theta), lim=limits))
                joints.append(joint(f"{jname}_dh", "fixed", helper.name, link.name, xyz=(a, 0.0, 0.0), rpy=(alpha, 0.0, 0.0)))
        else:
            # Constant Rx(alpha) Tx(a) first (one URDF origin), then Rz(theta) Tz(d).
            joints.append(joint(f"{jname}_dh", "fixed", parent, helper.name, xyz=(a, 0.0, 0.0), rpy=(alpha, 0.0, 0.0)))
            if jtype != "prismatic":
                joints.append(joint(jname, jtype, helper.name, link.name, xyz=(0.0, 0.0, d), rpy=(0.0, 0.0, theta), lim=limits))
            else:
                joints.append(joint(jname, "prismatic", helper.name, link.name, xyz=(0.0, 0.0, d), rpy=(0.0, 0.0, theta), lim=limits))
        links += [helper, link]
        parent = link.name
    return links, joints
