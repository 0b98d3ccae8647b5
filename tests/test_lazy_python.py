"""Lazily defined functions of the generated Python (issue 25, item 6: a big robot's module imports in
about a second): a module of more than WHOLE_OPS operations keeps EAGER_OPS of them, and its largest
functions live in python/<robot>_parts/<name>.py, compiled on their first call through a stand-in of
the same name, signature and docstring; they give bit for bit what the module that defines them
eagerly gives.

planar_2r (1 211 operations) is generated with the limits lowered to 1 000 and 550 and compared with
its committed module, which defines everything eagerly."""

from __future__ import annotations

import inspect
import json

import numpy as np
import pytest

from derive.codegen.backends import python as python_backend
from derive.codegen.generate import generate
from derive.resources import data_path
from util import load_module, params, robots

ROBOT = "planar_2r"
WHOLE, BUDGET = 1000, 550


def expected_lazy(manifest: dict, whole: int, budget: int) -> list[str]:
    """Above whole operations, the functions taken out, largest first (then by name), until the rest
    total at most budget."""
    sized = sorted((f for f in manifest["functions"] if f["ops"]), key=lambda f: (-f["ops"]["total"], f["name"]))
    rest, lazy = sum(f["ops"]["total"] for f in sized), []
    if rest <= whole:
        return lazy
    for f in sized:
        if rest <= budget:
            break
        lazy.append(f["python"]["function"])
        rest -= f["ops"]["total"]
    return lazy


@pytest.fixture(scope="module")
def lazy_robot(tmp_path_factory):
    """(the lazy module's folder, its manifest): planar_2r generated with the budget lowered."""
    out = tmp_path_factory.mktemp("lazy")
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(python_backend.BACKEND, "whole_ops", WHOLE)
        patch.setattr(python_backend.BACKEND, "eager_ops", BUDGET)
        generate({ROBOT: robots()[ROBOT]}, out, use_cache=False, log=lambda s: None)
    return out / ROBOT, json.loads((out / ROBOT / "manifest.json").read_text())


def inputs(fn: dict, shape: tuple, rng: np.random.Generator) -> list[np.ndarray]:
    r = robots()[ROBOT]
    lo, hi = r.joint_box()
    args = []
    for item in fn["inputs"]:
        name, n = item["name"], item["shape"][0] * item["shape"][1]
        if name == "p":
            args.append(params(r))
        elif name in ("q", "q0"):
            args.append(rng.uniform(lo, hi, shape + (n,)))
        elif name == "T":
            args.append(np.broadcast_to(np.eye(4), shape + (4, 4)).copy())
        elif name == "w":
            args.append(np.ones(shape + (n,)))
        elif name == "dt":
            args.append(np.full(shape + (n,), 0.01))
        else:
            args.append(rng.normal(size=shape + (n,)))
    return args


def test_budget_takes_the_largest_functions_first():
    f = [{"short_name": n, "ops": {"total": k} if k else None} for n, k in
         (("a", 50), ("b", 300), ("c", 300), ("d", 100), ("t", None))]
    assert python_backend.lazy_functions(f, 750, 0) == set()  # within whole: everything at import
    assert python_backend.lazy_functions(f, 749, 749) == {"b"}  # ties by name
    assert python_backend.lazy_functions(f, 749, 450) == {"b"}
    assert python_backend.lazy_functions(f, 749, 150) == {"b", "c"}
    assert python_backend.lazy_functions(f, 749, 149) == {"b", "c", "d"}
    assert python_backend.lazy_functions(f, 0, 0) == {"a", "b", "c", "d"}  # a template function (ops None) stays


def test_committed_modules_define_everything_eagerly():
    """The committed robots are within the budget: no part files, their modules as before."""
    generated = data_path("generated")
    for robot in robots():
        manifest = json.loads((generated / robot / "manifest.json").read_text())
        assert expected_lazy(manifest, python_backend.WHOLE_OPS, python_backend.EAGER_OPS) == [], robot
        assert not any("part" in f["python"] for f in manifest["functions"]), robot
        assert not (generated / robot / "python" / f"{robot}_parts").exists(), robot


def test_parts_hold_the_largest_functions(lazy_robot):
    folder, manifest = lazy_robot
    lazy = expected_lazy(manifest, WHOLE, BUDGET)
    assert len(lazy) == 8 and "ode_jac_x" in lazy and "ode_rhs" in lazy  # rk4_step calls ode_rhs's stand-in
    assert sorted(p.name for p in (folder / "python" / f"{ROBOT}_parts").iterdir()) == sorted(f"{n}.py" for n in lazy)
    for fn in manifest["functions"]:
        name = fn["python"]["function"]
        want = {"module": f"python/{ROBOT}.py", "function": name}
        assert {k: fn["python"][k] for k in ("module", "function")} == want
        assert fn["python"].get("part") == (f"python/{ROBOT}_parts/{name}.py" if name in lazy else None)
    text = (folder / "python" / f"{ROBOT}.py").read_text()
    assert all(f"def _{n}_chunk(" not in text and f'return _part("{n}")(' in text for n in lazy)


def test_lazy_module_matches_the_eager_one_bit_for_bit(lazy_robot, tmp_path):
    folder, manifest = lazy_robot
    lazy_names = expected_lazy(manifest, WHOLE, BUDGET)
    module = load_module(folder / "python" / f"{ROBOT}.py", "lazy_planar_2r")
    eager = load_module(data_path("generated") / ROBOT / "python" / f"{ROBOT}.py", "eager_planar_2r")
    # importing compiled no part: their bodies are not defined, nothing is loaded
    assert module._LOADED == {}
    assert not any(f"_{n}_chunk" in vars(module) for n in lazy_names)
    assert {n for n in dir(module) if not n.startswith("_")} == {n for n in dir(eager) if not n.startswith("_")}
    stand_ins = {n: getattr(module, n) for n in lazy_names}
    for n in lazy_names:
        assert str(inspect.signature(stand_ins[n])) == str(inspect.signature(getattr(eager, n)))
        assert stand_ins[n].__doc__ == getattr(eager, n).__doc__

    # a part that is not there: one line naming the file, on the call (the import did not read it)
    parts = folder / "python" / f"{ROBOT}_parts"
    parts.rename(tmp_path / "away")
    try:
        with pytest.raises(ImportError, match=rf"robot '{ROBOT}': ode_jac_x is defined in .*ode_jac_x\.py, which "
                                              rf"cannot be read \(No such file or directory\); keep the folder "
                                              rf"{ROBOT}_parts/ beside {ROBOT}\.py"):
            module.ode_jac_x(np.zeros(4), np.zeros(2))
    finally:
        (tmp_path / "away").rename(parts)

    rng = np.random.default_rng(7)
    for fn in manifest["functions"]:
        name = fn["python"]["function"]
        if fn["quantity"] == "ik":  # restarts per state: slow, and it calls no lazy function here
            continue
        one, batch = inputs(fn, (), rng), inputs(fn, (3,), rng)
        for args in (one, batch):
            got, want = getattr(module, name)(*args), getattr(eager, name)(*args)
            got, want = (got, want) if isinstance(got, tuple) else ((got,), (want,))
            for g, w in zip(got, want, strict=True):
                assert np.asarray(g).shape == np.asarray(w).shape and np.array_equal(g, w, equal_nan=True), name
        if fn["ops"]:  # a batch row is the state alone
            rows = getattr(module, name)(*batch)
            alone = getattr(module, name)(*[a[1] if a.ndim > 1 else a for a in batch])
            assert np.array_equal(np.asarray(rows[0] if isinstance(rows, tuple) else rows)[1],
                                  alone[0] if isinstance(alone, tuple) else alone), name
    assert sorted(module._LOADED) == sorted(lazy_names)
    assert all(getattr(module, n) is stand_ins[n] for n in lazy_names)  # the names keep their stand-ins
    assert all(module._LOADED[n].__code__.co_filename == str(parts / f"{n}.py") for n in lazy_names)
