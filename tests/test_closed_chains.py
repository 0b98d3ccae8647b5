"""Closed chains in reduced coordinates (docs/closed-chains.md): the shipped mechanisms of
models.yaml closed, projected and simulated, three implementations compared (the
description's check, the numpy reference, the CasADi model) and Pinocchio's constraintDynamics."""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import casadi as ca
import numpy as np
import pinocchio as pin
import pytest
import yaml

from derive.cli import main
from derive.description.closure import Closure
from derive.description.model import load_models, parse_models
from derive.reference.closure import ClosedChainReference
from derive.reference.pinocchio_model import PinRobot
from derive.symbolic.closure import ClosedChainModel

MODELS = Path(__file__).resolve().parent.parent / "models.yaml"
SHIPPED = ("fourbar", "slider_crank", "fivebar", "example2", "delta", "parallel_ankle")
PLANAR = ("fourbar", "slider_crank", "fivebar", "example2")
DOF = {"fourbar": 1, "slider_crank": 1, "fivebar": 2, "example2": 3, "delta": 3, "parallel_ankle": 2}


@lru_cache(maxsize=None)
def shipped():
    return load_models(MODELS)


@lru_cache(maxsize=None)
def built(name: str):
    robot = shipped()[name]
    return robot, ClosedChainReference(robot), ClosedChainModel(robot).functions()


def variant(name: str, **changes) -> dict:
    """The YAML entry of a shipped mechanism with some fields replaced (None removes one)."""
    entry = yaml.safe_load(MODELS.read_text())["robots"][name]
    for key, value in changes.items():
        if value is None:
            entry.pop(key, None)
        else:
            entry[key] = value
    return entry


def parse(entry: dict, name: str = "mech"):
    return parse_models(yaml.safe_dump({"robots": {name: entry}}))[name]


def state(ref: ClosedChainReference, seed: int):
    """A closed q near the reference, with random yd, ydd, tau_y."""
    rng = np.random.default_rng(seed)
    ny = len(ref.y)
    q, residual = ref.closure(ref.q_ref[ref.y] + rng.uniform(-0.1, 0.1, ny))
    assert residual <= 1e-12
    return q, rng.normal(size=ny), rng.normal(size=ny), rng.normal(size=ny)


def num(x) -> np.ndarray:
    """A casadi DM as numpy: a vector (or a single row or column) flat, a matrix as is."""
    a = np.array(x.full() if hasattr(x, "full") else x, dtype=float)
    return a.ravel() if a.ndim < 2 or 1 in a.shape else a


def mat(x) -> np.ndarray:
    """A casadi DM matrix as a 2-D numpy array."""
    return np.array(x.full(), dtype=float)


@pytest.mark.parametrize("name", SHIPPED)
def test_generated_closure_closes_the_loops(name):
    robot, ref, f = built(name)
    p = [x.default for x in robot.parameters]
    rng = np.random.default_rng(1)
    for _ in range(5):
        y = ref.q_ref[ref.y] + rng.uniform(-0.1, 0.1, len(ref.y))
        q, status, residual = f["closure"](y, ref.q_ref[ref.z], p)
        q = num(q)
        assert float(status) == 1 and float(residual) <= 1e-12
        assert np.max(np.abs(ref.phi(q))) <= 1e-12
        np.testing.assert_array_equal(q[ref.y], y)


@pytest.mark.parametrize("name", SHIPPED)
def test_reduced_model_matches_numpy_reference_and_kkt(name):
    """M_y, h_y, ID_y, FD_y, lambda of the CasADi model = the numpy reference = the tree's KKT to 1e-10;
    FD(ID(ydd)) = ydd to 1e-10."""
    robot, ref, f = built(name)
    p = [x.default for x in robot.parameters]
    for seed in range(3):
        q, yd, ydd, tau = state(ref, seed)
        G = ref.projection(q)
        qd = G @ yd
        np.testing.assert_allclose(num(f["phi"](q, p)), ref.phi(q), rtol=0, atol=1e-12)
        np.testing.assert_allclose(mat(f["constraint_jacobian"](q, p)), ref.constraint_jacobian(q), rtol=0, atol=1e-12)
        np.testing.assert_allclose(num(f["kdot_qd"](q, qd, p)), ref.kdot_qd(q, qd), rtol=0, atol=1e-10)
        np.testing.assert_allclose(mat(f["projection"](q, p)), G, rtol=0, atol=1e-12)
        np.testing.assert_allclose(mat(f["mass_matrix"](q, p)), ref.mass_matrix(q), rtol=0, atol=1e-10)
        np.testing.assert_allclose(num(f["bias"](q, yd, p)), ref.bias(q, yd), rtol=0, atol=1e-10)
        tau_id = num(f["inverse_dynamics"](q, yd, ydd, p))
        np.testing.assert_allclose(tau_id, ref.inverse_dynamics(q, yd, ydd), rtol=0, atol=1e-10)
        np.testing.assert_allclose(num(f["forward_dynamics"](q, yd, tau_id, p)), ydd, rtol=0, atol=1e-10)
        # forward dynamics and lambda against the tree's KKT system, solved in numpy
        ydd_fd = num(f["forward_dynamics"](q, yd, tau, p))
        qdd, lam = ref.kkt_forward_dynamics(q, qd, ref.actuation(tau))
        np.testing.assert_allclose(G @ ydd_fd + ref.gdot_yd(q, qd), qdd, rtol=0, atol=1e-10)
        np.testing.assert_allclose(num(f["constraint_forces"](q, yd, tau, p)), lam, rtol=0, atol=1e-10)
        # constrained inverse dynamics (which Pinocchio lacks) against the KKT's
        tau_kkt, lam_kkt = ref.kkt_inverse_dynamics(q, qd, G @ ydd + ref.gdot_yd(q, qd))
        np.testing.assert_allclose(tau_id, tau_kkt, rtol=0, atol=1e-10)
        np.testing.assert_allclose(num(f["constraint_forces_id"](q, yd, ydd, p)), lam_kkt, rtol=0, atol=1e-10)


@pytest.mark.parametrize("name", PLANAR)
def test_forward_dynamics_matches_pinocchio_constraint_dynamics(name):
    """Pinocchio's proximal constraintDynamics on the same tree with a CONTACT_3D RigidConstraintModel per
    loop (the planar loops' normal row is redundant there: an over-constrained system the proximal solver
    handles) gives the same qdd to 1e-8."""
    robot, ref, f = built(name)
    p = [x.default for x in robot.parameters]
    pr = PinRobot(robot)
    model = pr.model
    models, datas = pin.StdVec_RigidConstraintModel(), pin.StdVec_RigidConstraintData()
    for lp in robot.loops:
        fa, fb = model.frames[pr.frame_id(lp.a)], model.frames[pr.frame_id(lp.b)]
        cm = pin.RigidConstraintModel(pin.ContactType.CONTACT_3D, model, fa.parentJoint, fa.placement,
                                      fb.parentJoint, fb.placement, pin.ReferenceFrame.LOCAL)
        models.append(cm)
        datas.append(cm.createData())
    data = model.createData()
    pin.initConstraintDynamics(model, data, models, datas)
    for seed in range(3):
        q, yd, _, tau = state(ref, seed)
        G = ref.projection(q)
        qd = G @ yd
        ydd = num(f["forward_dynamics"](q, yd, tau, p))
        prox = pin.ProximalSettings(1e-14, 1e-12, 100)
        qdd_pin = pin.constraintDynamics(model, data, q, qd, ref.actuation(tau), models, datas, prox)
        np.testing.assert_allclose(G @ ydd + ref.gdot_yd(q, qd), qdd_pin, rtol=0, atol=1e-8)


@pytest.mark.parametrize("name", ["delta", "parallel_ankle"])
def test_rod_loops_forward_dynamics_matches_pinocchio_kkt(name):
    """Pinocchio has no 1-D distance constraint (RigidConstraintModel is 3D/6D), so the rods go
    to its KKT forwardDynamics(q, v, tau, J, gamma) with the rows built from Pinocchio's own kinematics:
    phi = (d.d - L^2)/(2L), d = p_a - p_b, K = d^T (J_a - J_b)/L, Kdot qd = (ddot.ddot + d.(a_a - a_b))/L
    (frame origins' classical accelerations at qdd = 0). Same qdd to 1e-8."""
    robot, ref, f = built(name)
    p = [x.default for x in robot.parameters]
    pr = PinRobot(robot)
    model, data = pr.model, pr.model.createData()
    world = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
    lengths = ref.lengths
    for seed in range(3):
        q, yd, _, tau = state(ref, seed)
        G = ref.projection(q)
        qd = G @ yd
        pin.forwardKinematics(model, data, q, qd, np.zeros_like(q))
        pin.updateFramePlacements(model, data)
        pin.computeJointJacobians(model, data, q)
        K, gamma = [], []
        for lp, L in zip(robot.loops, lengths):
            ia, ib = pr.frame_id(lp.a), pr.frame_id(lp.b)
            d = data.oMf[ia].translation - data.oMf[ib].translation
            ja = pin.getFrameJacobian(model, data, ia, world)[:3]
            jb = pin.getFrameJacobian(model, data, ib, world)[:3]
            dd = pin.getFrameVelocity(model, data, ia, world).linear - pin.getFrameVelocity(model, data, ib, world).linear
            acc = (pin.getFrameClassicalAcceleration(model, data, ia, world).linear
                   - pin.getFrameClassicalAcceleration(model, data, ib, world).linear)
            K.append(d @ (ja - jb) / L)
            gamma.append((dd @ dd + d @ acc) / L)
        ydd = num(f["forward_dynamics"](q, yd, tau, p))
        qdd_pin = pin.forwardDynamics(model, data, q, qd, ref.actuation(tau), np.array(K), np.array(gamma))
        np.testing.assert_allclose(G @ ydd + ref.gdot_yd(q, qd), qdd_pin, rtol=0, atol=1e-8)


@pytest.mark.parametrize("name", SHIPPED)
def test_description_check_computes_the_same_phi_and_k(name):
    robot, ref, _ = built(name)
    cl = Closure(robot)
    rng = np.random.default_rng(2)
    q = ref.q_ref + rng.uniform(-0.3, 0.3, ref.n)  # off the closure too
    np.testing.assert_allclose(cl.phi(q), ref.phi(q), rtol=0, atol=1e-14)
    np.testing.assert_allclose(cl.jacobian(q), ref.constraint_jacobian(q), rtol=0, atol=1e-13)


def rk4_step(name: str) -> ca.Function:
    """One RK4 step of x = (y, yd) under tau_y = 0, q = gamma(y) by the generated Newton closure from z."""
    robot, ref, f = built(name)
    ny = len(ref.y)
    x, z, dt = ca.MX.sym("x", 2 * ny), ca.MX.sym("z", len(ref.z)), ca.MX.sym("dt")
    p = ca.DM([v.default for v in robot.parameters])

    def rhs(x, z):
        q = f["closure"](x[:ny], z, p)[0]
        return ca.vertcat(x[ny:], f["forward_dynamics"](q, x[ny:], ca.DM.zeros(ny), p)), q[ref.z]

    k1, z1 = rhs(x, z)
    k2, z2 = rhs(x + dt / 2 * k1, z1)
    k3, z3 = rhs(x + dt / 2 * k2, z2)
    k4, z4 = rhs(x + dt * k3, z3)
    return ca.Function("rk4", [x, z, dt], [x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4), z4])


@pytest.mark.parametrize("name", ["fourbar", "example2"])
def test_rk4_in_y_keeps_the_loops_closed_and_the_energy(name):
    """1 s of RK4 at 1 ms from the reference at rest, unforced under gravity: the reconstructed q closes every
    loop to 1e-10 and the energy drifts less than 1e-8 of the largest kinetic energy (no friction)."""
    robot, ref, f = built(name)
    p = [v.default for v in robot.parameters]
    step = rk4_step(name)
    ny = len(ref.y)
    x, z = np.concatenate([ref.q_ref[ref.y], np.zeros(ny)]), ref.q_ref[ref.z]
    energies, kinetic = [], []
    for k in range(1001):
        if k % 50 == 0:
            q = num(f["closure"](x[:ny], z, p)[0])
            qd = ref.projection(q) @ x[ny:]
            assert np.max(np.abs(ref.phi(q))) <= 1e-10
            energies.append(ref.energy(q, qd))
            kinetic.append(ref.tree.kinetic_energy(q, qd))
        x, z = step(x, z, 1e-3)
        x, z = num(x), num(z)
    assert max(kinetic) > 1e-3  # it moved
    assert np.max(np.abs(np.array(energies) - energies[0])) < 1e-8 * max(kinetic)


def dof_output(capsys, name: str, models=MODELS) -> str:
    assert main(["dof", "--models", str(models), name]) == 0
    return capsys.readouterr().out


def test_dof_reports_the_rank_of_k_next_to_grubler(capsys):
    out = "".join(dof_output(capsys, name) for name in SHIPPED)
    for name in SHIPPED:
        robot = shipped()[name]
        n = robot.nq
        block = out.split(f"{name}: {'planar' if name in PLANAR else 'spatial'}", 1)[1]
        assert f"mobility = nq - rank K = {n} - {n - DOF[name]} = {DOF[name]}" in block
        assert f"agrees with Grübler's count ({DOF[name]})" in block
        assert DOF[name] == len(robot.independent)
    assert "DOF = m (N - 1 - J) + sum f_i = 3 (8 - 1 - 9) + 9 = 3" in out  # the lecture's eq. 10


def test_over_constrained_fourbar_in_3d(tmp_path, capsys):
    """The four-bar closed by a spatial hinge (5 rows): Grübler's spatial count is 6 (4 - 1 - 4) + 4 = -2, the
    rank of K is 2, the mobility 1; the reduced model is the planar loop's."""
    entry = variant("fourbar", loops=[{"frames": ["coupler_tip", "rocker_tip"], "kind": "hinge", "axis": [0, 0, 1]}])
    robot = parse(entry)
    assert robot.loop_rows is not None and len(robot.loop_rows) == 2
    path = tmp_path / "models.yaml"
    path.write_text(yaml.safe_dump({"robots": {"fourbar3d": entry}}))
    out = dof_output(capsys, "fourbar3d", path)
    assert "DOF = m (N - 1 - J) + sum f_i = 6 (4 - 1 - 4) + 4 = -2" in out
    assert "mobility = nq - rank K = 3 - 2 = 1 (K: 5 x 3" in out
    assert "differs from Grübler's count (-2) by 3: 3 of the 5 closure rows are redundant" in out
    _, planar, _ = built("fourbar")
    ref = ClosedChainReference(robot)
    f = ClosedChainModel(robot).functions()
    q, yd, ydd, tau = state(planar, 0)
    p = [v.default for v in robot.parameters]
    np.testing.assert_allclose(num(f["forward_dynamics"](q, yd, tau, p)), planar.forward_dynamics(q, yd, tau),
                               rtol=0, atol=1e-10)
    np.testing.assert_allclose(num(f["inverse_dynamics"](q, yd, ydd, p)), ref.inverse_dynamics(q, yd, ydd),
                               rtol=0, atol=1e-10)


def test_distance_and_point_loops():
    """The four-bar's coupler as a massless rod of length b (a distance loop, 1 row) and the planar four-bar
    closed by a point loop (3 rows, rank 2): the CasADi model equals the reference."""
    rod = variant("fourbar", loops=[{"frames": ["crank_tip", "rocker_tip"], "kind": "distance", "length": "b"}],
                  reference={"crank": 1.5707963267948966, "rocker": 1.8})
    rod["joints"] = [j for j in rod["joints"] if j["name"] != "coupler"]
    rod["links"] = [x for x in rod["links"] if x["name"] != "coupler"]
    rod["frames"] = [{"name": "crank_tip", "link": "crank", "xyz": ["a", 0, 0]},
                     {"name": "rocker_tip", "link": "rocker", "xyz": ["c", 0, 0]}]
    point = variant("fourbar", loops=[{"frames": ["coupler_tip", "rocker_tip"], "kind": "point"}])
    for entry, rows in ((rod, 1), (point, 2)):
        robot = parse(entry)
        assert len(robot.loop_rows) == rows and robot.independent == ("crank",)
        ref = ClosedChainReference(robot)
        f = ClosedChainModel(robot).functions()
        p = [v.default for v in robot.parameters]
        q, yd, ydd, tau = state(ref, 3)
        np.testing.assert_allclose(mat(f["constraint_jacobian"](q, p)), ref.constraint_jacobian(q), atol=1e-12)
        np.testing.assert_allclose(num(f["forward_dynamics"](q, yd, tau, p)), ref.forward_dynamics(q, yd, tau),
                                   rtol=0, atol=1e-10)
        qdd, lam = ref.kkt_forward_dynamics(q, ref.projection(q) @ yd, ref.actuation(tau))
        np.testing.assert_allclose(num(f["constraint_forces"](q, yd, tau, p)), lam, rtol=0, atol=1e-10)


def test_default_independent_by_pivoting_prefers_actuated_joints():
    robot = shipped()["fivebar"]  # no independent: given; the motors have effort limits
    assert robot.independent_chosen and robot.independent == ("motor1", "motor2")
    assert robot.dependent == ("elbow1", "elbow2")
    crank = parse(variant("fourbar", independent=None))
    assert crank.independent == ("crank",) and crank.independent_chosen


BAD = [
    ({"loops": [{"frames": ["coupler_tip", "nowhere"], "kind": "planar", "normal": [0, 0, 1]}]},
     "loops[0].frames: unknown frame 'nowhere'"),
    ({"loops": [{"frames": ["coupler_tip", "rocker_tip"], "kind": "ball"}]}, "loops[0].kind: unknown loop kind 'ball'"),
    ({"loops": [{"frames": ["coupler_tip", "rocker_tip"], "kind": "hinge"}]},
     "loops[0].axis: missing: a hinge loop needs 'axis'"),
    ({"loops": [{"frames": ["coupler_tip", "rocker_tip"], "kind": "point", "length": 1}]},
     "loops[0].length: a point loop has no 'length'"),
    ({"parameters": {"a": 0.15, "b": 0.45, "c": 0.35, "d": 2.0, "g": 9.81}},
     "loops[0].frames: 'coupler_tip' and 'rocker_tip' do not close at the reference configuration: residual max |phi| ="),
    ({"loops": [{"frames": ["coupler_tip", "rocker_tip"], "kind": "planar", "normal": [0, 0, 1]}] * 2},
     "loops[0]: redundant: it constrains nothing the other loops do not (rank K = 2 with or without it)"),
    ({"independent": ["crank", "rocker"]},
     "independent: 2 coordinate(s) given, but the loops leave nq - rank K = 3 - 2 = 1 degree(s) of freedom"),
    ({"independent": ["knee"]}, "independent[0]: unknown coordinate 'knee'"),
    ({"reference": {"knee": 1}}, "reference.knee: unknown coordinate"),
    ({"loops": [{"frames": ["coupler_tip", "rocker_tip"], "kind": "weld"}]},
     "loops: the loops leave no degree of freedom: rank K = 3 = nq at the reference configuration (a structure)"),
    ({"base": "floating"}, "loops: closed chains need a fixed base here"),
]


@pytest.mark.parametrize("changes,message", BAD, ids=[m.split(":")[0] + str(i) for i, (_, m) in enumerate(BAD)])
def test_bad_loops_are_one_line_errors(tmp_path, capsys, changes, message):
    path = tmp_path / "models.yaml"
    path.write_text(yaml.safe_dump({"robots": {"fourbar": variant("fourbar", **changes)}}))
    assert main(["dof", "--models", str(path), "fourbar"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"derive: error: {path}: robot 'fourbar': ") and message in err, err
    assert err.count("\n") == 1


def test_independent_set_that_is_no_chart():
    """theta1 and theta2 both in the four-bar of example2 (one DOF): K_z loses the four-bar's rank."""
    with pytest.raises(Exception, match=r"independent: \(theta1, theta2, theta4\) is not a valid chart at the "
                                        r"reference configuration: K_z is singular"):
        parse(variant("example2", independent=["theta1", "theta2", "theta4"]))


def test_info_states_the_chart(capsys):
    assert main(["info", "--models", str(MODELS), "fivebar"]) == 0
    out = capsys.readouterr().out
    assert ("closed chain: 1 loop(s), 2 closure rows, rank 2; independent y = (motor1, motor2) chosen by pivoting on "
            "K at the reference configuration") in out
