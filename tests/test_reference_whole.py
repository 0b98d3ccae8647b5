"""The whole numeric reference (derive.reference) against Pinocchio, fixed and floating base.

Pinocchio's model is built directly from the derive Robot (tests/pin_model.py, no URDF), so
every Robot can be checked: a synthetic branching tree (revolute and prismatic joints about
skew axes, rotated inertias, a fixed joint mid-branch, named frames on branches), a tree of
the multi-DOF joint types, and the shipped panda and ur5, each fixed and floating
(``dataclasses.replace(robot, base="floating")``). At seeded random states (unit quaternions):
frame poses, Jacobians, classical accelerations and Jdot v of every frame, M, g, rnea, aba,
rnea and aba with external wrenches, the COM, its Jacobian and the centroidal map, all to
1e-9 relative (|ours - theirs| / max(1, |theirs|), Frobenius norms).

Then what Pinocchio does not vouch for: wrenches are -J^T w, q_dot moves every frame at J v,
frame accelerations are d/dt (J v), the COM Jacobian is d com / dt, the Coriolis matrix
(C qd = bias, Mdot - 2C skew), all by complex step (also through the fixed-base path), and
pin_model itself against Pinocchio's URDF parser on the panda.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

pytest.importorskip("pinocchio")

from derive.description.model import load_models, parse_models  # noqa: E402
from derive.reference import NumericRobot  # noqa: E402
from pin_model import PinRobot  # noqa: E402

# Three branches off 'hub' (a: revolute -> prismatic; b: prismatic -> fixed -> revolute; c: revolute ->
# revolute) and one off the root (prismatic); skew axes, rotated full inertias, a massive root (a body
# when floating), a link fixed to the root, named frames on two branches and on the root's fixed link.
TREE = """
robots:
  tree:
    parameters: {a: 0.3}
    gravity: [0.5, -1.0, -9.5]
    links:
      - name: base
        mass: 2.0
        com: [0.01, -0.02, 0.05]
        inertia: {ixx: 0.02, iyy: 0.03, izz: 0.04, ixy: 0.001, ixz: 0.002, iyz: -0.001}
        inertia_rpy: [0.2, 0.1, -0.3]
      - {name: plate, mass: 0.5, com: [0, 0, 0.01], inertia: [0.001, 0.002, 0.003]}
      - name: hub
        mass: 1.5
        com: [0.02, 0.01, -0.03]
        inertia: {ixx: 0.01, iyy: 0.015, izz: 0.012, ixy: 0.001, ixz: -0.0005, iyz: 0.002}
        inertia_rpy: [0.4, -0.2, 0.9]
      - {name: a1, mass: 0.8, com: [0.1, 0, 0], inertia: [0.002, 0.006, 0.006], inertia_rpy: [0, 0.3, 0.1]}
      - {name: a2, mass: 0.4, com: [0, 0.05, 0.02], inertia: [0.001, 0.0008, 0.001]}
      - {name: b1, mass: 0.6, com: [0, 0, "a/3"], inertia: [0.003, 0.003, 0.001], inertia_rpy: [1.0, 0, 0]}
      - {name: b1x, mass: 0.2, com: [0.01, 0.01, 0], inertia: [0.0002, 0.0003, 0.0001]}
      - {name: b2, mass: 0.3, com: [0.02, 0, 0.04], inertia: [0.0005, 0.0006, 0.0004], inertia_rpy: [0.1, 0.2, 0.3]}
      - {name: c1, mass: 0.7, com: [-0.05, 0.02, 0], inertia: [0.004, 0.002, 0.003]}
      - {name: c2, mass: 0.25, com: [0, 0, 0.05], inertia: [0.0003, 0.0003, 0.0001], inertia_rpy: [-0.5, 0.4, 0.2]}
      - {name: d1, mass: 0.35, com: [0.03, 0.03, 0.03], inertia: [0.0004, 0.0005, 0.0006]}
    joints:
      - {name: plate_mount, type: fixed, parent: base, child: plate, origin: {xyz: [0, 0, 0.05], rpy: [0.1, 0, 0.2]}}
      - {name: j_hub, type: revolute, parent: plate, child: hub, axis: [0.2, 0.3, 0.9], origin: {xyz: [0.05, 0.02, 0.1], rpy: [0.3, -0.2, 0.5]}}
      - {name: ja1, type: revolute, parent: hub, child: a1, axis: [0, 1, 0], origin: {xyz: [0.1, 0, 0.05], rpy: [0, 0, 0.4]}}
      - {name: ja2, type: prismatic, parent: a1, child: a2, axis: [0.6, 0, 0.8], origin: {xyz: [0.2, 0.01, 0], rpy: [-0.3, 0.2, 0]}}
      - {name: jb1, type: prismatic, parent: hub, child: b1, axis: [0, 0, 1], origin: {xyz: [-0.1, 0.05, 0.02], rpy: [0.7, 0, -0.6]}}
      - {name: jb1x, type: fixed, parent: b1, child: b1x, origin: {xyz: [0, 0.02, a], rpy: [0, 0.5, 0]}}
      - {name: jb2, type: revolute, parent: b1x, child: b2, axis: [1, -1, 0.5], origin: {xyz: [0.03, 0, 0.05], rpy: [0.2, 0.2, 0.2]}}
      - {name: jc1, type: revolute, parent: hub, child: c1, axis: [1, 0, 0], origin: {xyz: [0, -0.1, 0.03], rpy: [0, -0.8, 0]}}
      - {name: jc2, type: revolute, parent: c1, child: c2, axis: [0, 0.6, -0.8], origin: {xyz: [-0.15, 0.02, 0], rpy: [1.2, 0, 0.3]}}
      - {name: jd1, type: prismatic, parent: base, child: d1, axis: [0.3, -0.5, 0.4], origin: {xyz: [0.2, -0.1, 0], rpy: [0, 0.3, 0.1]}}
    frames:
      - {name: tip_a, link: a2, xyz: [0.05, 0, 0.01], rpy: [0.3, 0.2, 0.1]}
      - {name: tip_b, link: b2, xyz: [0, 0.04, 0.02], rpy: [-1.0, 0.5, 2.0]}
      - {name: top, link: plate, xyz: [0, 0, 0.02], rpy: [0, 0, 0.7]}
"""

# The multi-DOF and screw joints (spherical ZYX, helical, universal, cylindrical) off one hub.
JOINTS = """
robots:
  joints:
    parameters: {h: 0.05}
    gravity: [0.0, 0.3, -9.81]
    links:
      - {name: base, mass: 1.0, com: [0, 0, 0.02], inertia: [0.01, 0.01, 0.01]}
      - name: hub
        mass: 1.0
        com: [0.01, 0.02, 0.03]
        inertia: {ixx: 0.01, iyy: 0.012, izz: 0.009, ixy: 0.001, ixz: 0, iyz: 0.0005}
        inertia_rpy: [0.1, 0.2, 0.3]
      - {name: ball, mass: 0.5, com: [0.05, 0, 0.02], inertia: [0.002, 0.003, 0.004], inertia_rpy: [0.3, -0.1, 0.2]}
      - {name: screw, mass: 0.3, com: [0, 0.02, 0.03], inertia: [0.001, 0.001, 0.0005]}
      - {name: cross, mass: 0.4, com: [0.02, -0.01, 0.05], inertia: [0.0015, 0.002, 0.001], inertia_rpy: [0, 0.5, 0]}
      - {name: sleeve, mass: 0.6, com: [0, 0.03, 0.04], inertia: [0.003, 0.002, 0.0025], inertia_rpy: [0.2, 0, -0.4]}
    joints:
      - {name: j0, type: revolute, parent: base, child: hub, axis: [0.1, 0.2, 1.0], origin: {xyz: [0, 0, 0.1], rpy: [0.1, 0.2, 0.3]}}
      - {name: ball_j, type: spherical, parent: hub, child: ball, origin: {xyz: [0.1, 0, 0.05], rpy: [0.3, -0.2, 0.1]}}
      - {name: screw_j, type: helical, parent: ball, child: screw, axis: [0.3, 0.4, 0.5], pitch: h, origin: {xyz: [0.1, 0.02, 0], rpy: [0, 0.4, 0]}}
      - {name: cross_j, type: universal, parent: hub, child: cross, axis: [0, 0, 1], axis2: [0.6, 0.8, 0], origin: {xyz: [-0.05, 0.1, 0], rpy: [0.5, 0, 0.2]}}
      - {name: sleeve_j, type: cylindrical, parent: hub, child: sleeve, axis: [0.2, -0.3, 0.9], origin: {xyz: [0.02, -0.1, 0.05], rpy: [0, -0.3, 0.6]}}
    frames:
      - {name: tcp, link: screw, xyz: [0.02, 0.03, 0.04], rpy: [0.5, 0.4, 0.3]}
"""

ROBOTS = {**parse_models(TREE), **parse_models(JOINTS), **{k: v for k, v in load_models().items() if k in ("panda", "ur5")}}
CASES = [("tree", "fixed"), ("tree", "floating"), ("joints", "fixed"), ("joints", "floating"),
         ("panda", "floating"), ("ur5", "floating")]
CASE_IDS = [f"{name}-{base}" for name, base in CASES]
STATES = 16
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


def robot_of(name: str, base: str):
    return dataclasses.replace(ROBOTS[name], base=base)


def states(ref: NumericRobot, seed: int, count: int = STATES):
    """(q, v, a, tau) with unit quaternions, joints within the joint box."""
    rng = np.random.default_rng(seed)
    for _ in range(count):
        yield ref.random_configuration(rng), rng.normal(0, 1.5, ref.nv), rng.normal(0, 2, ref.nv), rng.normal(0, 2, ref.nv)


def wrenches_for(robot, rng) -> dict[str, np.ndarray]:
    """Wrenches on two frames off the root (the last named frame, a link mid-tree) and on the root link
    (a body with a floating base; world, so without effect, with a fixed base)."""
    names = robot.frame_names
    return {names[-1]: rng.normal(0, 5, 6), names[len(names) // 2]: rng.normal(0, 5, 6), robot.root: rng.normal(0, 5, 6)}


# --------------------------------------------------------------------------- against Pinocchio


@pytest.mark.parametrize("name,base", CASES, ids=CASE_IDS)
def test_against_pinocchio(name, base):
    robot = robot_of(name, base)
    ours, pin = NumericRobot(robot), PinRobot(robot)
    rng = np.random.default_rng(1)
    for q, v, a, tau in states(ours, 0):
        for frame in robot.frame_names:
            check("frame pose", ours.frame_pose(q, frame), pin.pose(q, frame))
            check("frame Jacobian", ours.jacobian(q, frame), pin.jacobian(q, frame))
            check("frame classical acceleration", ours.frame_acceleration(q, v, a, frame), pin.frame_acceleration(q, v, a, frame))
            check("jdot_v", ours.jdot_v(q, v, frame), pin.jdot_v(q, v, frame))
        fk = ours.fk(q)
        for frame in robot.frame_names:
            check("frame pose", fk[frame], pin.pose(q, frame))
        check("crba", ours.crba(q), pin.crba(q))
        check("gravity", ours.gravity(q), pin.gravity(q))
        check("gravity", ours.rnea(q, np.zeros(robot.nv), np.zeros(robot.nv)), pin.gravity(q))
        check("rnea", ours.rnea(q, v, a), pin.rnea(q, v, a))
        check("aba", ours.aba(q, v, tau), pin.aba(q, v, tau))
        wrenches = wrenches_for(robot, rng)
        check("rnea with wrenches", ours.rnea(q, v, a, wrenches), pin.rnea(q, v, a, wrenches))
        check("aba with wrenches", ours.aba(q, v, tau, wrenches), pin.aba(q, v, tau, wrenches))
        check("com", ours.com(q), pin.com(q))
        check("com Jacobian", ours.com_jacobian(q), pin.com_jacobian(q))
        check("centroidal map", ours.centroidal_map(q), pin.centroidal_map(q))
        check("kinetic energy", ours.kinetic_energy(q, v), pin.kinetic_energy(q, v))
        check("potential energy", ours.potential_energy(q), pin.potential_energy(q))
        if name != "joints":  # Pinocchio's C leaves out Sdot of SphericalZYX and Universal (see test_coriolis_matrix)
            check("coriolis matrix", ours.coriolis_matrix(q, v), pin.coriolis_matrix(q, v))
    assert ours.total_mass == pytest.approx(sum(i.mass for i in pin.model.inertias[1:]), rel=1e-14)
    assert (ours.frames[robot.root][0] >= 0) == robot.floating  # the root is a body only when floating


def test_pin_model_matches_the_urdf_parser():
    """Fixed panda: pin_model's Pinocchio model (from the Robot) == Pinocchio's own URDF import (fingers locked)."""
    import pinocchio

    from test_urdf import SHIPPED, PinSide, erd_path, random_q

    robot = ROBOTS["panda"]
    args = SHIPPED["panda"]
    urdf = PinSide(pinocchio, erd_path(args["path"]), robot, {n: 0.0 for n in args["lock"].split(",")}, args["tip"])
    ours = PinRobot(robot)
    rng = np.random.default_rng(2)
    for _ in range(STATES):
        q, v, a = random_q(robot, rng), rng.normal(size=robot.nv), rng.normal(size=robot.nv)
        for frame in robot.frame_names:
            check("pin_model vs URDF: pose", ours.pose(q, frame), urdf.pose(q, frame))
            check("pin_model vs URDF: Jacobian", ours.jacobian(q, frame), urdf.jacobian(q, frame))
        check("pin_model vs URDF: crba", ours.crba(q), urdf.crba(q))
        check("pin_model vs URDF: gravity", ours.gravity(q), urdf.gravity(q))
        check("pin_model vs URDF: rnea", ours.rnea(q, v, a), urdf.rnea(q, v, a))
        qu = urdf.q(q)
        check("pin_model vs URDF: com", ours.com(q), pinocchio.centerOfMass(urdf.model, urdf.data, qu))
        check("pin_model vs URDF: centroidal map", ours.centroidal_map(q),
              pinocchio.computeCentroidalMap(urdf.model, urdf.data, qu)[:, urdf.perm])


# --------------------------------------------------------------------------- self-consistency (complex step)


@pytest.mark.parametrize("name,base", CASES, ids=CASE_IDS)
def test_wrenches_are_minus_jacobian_transpose(name, base):
    robot = robot_of(name, base)
    ref = NumericRobot(robot)
    rng = np.random.default_rng(3)
    for q, v, a, _ in states(ref, 1, 4):
        wrenches = wrenches_for(robot, rng)
        tau = ref.rnea(q, v, a, wrenches)
        expected = ref.rnea(q, v, a) - sum(ref.jacobian(q, f).T @ w for f, w in wrenches.items())
        check("rnea with wrenches == rnea - sum J^T w", tau, expected)
        check("aba(rnea) with wrenches == a", ref.aba(q, v, tau, wrenches), a)


@pytest.mark.parametrize("name,base", CASES, ids=CASE_IDS)
def test_time_derivatives_by_complex_step(name, base):
    """Along q(t) with dq/dt = q_dot(q, v), dv/dt = a (complex step, so exact to rounding):
    d pose/dt = J v for every frame, d (J v)/dt = the frame's classical acceleration,
    d com/dt = J_com v, and M d com/dt = the linear centroidal momentum."""
    robot = robot_of(name, base)
    ref = NumericRobot(robot)
    for q, v, a, _ in states(ref, 2, 3):
        qd = ref.q_dot(q, v)
        assert qd.shape == (robot.nq,)
        if robot.floating:
            assert abs(q[3:7] @ qd[3:7]) < 1e-15  # tangent to the unit sphere
        moved = q + 1j * H * qd
        poses, step = ref.fk(q), ref.fk(moved)
        for frame in robot.frame_names:
            jac = ref.jacobian(q, frame)
            dpose = step[frame].imag / H
            w = dpose[:3, :3] @ poses[frame][:3, :3].T
            check("Rdot R^T skew", w + w.T, np.zeros((3, 3)))
            check("d pose/dt along q_dot == J v", np.concatenate([dpose[:3, 3], [w[2, 1], w[0, 2], w[1, 0]]]), jac @ v)
            jv = ref.jacobian(moved, frame) @ (v + 1j * H * a)
            check("d(J v)/dt == frame classical acceleration", jv.imag / H, ref.frame_acceleration(q, v, a, frame))
        dcom = ref.com(moved).imag / H
        check("d com/dt == J_com v", dcom, ref.com_jacobian(q) @ v)
        check("linear centroidal momentum == m d com/dt", ref.centroidal_momentum(q, v)[:3], ref.total_mass * dcom)


@pytest.mark.parametrize("name,base", [("tree", "fixed"), ("joints", "fixed"), ("tree", "floating")])
def test_jacobians_by_complex_step(name, base):
    """Every column of the frame and COM Jacobians is the complex-step derivative of fk / com along
    q_dot(q, e_k) (= e_k with a fixed base: the plain partial derivative d/dq_k); g = dU/dq likewise."""
    robot = robot_of(name, base)
    ref = NumericRobot(robot)
    for q, _, _, _ in states(ref, 3, 2):
        poses = ref.fk(q)
        dirs = [ref.q_dot(q, e) for e in np.eye(robot.nv)]
        if not robot.floating:
            assert all(np.array_equal(d, e) for d, e in zip(dirs, np.eye(robot.nv)))
        steps = [ref.fk(q + 1j * H * d) for d in dirs]
        for frame in robot.frame_names:
            expected = np.zeros((6, robot.nv))
            for k, step in enumerate(steps):
                w = (step[frame][:3, :3].imag / H) @ poses[frame][:3, :3].T
                expected[:, k] = np.concatenate([step[frame][:3, 3].imag / H, [w[2, 1], w[0, 2], w[1, 0]]])
            check("J == d fk along q_dot(e_k)", ref.jacobian(q, frame), expected)
        com_cols = np.column_stack([ref.com(q + 1j * H * d).imag / H for d in dirs])
        check("J_com == d com along q_dot(e_k)", ref.com_jacobian(q), com_cols)
        du = np.array([ref.potential_energy(q + 1j * H * d).imag / H for d in dirs])
        check("g == dU along q_dot(e_k)", ref.gravity(q), du)


@pytest.mark.parametrize("name,base", CASES, ids=CASE_IDS)
def test_coriolis_matrix(name, base):
    """C qd == rnea(q, qd, 0) - g and Mdot - 2C skew (Mdot by complex step along q_dot); with a fixed base
    the Christoffel C == the spatial factorization (Pinocchio's form)."""
    robot = robot_of(name, base)
    ref = NumericRobot(robot)
    zero = np.zeros(robot.nv)
    for q, v, _, _ in states(ref, 4, 3):
        c = ref.coriolis_matrix(q, v)
        check("C v == rnea(q, v, 0) - g", c @ v, ref.rnea(q, v, zero) - ref.gravity(q))
        mdot = ref.crba(q + 1j * H * ref.q_dot(q, v)).imag / H
        n = mdot - 2 * c
        check("Mdot - 2C skew", n + n.T, np.zeros_like(n))
        if not robot.floating:
            check("Christoffel C == factorization", c, ref.coriolis_factorization(q, v))


def test_floating_base_conventions():
    """v[0:6] is the root's [linear; angular] velocity in the root frame, tau[0:6] the [force; torque] on
    it in the root frame; M does not depend on the base pose; a free root under gravity falls at g."""
    robot = robot_of("tree", "floating")
    ref = NumericRobot(robot)
    rng = np.random.default_rng(5)
    q, v, a, _ = next(states(ref, 5, 1))
    rot = ref.frame_pose(q, robot.root)[:3, :3]
    check("root Jacobian == blockdiag(R, R)", ref.jacobian(q, robot.root)[:, :6], np.kron(np.eye(2), rot))
    other = q.copy()
    other[:7] = ref.random_configuration(rng)[:7]
    check("M independent of the base pose", ref.crba(other), ref.crba(q))
    qdd = ref.aba(q, np.zeros(robot.nv), np.zeros(robot.nv))  # free fall: every body accelerates at g
    check("free fall: root at g", ref.frame_acceleration(q, np.zeros(robot.nv), qdd, robot.root)[:3], ref.gravity_vector)
    check("free fall: joints still", qdd[6:], np.zeros(robot.nv - 6))
    # a wrench at the root origin is tau[0:6] turned into the root frame
    wrench = rng.normal(size=6)
    tau = ref.rnea(q, v, a) - ref.rnea(q, v, a, {robot.root: wrench})
    check("root wrench == tau[0:6] in the root frame", tau[:6], np.concatenate([rot.T @ wrench[:3], rot.T @ wrench[3:]]))
    check("root wrench moves no joint", tau[6:], np.zeros(robot.nv - 6))
    assert ref.frames[robot.root][0] == 0 and ref.qdofs[1].start == ref.dofs[1].start + 1


def test_bad_inputs():
    ref = NumericRobot(robot_of("tree", "floating"))
    nq, nv = ref.nq, ref.nv
    assert (nq, nv) == (15, 14)
    with pytest.raises(ValueError, match="q must have nq = 15 entries"):
        ref.crba(np.zeros(nv))
    with pytest.raises(ValueError, match="qd must have nv = 14 entries"):
        ref.rnea(ref.neutral(), np.zeros(nq), np.zeros(nv))
    with pytest.raises(ValueError, match="no frame 'nope'"):
        ref.rnea(ref.neutral(), np.zeros(nv), np.zeros(nv), {"nope": np.zeros(6)})
    with pytest.raises(ValueError, match="6 entries"):
        ref.aba(ref.neutral(), np.zeros(nv), np.zeros(nv), {"tip_a": np.zeros(3)})


def test_zz_report():
    """Prints the worst relative errors of the checks above (run with -s to see them)."""
    print("\nworst relative errors:")
    for what, err in sorted(WORST.items()):
        print(f"  {what:50s} {err:.2e}")
