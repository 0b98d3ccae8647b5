"""Inverse kinematics (derive.solvers.ik, generated <robot>_ik_tcp): targets reached within the joint
limits as checked with the independent numpy reference FK; unreachable targets fail honestly
(finite residual, success False); singular configurations stay finite; the generated C and
Python agree with the API's notion of success.
"""

from __future__ import annotations

import ctypes

import casadi as ca
import numpy as np
import pytest

from derive.bench.ik import ik_sources, pose_errors, targets, verified
from derive.cli import main
from derive.errors import DeriveError
from derive.solvers.ik import solve_ik
from derive.symbolic.ik import TOL_POSITION, TOL_ROTATION, joint_ranges
from derive.reference import NumericRobot
from derive.symbolic.spatial import exp_so3, log_so3
from util import build_library, load_module, robots

CFLAGS = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic"]
N_TARGETS = 150
# deterministic runs: the iteration cap binds, never the wall-time cap
SOLVE = {"timeout": 60.0, "max_iterations": 20000}


def test_log_so3_inverts_exp_so3_including_near_0_and_pi():
    w = ca.SX.sym("w", 3)
    roundtrip = ca.Function("f", [w], [log_so3(exp_so3(w))])
    rng = np.random.default_rng(0)
    for angle in (0.0, 1e-12, 1e-6, 0.3, 2.0, np.pi - 1e-6, np.pi - 1e-10):
        axis = rng.normal(size=3)
        wv = angle * axis / np.linalg.norm(axis)
        assert np.abs(np.array(roundtrip(wv)).ravel() - wv).max() < 1e-9, angle
    at_pi = np.array(roundtrip(np.pi * np.array([0.0, 0.6, 0.8]))).ravel()   # sign is free at pi
    assert min(np.abs(at_pi - np.pi * np.array([0, 0.6, 0.8])).max(), np.abs(at_pi + np.pi * np.array([0, 0.6, 0.8])).max()) < 1e-12


@pytest.mark.parametrize("robot", ["panda", "ur5"])
def test_solve_ik_reaches_random_targets_within_limits(robot):
    """TRAC-IK protocol on a sample: every target reached, checked with the reference FK."""
    r = robots()[robot]
    _, Ts = targets(r, N_TARGETS, seed=1)
    results = [solve_ik(r, T, seed=k, **SOLVE) for k, T in enumerate(Ts)]
    assert all(res.success for res in results)
    assert verified(r, np.array([res.q for res in results]), Ts).all()
    assert all(res.position_error < TOL_POSITION and res.rotation_error < TOL_ROTATION for res in results)


def test_position_only_and_weighted_targets():
    r = robots()["panda"]
    ref = NumericRobot(r)
    res = solve_ik(r, [0.4, -0.2, 0.5], **SOLVE)
    assert res.success and res.rotation_error == 0.0
    assert np.linalg.norm(ref.frame_pose(res.q, "tcp")[:3, 3] - [0.4, -0.2, 0.5]) < TOL_POSITION
    # a pose whose rotation about world z is free: only the other rows count
    T = ref.frame_pose(np.array([0.1, -0.4, 0.2, -2.1, 0.1, 1.9, 0.3]), "tcp")
    T[:3, :3] = np.array(ca.DM(exp_so3([0, 0, 0.7]))) @ T[:3, :3]
    res = solve_ik(r, T, weights=[1, 1, 1, 1, 1, 0], **SOLVE)
    assert res.success
    z_tool = ref.frame_pose(res.q, "tcp")[:3, 2]
    assert abs(z_tool[2] - T[2, 2]) < 1e-4


@pytest.mark.parametrize("robot", ["panda", "ur5"])
def test_unreachable_target_fails_with_the_smallest_residual_found(robot):
    r = robots()[robot]
    T = np.eye(4)
    T[:3, 3] = [3.0, 0.0, 0.5]   # beyond reach of either arm (about 1 m)
    res = solve_ik(r, T, max_iterations=600, timeout=60.0)
    assert not res.success
    assert np.isfinite(res.q).all() and np.isfinite([res.position_error, res.rotation_error]).all()
    lo, hi, _, _ = joint_ranges(r)
    assert np.all(res.q >= lo) and np.all(res.q <= hi)
    assert res.iterations <= 600 + 100 and res.restarts > 0   # the cap binds (IPOPT may add its iterations)
    pos, _ = pose_errors(NumericRobot(r), res.q, T)
    assert pos == pytest.approx(res.position_error, abs=1e-9)
    assert pos < 3.0 - 0.5   # the best of the restarts: it stretched towards the target


def test_ur5_wrist_singularity_stays_finite_and_converges():
    """q5 = 0 aligns the wrist axes (J loses rank): starting there and reaching a target there."""
    r = robots()["ur5"]
    ref = NumericRobot(r)
    q_sing = np.array([0.5, -1.0, 1.2, 0.3, 0.0, 0.7])
    assert np.linalg.svd(ref.jacobian(q_sing, "tcp"), compute_uv=False)[-1] < 1e-12
    T = ref.frame_pose(q_sing, "tcp")
    for q0 in (q_sing, np.array([0.5, -1.0, 1.2, 0.0, 0.0, 0.0]), np.zeros(6)):
        res = solve_ik(r, T, q0=q0, method="lm", **SOLVE)
        assert res.success and np.isfinite(res.q).all()
    # a reachable target next to the singularity, from the singular start
    T2 = ref.frame_pose(q_sing + [0, 0, 0, 0, 1e-3, 0], "tcp")
    res = solve_ik(r, T2, q0=q_sing, method="lm", **SOLVE)
    assert res.success and verified(r, res.q[None], T2[None]).all()


def test_targets_at_the_joint_limits_are_reached():
    r = robots()["panda"]
    lo, hi, _, _ = joint_ranges(r)
    q = np.array([0.2, -0.3, 0.1, hi[3], 0.2, lo[5], hi[6]])   # three joints on a limit
    T = NumericRobot(r).frame_pose(q, "tcp")
    res = solve_ik(r, T, **SOLVE)
    assert res.success and verified(r, res.q[None], T[None]).all()


def test_opti_method_and_rest_posture():
    r = robots()["panda"]
    ref = NumericRobot(r)
    T = ref.frame_pose(np.array([0.3, -0.5, 0.2, -2.0, 0.1, 1.8, 0.5]), "tcp")
    res = solve_ik(r, T, method="opti", **SOLVE)
    assert res.success and verified(r, res.q[None], T[None]).all()
    rest = np.array([0.0, -0.3, 0.0, -2.2, 0.0, 2.0, 0.8])
    plain = solve_ik(r, T, q0=rest, **SOLVE)
    near = solve_ik(r, T, q0=rest, rest=rest, **SOLVE)
    assert near.success and verified(r, near.q[None], T[None]).all()
    assert np.linalg.norm(near.q - rest) < np.linalg.norm(plain.q - rest) - 1e-3   # moved along the self-motion


def test_bad_input_is_a_one_line_error():
    T = np.eye(4)
    with pytest.raises(DeriveError, match="4x4 pose or a position"):
        solve_ik("panda", np.zeros(5))
    with pytest.raises(DeriveError, match="not a rotation matrix"):
        solve_ik("panda", 2 * T)
    with pytest.raises(DeriveError, match="finite"):
        solve_ik("panda", [np.nan, 0, 0])
    with pytest.raises(DeriveError, match="q0 must be 7"):
        solve_ik("panda", T, q0=[0, 0])
    with pytest.raises(DeriveError, match="no frame 'nose'"):
        solve_ik("panda", T, frame="nose")
    with pytest.raises(DeriveError, match="does not move"):
        solve_ik("ur5", T, frame="base_link")
    with pytest.raises(DeriveError, match="weights"):
        solve_ik("panda", T, weights=[0] * 6)


def test_cli_prints_q_and_residuals(capsys):
    assert main(["ik", "panda", "--xyz", "0.4", "0.1", "0.5", "--rpy", "3.14159", "0", "0"]) == 0
    out = capsys.readouterr().out
    assert "solved" in out and "panda_joint7" in out and "position error" in out
    assert main(["ik", "ur5", "--xyz", "3", "0", "0", "--timeout", "0.05"]) == 1
    assert "NOT solved" in capsys.readouterr().out
    assert main(["ik", "ur5", "--xyz", "0.3", "0", "0", "--q0", "1", "2"]) == 2
    assert "q0 must be 6" in capsys.readouterr().err


# ---- generated C and Python ----

@pytest.fixture(scope="module")
def generated(generated_copy):
    return generated_copy("ik")  # the committed generated/ (conftest.py): panda, ur5, pendulum used here


def python_module(generated, robot: str):
    module = load_module(generated / robot / "python" / f"{robot}.py", f"generated_{robot}")
    return module


class CIk:
    """<robot>_ik_tcp through ctypes."""

    def __init__(self, generated, robot: str, build, extra=()):
        c_dir = generated / robot / "c"
        lib = build_library(["cc", *CFLAGS, "-O2", "-fPIC", *extra], ik_sources(c_dir, robot),
                            build / f"lib{robot}_ik{''.join(extra)}.so")
        self.real = ctypes.c_float if "-DDERIVE_FLOAT" in extra else ctypes.c_double
        self.np_real = np.float32 if self.real is ctypes.c_float else np.float64
        self.fn = getattr(ctypes.CDLL(str(lib)), f"{robot}_ik_tcp")
        self.fn.restype = ctypes.c_int
        self.nv, self.p = robots()[robot].nv, [par.default for par in robots()[robot].parameters]

    def __call__(self, T, q0=None, w=None):
        ptr = ctypes.POINTER(self.real)
        arr = lambda a: None if a is None else np.ascontiguousarray(a, dtype=self.np_real)  # noqa: E731
        ins = [arr(T), arr(q0), arr(w)] + ([arr(self.p)] if self.p else [])
        q, residual = np.zeros(self.nv, self.np_real), np.zeros(2, self.np_real)
        status = self.fn(*[None if a is None else a.ctypes.data_as(ptr) for a in ins],
                         q.ctypes.data_as(ptr), residual.ctypes.data_as(ptr))
        return q.astype(float), residual.astype(float), status


@pytest.fixture(scope="module")
def c_ik(generated, tmp_path_factory):
    """c_ik(robot, extra=()) -> CIk: each robot and set of flags built once for the module's tests."""
    build, built = tmp_path_factory.mktemp("ik_c"), {}

    def get(robot: str, extra=()) -> CIk:
        if (robot, tuple(extra)) not in built:
            built[robot, tuple(extra)] = CIk(generated, robot, build, extra)
        return built[robot, tuple(extra)]

    return get


@pytest.mark.parametrize("robot", ["panda", "ur5"])
def test_generated_c_ik_reaches_random_targets(robot, c_ik):
    r = robots()[robot]
    c_ik = c_ik(robot)
    _, Ts = targets(r, N_TARGETS, seed=2)
    out = [c_ik(T) for T in Ts]
    assert all(status == 0 for _, _, status in out)
    assert verified(r, np.array([q for q, _, _ in out]), Ts).all()
    ref = NumericRobot(r)
    for (q, residual, _), T in zip(out, Ts):
        assert residual == pytest.approx(pose_errors(ref, q, T), abs=1e-9)
    # unreachable: not converged, finite, within the limits; bad input: status 2, no NaN
    T = np.eye(4)
    T[:3, 3] = [3.0, 0.0, 0.5]
    q, residual, status = c_ik(T, q0=np.zeros(r.nv), w=np.ones(6))
    lo, hi, _, _ = joint_ranges(r)
    assert status == 1 and np.isfinite(residual).all() and residual[0] > 1.0 and np.all((q >= lo) & (q <= hi))
    for bad in ({"T": T * np.nan}, {"T": np.eye(4), "w": -np.ones(6)}, {"T": np.eye(4), "w": np.zeros(6)}):
        q, residual, status = c_ik(**bad)
        assert status == 2 and np.isfinite(q).all() and not np.isnan(residual).any()


def test_generated_c_ik_at_the_ur5_wrist_singularity(c_ik):
    r = robots()["ur5"]
    ref = NumericRobot(r)
    c_ik = c_ik("ur5")
    q_sing = np.array([0.5, -1.0, 1.2, 0.3, 0.0, 0.7])
    for q_target in (q_sing, q_sing + [0, 0, 0, 0, 1e-3, 0]):
        T = ref.frame_pose(q_target, "tcp")
        q, residual, status = c_ik(T, q0=q_sing)
        assert status == 0 and np.isfinite(q).all() and verified(r, q[None], T[None]).all()


def test_generated_float_c_and_python_ik_and_parameters(generated, c_ik):
    r = robots()["panda"]
    _, Ts = targets(r, 20, seed=3)
    c_float = c_ik("panda", extra=("-DDERIVE_FLOAT",))
    assert sum(c_float(T)[2] == 0 for T in Ts) >= 18   # single precision: a few may stall at ~1e-5
    py = python_module(generated, "panda")
    c_double = c_ik("panda")
    for T in Ts[:5]:
        q_py, res_py, status_py = py.ik_tcp(T)
        q_c, res_c, status_c = c_double(T)
        assert status_py == status_c == 0
        assert verified(r, q_py[None], T[None]).all()
        # the same algorithm in the same order of operations: the same iterate
        np.testing.assert_allclose(q_py, q_c, rtol=0, atol=1e-9)
        np.testing.assert_allclose(res_py, res_c, rtol=0, atol=1e-12)
    # a robot with parameters (p last among the inputs): the pendulum's bob, position only
    pendulum = c_ik("pendulum")
    T = np.eye(4)
    T[:3, 3] = [-np.sin(0.4), 0.0, -np.cos(0.4)]   # Ry(q) [0, 0, -l], l = 1
    q, residual, status = pendulum(T, w=[1, 1, 1, 0, 0, 0])
    assert status == 0 and q[0] == pytest.approx(0.4, abs=1e-6)
    q, residual, status = python_module(generated, "pendulum").ik_tcp(T, w=[1, 1, 1, 0, 0, 0])
    assert status == 0 and q[0] == pytest.approx(0.4, abs=1e-6)


# ---- the generated IK's input contract: BAD_INPUT (2), q mid-range, never a NaN residual ----

def bad_inputs(T: np.ndarray, nv: int) -> dict[str, dict]:
    """Calls that must return DERIVE_IK_BAD_INPUT, by name: non-finite q0, T or w, T not a rigid transform."""
    scaled, reflected, last_row, skewed = 2 * T, T.copy(), T.copy(), T.copy()
    scaled[3, 3] = 1.0                       # the rotation block scaled by 2 (and the position)
    reflected[:3, 0] *= -1                   # orthonormal, det -1
    last_row[3, 0] = 0.5
    skewed[0, 1] += 1e-3                     # R R^T = I off by 1e-3
    cases = {f"q0 {v}": {"T": T, "q0": np.where(np.arange(nv) == 2, v, 0.0)} for v in (np.nan, np.inf, -np.inf)}
    cases.update({"T NaN": {"T": T * np.nan}, "T one inf": {"T": np.where(np.arange(16).reshape(4, 4) == 3, np.inf, T)},
                  "w NaN": {"T": T, "w": [1, 1, np.nan, 1, 1, 1]}, "w inf": {"T": T, "w": [np.inf, 1, 1, 1, 1, 1]},
                  "T scaled by 2": {"T": scaled}, "T a reflection": {"T": reflected},
                  "last row not 0 0 0 1": {"T": last_row}, "R not orthonormal": {"T": skewed}})
    return cases


def assert_bad_input(result, mid, what: str) -> None:
    q, residual, status = result
    assert status == 2, what
    np.testing.assert_allclose(q, mid, rtol=0, atol=1e-6, err_msg=what)
    assert not np.isnan(residual).any() and (np.asarray(residual) > 1e20).all(), what


@pytest.mark.parametrize("robot", ["panda", "ur5"])
def test_generated_c_and_python_ik_reject_bad_input(robot, generated, c_ik):
    r = robots()[robot]
    _, _, slo, shi = joint_ranges(r)
    mid = 0.5 * (slo + shi)
    _, Ts = targets(r, 1, seed=4)
    T = Ts[0]
    solvers = {"C": c_ik(robot), "C float": c_ik(robot, extra=("-DDERIVE_FLOAT",)),
               "Python": python_module(generated, robot).ik_tcp}
    for name, solve in solvers.items():
        for what, call in bad_inputs(T, r.nv).items():
            assert_bad_input(solve(**call), mid, f"{name}: {what}")
        # the same target, its rotation off by far less than the tolerance: accepted and solved
        noisy = T.copy()
        noisy[:3, :3] += (1e-9 if name != "C float" else 1e-6) * np.random.default_rng(0).normal(size=(3, 3))
        solved = (0,) if name != "C float" else (0, 1)   # single precision may stall at ~1e-5
        assert solve(T=noisy)[2] in solved, name
        assert solve(T=T, q0=np.full(r.nv, 1e3))[2] in solved, name   # finite q0 far outside: clipped, not rejected


@pytest.mark.parametrize("flags", [("-ffast-math",), ("-Ofast",), ("-ffast-math", "-DDERIVE_FLOAT")])
def test_generated_c_ik_under_fast_math_never_reports_success_for_non_finite_input(flags, c_ik):
    """-ffast-math lets the compiler delete isfinite() and compare NaN below any tolerance: the
    checks read the bits instead, so a NaN target is still BAD_INPUT and a solve still solves."""
    r = robots()["panda"]
    _, _, slo, shi = joint_ranges(r)
    c_ik = c_ik("panda", extra=flags)
    _, Ts = targets(r, 10, seed=5)
    for what, call in bad_inputs(Ts[0], r.nv).items():
        q, residual, status = c_ik(**call)
        assert status == 2 and np.isfinite(q).all() and not np.isnan(residual).any(), what
    q, residual, status = c_ik(np.full((4, 4), np.nan), q0=np.full(r.nv, np.nan), w=np.full(6, np.nan))
    assert status == 2 and not np.isnan(residual).any()
    solved = [c_ik(T) for T in Ts]
    assert sum(status == 0 for _, _, status in solved) >= 9
    assert all(np.isfinite(res).all() and np.isfinite(q).all() for q, res, status in solved if status == 0)
