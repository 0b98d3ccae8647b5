"""Closed-form loop closures z = gamma(y): planar dyads (circle-circle, circle-line) and the Delta's
sphere intersection.

A planar loop (2 rows: the two frames' origins coincide in the plane normal to n) is a revolute joint
C about n. Where the loop's cycle holds exactly two coordinates not yet known, the cycle is a dyad:

- two revolute joints j1, j2 about +-n (RR): with C they are three pins; the segment of the cycle that
  holds the root is known, so the two pins at its ends are known points c0, c2, and the third pin X
  lies at the rigid in-plane distances r0, r2 from them:
      X = c0 + a e + sigma h (n x e),   e = (c2 - c0) / d,   a = (r0^2 - r2^2 + d^2) / (2 d),
      h = sqrt(r0^2 - a^2),   d = |c2 - c0|                                    (circle-circle);
- a revolute joint R and a prismatic joint P on the two sides of C (RP, the slider-crank): C lies at
  the rigid distance r from R's pin c and on P's line L0 + s a:
      |a|^2 s^2 + 2 a.(L0 - c) s + |L0 - c|^2 - r^2 = 0,   s = (-B + sigma sqrt(B^2 - A C)) / A
                                                                               (circle-line).

sigma (+-1, the assembly branch) is the one of the reference configuration. A revolute joint's angle
then turns its zero-angle direction onto the solved pin:
      q_j = c_j + s_j atan2(w0' x w, w0' . w),   w0' = w0 turned by s_j c_j about n,
with w0 the in-plane vector from j's pin to the next pin of the cycle at q_j = 0, w the solved one,
s_j = +-1 the joint axis against n and c_j the reference angle rounded to 1e-3 rad, so q_j stays
within (c_j - pi, c_j + pi] (continuous through the motion, no 2 pi jump at +-pi).

Loops are solved in turn, each as soon as its cycle has two unknowns left. A mechanism where that
fails (a loop that is not planar, a joint off the plane, three unknowns in every remaining loop)
has no closed form here: :func:`closed_form_closure` returns None and the Newton solve is used.

Three `distance` loops (rods of lengths L_i with ball joints) whose one ends hang on the same body,
carried by exactly the three unknown coordinates, all prismatic (the Delta's travelling plate on an
x-y-z translation chain), while the other ends E_i hang on known coordinates only: the plate's
translation P = A z (A the prismatic axes in world, constant: nothing turns them) puts end i at
B_i + P, so P lies on the three spheres |P - c_i| = L_i, c_i = E_i - B_i (trilateration):
      e_x = (c_2 - c_1)/|c_2 - c_1|,  i = e_x.(c_3 - c_1),  e_y = (c_3 - c_1 - i e_x)/|...|,
      e_z = e_x x e_y,  j = e_y.(c_3 - c_1),  d = |c_2 - c_1|,
      x = (L_1^2 - L_2^2 + d^2)/(2 d),  y = (L_1^2 - L_3^2 + i^2 + j^2 - 2 i x)/(2 j),
      P = c_1 + x e_x + y e_y + sigma sqrt(L_1^2 - x^2 - y^2) e_z,   z = A^-1 P,
with sigma the reference's branch (the Delta's plate below the base). The square root is the
assembly condition; the chart is lost where the three rods lie in one plane (K_z singular).
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from derive.description.robot import Robot, loop_basis
from derive.symbolic.model import SXModel

AGREE_TOL = 1e-9
"""gamma(y_ref) must give the reference configuration to this, else the closed form is not used."""


def _num(f: ca.Function, *args) -> np.ndarray:
    return np.array(f(*args), dtype=float)


def closed_form_closure(model: SXModel, y: ca.SX, given: tuple[str, ...] | None = None,
                        centred: bool = True) -> tuple[ca.SX, str] | None:
    """(q = gamma(y) as an SX expression of y and p, a one-line description) or None (no closed form).
    ``given``: the coordinates y holds (default the robot's independent ones; the motor <-> joint maps
    solve the other way, from the outputs). ``centred`` False: a planar dyad's angles within (-pi, pi]
    (atan2 alone, no turn about the reference angle: the shorter form ``derive latex`` prints)."""
    robot: Robot = model.robot
    given = robot.independent if given is None else given
    if robot.floating or not robot.loops or any(j.mimic is not None for j in robot.joints):
        return None
    s, kin = model.sym, model.kinematics
    names = list(s.joint_names)
    q_ref = np.array(robot.reference_q, dtype=float)
    p_def = np.array([p.default for p in robot.parameters], dtype=float)
    y_ref = q_ref[[names.index(c) for c in given]]

    def at_ref(e: ca.SX, known: dict | None = None) -> np.ndarray:
        """e (in q, y and p) at the reference configuration."""
        return _num(ca.Function("f", [s.q, y, s.p], [e]), q_ref, y_ref, p_def)

    known = {c: y[i] for i, c in enumerate(given)}  # coordinate -> expression in y, p
    if all(lp.kind == "distance" for lp in robot.loops):
        out = _sphere_closure(model, known, at_ref, q_ref)
        if out is None:
            return None
        q = ca.vertcat(*[out[c] if c in out else known[c] for c in names])
        got = _num(ca.Function("g", [y, s.p], [q]), y_ref, p_def).ravel()
        if not np.all(np.abs(got - q_ref) <= AGREE_TOL):
            return None
        return q, "closed form: sphere intersection"
    rows, start, kinds = set(robot.loop_rows), 0, []
    loops = []
    for lp in robot.loops:
        span = range(start, start + lp.rows)
        start += lp.rows
        if lp.kind != "planar" or lp.rotation or not set(span) <= rows:
            return None
        n = at_ref(kin.pose(lp.a).R @ ca.DM(list(lp.axis))).ravel()
        n = n / np.linalg.norm(n)
        loops.append((lp, n))
    for lp, n in loops:
        for key in set(kin.ancestors[lp.a]) | set(kin.ancestors[lp.b]):
            m = kin.motions[key]
            axis = at_ref(kin.joint_axis[key]).ravel()
            if m.kind == "revolute" and abs(abs(axis @ n) - 1) > 1e-12:
                return None
            if m.kind == "prismatic" and abs(axis @ n) > 1e-12:
                return None
            if m.kind not in ("revolute", "prismatic"):
                return None
    pending = list(loops)
    while pending:
        for entry in pending:
            out = _solve_loop(model, entry, known, at_ref, q_ref, centred)
            if out is not None:
                break
        else:
            return None
        kind, solved = out
        known.update(solved)
        kinds.append(kind)
        pending.remove(entry)
    q = ca.vertcat(*[known[c] for c in names])
    got = _num(ca.Function("g", [y, s.p], [q]), y_ref, p_def).ravel()
    if not np.all(np.abs(got - q_ref) <= AGREE_TOL):
        return None
    return q, "closed form: " + ", ".join(kinds)


def _solve_loop(model: SXModel, entry, known: dict, at_ref, q_ref, centred: bool = True) -> tuple[str, dict] | None:
    """One planar loop whose cycle has exactly two unknown coordinates: (its kind, {coordinate: expression})."""
    s, kin = model.sym, model.kinematics
    names = list(s.joint_names)
    lp, n = entry
    u, v = (ca.DM(list(x)) for x in loop_basis(n))
    anc_a, anc_b = kin.ancestors[lp.a], kin.ancestors[lp.b]
    c = 0
    while c < min(len(anc_a), len(anc_b)) and anc_a[c] == anc_b[c]:
        c += 1
    if any(k not in known for k in anc_a[:c]):
        return None
    side_a = [k for k in anc_a[c:] if k not in known]
    side_b = [k for k in anc_b[c:] if k not in known]
    if len(side_a) + len(side_b) != 2:
        return None
    unknown = side_a + side_b
    solved: dict = {}

    def sub(e: ca.SX, zero: bool = True) -> ca.SX:
        """e with the known coordinates put in and the loop's unknowns not yet solved at 0 (their own
        motion leaves the distances and zero-angle directions used here unchanged)."""
        pairs = [(s.q[names.index(k)], x) for k, x in {**known, **solved}.items()]
        pairs += [(s.q[names.index(k)], ca.SX(0)) for k in unknown if k not in solved] if zero else []
        return ca.substitute([e], [ca.vertcat(*[a for a, _ in pairs])], [ca.vertcat(*[b for _, b in pairs])])[0]

    def plane(p: ca.SX) -> ca.SX:
        return ca.vertcat(ca.dot(u, p), ca.dot(v, p))

    def pin(vertex: str, side: str) -> ca.SX:
        """The in-plane position of a pin: a joint's origin, or C reached from side a or b."""
        if vertex == "C":
            return plane(kin.pose(lp.a if side == "a" else lp.b).p)
        return plane(kin.joint_origin[vertex])

    def side(vertex: str) -> str:
        return "b" if vertex in side_b else "a"

    kinds = [kin.motions[k].kind for k in unknown]
    cycle = side_a + ["C"] + side_b[::-1]  # the pins in cycle order
    ref = lambda e: at_ref(e, known).ravel()  # noqa: E731
    seg = lambda p_, q_: "b" if p_ in side_b or q_ in side_b else "a"  # noqa: E731  # the side a segment lies on
    if kinds == ["revolute", "revolute"]:
        v0, v1, v2 = cycle
        c0, c2 = sub(pin(v0, "a")), sub(pin(v2, "b"))
        r0 = ca.norm_2(sub(pin(v1, seg(v0, v1)) - pin(v0, seg(v0, v1))))
        r2 = ca.norm_2(sub(pin(v2, seg(v1, v2)) - pin(v1, seg(v1, v2))))
        dvec = c2 - c0
        d = ca.norm_2(dvec)
        e = dvec / d
        ep = ca.vertcat(-e[1], e[0])  # n x e in the plane
        a = (r0 * r0 - r2 * r2 + d * d) / (2 * d)
        h = ca.sqrt(r0 * r0 - a * a)
        sigma = 1.0 if float((ref(pin(v1, seg(v0, v1))) - ref(c0)) @ ref(ep)) >= 0 else -1.0
        position = {v0: c0, v1: c0 + a * e + sigma * h * ep, v2: c2}
        kind = "circle-circle"
    elif sorted(kinds) == ["prismatic", "revolute"] and side_a and side_b:
        r_key = unknown[kinds.index("revolute")]
        p_key = unknown[kinds.index("prismatic")]
        r_side, p_side = side(r_key), side(p_key)
        cpin = sub(pin(r_key, r_side))
        r = ca.norm_2(sub(pin("C", r_side) - pin(r_key, r_side)))
        line0 = sub(pin("C", p_side))  # C on P's side at s = 0
        adir = sub(plane(kin.joint_axis[p_key]))
        w = line0 - cpin
        A, B, Cc = ca.dot(adir, adir), ca.dot(adir, w), ca.dot(w, w) - r * r
        # the branch: A s + B = sigma sqrt(B^2 - A C), sigma as at the reference
        sigma = 1.0 if float(ref(A)[0] * q_ref[names.index(p_key)] + ref(B)[0]) >= 0 else -1.0
        svalue = (-B + sigma * ca.sqrt(B * B - A * Cc)) / A
        solved[p_key] = svalue
        position = {r_key: cpin, "C": line0 + svalue * adir}
        kind = "circle-line"
    else:
        return None
    # the revolute joints' angles, ancestors first on each side
    for k in side_a + side_b:
        if kin.motions[k].kind != "revolute":
            continue
        order = cycle.index(k)
        target = cycle[order + 1] if k in side_a else cycle[order - 1]
        here = side(k)
        w0 = sub(pin(target, here) - pin(k, here))  # at q_k = 0 (and later unknowns at 0)
        wt = position[target] - position[k]
        sgn = 1.0 if float(ref(kin.joint_axis[k]) @ n) > 0 else -1.0
        centre = round(float(q_ref[names.index(k)]), 3) if centred else 0.0
        cs, sn = math.cos(sgn * centre), math.sin(sgn * centre)
        w0r = ca.vertcat(cs * w0[0] - sn * w0[1], sn * w0[0] + cs * w0[1]) if centred else w0
        solved[k] = centre + sgn * ca.atan2(w0r[0] * wt[1] - w0r[1] * wt[0], ca.dot(w0r, wt))
    return kind, solved


def _sphere_closure(model: SXModel, known: dict, at_ref, q_ref) -> dict | None:
    """Three distance loops closing a body carried by the three unknown prismatic coordinates:
    {coordinate: expression} by trilateration (module docstring), or None."""
    robot: Robot = model.robot
    s, kin = model.sym, model.kinematics
    names = list(s.joint_names)
    unknown = [c for c in names if c not in known]
    if len(robot.loops) != 3 or len(unknown) != 3:
        return None
    if any(kin.motions[k].kind != "prismatic" for k in unknown):
        return None
    ends = []  # (known end, moving end) per loop
    for lp in robot.loops:
        anc_a, anc_b = set(kin.ancestors[lp.a]), set(kin.ancestors[lp.b])
        if anc_a <= set(known) and anc_b == set(unknown):
            ends.append((lp.a, lp.b))
        elif anc_b <= set(known) and anc_a == set(unknown):
            ends.append((lp.b, lp.a))
        else:
            return None
    zero = ca.vertcat(*[s.q[names.index(k)] for k in unknown])
    pairs_a = ca.vertcat(*[s.q[names.index(k)] for k in known])
    pairs_b = ca.vertcat(*[x for x in known.values()])

    def sub(e: ca.SX) -> ca.SX:
        """e with the known coordinates as expressions of y and the unknown ones at 0."""
        e = ca.substitute([e], [pairs_a], [pairs_b])[0]
        return ca.substitute([e], [zero], [ca.SX.zeros(3)])[0]

    A = ca.horzcat(*[sub(kin.joint_axis[k]) for k in unknown])  # P = A z
    if ca.depends_on(A, ca.vertcat(s.q, s.p, *known.values())):
        return None  # axes turned by a coordinate or set by a parameter: not a pure translation here
    A_num = at_ref(A).reshape(3, 3)
    if abs(np.linalg.det(A_num)) < 1e-9:
        return None
    c = [sub(kin.pose(e).p) - sub(kin.pose(m).p) for e, m in ends]
    L = [s.value(lp.length) for lp in robot.loops]
    d21, d31 = c[1] - c[0], c[2] - c[0]
    d = ca.norm_2(d21)
    ex = d21 / d
    i = ca.dot(ex, d31)
    ey_raw = d31 - i * ex
    ey = ey_raw / ca.norm_2(ey_raw)
    ez = ca.cross(ex, ey)
    j = ca.dot(ey, d31)
    x = (L[0] ** 2 - L[1] ** 2 + d * d) / (2 * d)
    yy = (L[0] ** 2 - L[2] ** 2 + i * i + j * j - 2 * i * x) / (2 * j)
    h = ca.sqrt(L[0] ** 2 - x * x - yy * yy)
    base = c[0] + x * ex + yy * ey
    P_ref = A_num @ q_ref[[names.index(k) for k in unknown]]
    sigma = 1.0 if float((P_ref - at_ref(base).ravel()) @ at_ref(ez).ravel()) >= 0 else -1.0
    z = ca.DM(np.linalg.inv(A_num)) @ (base + sigma * h * ez)  # constant A: no symbolic solve
    return {k: z[n] for n, k in enumerate(unknown)}
