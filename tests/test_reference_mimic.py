"""Mimic joints in the numeric reference (derive.reference), fixed and floating base.

The robot: a tree off a revolute hub with five mimic joints, each following an ordinary joint
(q_m = a q_J + b), every one with a non-zero offset:

- ``jm_a`` (revolute) follows the hub, its ANCESTOR (a = -0.7), so one coordinate moves two bodies of
  one chain and M gets a body pair on its diagonal;
- ``jb1`` (prismatic) follows the prismatic ``ja1`` on another branch (a = -2);
- ``jb2`` (revolute) follows the revolute ``ja2`` (a = 0.5), with an ordinary joint ``jb3`` below it
  (a moving child of a mimic joint) and a fixed link and a named frame below that;
- ``jc1`` (helical, pitch h) follows ``ja2`` as well (a = 1.3): two mimics of one joint;
- ``jc2`` (prismatic) follows the revolute hub (a = 0.05).

Against Pinocchio (tests/pin_model.py: ``transformJointIntoMimic``, the mimic joints having no entries
of q and v), at seeded states, to 1e-9 relative: frame poses, Jacobians, classical accelerations and
Jdot v of every frame, M, g, rnea, rnea with wrenches, forward dynamics (Pinocchio's ABA refuses mimic
joints: there M^-1 (tau - rnea(q, v, 0)), as the reference does), COM, COM Jacobian, centroidal map.
Pinocchio 4.1 gets helical mimic joints wrong (a segmentation fault, or the pitch left out of its
Jacobian and rnea), so there ``jc1`` is a revolute mimic joint (same axis, multiplier, offset); the
helical one is checked by the reduction and the complex-step tests.

Then independently of Pinocchio: the reference with mimic joints equals the reference of the same
robot WITHOUT them (every mimic joint an ordinary coordinate), reduced by hand through
q_full = Gq q + b and v_full = G v: M = G^T M_full G, tau = G^T rnea_full(q_full, G v, G a) (also with
wrenches), J = J_full G, the same poses, COM, energies and frame accelerations, A_G = A_full G,
C = G^T C_full G, and FD consistent (rnea(aba(tau)) = tau). Plus the Coriolis matrix's identities
and the Jacobians and g as complex-step derivatives of fk and U.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

pytest.importorskip("pinocchio")

from derive.description.model import parse_models  # noqa: E402
from derive.reference import NumericRobot  # noqa: E402
from pin_model import PinRobot  # noqa: E402

MIMIC = """
robots:
  mimic_tree:
    parameters: {h: 0.04}
    gravity: [0.3, -0.5, -9.7]
    links:
      - name: base
        mass: 2.0
        com: [0.01, -0.02, 0.05]
        inertia: {ixx: 0.02, iyy: 0.03, izz: 0.04, ixy: 0.001, ixz: 0.002, iyz: -0.001}
        inertia_rpy: [0.2, 0.1, -0.3]
      - name: hub
        mass: 1.5
        com: [0.02, 0.01, -0.03]
        inertia: {ixx: 0.01, iyy: 0.015, izz: 0.012, ixy: 0.001, ixz: -0.0005, iyz: 0.002}
        inertia_rpy: [0.4, -0.2, 0.9]
      - {name: a1, mass: 0.8, com: [0.1, 0, 0], inertia: [0.002, 0.006, 0.006], inertia_rpy: [0, 0.3, 0.1]}
      - {name: a2, mass: 0.4, com: [0, 0.05, 0.02], inertia: [0.001, 0.0008, 0.001]}
      - {name: a3, mass: 0.3, com: [0.03, 0, 0.01], inertia: [0.0005, 0.0004, 0.0006], inertia_rpy: [0.5, 0, 0.2]}
      - {name: b1, mass: 0.6, com: [0, 0, 0.1], inertia: [0.003, 0.003, 0.001], inertia_rpy: [1.0, 0, 0]}
      - {name: b2, mass: 0.3, com: [0.02, 0, 0.04], inertia: [0.0005, 0.0006, 0.0004], inertia_rpy: [0.1, 0.2, 0.3]}
      - {name: b3, mass: 0.25, com: [0, 0.03, 0.05], inertia: [0.0003, 0.0003, 0.0001], inertia_rpy: [-0.5, 0.4, 0.2]}
      - {name: b3x, mass: 0.1, com: [0.01, 0.01, 0], inertia: [0.0002, 0.0003, 0.0001]}
      - {name: c1, mass: 0.7, com: [-0.05, 0.02, 0], inertia: [0.004, 0.002, 0.003]}
      - {name: c2, mass: 0.35, com: [0.03, 0.03, 0.03], inertia: [0.0004, 0.0005, 0.0006]}
    joints:
      - {name: j_hub, type: revolute, parent: base, child: hub, axis: [0.2, 0.3, 0.9], origin: {xyz: [0.05, 0.02, 0.1], rpy: [0.3, -0.2, 0.5]}}
      - {name: ja1, type: prismatic, parent: hub, child: a1, axis: [0.6, 0, 0.8], origin: {xyz: [0.1, 0, 0.05], rpy: [0, 0, 0.4]}}
      - {name: ja2, type: revolute, parent: a1, child: a2, axis: [0, 1, 0], origin: {xyz: [0.2, 0.01, 0], rpy: [-0.3, 0.2, 0]}}
      - {name: jm_a, type: revolute, parent: a2, child: a3, axis: [1, -1, 0.5], origin: {xyz: [0.03, 0.1, 0], rpy: [0.2, 0.2, 0.2]},
         mimic: {joint: j_hub, multiplier: -0.7, offset: 0.3}}
      - {name: jb1, type: prismatic, parent: hub, child: b1, axis: [0, 0, 1], origin: {xyz: [-0.1, 0.05, 0.02], rpy: [0.7, 0, -0.6]},
         mimic: {joint: ja1, multiplier: -2.0, offset: 0.05}}
      - {name: jb2, type: revolute, parent: b1, child: b2, axis: [1, 0, 0], origin: {xyz: [0, 0.02, 0.3], rpy: [0, 0.5, 0]},
         mimic: {joint: ja2, multiplier: 0.5, offset: 0.2}}
      - {name: jb3, type: revolute, parent: b2, child: b3, axis: [0, 0.6, -0.8], origin: {xyz: [-0.15, 0.02, 0], rpy: [1.2, 0, 0.3]}}
      - {name: jb3x, type: fixed, parent: b3, child: b3x, origin: {xyz: [0, 0.05, 0.1], rpy: [0, 0.3, 0]}}
      - {name: jc1, type: helical, parent: hub, child: c1, axis: [0, 0, 1], pitch: h, origin: {xyz: [0, -0.1, 0.03], rpy: [0, -0.8, 0]},
         mimic: {joint: ja2, multiplier: 1.3, offset: -0.1}}
      - {name: jc2, type: prismatic, parent: c1, child: c2, axis: [0.3, -0.5, 0.4], origin: {xyz: [0.2, -0.1, 0], rpy: [0, 0.3, 0.1]},
         mimic: {joint: j_hub, multiplier: 0.05, offset: 0.02}}
    frames:
      - {name: tip_a, link: a3, xyz: [0.05, 0, 0.01], rpy: [0.3, 0.2, 0.1]}
      - {name: tip_b, link: b3x, xyz: [0, 0.04, 0.02], rpy: [-1.0, 0.5, 2.0]}
      - {name: tip_c, link: c2, xyz: [0.02, 0.01, 0.03]}
"""

ROBOT = parse_models(MIMIC)["mimic_tree"]
MIMICS = {j.name: j.mimic for j in ROBOT.joints if j.mimic is not None}
BASES = ["fixed", "floating"]
STATES = 10
TOL = 1e-9
H = 1e-30  # complex step
WORST: dict[str, float] = {}  # quantity -> worst relative error seen (printed by test_zz_report)


def rel(ours, theirs) -> float:
    """|ours - theirs| / max(1, |theirs|), Frobenius norms."""
    ours, theirs = np.asarray(ours), np.asarray(theirs)
    assert ours.shape == theirs.shape, (ours.shape, theirs.shape)
    return float(np.linalg.norm(ours - theirs) / max(1.0, np.linalg.norm(theirs)))


def check(what: str, ours, theirs, tol: float = TOL) -> None:
    err = rel(ours, theirs)
    WORST[what] = max(WORST.get(what, 0.0), err)
    assert err <= tol, f"{what}: relative error {err:.3e} > {tol:.0e}\nours\n{ours}\ntheirs\n{theirs}"


def robot_of(base: str, mimic: bool = True, helical: bool = True):
    """The mimic tree, or (mimic=False) the same tree with every mimic joint an ordinary joint; helical=False:
    ``jc1`` a revolute joint (for Pinocchio)."""
    robot = dataclasses.replace(ROBOT, base=base)
    if not mimic:
        robot = dataclasses.replace(robot, joints=tuple(dataclasses.replace(j, mimic=None) for j in robot.joints))
    if not helical:
        robot = dataclasses.replace(robot, joints=tuple(dataclasses.replace(j, type="revolute", pitch=None) if j.name == "jc1" else j
                                                        for j in robot.joints))
    return robot


def states(ref: NumericRobot, seed: int, count: int = STATES):
    """(q, v, a, tau) with unit quaternions, joints within the joint box."""
    rng = np.random.default_rng(seed)
    for _ in range(count):
        yield ref.random_configuration(rng), rng.normal(0, 1.5, ref.nv), rng.normal(0, 2, ref.nv), rng.normal(0, 2, ref.nv)


def wrenches_for(rng) -> dict[str, np.ndarray]:
    """On a frame below a mimic joint's moving child, on a mimic joint's link, on a link moved by a mimic
    of its ancestor's joint and on the root (world with a fixed base)."""
    return {name: rng.normal(0, 5, 6) for name in ("tip_b", "c1", "a3", ROBOT.root)}


def test_the_fixture():
    """Five mimic joints, none with an entry of q; the leaders come first (Pinocchio needs that)."""
    assert set(MIMICS) == {"jm_a", "jb1", "jb2", "jc1", "jc2"}
    assert [c.name for c in ROBOT.coordinates] == ["j_hub", "ja1", "ja2", "jb3"]
    assert (ROBOT.nq, ROBOT.nv) == (4, 4) and robot_of("floating").nv == 10 and robot_of("fixed", False).nv == 9
    order = [j.name for j in ROBOT.joints]
    assert all(order.index(m.joint) < order.index(name) for name, m in MIMICS.items())
    ref = NumericRobot(robot_of("floating"))
    assert ref.has_mimic and sum(ref.mimic) == 5 and ref.nb == 10


# --------------------------------------------------------------------------- against Pinocchio


@pytest.mark.parametrize("base", BASES)
def test_against_pinocchio(base):
    robot = robot_of(base, helical=False)
    ours, pin = NumericRobot(robot), PinRobot(robot)
    assert pin.mimic and (pin.model.nq, pin.model.nv) == (robot.nq, robot.nv)
    rng = np.random.default_rng(1)
    for q, v, a, tau in states(ours, 0):
        fk = ours.fk(q)
        for frame in robot.frame_names:
            check("frame pose", fk[frame], pin.pose(q, frame))
            check("frame Jacobian", ours.jacobian(q, frame), pin.jacobian(q, frame))
            check("frame classical acceleration", ours.frame_acceleration(q, v, a, frame), pin.frame_acceleration(q, v, a, frame))
            check("jdot_v", ours.jdot_v(q, v, frame), pin.jdot_v(q, v, frame))
        check("crba", ours.crba(q), pin.crba(q))
        check("gravity", ours.gravity(q), pin.gravity(q))
        check("rnea", ours.rnea(q, v, a), pin.rnea(q, v, a))
        check("forward dynamics", ours.aba(q, v, tau), pin.aba(q, v, tau))
        wrenches = wrenches_for(rng)
        check("rnea with wrenches", ours.rnea(q, v, a, wrenches), pin.rnea(q, v, a, wrenches))
        check("forward dynamics with wrenches", ours.aba(q, v, tau, wrenches), pin.aba(q, v, tau, wrenches))
        check("com", ours.com(q), pin.com(q))
        check("com Jacobian", ours.com_jacobian(q), pin.com_jacobian(q))
        check("centroidal map", ours.centroidal_map(q), pin.centroidal_map(q))
        check("kinetic energy (Pinocchio: 1/2 v^T M v)", ours.kinetic_energy(q, v), pin.kinetic_energy(q, v))
        check("potential energy (Pinocchio: -m g . com)", ours.potential_energy(q), pin.potential_energy(q))
    assert ours.total_mass == pytest.approx(sum(i.mass for i in pin.model.inertias[1:]), rel=1e-14)


def test_pin_model_refuses_what_pinocchio_gets_wrong():
    """A helical mimic joint (Pinocchio 4.1: segmentation fault or wrong dynamics) and a mimic joint before its
    leader (Pinocchio needs the leader first)."""
    with pytest.raises(ValueError, match="'jc1' is helical"):
        PinRobot(robot_of("fixed"))
    robot = robot_of("fixed", helical=False)
    joints = [j for j in robot.joints if j.name != "jc1"]
    early = next(j for j in robot.joints if j.name == "jc1")
    early = dataclasses.replace(early, parent="hub", mimic=dataclasses.replace(early.mimic, joint="ja2"))
    with pytest.raises(ValueError, match="'jc1' comes before its leader 'ja2'"):
        PinRobot(dataclasses.replace(robot, joints=(joints[0], early, *joints[1:])))


# --------------------------------------------------------------------------- against the full tree, reduced by hand


def reduction(robot, full):
    """(Gq, b, G): q_full = Gq q + b and v_full = G v, row by row from the coordinate names (a mimic
    joint's row is its multiplier in its leader's column)."""
    def rows(names_full, names):
        g, b = np.zeros((len(names_full), len(names))), np.zeros(len(names_full))
        for r, name in enumerate(names_full):
            if name in MIMICS:
                g[r, names.index(MIMICS[name].joint)], b[r] = MIMICS[name].multiplier, MIMICS[name].offset
            else:
                g[r, names.index(name)] = 1.0
        return g, b

    gq, b = rows([c.name for c in full.coordinates], [c.name for c in robot.coordinates])
    g, _ = rows(list(full.velocity_names), list(robot.velocity_names))  # the offsets move no velocity
    return gq, b, g


@pytest.mark.parametrize("base", BASES)
def test_equals_the_full_tree_reduced_by_hand(base):
    robot, full = robot_of(base), robot_of(base, mimic=False)
    ours, ref = NumericRobot(robot), NumericRobot(full)
    gq, b, g = reduction(robot, full)
    assert g.shape == (full.nv, robot.nv) and gq.shape == (full.nq, robot.nq)
    rng = np.random.default_rng(2)
    for q, v, a, tau in states(ours, 1, 4):
        qf, vf, af = gq @ q + b, g @ v, g @ a
        fk, fk_full = ours.fk(q), ref.fk(qf)
        for frame in robot.frame_names:
            check("reduced: frame pose", fk[frame], fk_full[frame])
            check("reduced: J = J_full G", ours.jacobian(q, frame), ref.jacobian(qf, frame) @ g)
            check("reduced: frame acceleration", ours.frame_acceleration(q, v, a, frame), ref.frame_acceleration(qf, vf, af, frame))
        m = ours.crba(q)
        check("reduced: M = G^T M_full G", m, g.T @ ref.crba(qf) @ g)
        check("reduced: tau = G^T rnea_full", ours.rnea(q, v, a), g.T @ ref.rnea(qf, vf, af))
        wrenches = wrenches_for(rng)
        check("reduced: tau = G^T rnea_full, wrenches", ours.rnea(q, v, a, wrenches), g.T @ ref.rnea(qf, vf, af, wrenches))
        check("reduced: g = G^T g_full", ours.gravity(q), g.T @ ref.gravity(qf))
        for w in (None, wrenches):
            qdd = ours.aba(q, v, tau, w)
            bias = g.T @ ref.rnea(qf, vf, np.zeros(full.nv), w)
            check("reduced: FD = (G^T M_full G)^-1 (tau - G^T bias_full)", qdd, np.linalg.solve(g.T @ ref.crba(qf) @ g, tau - bias))
            check("reduced: rnea(FD(tau)) = tau", ours.rnea(q, v, qdd, w), tau)
        check("reduced: com", ours.com(q), ref.com(qf))
        check("reduced: A_G = A_full G", ours.centroidal_map(q), ref.centroidal_map(qf) @ g)
        check("reduced: J_com = J_com_full G", ours.com_jacobian(q), ref.com_jacobian(qf) @ g)
        check("reduced: kinetic energy", ours.kinetic_energy(q, v), ref.kinetic_energy(qf, vf))
        check("reduced: kinetic energy = 1/2 v^T M v", ours.kinetic_energy(q, v), 0.5 * v @ m @ v)
        check("reduced: potential energy", ours.potential_energy(q), ref.potential_energy(qf))
        check("reduced: C = G^T C_full(G v) G", ours.coriolis_matrix(q, v), g.T @ ref.coriolis_matrix(qf, vf) @ g)
        check("reduced: q_dot", gq @ ours.q_dot(q, v), ref.q_dot(qf, vf))


@pytest.mark.parametrize("base", BASES)
def test_leader_after_its_mimic(base):
    """The reference takes a mimic joint before its leader in the tree's order (Pinocchio does not): with
    jc1 and jc2 moved before ja1 and ja2 the bodies come in another order but q, v and every result stay."""
    robot = robot_of(base)
    joints = {j.name: j for j in robot.joints}
    order = ["j_hub", "jc1", "jc2", "ja1", "ja2", "jm_a", "jb1", "jb2", "jb3", "jb3x"]
    assert sorted(order) == sorted(joints)
    moved = dataclasses.replace(robot, joints=tuple(joints[n] for n in order))
    assert moved.velocity_names == robot.velocity_names
    ours, ref = NumericRobot(moved), NumericRobot(robot)
    for q, v, a, tau in states(ref, 5, 2):
        for frame in robot.frame_names:
            check("leader after: frame pose", ours.frame_pose(q, frame), ref.frame_pose(q, frame))
            check("leader after: Jacobian", ours.jacobian(q, frame), ref.jacobian(q, frame))
        check("leader after: crba", ours.crba(q), ref.crba(q))
        check("leader after: rnea", ours.rnea(q, v, a), ref.rnea(q, v, a))
        check("leader after: FD", ours.aba(q, v, tau), ref.aba(q, v, tau))
        check("leader after: centroidal map", ours.centroidal_map(q), ref.centroidal_map(q))
        check("leader after: Coriolis", ours.coriolis_matrix(q, v), ref.coriolis_matrix(q, v))


# --------------------------------------------------------------------------- self-consistency (complex step)


@pytest.mark.parametrize("base", BASES)
def test_coriolis_and_derivatives(base):
    """C v = rnea(q, v, 0) - g, Mdot - 2C skew (Mdot by complex step along q_dot), Christoffel == the
    factorization (fixed base); the Jacobians and g are complex-step derivatives of fk and U along
    q_dot(q, e_k) (Pinocchio 4.1's own Coriolis matrix fails C v = its rnea - g on mimic joints)."""
    robot = robot_of(base)
    ref = NumericRobot(robot)
    zero = np.zeros(robot.nv)
    for q, v, _, _ in states(ref, 3, 2):
        c = ref.coriolis_matrix(q, v)
        check("C v == rnea(q, v, 0) - g", c @ v, ref.rnea(q, v, zero) - ref.gravity(q))
        n = ref.crba(q + 1j * H * ref.q_dot(q, v)).imag / H - 2 * c
        check("Mdot - 2C skew", n + n.T, np.zeros_like(n))
        if not robot.floating:
            check("Christoffel C == factorization", c, ref.coriolis_factorization(q, v))
        dirs = [ref.q_dot(q, e) for e in np.eye(robot.nv)]
        poses, steps = ref.fk(q), [ref.fk(q + 1j * H * d) for d in dirs]
        for frame in robot.frame_names:
            expected = np.zeros((6, robot.nv))
            for k, step in enumerate(steps):
                w = (step[frame][:3, :3].imag / H) @ poses[frame][:3, :3].T
                expected[:, k] = np.concatenate([step[frame][:3, 3].imag / H, [w[2, 1], w[0, 2], w[1, 0]]])
            check("J == d fk along q_dot(e_k)", ref.jacobian(q, frame), expected)
        check("g == dU along q_dot(e_k)", ref.gravity(q), [ref.potential_energy(q + 1j * H * d).imag / H for d in dirs])


def test_zz_report():
    """Prints the worst relative errors of the checks above (run with -s to see them)."""
    print("\nworst relative errors:")
    for what, err in sorted(WORST.items()):
        print(f"  {what:55s} {err:.2e}")
