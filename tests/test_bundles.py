"""Control-tick bundles: one generated function returning the outputs of several, in one pass.

Every bundle of every shipped robot equals the separate generated functions it names to 1e-14
(generated Python and C, double), at seeded states; a floating-base robot with contact frames
(solo12) is checked on the symbolic graphs; models.yaml's ``bundles:`` field builds custom
bundles (a link's quantities too) and refuses bad ones in one line.
"""

from __future__ import annotations

import ctypes
import json
import subprocess
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from derive.codegen.catalogue import function_specs
from derive.codegen.generate import generate
from derive.description.model import parse_models, parse_robot
from derive.description.robot import ModelError
from derive.description.urdf import example_robot_data_dir, import_urdf_named
from derive.resources import CHECKOUT
from derive.symbolic.model import SXModel
from util import assert_close, load_module, params, random_q, robots, tree_robots

GENERATED = CHECKOUT / "generated"
ROBOTS = tree_robots()  # a closed chain has no control bundles
TOL = 1e-14
CFLAGS = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-O1", "-shared", "-fPIC"]


def python_module(folder: Path, robot: str):
    return load_module(folder / "python" / f"{robot}.py", f"bundles_{robot}_{abs(hash(folder))}")


def c_library(folder: Path, manifest: dict, names: list[str], out: Path) -> ctypes.CDLL:
    """The robot's C functions ``names`` built into one shared library (-O1: correctness only)."""
    by_name = {f["name"]: f for f in manifest["functions"]}
    sources = [str(folder / f"{by_name[n]['c']['source']}") for n in names]
    lib = out / f"lib{manifest['robot']}_bundles.so"
    subprocess.run(["cc", *CFLAGS, f"-I{folder / 'c'}", "-o", str(lib), *sources, "-lm"], check=True)
    return ctypes.CDLL(str(lib))


def call_c(lib: ctypes.CDLL, fn: dict, args: dict) -> list[np.ndarray]:
    ptr = ctypes.POINTER(ctypes.c_double)
    ins = [np.ascontiguousarray(args[i["name"]], dtype=float) for i in fn["inputs"]]
    outs = [np.zeros(o["shape"]) for o in fn["outputs"]]
    f = getattr(lib, fn["name"])
    f.restype = None
    f(*[a.ctypes.data_as(ptr) for a in ins + outs])
    return outs


def check_bundles(folder: Path, robot, tmp: Path, n_states: int = 5) -> int:
    """Compare every bundle of ``robot`` generated in ``folder`` with its separate functions (Python and C)."""
    manifest = json.loads((folder / "manifest.json").read_text())
    by_name = {f["name"]: f for f in manifest["functions"]}
    bundles = [f for f in manifest["functions"] if f["quantity"] == "bundle"]
    assert bundles, f"{robot.name}: no bundle generated"
    names = sorted({b["name"] for b in bundles} | {f"{robot.name}_{p['output']}" for b in bundles for p in b["bundle"]})
    lib = c_library(folder, manifest, names, tmp)
    py = python_module(folder, robot.name)
    rng = np.random.default_rng(7)
    checked = 0
    for _ in range(n_states):
        q = random_q(robot, rng)
        a = {"q": q, "qd": rng.normal(size=robot.nv), "qdd": rng.normal(size=robot.nv),
             "tau": rng.normal(size=robot.nv), "w": rng.normal(size=6 * len(robot.wrench_frames)), "p": params(robot)}
        for b in bundles:
            got_c = call_c(lib, b, a)
            got_py = py.__dict__[b["python"]["function"]](*[a[i["name"]] for i in b["inputs"]])
            got_py = got_py if isinstance(got_py, tuple) else (got_py,)
            assert [o["name"] for o in b["outputs"]] == [p["output"] for p in b["bundle"]]
            for k, part in enumerate(b["bundle"]):
                separate = by_name[f"{robot.name}_{part['output']}"]
                assert part["quantity"] == separate["quantity"] and part["frame"] == separate["frame"]
                want_c = call_c(lib, separate, a)[0]
                want_py = py.__dict__[separate["python"]["function"]](*[a[i["name"]] for i in separate["inputs"]])
                what = f"{b['name']} output {part['output']}"
                assert_close(got_c[k], want_c, rtol=TOL, what="C " + what)
                assert_close(got_py[k], want_py, rtol=TOL, what="Python " + what)
                checked += 1
    return checked


@pytest.mark.parametrize("robot", ROBOTS)
def test_shipped_bundles_equal_the_separate_functions(robot, tmp_path):
    r = robots()[robot]
    assert [b.name for b in r.control_bundles] == ["control", "computed_torque"]
    assert check_bundles(GENERATED / robot, r, tmp_path) == 5 * 9


def test_shipped_bundles_cost_less_than_the_separate_functions():
    """The bundles' arithmetic (after CSE) against the sum of the separate functions', from manifest.json
    (the timed comparison is `make bench`'s "bundles" section)."""
    for robot in ROBOTS:
        manifest = json.loads((GENERATED / robot / "manifest.json").read_text())
        ops = {f["name"]: f["ops"]["total"] for f in manifest["functions"] if f["ops"]}
        for b in (f for f in manifest["functions"] if f["quantity"] == "bundle"):
            separate = sum(ops[f"{robot}_{p['output']}"] for p in b["bundle"])
            assert b["ops"]["total"] < 0.8 * separate, (b["name"], b["ops"]["total"], separate)


def test_floating_base_bundle_with_contacts_on_the_graphs():
    """solo12 on a floating base with four foot wrench frames: the default control bundle holds M, h and
    each foot's Jacobian and J'qd, equal to the separate functions' graphs."""
    if example_robot_data_dir() is None:
        pytest.skip("example-robot-data is not installed (the test extra installs it)")
    name, entry = import_urdf_named("example-robot-data:solo_description/robots/solo12.urdf", floating=True)
    feet = ("FL_FOOT", "FR_FOOT", "HL_FOOT", "HR_FOOT")
    robot = parse_robot(name, {**entry, "wrenches": list(feet)})
    control = robot.control_bundles[0]
    assert control.quantities == ("mass_matrix", "bias") + tuple(f"{q}_{f}" for f in feet for q in ("jacobian", "jdot_qd"))
    assert len(robot.control_bundles) == 1  # no tcp: no computed_torque bundle
    specs = {s.short_name: s for s in function_specs(SXModel(robot))}
    bundle = specs["bundle_control"]
    f = ca.Function("b", [x for _, x in bundle.inputs], [e for _, e in bundle.outputs])
    rng = np.random.default_rng(3)
    for _ in range(3):
        q = random_q(robot, rng)
        args = {"q": q, "qd": rng.normal(size=robot.nv)}
        got = f(*[args[n] for n, _ in bundle.inputs])
        for k, name in enumerate(control.quantities):
            s = specs[name]
            want = ca.Function("s", [x for _, x in s.inputs], [s.outputs[0][1]])(*[args[n] for n, _ in s.inputs])
            assert_close(np.array(got[k]), np.array(want), rtol=TOL, what=name)


CUSTOM = """
robots:
  arm:
    links:
      - {name: base}
      - {name: l1, mass: 1.0, com: [0.5, 0, 0], inertia: [0.01, 0.1, 0.1]}
      - {name: l2, mass: 0.5, com: [0.4, 0, 0], inertia: [0.01, 0.05, 0.05]}
    joints:
      - {name: j1, type: revolute, parent: base, child: l1, axis: [0, 0, 1]}
      - {name: j2, type: revolute, parent: l1, child: l2, origin: {xyz: [1, 0, 0]}, axis: [0, 1, 0]}
    frames:
      - {name: tcp, link: l2, xyz: [0.8, 0, 0.1], rpy: [0.1, 0.2, 0.3]}
    bundles:
      - {name: tick, quantities: [mass_matrix, gravity, fk_l1, jdot_qd_l2, jacobian_tcp]}
      - {name: ct, quantities: [inverse_dynamics, frame_acceleration_tcp, com]}
"""


def test_custom_bundles_from_models_yaml(tmp_path):
    robot = parse_models(CUSTOM)["arm"]
    assert [b.name for b in robot.control_bundles] == ["tick", "ct"]
    generate({"arm": robot}, tmp_path / "gen", log=lambda s: None)
    folder = tmp_path / "gen" / "arm"
    manifest = json.loads((folder / "manifest.json").read_text())
    tick = next(f for f in manifest["functions"] if f["name"] == "arm_bundle_tick")
    assert [i["name"] for i in tick["inputs"]] == ["q", "qd"]
    assert [o["name"] for o in tick["outputs"]] == ["mass_matrix", "gravity", "fk_l1", "jdot_qd_l2", "jacobian_tcp"]
    ct = next(f for f in manifest["functions"] if f["name"] == "arm_bundle_ct")
    assert [i["name"] for i in ct["inputs"]] == ["q", "qd", "qdd"]
    # links have no separate fk/jdot functions: compare those outputs with the graphs of the model
    model = SXModel(robot)
    py = python_module(folder, "arm")
    rng = np.random.default_rng(5)
    for _ in range(3):
        q, qd = rng.normal(size=2), rng.normal(size=2)
        M, g, T1, a2, J = py.bundle_tick(q, qd)
        assert_close(M, py.mass_matrix(q), rtol=TOL, what="M")
        assert_close(g, py.gravity(q), rtol=TOL, what="g")
        assert_close(J, py.jacobian_tcp(q), rtol=TOL, what="J")
        fk1 = ca.Function("f", [model.sym.q], [model.fk("l1")])
        jd2 = ca.Function("j", [model.sym.q, model.sym.qd], [model.whole_body.jdot_qd("l2")])
        assert_close(T1, np.array(fk1(q)), rtol=TOL, what="fk_l1")
        assert_close(a2, np.array(jd2(q, qd)).ravel(), rtol=TOL, what="jdot_qd_l2")
    subprocess.run(["cc", "-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-c", "-o", str(tmp_path / "t.o"),
                    str(folder / "c" / "arm_bundle_tick.c")], check=True)


@pytest.mark.parametrize("bundles, message", [
    ("[{name: t, quantities: [mass_matrix, nope]}]", "bundles[0].quantities[1]: unknown quantity 'nope'"),
    ("[{name: t, quantities: [fk_nowhere]}]", "bundles[0].quantities[0]: unknown quantity 'fk_nowhere'"),
    ("[{name: t, quantities: [bias, bias]}]", "bundles[0].quantities: a quantity is listed twice"),
    ("[{name: t, quantities: []}]", "bundles[0].quantities: expected a non-empty list"),
    ("[{name: t, quantities: [bias]}, {name: t, quantities: [gravity]}]", "bundles: two bundles have the same name"),
    ("[{name: 1t, quantities: [bias]}]", "bundles[0].name"),
    ("[{quantities: [bias]}]", "bundles[0].name: missing"),
    ("[{name: t, quantities: [bias], extra: 1}]", "bundles[0].extra"),
    ("{name: t}", "bundles: expected a list"),
    ("[{name: t, quantities: [inverse_dynamics_fext]}]\n    wrenches: []", "bundles[0].quantities[0]: 'inverse_dynamics_fext' needs"),
])
def test_bad_bundles_are_refused_in_one_line(bundles, message):
    text = CUSTOM.split("    bundles:")[0] + f"    bundles: {bundles}\n"
    with pytest.raises(ModelError) as err:
        parse_models(text)
    assert message in str(err.value) and "\n" not in str(err.value)
