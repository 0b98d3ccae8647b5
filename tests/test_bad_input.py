"""Bad input and faults never hurt: one case per class of the project's bad-input corpus.

Each case ends in exactly one line `derive: error: ...` naming the file, robot and field
(exit status 2, nothing written, the output folder untouched) or in output that works. Cases
that used to hang run in a subprocess with a time limit, so a regression fails instead of
hanging the suite.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from derive.cli import main

ROOT = Path(__file__).resolve().parent.parent

ARM = """\
robots:
  {name}:
    parameters: {{{params}}}
    links:
      - {{name: base}}
      - {{name: l1, mass: {mass}, com: [0.1, 0, 0], inertia: [0.01, 0.01, 0.01]}}
      - {{name: l2, mass: 0.5, com: [0.1, 0, 0], inertia: [0.01, 0.01, 0.01]}}
    joints:
      - {{name: {j1}, type: revolute, parent: base, child: l1, axis: [0, 0, 1]}}
      - {{name: {j2}, type: revolute, parent: l1, child: l2, axis: [0, 1, 0], origin: {{xyz: [0.2, 0, 0]}}}}
    frames:
      - {{name: tcp, link: l2, xyz: [0.1, 0, 0]}}
"""


def arm(name="arm", mass="1.0", j1="q1", j2="q2", params="L: 1.0"):
    return ARM.format(name=name, mass=mass, j1=j1, j2=j2, params=params)


BOMB = "robots:\n  arm:\n    description: &a0 [x, x, x, x, x, x, x, x, x]\n" + "".join(
    f"    d{i}: &a{i} [*a{i - 1}, *a{i - 1}, *a{i - 1}, *a{i - 1}, *a{i - 1}, *a{i - 1}, *a{i - 1}, *a{i - 1}, *a{i - 1}]\n"
    for i in range(1, 12))

# (id, models text (or bytes), fragment of the error line)
MODELS = [
    ("hang-exponent", arm(mass="9**9**9"), "links[1].mass: '9**9**9': an exponent must be a number"),
    ("hang-alias-bomb", BOMB, "YAML expands to more than"),
    ("binary-file", b"\x89PNG\r\n\x1a\n\x00\x00\xff\xfe" * 100, "is not UTF-8 text"),
    ("deep-nesting", "robots: " + "[" * 20000 + "]" * 20000 + "\n", "nested"),
    ("wrong-arity", arm(mass="atan2(1)"), "atan2 takes 2 arguments, got 1"),
    ("long-expression", arm(mass="+".join(["L"] * 5000)), "longer than 500 characters"),
    ("long-name", arm(name="a" * 300), "is longer than 64 characters"),
    ("overflow", arm(mass="1e300"), "larger than 1e+12 in magnitude"),
    ("overflow-expression", arm(mass="L*1e200*1e200"), "evaluates to inf"),
    ("shadows-math-h", arm(name="math"), "generated math.h / math.py would shadow <math.h>"),
    ("shadows-support", arm(name="derive_ik"), "reserved for derive's support files"),
    ("shadows-real", arm(name="derive_real"), "reserved for derive's support files"),
    ("velocity-symbol", arm(j1="q1", j2="dq1"), "'dq1' of coordinate 'dq1' is already the symbol of the velocity of 'q1'"),
    ("torque-symbol", arm(params="tau_q1: 1.0"), "torque symbol 'tau_q1' of coordinate 'q1' is already the symbol of parameter"),
    ("parameter-pi", arm(params="pi: 3.0"), "'pi' is reserved in expressions"),
    ("parameter-sin", arm(params="sin: 3.0"), "'sin' is reserved in expressions"),
    ("case-clash", arm("arm") + arm("Arm").replace("robots:\n", ""), "robot 'Arm': name: differs from robot 'arm' only by case"),
    ("duplicate-key", arm().replace("    parameters:", "    gravity: [0, 0, -9.81]\n    gravity: [0, 0, -1]\n    parameters:"),
     "duplicate key 'gravity'"),
    ("frame-case-clash", arm().replace("      - {name: tcp, link: l2, xyz: [0.1, 0, 0]}\n",
                                       "      - {name: tcp, link: l2}\n      - {name: TCP, link: l2}\n"), "only by case"),
]


def files_of(folder: Path) -> dict[str, str]:
    return {p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def run_cli(argv, cwd: Path, timeout: float = 30) -> tuple[int, str, float]:
    env = {k: v for k, v in os.environ.items() if k != "DERIVE_MODELS"}
    start = time.perf_counter()
    res = subprocess.run([sys.executable, "-m", "derive", *argv], cwd=cwd, env=env, capture_output=True,
                         text=True, timeout=timeout)
    return res.returncode, res.stderr, time.perf_counter() - start


@pytest.fixture(scope="module")
def generated_ok_arm(tmp_path_factory):
    """One robot generated once for the module, copied by ``output``."""
    base = tmp_path_factory.mktemp("ok_arm")
    (base / "ok.yaml").write_text(arm("ok_arm"))
    assert main(["--models", str(base / "ok.yaml"), "generate", "--out", str(base / "generated")]) == 0
    return base / "generated"


@pytest.fixture()
def output(tmp_path, generated_ok_arm):
    """An output folder holding one generated robot (a copy of the module's), to prove that failures
    leave it untouched."""
    out = tmp_path / "generated"
    shutil.copytree(generated_ok_arm, out)
    return out


@pytest.mark.parametrize("text, fragment", [pytest.param(t, f, id=i) for i, t, f in MODELS])
def test_bad_models_end_in_one_line(text, fragment, tmp_path, output):
    models = tmp_path / "models.yaml"
    (models.write_bytes if isinstance(text, bytes) else models.write_text)(text)
    before = files_of(output)
    status, err, seconds = run_cli(["--models", str(models), "generate", "--out", str(output)], tmp_path)
    lines = err.splitlines()
    assert status == 2 and len(lines) == 1 and lines[0].startswith("derive: error: "), err
    assert str(models) in lines[0] or "robot '" in lines[0], lines[0]
    assert fragment in lines[0], lines[0]
    assert seconds < 20
    assert files_of(output) == before
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == []


def test_models_file_that_is_not_a_file(tmp_path, output):
    before = files_of(output)
    for models, fragment in (("/dev/zero", "/dev/zero: cannot read models file: not a regular file"),
                             (str(tmp_path), "not a regular file"),
                             ("", "models file: empty path")):
        status, err, seconds = run_cli(["--models", models, "generate", "--out", str(output)], tmp_path, timeout=20)
        assert status == 2 and err.count("\n") == 1 and fragment in err, err
    assert files_of(output) == before


def test_a_massless_last_link_is_refused_not_divided_by_zero(tmp_path, output, capsys):
    text = arm().replace("      - {name: l2, mass: 0.5, com: [0.1, 0, 0], inertia: [0.01, 0.01, 0.01]}", "      - {name: l2}")
    (tmp_path / "m.yaml").write_text(text)
    before = files_of(output)
    assert main(["--models", str(tmp_path / "m.yaml"), "generate", "--strict", "--out", str(output)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err == [f"derive: error: {tmp_path / 'm.yaml'}: robot 'arm': joints (q2): coordinate 'q2' moves no mass or inertia, so M(q) is "
                   "singular and forward dynamics do not exist; give the links it moves a mass (links[i].mass) or "
                   "inertia about its axis"]
    assert files_of(output) == before


@pytest.mark.parametrize("case", ["file-as-parent", "proc"])
def test_write_failures_are_one_line(case, tmp_path, capsys):
    (tmp_path / "m.yaml").write_text(arm())
    if case == "file-as-parent":
        (tmp_path / "plain").write_text("a file")
        out = tmp_path / "plain" / "generated"
    else:
        out = Path("/proc/derive-cannot-write-here")
    assert main(["--models", str(tmp_path / "m.yaml"), "generate", "--out", str(out)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("derive: error: ") and "Traceback" not in err[0], err
    assert str(out.parent) in err[0] or str(out) in err[0]
    # the other commands' outputs likewise
    assert main(["--models", str(tmp_path / "m.yaml"), "latex", "arm", "--out", str(out / "arm.tex")]) == 2
    err = capsys.readouterr().err.splitlines()  # after its progress line "deriving arm ..."
    assert err[-1].startswith("derive: error: ") and str(out) in err[-1] and "Traceback" not in "".join(err), err


def test_symlinked_output_folder_is_written_through(tmp_path):
    (tmp_path / "m.yaml").write_text(arm())
    target = tmp_path / "real"
    link = tmp_path / "link"
    link.symlink_to(target, target_is_directory=True)
    assert main(["--models", str(tmp_path / "m.yaml"), "generate", "--out", str(link)]) == 0
    assert link.is_symlink() and (target / "arm" / "python" / "arm.py").is_file()
    assert main(["--models", str(tmp_path / "m.yaml"), "generate", "--out", str(link), "--no-cache"]) == 0
    assert link.is_symlink() and link.resolve() == target.resolve()


def test_a_killed_generation_leaves_the_old_folder_and_is_cleaned_up(tmp_path):
    """SIGKILL mid-run: the output folder is the old one, and the next run removes the leftovers.
    SIGTERM: the temporary folder is removed on the way out (exit status 143)."""
    from derive.codegen.generate import generate
    from derive.description.model import load_models

    (tmp_path / "m.yaml").write_text(arm())
    out = tmp_path / "generated"
    assert main(["--models", str(tmp_path / "m.yaml"), "generate", "--out", str(out)]) == 0
    before = files_of(out)
    # a 9-link chain takes several seconds to generate: ample time to be signalled before the swap
    links = ["      - {name: l0}"] + [f"      - {{name: l{i}, mass: 1.0, com: [0.1, 0, 0], inertia: [0.01, 0.02, 0.03]}}"
                                      for i in range(1, 10)]
    joints = [f"      - {{name: j{i}, type: revolute, parent: l{i - 1}, child: l{i}, axis: {['[0, 0, 1]', '[0, 1, 0]', '[1, 0, 0]'][i % 3]}, "
              f"origin: {{xyz: [0.2, 0.05, 0.1]}}}}" for i in range(1, 10)]
    (tmp_path / "big.yaml").write_text("robots:\n  chain9:\n    links:\n" + "\n".join(links) + "\n    joints:\n"
                                       + "\n".join(joints) + "\n    frames:\n      - {name: tcp, link: l9}\n")

    def leftovers():
        return [p.name for p in tmp_path.iterdir() if p.name.startswith(".generated.")]

    def start_and_signal(sig):
        proc = subprocess.Popen([sys.executable, "-m", "derive", "--models", str(tmp_path / "big.yaml"), "generate",
                                 "--out", str(out), "--no-cache"], cwd=tmp_path,
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        mine = f".generated.tmp-{proc.pid}-"
        deadline = time.time() + 60
        while time.time() < deadline and not any(name.startswith(mine) for name in leftovers()):
            time.sleep(0.01)
        assert any(name.startswith(mine) for name in leftovers()), "generation never started"
        proc.send_signal(sig)
        proc.communicate(timeout=60)
        assert files_of(out) == before  # the old folder, whole
        return proc.returncode

    assert start_and_signal(signal.SIGKILL) == -signal.SIGKILL
    assert leftovers(), "SIGKILL cannot be caught: the temporary folder stays until the next run"
    logs: list[str] = []
    generate(load_models(tmp_path / "m.yaml"), out, log=logs.append)
    assert leftovers() == [] and any("left by an interrupted run" in line for line in logs)
    before = files_of(out)
    assert start_and_signal(signal.SIGTERM) == 128 + signal.SIGTERM
    assert leftovers() == []


def test_a_kill_between_the_renames_of_the_fallback_swap_is_recovered(tmp_path, monkeypatch):
    """Where the system has no atomic exchange, the backup left by a kill between the two
    renames is put back by the next run."""
    import derive.codegen.generate as gen
    from derive.description.model import load_models

    (tmp_path / "m.yaml").write_text(arm())
    robots = load_models(tmp_path / "m.yaml")
    out = tmp_path / "generated"
    gen.generate(robots, out, log=lambda s: None)
    before = files_of(out)
    # a dead run's backup, as the fallback swap leaves it between its two renames
    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True)
    os.rename(out, tmp_path / f".generated.old-{int(dead.stdout)}")
    assert not out.exists()
    monkeypatch.setattr(gen, "_exchange", lambda a, b: False)
    logs: list[str] = []
    gen.generate(robots, out, log=logs.append)
    assert files_of(out) == before
    assert any("restored" in line for line in logs)
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".generated.")] == []


def test_unexpected_faults_are_one_line_too(monkeypatch, capsys):
    import derive.cli.models as models_cli

    def boom(args):
        raise ZeroDivisionError("float division by zero")

    monkeypatch.setattr(models_cli, "cmd_info", boom)
    monkeypatch.delenv("DERIVE_DEBUG", raising=False)
    assert main(["info"]) == 3
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 1 and err[0].startswith("derive: internal error: ZeroDivisionError: float division by zero")
