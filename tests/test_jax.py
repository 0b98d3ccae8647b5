"""The JAX backend (generated/<robot>/jax/<robot>.py): every function it provides agrees with the
numpy module of the same folder to 1e-12 relative, one state at a time and on batches (leading
batch shapes, parameters batched too); jax.jit and jax.vmap give the same; jax.grad of
tau . inverse_dynamics w.r.t. q and qd matches the numpy ode_jac_x blocks (and a central
difference); the manifest entries say what each function returns, null for IK, which this
flavour leaves out; generating needs no jax.
"""

from __future__ import annotations

import functools
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

# XLA_FLAGS for these tests' compiles (LLVM at -O0, the loop emitters): tests/conftest.py
jax = pytest.importorskip("jax", reason="the jax extra is not installed (pip install derive-robotics[jax])")
# float64, as a user of the modules turns it on (importing one changes no JAX setting:
# test_import_changes_no_jax_setting, in a fresh process)
jax.config.update("jax_enable_x64", True)

from derive.codegen.generate import generate  # noqa: E402
from derive.description.model import load_models, parse_models  # noqa: E402

from util import assert_close, closed_inputs, load_module  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
MODELS = load_models()
ROBOTS = sorted(MODELS)
RTOL = 1e-12  # the target: the same arithmetic, so agreement to rounding
# one state at a time: the shapes and values of unbatched calls (two states of the small robots, one of
# the others: each unbatched call of panda's functions costs what a batch does); values at more states: the batches
N_STATES_SMALL, N_STATES = 2, 1
BATCH = 16
# jit compiles each function once per shape (ode_jac_x, rk4_step of panda: 20-50 s on a small CPU): these
# on the robots of JIT_ROBOTS, every function of some. These, and every function of planar_2r (it has
# every quantity of an open chain), take a batch shape (2, B/2) in test_batches_match_numpy (the shape
# handling is the same few lines of every function)
JIT_ALWAYS = ("fk_jacobian", "mass_matrix", "inverse_dynamics", "forward_dynamics", "closure", "forward_dynamics_y")
JIT_ALL = "planar_2r"
SMALL = ("cartpole", "pendulum", "planar_2r")


def every_check(robot: str, fn: dict) -> bool:
    """Whether fn gets the batch-shape checks: every function of JIT_ALL, JIT_ALWAYS of the others."""
    return robot == JIT_ALL or fn["quantity"] in JIT_ALWAYS


@pytest.fixture(scope="module")
def generated(generated_copy) -> Path:
    return generated_copy("jax")  # the committed generated/ (conftest.py), this module's copy


@functools.cache
def modules(generated: Path, robot: str):
    """(jax module, numpy module, manifest) of one robot, from the same folder; loaded once per module
    (panda's 1 MB JAX module takes seconds to compile to bytecode), read only by the tests."""
    folder = generated / robot
    jx = load_module(folder / "jax" / f"{robot}.py", f"{robot}_jax_flavour")
    py = load_module(folder / "python" / f"{robot}.py", f"{robot}_numpy_flavour")
    return jx, py, json.loads((folder / "manifest.json").read_text())


def provided(manifest: dict) -> list[dict]:
    return [fn for fn in manifest["functions"] if fn["jax"] is not None]


def inputs(robot: str, rng: np.random.Generator, batch: tuple[int, ...] = (), models=MODELS) -> dict[str, np.ndarray]:
    """Seeded arguments by name, of shape (*batch, n): q within the joint limits, the rest normal."""
    r = models[robot]
    lo, hi = r.joint_box()
    q = rng.uniform(lo, hi, size=batch + (r.nq,))
    qd = rng.normal(size=batch + (r.nv,))
    a = {"q": q, "qd": qd, "qdd": rng.normal(size=batch + (r.nv,)), "tau": 5 * rng.normal(size=batch + (r.nv,)),
         "u": 5 * rng.normal(size=batch + (r.nv,)), "x": np.concatenate([q, qd], axis=-1),
         "dt": np.full(batch + (1,), 0.01), "w": 5 * rng.normal(size=batch + (6 * len(r.wrench_frames),))}
    if r.closed:  # the closed chain's functions in y (and x = [y; yd], u = tau_y) near the reference
        a |= closed_inputs(r, rng, batch)
    return a


def call_args(fn: dict, a: dict, with_p: bool = False) -> list:
    return [a[i["name"]] for i in fn["inputs"] if with_p or i["name"] != "p"]


def values(v) -> tuple:
    return v if isinstance(v, tuple) else (v,)


def check(got, want, fn: dict, what: str, rtol: float = RTOL) -> None:
    """Each returned array against the numpy one: relative to the array's largest entry, and for
    manipulability entry by entry (mu2 = mu1^2 dwarfs mu3)."""
    got, want = values(got), values(want)
    assert len(got) == len(want), what
    for k, (g, w) in enumerate(zip(got, want)):
        g, w = np.asarray(g), np.asarray(w)
        assert g.dtype == np.float64, f"{what}: dtype {g.dtype}"
        if fn["quantity"] in ("closure", "motor_to_joint_position", "joint_to_motor_position") and k == 2:  # max |phi|: rounding
            assert g.max() <= 1e-12 and w.max() <= 1e-12, f"{what}: residual {g.max():.3g}, numpy {w.max():.3g}"
        elif fn["quantity"] == "manipulability":
            for k in range(w.shape[-1]):
                assert_close(g[..., k], w[..., k], rtol=rtol, what=f"{what} mu{k + 1}")
        else:
            assert_close(g, w, rtol=rtol, what=what)


def numpy_batch(py, fn: dict, a: dict, batch: int) -> tuple:
    """The numpy function state by state, stacked: the expected batch result."""
    rows = [values(getattr(py, fn["python"]["function"])(*[x[b] for x in call_args(fn, a, True)]))
            for b in range(batch)]
    return tuple(np.stack([row[k] for row in rows]) for k in range(len(rows[0])))


@pytest.mark.parametrize("robot", ROBOTS)
def test_manifest_names_the_jax_functions(robot, generated):
    jx, py, manifest = modules(generated, robot)
    assert provided(manifest)
    for fn in manifest["functions"]:
        if fn["quantity"] == "ik":
            assert fn["jax"] is None, fn["name"]
            assert fn["python"]["function"] not in vars(jx), fn["name"]
            assert f"Not provided in this flavour: {fn['python']['function']}" in jx.__doc__
            continue
        assert fn["jax"] == {"module": f"jax/{robot}.py", "function": fn["python"]["function"],
                             "returns": fn["python"]["returns"]}, fn["name"]
        assert callable(getattr(jx, fn["jax"]["function"]))
    assert "jax_enable_x64" in jx.__doc__ and "changes no JAX setting" in jx.__doc__
    support = [s for s in manifest["support"] if s["file"] == f"jax/{robot}.py"]
    has_manipulability = any(fn["quantity"] == "manipulability" for fn in manifest["functions"])
    assert support == ([{"file": f"jax/{robot}.py", "source": "templates/jax/support/manipulability.py"}]
                       if has_manipulability else [])
    assert (jx.NQ, jx.NV, list(jx.JOINTS)) == (py.NQ, py.NV, list(py.JOINTS))
    np.testing.assert_array_equal(jx.DEFAULT_P, py.DEFAULT_P)


@pytest.mark.parametrize("robot", ROBOTS)
def test_one_state_matches_numpy(robot, generated):
    """One 1-D state: the numpy module's shapes (the manifest's "returns") and values to 1e-12."""
    jx, py, manifest = modules(generated, robot)
    rng = np.random.default_rng(11)
    for _ in range(N_STATES_SMALL if robot in SMALL else N_STATES):
        a = inputs(robot, rng)
        for fn in provided(manifest):
            args = call_args(fn, a)
            got = getattr(jx, fn["jax"]["function"])(*args)
            want = getattr(py, fn["python"]["function"])(*args)
            returns = fn["jax"]["returns"]
            assert isinstance(got, tuple) == (len(returns) > 1), fn["name"]
            assert [list(np.shape(g)) for g in values(got)] == [r["shape"] for r in returns], fn["name"]
            check(got, want, fn, f"{fn['name']} at q = {a['q']}")


@pytest.mark.parametrize("robot", ROBOTS)
def test_batches_match_numpy(robot, generated):
    """A batch (B, n) of states, with a batch of parameters where the robot has them, gives (B, *shape)
    equal to the numpy module state by state; a batch shape (2, B/2) and a shared p broadcast (the
    functions every_check names)."""
    jx, py, manifest = modules(generated, robot)
    rng = np.random.default_rng(12)
    a = inputs(robot, rng, (BATCH,))
    p = np.asarray(py.DEFAULT_P)
    a["p"] = p * (1.0 + 0.1 * rng.uniform(-1.0, 1.0, size=(BATCH, p.size)))
    for fn in provided(manifest):
        f = getattr(jx, fn["jax"]["function"])
        got = f(*call_args(fn, a, True))
        want = numpy_batch(py, fn, a, BATCH)
        assert [list(np.shape(g)) for g in values(got)] == [[BATCH] + r["shape"] for r in fn["jax"]["returns"]]
        check(got, want, fn, f"{fn['name']} on a batch of {BATCH}")
        if not every_check(robot, fn):
            continue
        # leading batch shape (2, B/2); one p shared by the whole batch
        shaped = [np.reshape(x, (2, BATCH // 2, -1)) for x in call_args(fn, a)]
        takes_p = "p" in [i["name"] for i in fn["inputs"]]
        got2 = f(*shaped, *([a["p"][0]] if takes_p else []))
        a0 = dict(a, p=np.broadcast_to(a["p"][0], a["p"].shape))
        want2 = numpy_batch(py, fn, a0, BATCH)
        check(tuple(np.reshape(g, (BATCH,) + np.shape(g)[2:]) for g in values(got2)), want2, fn,
              f"{fn['name']} on a batch of shape (2, {BATCH // 2})")


JIT_ROBOTS = {"planar_2r": None, "parallel_ankle": ("motor_to_joint_position", "joint_to_motor_torque"),
              "fourbar": ("velocity_map", "mass_matrix_y", "bias_y", "inverse_dynamics_y", "constraint_forces",
                          "ode_jac_x", "base_regressor_y"), "delta": (), "panda": ()}
"""The robots of test_jit_and_vmap_give_the_same and what they add to JIT_ALWAYS (None: every function). jit
compiles and vmap traces op by op, both a matter of the operations used, not of size: every open chain's
quantity is among planar_2r's; a closed chain's own, but for its ODE's compositions of FD_y (ode_rhs,
rk4_step) and the regressor that base_regressor_y multiplies, among fourbar's, the motor maps parallel_ankle's;
delta's closure is spatial (ball joints), panda's graphs are the largest. Every function of every robot
is compared with numpy, one state and batched, in the tests above."""


@pytest.mark.parametrize("robot", sorted(JIT_ROBOTS))
def test_jit_and_vmap_give_the_same(robot, generated):
    """jax.jit(f) on a batch equals numpy to 1e-12; jax.vmap(f) over the batch equals f on the batch:
    the functions JIT_ROBOTS names."""
    jx, py, manifest = modules(generated, robot)
    rng = np.random.default_rng(13)
    a = inputs(robot, rng, (BATCH,))
    jitted = 0
    extra = JIT_ROBOTS[robot]
    for fn in provided(manifest):
        if extra is not None and fn["quantity"] not in JIT_ALWAYS + extra:
            continue  # its batches: test_batches_match_numpy
        f = getattr(jx, fn["jax"]["function"])
        args = call_args(fn, a)
        batched = f(*args)
        want = numpy_batch(py, fn, dict(a, p=np.broadcast_to(py.DEFAULT_P, (BATCH, len(py.DEFAULT_P)))), BATCH)
        mapped = jax.vmap(f)(*args)
        check(mapped, want, fn, f"vmap {fn['name']}")
        check(mapped, batched, fn, f"vmap vs batch {fn['name']}")
        check(jax.jit(f)(*args), want, fn, f"jit {fn['name']}")
        jitted += 1
    assert jitted >= 4


@pytest.mark.parametrize("robot", ROBOTS)
def test_grad_of_inverse_dynamics_matches_the_ode_jacobian(robot, generated):
    """s(q, qd) = w . inverse_dynamics(q, qd, qdd) at qdd = forward_dynamics(q, qd, tau): since
    ID(q, qd, FD(q, qd, tau)) = tau, dID/d(q, qd) = -M(q) d(FD)/d(q, qd), the lower blocks of the numpy
    ode_jac_x; so grad s = -(M A)^T w. Also against a central difference of the numpy module."""
    jx, py, manifest = modules(generated, robot)
    r = MODELS[robot]
    nq, nv = r.nq, r.nv
    rng = np.random.default_rng(14)
    # a closed chain: the same identity in y, ID_y(y, yd, FD_y(y, yd, tau_y)) = tau_y, with M_y and its ODE
    suffix = "_y" if r.closed else ""
    if r.closed:
        nq = nv = len(r.independent)
    inverse_dynamics = getattr(jx, "inverse_dynamics" + suffix)

    def s(q, qd, w, qdd):
        return jax.numpy.dot(w, inverse_dynamics(q, qd, qdd))

    grad_s = jax.grad(s, argnums=(0, 1))
    # jit of the grad on the small robots (w and qdd arguments, not constants of a closure: one compile for
    # both states), against the eager grad at the first; the others' eager grad at both states (XLA took
    # 24 s to compile example2's grad of ID_y, 6 s Panda's; eager 5 s and 4.6 s)
    jitted = robot in SMALL
    jit_grad_s = jax.jit(grad_s) if jitted else grad_s
    for k in range(2):
        a = inputs(robot, rng)
        q, qd, tau = (a["y"], a["yd"], a["tau_y"]) if r.closed else (a["q"], a["qd"], a["tau"])
        qdd = getattr(py, "forward_dynamics" + suffix)(q, qd, tau)
        w = rng.normal(size=nv)

        jgq, jgqd = jit_grad_s(q, qd, w, qdd)
        gq, gqd = grad_s(q, qd, w, qdd) if k == 0 and jitted else (jgq, jgqd)
        M = np.reshape(getattr(py, "mass_matrix" + suffix)(q), (nv, nv))  # (1,) for a 1 x 1 M
        A = py.ode_jac_x(np.concatenate([q, qd]), tau)[nq:, :]  # d FD / d [q, qd]
        want_q, want_qd = -(M @ A[:, :nq]).T @ w, -(M @ A[:, nq:]).T @ w
        assert_close(gq, want_q, rtol=1e-9, what=f"{robot} grad_q")
        assert_close(gqd, want_qd, rtol=1e-9, what=f"{robot} grad_qd")
        assert_close(jgq, gq, rtol=1e-12, what=f"{robot} jit grad_q")
        assert_close(jgqd, gqd, rtol=1e-12, what=f"{robot} jit grad_qd")
        h = 1e-6
        id_py = getattr(py, "inverse_dynamics" + suffix)
        fd = np.array([(w @ id_py(q + h * e, qd, qdd) - w @ id_py(q - h * e, qd, qdd))
                       / (2 * h) for e in np.eye(nq)])
        assert_close(gq, fd, rtol=1e-6, what=f"{robot} grad_q vs central difference")


def test_blocks_match_the_function_as_written(generated):
    """The blocks of @_blocks (on the CPU, a batch of more than `block` states evaluated in blocks) give
    the function as written to 1e-12: planar_2r's inverse_dynamics in blocks of 4 states on a batch of 15
    (the last block padded), a batch shape (3, 5) with one p, jax.jit(jax.vmap) with p not mapped, nested
    vmap, derivatives through the blocks (jax.grad of a weighted sum over the batch) and under vmap
    (jax.jacrev, jax.jacfwd). Which functions are blocked, in blocks of BLOCK, is the printer's rule
    (test_jax_printer.py): rrprr's ode_jac_x is, its mass_matrix not."""
    from derive.codegen.backends.jax.printer import BLOCK

    jx, py, manifest = modules(generated, "planar_2r")
    fn = next(f for f in provided(manifest) if f["quantity"] == "inverse_dynamics")
    written = jx.inverse_dynamics
    blocked = jx._blocks(4, tuple((i["name"], i["shape"][0] * i["shape"][1]) for i in fn["inputs"]))(written)
    assert blocked.block == 4 and blocked.__wrapped__ is written
    rng = np.random.default_rng(16)
    a = inputs("planar_2r", rng, (15,))
    a["p"] = np.asarray(py.DEFAULT_P) * (1.0 + 0.1 * rng.uniform(-1.0, 1.0, size=(15, len(py.DEFAULT_P))))
    args = call_args(fn, a, True)
    check(blocked(*args), numpy_batch(py, fn, a, 15), fn, "in blocks of 4")
    check(blocked(*args), written(*args), fn, "in blocks of 4 vs as written")
    shaped = [np.reshape(v, (3, 5, -1)) for v in args]
    check(blocked(*shaped[:-1], args[-1][0]), written(*shaped[:-1], args[-1][0]), fn, "batch shape (3, 5), one p")
    check(jax.jit(jax.vmap(blocked, in_axes=(0, 0, 0, None)))(*args[:-1], args[-1][0]), written(*args[:-1], args[-1][0]),
          fn, "jit(vmap)")
    check(jax.vmap(jax.vmap(blocked))(*shaped), written(*shaped), fn, "vmap(vmap)")
    w = rng.normal(size=(15, 2))

    def weighted(f):  # jit: one compile instead of eager op-by-op dispatch (seconds); blocks on the CPU all the same
        return jax.jit(jax.grad(lambda *xs: jax.numpy.sum(w * f(*xs)), argnums=(0, 1, 2, 3)))(*args)

    for k, (got, want) in enumerate(zip(weighted(blocked), weighted(written))):
        assert_close(got, want, rtol=RTOL, what=f"grad through the blocks, argument {k}")
    for derivative in (jax.jacrev, jax.jacfwd):
        got = jax.jit(jax.vmap(derivative(blocked)))(*args)
        assert_close(got, jax.jit(jax.vmap(derivative(written)))(*args), rtol=RTOL, what=f"vmap({derivative.__name__})")
    rrprr = modules(generated, "rrprr")[0]
    assert rrprr.ode_jac_x.block == BLOCK and not hasattr(rrprr.mass_matrix, "block")


ONE_JOINT = """\
robots:
  slider:
    links:
      - {name: base}
      - {name: cart, mass: 2.0, inertia: [0.01, 0.01, 0.01]}
    joints:
      - {name: s, type: prismatic, parent: base, child: cart, axis: [1, 0, 0],
         limits: {lower: -1, upper: 1, velocity: 1, effort: 10}}
    frames:
      - {name: tcp, link: cart, xyz: [0.1, 0, 0]}
"""


def test_one_joint_robot(tmp_path):
    """nv = 1: the Jacobian comes back as (..., 6), a 6 x 1 column, and manipulability of its one
    task row still works, one state and batched, as in the numpy module."""
    models = parse_models(ONE_JOINT)
    generate(models, tmp_path, log=lambda s: None)
    jx, py, manifest = modules(tmp_path, "slider")
    assert "manipulability" in [fn["quantity"] for fn in provided(manifest)]
    rng = np.random.default_rng(15)
    a = inputs("slider", rng, (BATCH,), models)
    for fn in provided(manifest):
        f = getattr(jx, fn["jax"]["function"])
        check(f(*call_args(fn, a)), numpy_batch(py, fn, a, BATCH), fn, f"{fn['name']} on a batch")
        one = [x[0] for x in call_args(fn, a)]
        check(f(*one), getattr(py, fn["python"]["function"])(*one), fn, fn["name"])


def test_functions_check_their_inputs(generated):
    jx, _, _ = modules(generated, "planar_2r")
    with pytest.raises(ValueError, match="q must have 2 elements in its last axis"):
        jx.mass_matrix([0.0, 1.0, 2.0])
    with pytest.raises(ValueError, match="p must have 5 elements"):
        jx.mass_matrix([0.0, 1.0], [1.0])
    assert jx.mass_matrix([0.1, 0.2]).shape == (2, 2)
    assert jx.rk4_step([0.1, 0.2, 0.0, 0.0], [0.0, 0.0], 0.01).shape == (4,)  # a scalar dt counts as [dt]


def test_import_changes_no_jax_setting(generated):
    """In a fresh process: importing a module leaves jax_enable_x64 off, the functions then compute
    in float32; inside `with jax.enable_x64(True)` around the jit call they compute in float64 and
    equal the numpy module to 1e-12."""
    code = ("import importlib.util, jax, numpy as np, sys\n"
            "def load(path, name):\n"
            "    spec = importlib.util.spec_from_file_location(name, path)\n"
            "    m = importlib.util.module_from_spec(spec); spec.loader.exec_module(m); return m\n"
            f"jx = load({str(generated / 'planar_2r' / 'jax' / 'planar_2r.py')!r}, 'jx')\n"
            f"py = load({str(generated / 'planar_2r' / 'python' / 'planar_2r.py')!r}, 'py')\n"
            "assert jax.config.jax_enable_x64 is False\n"
            "q = np.array([[0.3, -0.7], [1.1, 0.2]])\n"
            "assert jax.jit(jx.mass_matrix)(q).dtype == np.float32\n"
            "with jax.enable_x64(True):\n"
            "    got = np.asarray(jax.jit(jx.mass_matrix)(q))\n"
            "assert got.dtype == np.float64 and jax.config.jax_enable_x64 is False\n"
            "want = np.stack([py.mass_matrix(s) for s in q])\n"
            "assert np.max(np.abs(got - want)) <= 1e-12 * np.max(np.abs(want)), (got, want)\n"
            "print('ok')\n")
    env = {k: v for k, v in os.environ.items() if k != "JAX_ENABLE_X64"}
    out = subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT, timeout=300, env=env,
                         capture_output=True, text=True)
    assert out.stdout.strip() == "ok"


def test_generation_does_not_import_jax(tmp_path):
    """The backend writes text: with jax unimportable, generation still writes jax/<robot>.py."""
    code = ("import sys; sys.modules['jax'] = None\n"
            "from pathlib import Path\n"
            "from derive.codegen.generate import generate\n"
            "from derive.description.model import load_models\n"
            f"out = Path({str(tmp_path / 'out')!r})\n"
            "generate({'pendulum': load_models()['pendulum']}, out, log=lambda s: None)\n"
            "assert 'jax' not in sys.modules or sys.modules['jax'] is None\n")
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT, timeout=300)
    assert (tmp_path / "out" / "pendulum" / "jax" / "pendulum.py").is_file()
