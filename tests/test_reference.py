"""The numeric reference (derive.reference) against closed forms and against itself.

Closed forms: pendulum, planar 2R, cart-pole dynamics and the RRPRR forward
kinematics. Self-consistency at random states of every shipped model: CRBA vs
RNEA columns, ABA vs RNEA, Christoffel C vs RNEA, skew Mdot - 2C, energy balance,
g = dU/dq, T = qd^T M qd / 2 and Jacobians vs complex-step derivatives of FK.
"""

from __future__ import annotations

import numpy as np
import pytest

from derive.description import expr
from derive.description.model import load_models, parse_models
from derive.reference import NumericRobot

# A branching tree that exercises what the shipped models leave at zero: joint and frame rpy,
# skew (unnormalised) axes, a tilted prismatic joint, full inertias with inertia_rpy, fixed
# joints mid-chain (moving joints hanging off merged links), a massive link fixed to the root,
# a massless leaf, parameter expressions and a gravity off every axis.
ZOO = """
robots:
  zoo:
    parameters: {a: 0.3, b: 0.2}
    gravity: [1.0, -2.0, -9.0]
    links:
      - {name: base}
      - {name: pedestal, mass: 5.0, com: [0, 0, 0.1], inertia: [0.1, 0.1, 0.1]}
      - name: l1
        mass: 1.2
        com: [0.1, 0.02, -0.03]
        inertia: {ixx: 0.02, iyy: 0.03, izz: 0.025, ixy: 0.001, ixz: -0.002, iyz: 0.003}
        inertia_rpy: [0.3, -0.5, 1.1]
      - {name: l1b, mass: 0.4, com: [0.0, 0.05, 0.0], inertia: [0.002, 0.001, 0.002], inertia_rpy: [0.1, 0.2, 0.3]}
      - {name: l2, mass: "3*b", com: [0.05, 0, 0.1], inertia: [0.01, 0.012, 0.005]}
      - {name: l3, mass: 0.5, com: [0, "a/3", 0], inertia: [0.004, 0.001, 0.004], inertia_rpy: [0, 0.4, 0]}
      - {name: l4, mass: 0.7, com: [0.02, 0.03, 0.04], inertia: [0.005, 0.006, 0.007]}
      - {name: tool, mass: 0.2, com: [0, 0, 0.02], inertia: [0.0005, 0.0005, 0.0002]}
      - {name: marker}
    joints:
      - {name: pedestal_mount, type: fixed, parent: base, child: pedestal, origin: {xyz: [0, 0, 0.2], rpy: [0, 0, 0.5]}}
      - {name: j1, type: revolute, parent: pedestal, child: l1, axis: [0, 0, 1], origin: {xyz: [0.1, -0.05, 0.3], rpy: [0.2, -0.3, 0.4]}}
      - {name: j1b, type: fixed, parent: l1, child: l1b, origin: {xyz: [a, 0, 0.05], rpy: ["pi/2", 0, 0]}}
      - {name: j2, type: prismatic, parent: l1b, child: l2, axis: [1, 1, 0], origin: {xyz: [0, b, 0], rpy: [0, 0.7, 0]}}
      - {name: j3, type: revolute, parent: l2, child: l3, axis: [0.3, -0.4, 0.8], origin: {xyz: [0.1, 0, "a/2"], rpy: [-0.6, 0.2, 0.9]}}
      - {name: j4, type: revolute, parent: l1, child: l4, axis: [0, 1, 0], origin: {xyz: [-0.1, 0.1, 0], rpy: [0, 0, -1.0]}}
      - {name: tool_mount, type: fixed, parent: l3, child: tool, origin: {xyz: [0, 0.15, 0], rpy: [0.3, 0.3, 0.3]}}
      - {name: marker_mount, type: fixed, parent: l4, child: marker, origin: {xyz: [0.05, 0, 0]}}
    frames:
      - {name: tcp, link: tool, xyz: [0, 0, 0.05], rpy: [3.0, -0.2, 0.1]}
      - {name: cam, link: l4, xyz: [0.01, 0.02, 0.03], rpy: [0.5, 0.6, 0.7]}
"""

ROBOTS = load_models()
SHIPPED = list(ROBOTS)
ROBOTS.update(parse_models(ZOO))
MODELS = SHIPPED + ["zoo"]
STATES = 50
TOL = 1e-9
H = 1e-30  # complex step
WORST: dict[str, float] = {}  # check name -> worst relative error seen (for reporting)


def check(what: str, actual, expected, scale=None, tol: float = TOL) -> None:
    """max|actual - expected| <= tol * max|scale or expected| (relative, max-norm)."""
    actual, expected = np.asarray(actual), np.asarray(expected)
    ref = np.max(np.abs(expected if scale is None else np.asarray(scale)))
    err = np.max(np.abs(actual - expected)) / ref if ref > 0 else np.max(np.abs(actual - expected))
    WORST[what] = max(WORST.get(what, 0.0), float(err))
    assert err <= tol, f"{what}: relative error {err:.3e} > {tol:.0e}\nactual\n{actual}\nexpected\n{expected}"


def states(robot, rng, count=STATES):
    for _ in range(count):
        yield (rng.uniform(-np.pi, np.pi, robot.nq), rng.normal(0, 2, robot.nv), rng.normal(0, 3, robot.nv))


# --------------------------------------------------------------------------- closed forms


def rot(axis: str, angle: float) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    r = {"x": [[1, 0, 0], [0, c, -s], [0, s, c]], "y": [[c, 0, s], [0, 1, 0], [-s, 0, c]],
         "z": [[c, -s, 0], [s, c, 0], [0, 0, 1]]}[axis]
    t = np.eye(4)
    t[:3, :3] = r
    return t


def trans(x, y, z) -> np.ndarray:
    t = np.eye(4)
    t[:3, 3] = x, y, z
    return t


def test_pendulum_closed_form():
    rng = np.random.default_rng(0)
    robot = ROBOTS["pendulum"]
    for _ in range(20):
        p = dict(m_r=rng.uniform(0.5, 2), m_s=rng.uniform(0.5, 2), I_r=rng.uniform(0.01, 0.2),
                 I_s=rng.uniform(0.001, 0.01), l=rng.uniform(0.5, 2), g=rng.uniform(5, 15))
        ref = NumericRobot(robot, p)
        phi, phid = rng.uniform(-np.pi, np.pi), rng.normal()
        q, qd = np.array([phi]), np.array([phid])
        m = p["m_r"] * (p["l"] / 2) ** 2 + p["m_s"] * p["l"] ** 2 + p["I_r"] + p["I_s"]
        g = p["g"] * np.sin(phi) * (p["l"] / 2 * p["m_r"] + p["l"] * p["m_s"])
        check("closed form M", ref.crba(q), [[m]])
        check("closed form g", ref.gravity(q), [g])
        check("closed form C", ref.coriolis_matrix(q, qd), [[0.0]], scale=m)
        check("closed form fk", ref.frame_pose(q, "tcp"), rot("y", phi) @ trans(0, 0, -p["l"]))
        check("closed form J", ref.jacobian(q, "tcp")[:, 0], [-p["l"] * np.cos(phi), 0, p["l"] * np.sin(phi), 0, 1, 0])
        check("closed form U", ref.potential_energy(q), -p["g"] * np.cos(phi) * (p["l"] / 2 * p["m_r"] + p["l"] * p["m_s"]))


def test_planar_2r_closed_form():
    """Uniform rods, COM at L_i/2, I_i = m_i L_i^2 / 12 about z; gravity along -y (Spong, Example 7.3.2)."""
    rng = np.random.default_rng(0)
    robot = ROBOTS["planar_2r"]
    for _ in range(20):
        p = dict(L1=rng.uniform(0.5, 2), L2=rng.uniform(0.5, 2), m1=rng.uniform(0.5, 2), m2=rng.uniform(0.5, 2),
                 g=rng.uniform(5, 15))
        ref = NumericRobot(robot, p)
        L1, L2, m1, m2, g0 = p["L1"], p["L2"], p["m1"], p["m2"], p["g"]
        lc1, lc2, i1, i2 = L1 / 2, L2 / 2, m1 * L1**2 / 12, m2 * L2**2 / 12
        q, qd = rng.uniform(-np.pi, np.pi, 2), rng.normal(0, 2, 2)
        c1, c2, c12 = np.cos(q[0]), np.cos(q[1]), np.cos(q[0] + q[1])
        s1, s2, s12 = np.sin(q[0]), np.sin(q[1]), np.sin(q[0] + q[1])
        m11 = m1 * lc1**2 + i1 + m2 * (L1**2 + lc2**2 + 2 * L1 * lc2 * c2) + i2
        m12 = m2 * (lc2**2 + L1 * lc2 * c2) + i2
        m22 = m2 * lc2**2 + i2
        m = np.array([[m11, m12], [m12, m22]])
        h = -m2 * L1 * lc2 * s2
        c = np.array([[h * qd[1], h * (qd[0] + qd[1])], [-h * qd[0], 0.0]])
        g = np.array([(m1 * lc1 + m2 * L1) * g0 * c1 + m2 * lc2 * g0 * c12, m2 * lc2 * g0 * c12])
        check("closed form M", ref.crba(q), m)
        check("closed form g", ref.gravity(q), g)
        check("closed form C", ref.coriolis_matrix(q, qd), c, scale=np.abs(m).max() * np.abs(qd).max())
        tcp = ref.frame_pose(q, "tcp")
        check("closed form fk", tcp, trans(L1 * c1 + L2 * c12, L1 * s1 + L2 * s12, 0) @ rot("z", q[0] + q[1]))
        jac = np.array([[-L1 * s1 - L2 * s12, -L2 * s12], [L1 * c1 + L2 * c12, L2 * c12], [0, 0], [0, 0], [0, 0], [1, 1]])
        check("closed form J", ref.jacobian(q, "tcp"), jac)


def test_cartpole_closed_form():
    """Cart (mass mc) at x = s; pole (mp, COM at lc below the pivot, I about y) swings about y; gravity -z."""
    robot = ROBOTS["cartpole"]
    ref = NumericRobot(robot)
    mc, mp, lc, inertia, g0 = 1.0, 0.1, 0.5, 0.00833333333333333, 9.81
    rng = np.random.default_rng(0)
    for q, qd, _ in states(robot, rng, 20):
        th = q[1]
        m = np.array([[mc + mp, -mp * lc * np.cos(th)], [-mp * lc * np.cos(th), mp * lc**2 + inertia]])
        c = np.array([[0.0, mp * lc * np.sin(th) * qd[1]], [0.0, 0.0]])
        check("closed form M", ref.crba(q), m)
        check("closed form g", ref.gravity(q), [0.0, mp * g0 * lc * np.sin(th)], scale=mp * g0 * lc)
        check("closed form C", ref.coriolis_matrix(q, qd), c, scale=np.abs(m).max() * np.abs(qd).max())


def test_rrprr_forward_kinematics():
    """Lecture eq. 11-12: TCP = Rx(t1) T(0, L1 + t2, 0) Ry(t3) Rx(t4) T(0, L2, 0) Ry(t5) T(0, L_tcp, 0)."""
    robot = ROBOTS["rrprr"]
    ref = NumericRobot(robot)
    L1, L2, Lt = 0.4, 0.3, 0.1
    rng = np.random.default_rng(0)
    for q, _, _ in states(robot, rng, 20):
        t1, t2, t3, t4, t5 = q
        frames = ref.fk(q)
        assert list(frames) == list(robot.frame_names)
        tcp = rot("x", t1) @ trans(0, L1 + t2, 0) @ rot("y", t3) @ rot("x", t4) @ trans(0, L2, 0) @ rot("y", t5) @ trans(0, Lt, 0)
        check("closed form fk", frames["tcp"], tcp)
        check("closed form fk", frames["link3"], rot("x", t1) @ trans(0, L1 + t2, 0) @ rot("y", t3))
        check("closed form fk", frames["s"], np.eye(4))


def rodrigues(axis, angle) -> np.ndarray:
    k = np.array(axis, dtype=float) / np.linalg.norm(axis)
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    t = np.eye(4)
    t[:3, :3] = np.cos(angle) * np.eye(3) + np.sin(angle) * kx + (1 - np.cos(angle)) * np.outer(k, k)
    return t


def rpy(r, p, y) -> np.ndarray:
    return rot("z", y) @ rot("y", p) @ rot("x", r)


def test_zoo_forward_kinematics():
    """URDF chain product Trans(xyz) Rz(yaw) Ry(pitch) Rx(roll) * motion, written out for the zoo's tcp and cam."""
    robot = ROBOTS["zoo"]
    assert [j.name for j in robot.moving_joints] == ["j1", "j2", "j3", "j4"]  # q order: depth-first, file order among siblings (Pinocchio's)
    rng = np.random.default_rng(0)
    for _ in range(10):
        a, b = rng.uniform(0.1, 0.5, 2)
        ref = NumericRobot(robot, {"a": a, "b": b})
        q = rng.uniform(-np.pi, np.pi, 4)
        j1, j2, j3, j4 = q
        l1 = trans(0, 0, 0.2) @ rot("z", 0.5) @ trans(0.1, -0.05, 0.3) @ rpy(0.2, -0.3, 0.4) @ rot("z", j1)
        l2 = l1 @ trans(a, 0, 0.05) @ rot("x", np.pi / 2) @ trans(0, b, 0) @ rot("y", 0.7) @ trans(*(j2 * np.array([1, 1, 0]) / np.sqrt(2)))
        l3 = l2 @ trans(0.1, 0, a / 2) @ rpy(-0.6, 0.2, 0.9) @ rodrigues([0.3, -0.4, 0.8], j3)
        tcp = l3 @ trans(0, 0.15, 0) @ rpy(0.3, 0.3, 0.3) @ trans(0, 0, 0.05) @ rpy(3.0, -0.2, 0.1)
        l4 = l1 @ trans(-0.1, 0.1, 0) @ rot("z", -1.0) @ rot("y", j4)
        frames = ref.fk(q)
        assert list(frames) == list(robot.frame_names)
        for name, expected in [("l2", l2), ("l3", l3), ("tcp", tcp), ("l4", l4),
                               ("cam", l4 @ trans(0.01, 0.02, 0.03) @ rpy(0.5, 0.6, 0.7)), ("marker", l4 @ trans(0.05, 0, 0))]:
            check("closed form fk", frames[name], expected)


def link_energies(robot, ref, q, qd):
    """T and U summed link by link from FK alone (complex step for the velocities).

    T = sum 1/2 (m |v_c|^2 + w . R_in_w I R_in_w^T w), U = -sum m gravity . p_c, with
    R_in_w = R_link Rz Ry Rx(inertia_rpy); an independent check of the inertia pipeline.
    Links welded to the root (no moving joint above them) are world and left out.
    """
    env = ref.params
    num = lambda v: float(expr.evaluate(v, env))  # noqa: E731
    gravity = np.array([num(x) for x in robot.gravity])
    poses, moved = ref.fk(q), ref.fk(q + 1j * H * qd)
    kinetic = potential = 0.0
    for link in robot.links:
        joint = robot.parent_joint(link.name)
        while joint is not None and joint.dof == 0:
            joint = robot.parent_joint(joint.parent)
        if joint is None:
            continue
        pose, dpose = poses[link.name], moved[link.name].imag / H
        mass, com = num(link.mass), np.array([num(x) for x in link.com])
        inertia = np.array([[num(x) for x in row] for row in link.inertia])
        r_in = pose[:3, :3] @ rpy(*[num(x) for x in link.inertia_rpy])[:3, :3]
        w_hat = dpose[:3, :3] @ pose[:3, :3].T
        w = np.array([w_hat[2, 1], w_hat[0, 2], w_hat[1, 0]])
        v_c = dpose[:3, :3] @ com + dpose[:3, 3]
        kinetic += 0.5 * mass * v_c @ v_c + 0.5 * w @ r_in @ inertia @ r_in.T @ w
        potential -= mass * gravity @ (pose[:3, :3] @ com + pose[:3, 3])
    return kinetic, potential


@pytest.mark.parametrize("name", MODELS)
def test_energies_from_first_principles(name):
    robot = ROBOTS[name]
    ref = NumericRobot(robot)
    rng = np.random.default_rng(0)
    for q, qd, _ in states(robot, rng):
        kinetic, potential = link_energies(robot, ref, q, qd)
        check("T from link velocities", ref.kinetic_energy(q, qd), kinetic)
        check("T from link velocities", 0.5 * qd @ ref.crba(q) @ qd, kinetic)
        check("U from link COMs", ref.potential_energy(q), potential)


def test_parameters_override_and_unknown():
    robot = ROBOTS["pendulum"]
    q = np.array([0.3])
    assert NumericRobot(robot, {"l": 2.0}).frame_pose(q, "tcp")[2, 3] == pytest.approx(-2.0 * np.cos(0.3), rel=1e-14)
    with pytest.raises(ValueError, match="no parameter"):
        NumericRobot(robot, {"nope": 1.0})


# --------------------------------------------------------------------------- self-consistency, every model


@pytest.mark.parametrize("name", MODELS)
def test_crba_matches_rnea_columns(name):
    robot = ROBOTS[name]
    ref = NumericRobot(robot)
    rng = np.random.default_rng(0)
    eye = np.eye(robot.nv)
    for q, qd, _ in states(robot, rng):
        m = ref.crba(q)
        g = ref.rnea(q, np.zeros(robot.nv), np.zeros(robot.nv))
        check("M == rnea columns", m, np.column_stack([ref.rnea(q, np.zeros(robot.nv), e) - g for e in eye]))
        check("M symmetric", m, m.T)
        assert np.linalg.eigvalsh(m).min() > 1e-9 * np.abs(m).max(), "M not positive definite"
        check("T == qd'M qd/2", ref.kinetic_energy(q, qd), 0.5 * qd @ m @ qd)
        check("gravity == rnea(q,0,0)", ref.gravity(q), g)


@pytest.mark.parametrize("name", MODELS)
def test_aba_inverts_rnea(name):
    robot = ROBOTS[name]
    ref = NumericRobot(robot)
    rng = np.random.default_rng(0)
    for q, qd, qdd in states(robot, rng):
        tau = ref.rnea(q, qd, qdd)
        check("aba(rnea) == qdd", ref.aba(q, qd, tau), qdd)
        check("M qdd + h == tau", ref.crba(q) @ qdd + ref.rnea(q, qd, np.zeros(robot.nv)), tau)


@pytest.mark.parametrize("name", MODELS)
def test_coriolis_matrix(name):
    robot = ROBOTS[name]
    ref = NumericRobot(robot)
    rng = np.random.default_rng(0)
    zero = np.zeros(robot.nv)
    for q, qd, _ in states(robot, rng):
        c = ref.coriolis_matrix(q, qd)
        bias = ref.rnea(q, qd, zero) - ref.gravity(q)
        scale = np.abs(ref.crba(q)).max() * np.abs(qd).max() ** 2
        check("C qd == rnea(q,qd,0) - g", c @ qd, bias, scale=scale)
        mdot = ref.crba(q + 1j * H * qd).imag / H
        n = mdot - 2 * c
        check("Mdot - 2C skew", n + n.T, np.zeros_like(n), scale=np.abs(mdot).max() + np.abs(c).max())
        check("Mdot == sum dM/dq_k qd_k", mdot, np.einsum("kij,k->ij", ref.mass_matrix_partials(q), qd),
              scale=np.abs(mdot).max() + 1e-300)


@pytest.mark.parametrize("name", MODELS)
def test_energy(name):
    robot = ROBOTS[name]
    ref = NumericRobot(robot)
    rng = np.random.default_rng(0)
    for q, qd, tau in states(robot, rng):
        qdd = ref.aba(q, qd, tau)
        # d/dt (T + U) along (q, qd, qdd) by complex step equals the power of tau.
        dt = lambda f, *x: f(*x).imag / H  # noqa: E731
        power = dt(ref.kinetic_energy, q + 1j * H * qd, qd + 1j * H * qdd) + dt(ref.potential_energy, q + 1j * H * qd)
        scale = np.abs(qd).max() * (np.abs(tau).max() + np.abs(ref.rnea(q, qd, qdd)).max())
        check("d(T+U)/dt == qd.tau", power, qd @ tau, scale=scale)
        # g = dU/dq
        du = np.array([dt(ref.potential_energy, q + 1j * H * e) for e in np.eye(robot.nv)])
        check("g == dU/dq", ref.gravity(q), du, scale=np.abs(du).max() + np.abs(ref.gravity(q)).max())


@pytest.mark.parametrize("name", MODELS)
def test_jacobian_is_fk_derivative(name):
    robot = ROBOTS[name]
    ref = NumericRobot(robot)
    rng = np.random.default_rng(0)
    for q, _, _ in states(robot, rng):
        poses = ref.fk(q)
        steps = [ref.fk(q + 1j * H * e) for e in np.eye(robot.nv)]
        for frame in robot.frame_names:
            jac = ref.jacobian(q, frame)
            rot_ = poses[frame][:3, :3]
            expected = np.zeros((6, robot.nv))
            for k, step in enumerate(steps):
                expected[:3, k] = step[frame][:3, 3].imag / H
                w = (step[frame][:3, :3].imag / H) @ rot_.T  # Rdot R^T = w^
                expected[3:, k] = w[2, 1], w[0, 2], w[1, 0]
                check("Rdot R^T skew", w + w.T, np.zeros((3, 3)), scale=1.0)
            check("J == d fk / dq", jac, expected, scale=max(1.0, np.abs(expected).max()))
            check("frame_pose == fk", ref.frame_pose(q, frame), poses[frame])
