"""``derive export-casadi``: each generated function as a serialised casadi.Function (what acados and CasADi-based
MPC load), read back with casadi.Function.load and compared with the generated Python at seeded states to 1e-12.

- planar_2r (shipped, with a parameter input): every exported function, rk4_step included, against
  generated/planar_2r/python; the loop functions (ik, manipulability) are named as not exported;
- the contact biped of test_contacts.py: contact dynamics, contact-consistent inverse dynamics, impulse dynamics
  and A_G' qd against its freshly generated Python;
- the files are byte-identical across exports; a bad --functions name is one line, exit 2, nothing written;
- examples/contact_mpc.py, a multiple-shooting OCP on the exported contact dynamics, runs and keeps its feet.
"""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import casadi as ca
import numpy as np

from derive.cli import main
from derive.codegen.casadi_export import export_casadi
from derive.codegen.generate import generate
from derive.description.model import load_models, parse_models
from derive.reference import NumericRobot
from test_contacts import BIPED
from util import assert_close, load_module

ROOT = Path(__file__).resolve().parent.parent
TOL = 1e-12


def load(path: Path, name: str):
    mod = load_module(path, name)
    return mod


def compare(folder: Path, manifest: dict, py, robot_name: str, states, skip=()) -> int:
    """Every exported function of ``manifest`` (except ``skip``) against the Python module at ``states``:
    {input name: value} (others random); returns how many were compared."""
    rng = np.random.default_rng(0)
    done = 0
    for f in manifest["functions"]:
        if f["name"] in skip:
            continue
        loaded = ca.Function.load(str(folder / f"{f['name']}.casadi"))
        assert [loaded.name_in(k) for k in range(loaded.n_in())] == [i["name"] for i in f["inputs"]], f["name"]
        assert [loaded.name_out(k) for k in range(loaded.n_out())] == [o["name"] for o in f["outputs"]], f["name"]
        for state in states:
            args = [np.asarray(state.get(i["name"], rng.normal(size=i["shape"][0])), dtype=float) for i in f["inputs"]]
            mine = loaded(*args)
            mine = mine if isinstance(mine, tuple) else (mine,)
            result = getattr(py, f["name"].removeprefix(robot_name + "_"))(*args)
            result = result if isinstance(result, tuple) else (result,)
            for o, a, b in zip(f["outputs"], mine, result):
                assert_close(np.asarray(a), np.asarray(b, dtype=float).reshape(o["shape"]), TOL, f"{f['name']}: {o['name']}")
        done += 1
    return done


def test_planar_2r_every_function(tmp_path):
    robot = load_models()["planar_2r"]
    written, skipped = export_casadi(robot, tmp_path)
    assert skipped == ["planar_2r_ik_tcp", "planar_2r_manipulability_tcp"]
    manifest = json.loads((ROOT / "generated" / "planar_2r" / "manifest.json").read_text())
    assert sorted(p.name for p in written) == sorted(f"{f['name']}.casadi" for f in manifest["functions"]
                                                     if f["name"] not in skipped)
    py = load(ROOT / "generated" / "planar_2r" / "python" / "planar_2r.py", "casadi_export_planar_2r")
    p = np.array([x.default for x in robot.parameters])
    states = [{"p": p, "dt": np.array([0.01])}, {"p": p * 1.1, "dt": np.array([0.02])}]
    assert compare(tmp_path, manifest, py, "planar_2r", states, skipped) == len(written)
    again, _ = export_casadi(robot, tmp_path / "again", ["mass_matrix", "planar_2r_rk4_step"])
    for path in again:
        assert path.read_bytes() == (tmp_path / path.name).read_bytes(), f"{path.name}: not byte-identical"


def test_biped_contact_functions(tmp_path):
    quantities = ("contact_dynamics", "contact_inverse_dynamics", "impulse_dynamics", "centroidal_map_dot_qd")
    robot = dataclasses.replace(parse_models(BIPED)["biped"], generate_quantities=quantities)
    generate({"biped": robot}, tmp_path / "gen", log=lambda s: None)
    manifest = json.loads((tmp_path / "gen" / "biped" / "manifest.json").read_text())
    written, _ = export_casadi(robot, tmp_path / "casadi")
    assert len(written) == len(manifest["functions"]) == 7
    py = load(tmp_path / "gen" / "biped" / "python" / "biped.py", "casadi_export_biped")
    nr = NumericRobot(robot)
    rng = np.random.default_rng(1)
    states = [{"q": nr.random_configuration(rng), "e": np.array([0.3])} for _ in range(3)]
    # the redundant stance's forward and impulse dynamics have status 0: their other outputs are rounding, not compared
    garbage = ("biped_contact_dynamics_redundant", "biped_impulse_dynamics_redundant")
    assert compare(tmp_path / "casadi", manifest, py, "biped", states, garbage) == 5
    for name in garbage:
        status = ca.Function.load(str(tmp_path / "casadi" / f"{name}.casadi"))(states[0]["q"], *np.ones((2, 12)))[-1] \
            if "contact" in name else ca.Function.load(str(tmp_path / "casadi" / f"{name}.casadi"))(states[0]["q"], np.ones(12), 0.3)[-1]
        assert float(status) == 0.0, name


def test_bad_function_name_is_one_line(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["export-casadi", "planar_2r", "--out", str(out), "--functions", "mass_matrix", "nope"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("derive: error: ") and "'nope'" in lines[0], lines
    assert not out.exists()
    assert main(["export-casadi", "planar_2r", "--out", str(out), "--functions", "gravity"]) == 0
    assert [p.name for p in out.iterdir()] == ["planar_2r_gravity.casadi"]


def test_contact_mpc_example(tmp_path):
    """examples/contact_mpc.py as a user runs it: it exports the biped's contact dynamics, solves its OCP and
    prints the check it makes (feet held, forces pushing, base height reached)."""
    run = subprocess.run([sys.executable, str(ROOT / "examples" / "contact_mpc.py"), str(tmp_path / "casadi")],
                         cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stdout + run.stderr
    assert "solved" in run.stdout and (tmp_path / "casadi" / "biped_contact_dynamics_baumgarte_stance.casadi").is_file(), run.stdout
