"""`derive generate` on a user's own models: only the robots asked about are touched, --prune and
--check, `derive init`, C++ linking, and a new backend as one folder plus one registry line."""

from __future__ import annotations

import hashlib
import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from derive.cli import main
from derive.codegen import backends
from derive.codegen.generate import check, generate
from derive.description.model import load_models, parse_models
from derive.description.robot import model_data
from derive.resources import EXAMPLE_MODELS

from util import compile_objects, load_module, robots

ROOT = Path(__file__).resolve().parent.parent

# A robot that is none of the shipped ones: a 2-link arm in a vertical plane, one parameter.
MY_MODELS = """\
robots:
  my_arm:
    parameters: {L: 0.4}
    links:
      - {name: base}
      - {name: upper, mass: 1.2, com: [L/2, 0, 0], inertia: [0.001, 0.02, 0.02]}
      - {name: fore, mass: 0.7, com: [0.15, 0, 0], inertia: [0.001, 0.01, 0.01]}
    joints:
      - {name: shoulder, type: revolute, parent: base, child: upper, axis: [0, 1, 0],
         limits: {lower: -2, upper: 2, velocity: 3, effort: 40}}
      - {name: elbow, type: revolute, parent: upper, child: fore, axis: [0, 1, 0], origin: {xyz: [L, 0, 0]},
         limits: {lower: -2.5, upper: 2.5, velocity: 3, effort: 20}}
    frames:
      - {name: tcp, link: fore, xyz: [0.3, 0, 0]}
"""


def digests(folder: Path) -> dict[str, str]:
    """sha256 of every file, but Python's byte-code cache (importing a generated module writes it)."""
    return {p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file() and "__pycache__" not in p.parts}


def test_generate_leaves_robots_of_other_models_files_untouched(tmp_path, capsys):
    out = tmp_path / "generated"
    mine = tmp_path / "my.yaml"
    mine.write_text(MY_MODELS)
    assert main(["--models", str(EXAMPLE_MODELS), "generate", "--robot", "pendulum", "--out", str(out)]) == 0
    before = digests(out / "pendulum")
    assert main(["--models", str(mine), "generate", "--out", str(out)]) == 0
    assert "1 other robot(s) left as they were" in capsys.readouterr().out
    assert digests(out / "pendulum") == before
    manifest = json.loads((out / "MANIFEST.json").read_text())
    assert sorted(manifest["robots"]) == ["my_arm", "pendulum"]
    # --check judges the models file's robots only, unless --prune
    assert main(["generate", "--models", str(mine), "--out", str(out), "--check"]) == 0
    assert main(["generate", "--models", str(mine), "--out", str(out), "--check", "--prune"]) == 1
    assert "pendulum/ (robot not in the models file; --prune removes it)" in capsys.readouterr().err
    assert main(["generate", "--models", str(mine), "--out", str(out), "--prune"]) == 0
    assert f"pruned {out / 'pendulum'}/" in capsys.readouterr().out
    assert sorted(p.name for p in out.iterdir()) == ["MANIFEST.json", "my_arm"]
    assert main(["generate", "--models", str(mine), "--out", str(out), "--check", "--prune"]) == 0


def test_generate_reads_models_yaml_of_the_working_folder(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("DERIVE_MODELS", raising=False)
    (tmp_path / "models.yaml").write_text(MY_MODELS)
    assert main(["generate"]) == 0
    assert (tmp_path / "generated" / "my_arm" / "python" / "my_arm.py").is_file()
    assert sorted(p.name for p in (tmp_path / "generated").iterdir()) == ["MANIFEST.json", "my_arm"]
    monkeypatch.setenv("DERIVE_MODELS", str(EXAMPLE_MODELS))  # the variable wins over ./models.yaml
    assert main(["generate", "--robot", "pendulum", "--check"]) == 1
    assert "pendulum/ (not generated)" in capsys.readouterr().err


def test_init_writes_the_shipped_robots_as_written(tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert main(["init", "--robot", "cartpole", "--robot", "pendulum"]) == 0
    text = (tmp_path / "models.yaml").read_text()
    assert "# Cart-pole: a cart on a prismatic rail" in text  # comments come along
    mine, shipped = load_models(tmp_path / "models.yaml"), load_models(EXAMPLE_MODELS)
    assert list(mine) == ["pendulum", "cartpole"]  # file order
    for name in mine:
        assert model_data(mine[name]) == model_data(shipped[name])
    assert main(["init", "--out", "all.yaml"]) == 0
    assert list(load_models(tmp_path / "all.yaml")) == list(shipped)
    assert main(["init"]) == 2 and "exists already" in capsys.readouterr().err
    assert main(["init", "--force", "--robot", "ur5"]) == 0
    assert list(load_models(tmp_path / "models.yaml")) == ["ur5"]


def test_generated_headers_link_from_cpp(tmp_path):
    """Every header has extern "C" guards: a C++ program calls the C functions."""
    cxx = shutil.which("c++") or shutil.which("g++")
    cc = shutil.which("cc") or shutil.which("gcc")
    if not (cxx and cc):
        pytest.fail("a C and a C++ compiler are needed (Debian: gcc, g++)")
    src = ROOT / "generated" / "planar_2r" / "c"
    for h in src.glob("*.h"):
        if not h.name.startswith("derive_"):
            text = h.read_text()
            assert text.count('extern "C" {') == (0 if h.name == "planar_2r.h" else 1), h.name
    (tmp_path / "main.cpp").write_text(
        '#include <cstdio>\n#include "planar_2r.h"\n'
        'int main() { double q[2] = {0.3, -0.7}, p[PLANAR_2R_NP] = {PLANAR_2R_DEFAULT_L1, PLANAR_2R_DEFAULT_L2, '
        'PLANAR_2R_DEFAULT_m1, PLANAR_2R_DEFAULT_m2, PLANAR_2R_DEFAULT_g}, M[4];\n'
        '  planar_2r_mass_matrix(q, p, M); std::printf("%.17g %.17g %.17g %.17g\\n", M[0], M[1], M[2], M[3]); }\n')
    objects = compile_objects([cc, "-std=c99", "-O1", "-Wall", "-Wextra", "-Werror", "-pedantic", f"-I{src}"],
                              sorted(src.glob("*.c")), tmp_path)  # one source per process, CPUs at once
    exe = tmp_path / "main"
    subprocess.run([cxx, "-std=c++11", "-Wall", "-Wextra", "-Werror", "-pedantic", f"-I{src}", str(tmp_path / "main.cpp"),
                    *map(str, objects), "-lm", "-o", str(exe)], check=True)
    printed = [float(x) for x in subprocess.run([str(exe)], check=True, capture_output=True, text=True).stdout.split()]
    py = load_module(ROOT / "generated" / "planar_2r" / "python" / "planar_2r.py", "planar_2r_cpp")
    assert printed == py.mass_matrix([0.3, -0.7]).reshape(-1).tolist()
    names = [p.name for p in robots()["planar_2r"].parameters]
    assert names == ["L1", "L2", "m1", "m2", "g"]


def test_a_new_backend_is_one_folder_and_one_registry_line(tmp_path, monkeypatch):
    """tests/toy_backend/ (a plain-list Python flavour) registered by one line: its output equals the
    numpy module's bit for bit, and the other backends' files do not change."""
    monkeypatch.setitem(backends.REGISTRY, "pylist", "toy_backend")  # the one registry line
    models = {name: robots()[name] for name in ("planar_2r", "panda")}
    generate(models, tmp_path, log=lambda s: None)
    for name in models:
        committed = ROOT / "generated" / name
        fresh = digests(tmp_path / name)
        assert {k: v for k, v in fresh.items() if not k.startswith("pylist/") and k != "manifest.json"} == \
            {k: v for k, v in digests(committed).items() if k != "manifest.json"}
        manifest = json.loads((tmp_path / name / "manifest.json").read_text())
        assert manifest["functions"][0]["pylist"] == {"module": f"pylist/{name}.py", "function": manifest["functions"][0]["name"].removeprefix(name + "_")}
        toy = load_module(tmp_path / name / "pylist" / f"{name}.py", f"{name}_pylist")
        ref = load_module(committed / "python" / f"{name}.py", f"{name}_numpy")
        rng = np.random.default_rng(0)
        robot = models[name]
        lo, hi = robot.joint_box()
        compared = 0
        for fn in manifest["functions"]:
            if fn["pylist"] is None:
                assert fn["quantity"] in ("ik", "rk4_step", "manipulability")
                continue
            args = [rng.uniform(lo, hi) if i["name"] == "q" else rng.normal(size=i["shape"][0])
                    for i in fn["inputs"] if i["name"] != "p"]
            got = getattr(toy, fn["pylist"]["function"])(*[a.tolist() for a in args])
            want = getattr(ref, fn["python"]["function"])(*args)
            got, want = (got, want) if isinstance(want, tuple) else ((got,), (want,))
            for g, w in zip(got, want):
                assert g == np.asarray(w).reshape(-1).tolist(), fn["name"]
            compared += 1
        assert compared == len([f for f in manifest["functions"] if f["ops"]]) >= 11
    assert check(models, tmp_path) == []


def test_shipped_models_parse_the_same_as_the_project_file():
    """The wheel ships models.yaml as package data; in a checkout it is the project's own file."""
    assert EXAMPLE_MODELS.resolve() == (ROOT / "models.yaml").resolve() or \
        parse_models(EXAMPLE_MODELS.read_text()).keys() == parse_models((ROOT / "models.yaml").read_text()).keys()
