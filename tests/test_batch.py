"""Batched generated Python (issue 15): every function of every robot takes inputs (..., n) of any
leading batch shape, broadcast against each other, and returns (..., *shape), bit for bit what it
returns for each state alone; one state (1-D inputs) returns exactly the shapes of the manifest.

The code is generated into a temporary folder (generated/ is not read). IK solves a batch one
state after the other (the documented exception), so its batches stay small.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from derive.codegen.backends.python import BACKEND
from derive.codegen.render import render_robot
from derive.codegen.spec import FunctionSpec
from util import closed_inputs, load_module, params, robots

ROBOTS = sorted(robots())
BATCHES = [(7,), (3, 4), (10000,)]
IK_BATCHES = [(7,), (3, 4)]  # a Python loop of solves: 10000 of them would take minutes


@pytest.fixture(scope="module")
def generated(generated_copy) -> Path:
    return generated_copy("batch")  # the committed generated/ (conftest.py), this module's copy


def load(generated: Path, robot: str):
    manifest = json.loads((generated / robot / "manifest.json").read_text())
    return load_module(generated / robot / "python" / f"{robot}.py", f"batch_{robot}"), manifest


def random_inputs(robot: str, module, fn: dict, shape: tuple, rng: np.random.Generator) -> dict:
    """Seeded inputs of fn, each of the full batch shape (shape + its own); T reachable: fk of a random q
    with the same p."""
    r = robots()[robot]
    lo, hi = r.joint_box()
    names = [i["name"] for i in fn["inputs"]]
    a = {"p": params(r) * rng.uniform(0.9, 1.1, shape + (len(r.parameters),))} if "p" in names else {}
    closed = closed_inputs(r, rng, shape) if r.closed else {}  # y near the reference configuration
    for item in fn["inputs"]:
        name, n = item["name"], item["shape"][0]
        if name in ("y", "x") and closed and fn.get("coordinates") == "y" or name in ("o", "w0") and closed:
            a[name] = closed[name]
        elif name in ("q", "q0"):
            a[name] = rng.uniform(lo, hi, shape + (n,))
        elif name == "p":
            continue
        elif name == "dt":
            a[name] = rng.uniform(0.001, 0.02, shape + (1,))
        elif name == "x":
            a[name] = np.concatenate([rng.uniform(lo, hi, shape + (r.nq,)), rng.normal(size=shape + (r.nv,))], axis=-1)
        elif name == "T":
            extra = [a["p"]] if "p" in a else []
            a[name] = getattr(module, f"fk_{fn['frame']}")(rng.uniform(lo, hi, shape + (r.nq,)), *extra)
        elif name == "w" and fn["quantity"] == "ik":  # left to its default (None) in one batch shape, per state in the others
            a[name] = None if shape == (7,) else rng.uniform(0.5, 1.5, shape + (n,))
        else:
            a[name] = rng.normal(size=shape + (n,))
    return a


def outputs(value, fn: dict) -> tuple:
    return value if len(fn["python"]["returns"]) > 1 else (value,)


SAMPLE_STRIDE, SAMPLE_EDGE = 16, 64


def sample(shape: tuple) -> np.ndarray:
    """Flat indices of the states of a batch ``shape`` checked one by one: all of a small batch; of
    a large one every SAMPLE_STRIDE-th and the first and last SAMPLE_EDGE."""
    n = int(np.prod(shape))
    if n <= 4 * SAMPLE_EDGE:
        return np.arange(n)
    return np.unique(np.r_[0:SAMPLE_EDGE, SAMPLE_EDGE:n - SAMPLE_EDGE:SAMPLE_STRIDE, n - SAMPLE_EDGE:n])


def per_state(f, args: list, shape: tuple, fn: dict) -> list[np.ndarray]:
    """f called on each state of the batch alone, stacked to shape + each output's shape."""
    returns = fn["python"]["returns"]
    stacked = [np.empty(shape + tuple(o["shape"]), dtype=int if o["shape"] == [] else float) for o in returns]
    for idx in np.ndindex(shape):
        for k, v in enumerate(outputs(f(*[None if a is None else a[idx] for a in args]), fn)):
            stacked[k][idx] = v
    return stacked


def assert_bits(got: np.ndarray, want: np.ndarray, what: str) -> None:
    assert got.shape == want.shape and got.dtype == want.dtype, f"{what}: {got.shape} {got.dtype} != {want.shape} {want.dtype}"
    same = got.view(np.uint8).reshape(got.shape + (-1,)) == want.view(np.uint8).reshape(want.shape + (-1,))
    bad = ~same.all(axis=-1) if got.ndim else ~same.all()
    assert not bad.any(), (f"{what}: {int(bad.sum())} entries differ in their bits, e.g. {got[bad][:3]} != {want[bad][:3]}")


@pytest.mark.parametrize("robot", ROBOTS)
def test_batches_equal_the_states_one_by_one_bit_for_bit(robot, generated):
    """Batches (7,), (3, 4) and (10000,) of seeded states: each output (..., *shape), float64 (status
    an int array), equal in its bits to calling the function on each state alone (of the 10 000,
    745 of them: sample)."""
    module, manifest = load(generated, robot)
    rng = np.random.default_rng(15)
    checked = 0
    for fn in manifest["functions"]:
        f = getattr(module, fn["python"]["function"])
        returns = fn["python"]["returns"]
        for shape in IK_BATCHES if fn["quantity"] == "ik" else BATCHES:
            a = random_inputs(robot, module, fn, shape, rng)
            args = [a[i["name"]] for i in fn["inputs"]]
            with warnings.catch_warnings():
                warnings.simplefilter("error")  # a batch of valid states raises no numpy warning
                got = outputs(f(*args), fn)
            assert isinstance(got, tuple) and len(got) == len(returns), fn["name"]
            # of the large batch (several chunks where a function needs many registers), every
            # SAMPLE_STRIDE-th state and the first and last SAMPLE_EDGE (one by one, a panda batch
            # of 10 000 took 30 s): each alone in its bits
            pick = sample(shape)
            want = per_state(f, [None if x is None else x.reshape((-1,) + x.shape[len(shape):])[pick] for x in args],
                             pick.shape, fn)
            for g, w, declared in zip(got, want, returns):
                what = f"{fn['name']} batch {shape} -> {declared['name']}"
                assert isinstance(g, np.ndarray), what
                assert g.shape == shape + tuple(declared["shape"]), f"{what}: shape {g.shape}"
                assert g.dtype == (np.dtype(int) if declared["shape"] == [] else np.float64), what
                assert g.flags.c_contiguous, what
                assert_bits(g.reshape((-1,) + g.shape[len(shape):])[pick], w, what)
            checked += 1
    assert checked == sum(2 if fn["quantity"] == "ik" else 3 for fn in manifest["functions"])


@pytest.mark.parametrize("robot", ROBOTS)
def test_one_state_returns_the_shapes_of_the_manifest(robot, generated):
    """1-D inputs: the value itself (one output) or a tuple, each a float64 array of exactly the
    declared shape (no batch axis), a status a Python int; lists work as arrays do."""
    module, manifest = load(generated, robot)
    rng = np.random.default_rng(16)
    for fn in manifest["functions"]:
        f = getattr(module, fn["python"]["function"])
        a = {k: (None if v is None else v[0]) for k, v in random_inputs(robot, module, fn, (1,), rng).items()}
        args = [a[i["name"]] for i in fn["inputs"]]
        value = f(*args)
        returns = fn["python"]["returns"]
        values = value if len(returns) > 1 else (value,)
        assert isinstance(values, tuple) and len(values) == len(returns), fn["name"]
        listed = outputs(f(*[None if v is None else v.tolist() for v in args]), fn)
        for v, v_list, declared in zip(values, listed, returns):
            if declared["shape"] == []:
                assert type(v) is int and v == v_list, fn["name"]
            else:
                assert isinstance(v, np.ndarray) and v.dtype == np.float64 and list(v.shape) == declared["shape"], \
                    f"{fn['name']} -> {declared['name']}: {v.shape} != {declared['shape']}"
                assert_bits(v_list, v, f"{fn['name']} from lists")


@pytest.mark.parametrize("robot", [r for r in ROBOTS if robots()[r].parameters])
def test_one_p_broadcasts_against_a_batch(robot, generated):
    """One p (1-D) for a batch of states, a batch of p for one state, the default p for a batch,
    and batch shapes (3, 4) and (4,) broadcasting: each the per-state results bit for bit."""
    module, manifest = load(generated, robot)
    r = robots()[robot]
    rng = np.random.default_rng(17)
    lo, hi = r.joint_box()
    p1 = params(r) * rng.uniform(0.9, 1.1, len(r.parameters))
    Q = rng.uniform(lo, hi, (50, r.nq))
    P = params(r) * rng.uniform(0.9, 1.1, (50, len(r.parameters)))
    for name in ("mass_matrix", "gravity", "fk_jacobian_tcp", "manipulability_tcp"):
        if not hasattr(module, name):
            continue
        f = getattr(module, name)
        fn = next(x for x in manifest["functions"] if x["python"]["function"] == name)
        for got, want in (
            (f(Q, p1), per_state(lambda q: f(q, p1), [Q], (50,), fn)),
            (f(Q[0], P), per_state(lambda p: f(Q[0], p), [P], (50,), fn)),
            (f(Q), per_state(lambda q: f(q, module.DEFAULT_P), [Q], (50,), fn)),
        ):
            for g, w in zip(outputs(got, fn), want):
                assert_bits(g, w, name)
    nq, nv, fd = r.nq, r.nv, "forward_dynamics"
    q = rng.uniform(lo, hi, (3, 4, nq))
    if r.closed:  # the closed chain's forward dynamics and ODE, in y near the reference configuration
        nq = nv = len(r.independent)
        fd, q = "forward_dynamics_y", closed_inputs(r, rng, (3, 4))["y"]
    qd, tau = rng.normal(size=(4, nv)), rng.normal(size=(nv,))
    got = getattr(module, fd)(q, qd, tau, P[:4])
    assert got.shape == (3, 4, nv)
    for i, j in np.ndindex(3, 4):
        assert_bits(got[i, j], getattr(module, fd)(q[i, j], qd[j], tau, P[j]), "forward_dynamics broadcast")
    x = np.concatenate([q, np.broadcast_to(qd, (3, 4, nv))], axis=-1)
    step = module.rk4_step(x, tau, 0.01, p1)  # one dt (a number) for the batch
    assert step.shape == (3, 4, nq + nv)
    for i, j in np.ndindex(3, 4):
        assert_bits(step[i, j], module.rk4_step(x[i, j], tau, [0.01], p1), "rk4_step with one dt")


@pytest.mark.parametrize("robot", ["panda", "pendulum"])
def test_a_batch_of_several_chunks_equals_the_states_one_by_one(robot, generated):
    """A batch runs in chunks of at most _CHUNK states (one chunk in the batches above): with
    chunks of 7, a batch (5, 10) of 50 states is 8 chunks, the last one shorter, and the outputs,
    constant entries included, are still each state's bit for bit; one p for all states as well,
    and a batch of one state (1, 1) (run as two copies of it)."""
    module, manifest = load(generated, robot)
    module._CHUNK = 7
    rng = np.random.default_rng(19)
    for fn in manifest["functions"]:
        if fn["quantity"] == "ik":
            continue
        f = getattr(module, fn["python"]["function"])
        for shape in ((5, 10), (1, 1)):
            a = random_inputs(robot, module, fn, shape, rng)
            if "p" in a:
                a["p"] = a["p"].reshape(-1, a["p"].shape[-1])[0]
            args = [a[i["name"]] for i in fn["inputs"]]
            got = outputs(f(*args), fn)
            want = per_state(f, [v if v.ndim > 1 else np.broadcast_to(v, shape + v.shape) for v in args], shape, fn)
            for g, w, declared in zip(got, want, fn["python"]["returns"]):
                assert g.shape == w.shape and g.flags.c_contiguous, fn["name"]
                assert_bits(g, w, f"{fn['name']} batch {shape} in chunks of 7 -> {declared['name']}")


def test_inputs_are_checked_and_a_number_is_one_element(generated):
    module, _ = load(generated, "planar_2r")
    with pytest.raises(ValueError, match="q must have 2 elements in its last axis, got shape \\(5, 3\\)"):
        module.mass_matrix(np.zeros((5, 3)))
    with pytest.raises(ValueError, match="q must have 2 elements"):
        module.mass_matrix(0.3)
    with pytest.raises(ValueError, match="shape mismatch|broadcast"):
        module.inverse_dynamics(np.zeros((5, 2)), np.zeros((4, 2)), np.zeros(2))
    assert module.mass_matrix(np.zeros((0, 2))).shape == (0, 2, 2)
    pendulum, _ = load(generated, "pendulum")
    assert_bits(pendulum.gravity(0.3), pendulum.gravity([0.3]), "a number for q [1]")
    assert pendulum.gravity(np.array([[0.3], [0.4]])).shape == (2, 1)


def test_every_function_a_body_calls_is_bit_exact_in_a_batch(tmp_path):
    """The robots' bodies call sin and cos only; every other function CasADi can emit (numpy's SIMD
    tan, exp, log, ... can differ from libm in the last bit) is bound so that a batch still equals
    the states one by one in every bit, and one state matches CasADi (the same libm)."""
    q = ca.SX.sym("q", 3)
    body = ca.vertcat(ca.sin(q[0]) * ca.cos(q[1]), ca.tan(q[0]), ca.sqrt(ca.fabs(q[1]) + 0.5), ca.exp(q[2]),
                      ca.log(ca.fabs(q[0]) + 1.0), ca.asin(q[0] / 4.0), ca.acos(q[1] / 4.0), ca.atan(q[2]),
                      ca.tanh(q[0]), ca.power(ca.fabs(q[1]) + 0.1, q[2]), ca.atan2(q[0], q[1]), ca.fmin(q[0], q[1]),
                      ca.fmax(q[0], q[2]), q[1], 2.5)
    spec = FunctionSpec("toy", "every_op", None, (("q", q),), (("y", body),), "every function a body can call")
    text = render_robot(robots()["pendulum"], [spec], "0", backends=[BACKEND])["python/pendulum.py"]
    for name in ("tan", "exp", "log", "asin", "acos", "atan", "tanh", "pow", "atan2", "fmin", "fmax"):
        assert f"_batch_{name}" in text, name
    (tmp_path / "every_op.py").write_text(text)
    module = load_module(tmp_path / "every_op.py", "every_op")
    rng = np.random.default_rng(18)
    Q = rng.uniform(-3.0, 3.0, (20000, 3))
    Q[:10, 1] = Q[:10, 0]  # ties of fmin/fmax
    got = module.every_op(Q)
    assert got.shape == (20000, 15)
    want = np.array([module.every_op(x) for x in Q])
    assert_bits(got, want, "every_op")
    reference = ca.Function("f", [q], [body])
    for x, y in zip(Q[:200], want[:200]):
        np.testing.assert_allclose(y, np.asarray(reference(x)).reshape(-1), rtol=1e-14, atol=0.0)
