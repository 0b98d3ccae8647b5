"""The installed tool: the wheel, in a fresh virtual environment, used from a folder of the user's own.

Builds the wheel (pip wheel, hatchling), installs it with the pinned dependencies into a new
venv (conftest.py's build_installed, in the background from the start of the session), and runs
`derive` there from a temporary folder on a models file that is none of the shipped ones: init,
generate (other robots untouched), latex, simulate, ik. The generated C compiles clean, the
generated Python imports and matches the numeric reference.
"""

from __future__ import annotations

import hashlib
import re
import importlib.util
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from derive.description.model import parse_models
from derive.reference import NumericRobot

from test_generate import MY_MODELS
from util import compile_objects, load_module

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def installed(installed_venv):
    """(path of the venv's `derive` command, its python) with the wheel installed: conftest.py's
    build_installed, begun in the background when the session started."""
    return installed_venv()


def run(installed, folder: Path, *argv: str, status: int = 0) -> subprocess.CompletedProcess:
    env = {k: v for k, v in os.environ.items() if k not in ("DERIVE_MODELS", "PYTHONPATH")}
    res = subprocess.run([str(installed[0]), *argv], cwd=folder, env=env, capture_output=True, text=True, timeout=300)
    assert res.returncode == status, f"derive {' '.join(argv)}: exit {res.returncode}\n{res.stdout}\n{res.stderr}"
    assert "Traceback" not in res.stderr
    return res


def digests(folder: Path) -> dict[str, str]:
    return {p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def test_the_wheel_carries_templates_and_models_and_not_the_checkout(installed, tmp_path):
    code = "import derive, derive.resources as r; print(derive.__file__); print(r.TEMPLATES); print(r.EXAMPLE_MODELS)"
    out = subprocess.run([str(installed[1]), "-c", code], cwd=tmp_path, capture_output=True, text=True,
                         check=True).stdout.split()
    venv = installed[1].parent.parent
    assert all(Path(p).is_relative_to(venv) for p in out), out
    assert (Path(out[1]) / "c" / "support" / "derive_ik.h").is_file()


def test_own_robot_from_any_folder(installed, tmp_path):
    user = tmp_path / "my_project"
    user.mkdir()
    # start from a shipped robot, generate it; then generate the user's own robot beside it
    run(installed, user, "init", "--robot", "pendulum")
    run(installed, user, "generate")
    pendulum = digests(user / "generated" / "pendulum")
    (user / "my.yaml").write_text(MY_MODELS)
    out = run(installed, user, "--models", "my.yaml", "generate").stdout
    assert "1 other robot(s) left as they were" in out
    assert digests(user / "generated" / "pendulum") == pendulum
    run(installed, user, "generate", "--models", "my.yaml", "--check")

    # the C compiles clean, the Python imports and matches the reference
    c_dir = user / "generated" / "my_arm" / "c"
    cc = shutil.which("cc") or shutil.which("gcc")
    compile_objects([cc, "-std=c99", "-O1", "-Wall", "-Wextra", "-Werror", "-pedantic", f"-I{c_dir}"],
                    sorted(c_dir.glob("*.c")), tmp_path)  # one source per process, CPUs at once
    mod = load_module(user / "generated" / "my_arm" / "python" / "my_arm.py", "my_arm")
    ref = NumericRobot(parse_models(MY_MODELS)["my_arm"])
    rng = np.random.default_rng(0)
    for _ in range(10):
        q, qd, qdd = rng.uniform(-2, 2, 2), rng.normal(size=2), rng.normal(size=2)
        np.testing.assert_allclose(mod.inverse_dynamics(q, qd, qdd), ref.rnea(q, qd, qdd), rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(mod.mass_matrix(q), ref.crba(q), rtol=1e-9, atol=1e-12)

    # the other commands work on the user's robot in the user's folder
    run(installed, user, "--models", "my.yaml", "latex", "my_arm", "--out", "my_arm.tex")
    assert "\\begin{document}" in (user / "my_arm.tex").read_text()
    sim = run(installed, user, "--models", "my.yaml", "simulate", "my_arm", "--q0", "0.1", "0.2", "--t", "0.5").stdout
    assert "my_arm" in sim and (user / "simulate_out").is_dir()
    ik = run(installed, user, "--models", "my.yaml", "ik", "my_arm", "--xyz", "0.5", "0", "0.2").stdout
    assert "solved" in ik and "NOT solved" not in ik
    # without a models file in the folder, the shipped examples answer (generate alone refuses)
    empty = tmp_path / "empty"
    empty.mkdir()
    assert "panda" in run(installed, empty, "info").stdout
    assert "no models.yaml in" in run(installed, empty, "generate", status=2).stderr
    assert sorted(os.listdir(empty)) == []


def test_the_getting_started_page_runs_verbatim_from_the_wheel(installed):
    """docs/getting-started/own-robot.md, every block in order (the site's own runner), with the wheel's
    `derive` and python: a models file from scratch, generate, C that compiles and runs, the generated
    Python; the torques the C and the Python print equal the numeric reference's g(q)."""
    spec = importlib.util.spec_from_file_location("derive_docs_hooks", ROOT / "docs" / "_hooks" / "derive_docs.py")
    hooks = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hooks)
    page = (ROOT / "docs" / "getting-started" / "own-robot.md").read_text()
    shown, times = hooks.run_blocks(page, "own-robot.md", required=True, python=str(installed[1]))
    assert len(times) == len(re.findall(r"^```[a-z]+ run", page, re.M)) == 9
    models = page.split("cat > models.yaml <<'YAML'\n", 1)[1].split("YAML\n", 1)[0]
    robot = parse_models(models)["my_arm"]
    q = np.array([0.5, 0.3])
    want = NumericRobot(robot).rnea(q, np.zeros(2), np.zeros(2))
    c_line = next(line for line in shown.splitlines() if line.startswith("tau = ") and "[" not in line)
    py_line = next(line for line in shown.splitlines() if line.startswith("tau = ["))
    np.testing.assert_allclose([float(x) for x in c_line.split()[2:]], want, rtol=0, atol=1e-6)  # printed %.6f
    np.testing.assert_allclose([float(x) for x in py_line[7:].strip("[]").split()], want, rtol=0, atol=1e-6)
