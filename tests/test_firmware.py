"""Firmware: the generated C cross-compiles clean for Cortex-M4F and M7 (double and float, -O2 and
-O0) and its text and stack are what manifest.json records; the drop-in build files work from a
user's CMake project and plain Makefile, and the example control loop runs (fixed and floating
base) and agrees with the generated Python.

The cross builds need arm-none-eabi-gcc (Debian: gcc-arm-none-eabi, libnewlib-arm-none-eabi; .ci/run
installs them), the CMake test cmake: without them those tests are skipped, except in CI (CI set),
where a missing tool is a failure. Kept short: planar_2r whole, three Panda functions in one
configuration, and Panda's ode_jac_x, the largest translation unit, at -O0 only (at -O2 it alone takes
20 s of CPU; its -O2 figures are the recorded ones, whose recording the others check).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from derive.bench import firmware
from derive.bench.firmware import BUILDS, MEASURES, Build
from derive.cli import main
from derive.codegen.generate import check, generate, record_firmware, robot_files, source_hashes
from derive.description.model import parse_models

from util import load_module, robots

ROOT = Path(__file__).resolve().parent.parent
GENERATED = ROOT / "generated"
PANDA = ["panda_inverse_dynamics", "panda_mass_matrix", "panda_forward_dynamics"]
PANDA_DEBUG = "panda_ode_jac_x"  # measured at -O0 only
M4F_FLOAT = (Build("cortex-m4f", "float", "O2"), Build("cortex-m4f", "float", "O0"))
CFLAGS = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-Wdouble-promotion"]

FLOATING = """\
robots:
  hopper:
    base: floating
    links:
      - {name: body, mass: 2.0, com: [0, 0, 0.02], inertia: [0.02, 0.03, 0.04]}
      - {name: leg, mass: 0.5, com: [0, 0, -0.1], inertia: [0.002, 0.002, 0.0005]}
    joints:
      - {name: hip, type: revolute, parent: body, child: leg, axis: [0, 1, 0], origin: {xyz: [0, 0, -0.1]},
         limits: {lower: -1, upper: 1, velocity: 5, effort: 10}}
    frames:
      - {name: foot, link: leg, xyz: [0, 0, -0.2]}
"""


def need(tool: str) -> str:
    found = shutil.which(tool)
    if found is None:
        if os.environ.get("CI"):
            pytest.fail(f"{tool} not found: .ci/run installs it")
        pytest.skip(f"no {tool} on PATH (Debian: apt-get install "
                    f"{' '.join(firmware.DEBIAN_PACKAGES) if 'arm' in tool else tool})")
    return found


@pytest.fixture(scope="module")
def measured():
    """One pool: every file of planar_2r in all eight builds, three Panda functions in M4F float."""
    need("arm-none-eabi-gcc")
    return firmware.measure(GENERATED, {"planar_2r": None, "panda": PANDA},
                            builds={"planar_2r": BUILDS, "panda": M4F_FLOAT}, log=lambda s: None)


@pytest.fixture(scope="module")
def measured_debug():
    """Panda's ode_jac_x in M4F float at -O0."""
    need("arm-none-eabi-gcc")
    return firmware.measure(GENERATED, {"panda": [PANDA_DEBUG]}, builds=(M4F_FLOAT[1],), log=lambda s: None)


def test_generated_c_builds_clean_for_cortex_m(measured):
    assert measured.failures == []
    planar = measured.figures["planar_2r"]
    manifest = json.loads((GENERATED / "planar_2r" / "manifest.json").read_text())
    assert sorted(planar) == sorted(fn["name"] for fn in manifest["functions"])
    for name, fig in planar.items():
        for target, precision in firmware.configurations():
            values = fig[target][precision]
            assert sorted(values) == sorted(MEASURES), name
            assert values["text_O2"] > 0 and values["stack_O2"] >= 0 and values["stack_O0"] > 0, (name, target, precision)
    # the deepest chain: rk4_step's stack holds ode_rhs's frame under its own, ik_tcp's fk_jacobian_tcp's
    for target, precision in firmware.configurations():
        for level in ("stack_O2", "stack_O0"):
            assert planar["planar_2r_rk4_step"][target][precision][level] > planar["planar_2r_ode_rhs"][target][precision][level]
            assert planar["planar_2r_ik_tcp"][target][precision][level] > planar["planar_2r_fk_jacobian_tcp"][target][precision][level]
    # double is software on the M4F: its double code is the larger
    assert planar["planar_2r_ode_jac_x"]["cortex-m4f"]["double"]["text_O2"] > planar["planar_2r_ode_jac_x"]["cortex-m4f"]["float"]["text_O2"]


def test_panda_debug_build_stack_within_4x_of_optimised(measured, measured_debug):
    """Issue 16: at -O0 the Panda's functions need at most 4x their -O2 stack (work variables are
    reused); ode_jac_x's fresh -O0 figure against its recorded -O2 one (test_every_committed_function_has_clean_cortex_m_builds:
    recorded for its translation unit as committed)."""
    assert measured_debug.failures == []
    panda = measured.figures["panda"]
    assert sorted(panda) == sorted(PANDA)
    for name in PANDA:
        m4f = panda[name]["cortex-m4f"]["float"]
        assert 0 < m4f["stack_O0"] <= 4 * m4f["stack_O2"], (name, m4f)
        assert m4f["text_O2"] > 1000
    jac = measured_debug.figures["panda"][PANDA_DEBUG]["cortex-m4f"]["float"]
    assert sorted(jac) == ["stack_O0"]
    recorded = json.loads((GENERATED / "panda" / "manifest.json").read_text())["firmware"]["functions"][PANDA_DEBUG]
    assert 0 < jac["stack_O0"] <= 4 * recorded["cortex-m4f"]["float"]["stack_O2"], (jac, recorded["cortex-m4f"])
    assert jac["stack_O0"] < 4096, jac  # was about 41 kB before the work variables


def test_recorded_figures_match_a_fresh_measurement(measured, measured_debug):
    """manifest.json's figures (recorded by `make firmware-check`) are this toolchain's, function by function
    (Panda's ode_jac_x: its -O0 stack, the one figure measured of it)."""
    for robot, figures in [*measured.figures.items(), *measured_debug.figures.items()]:
        section = json.loads((GENERATED / robot / "manifest.json").read_text()).get("firmware")
        assert section, f"{robot}: manifest.json has no firmware figures; run `make firmware-check`"
        if section["toolchain"] != measured.toolchain.version:
            pytest.skip(f"figures recorded with {section['toolchain']}, this machine has {measured.toolchain.version}")
        hashes = source_hashes(robot_files(GENERATED / robot))
        for name, fig in figures.items():
            assert name in section["functions"], f"{name}: no recorded figures (its code changed?); run `make firmware-check`"
            recorded = section["functions"][name]
            assert recorded["source_sha256"] == hashes[name]
            for target, by_precision in fig.items():
                for precision, values in by_precision.items():
                    assert {k: recorded[target][precision][k] for k in values} == values, (robot, name, target, precision)


def test_every_committed_function_has_clean_cortex_m_builds():
    """Every function of every committed robot has recorded figures for all eight builds (M4F and M7,
    double and float, -O2 and -O0, each under -Werror -pedantic: `derive firmware-check` records
    figures only of clean builds) of its translation unit as committed. tests/conftest.py's host
    builds lean on this: their straight-line files build at -O0 only."""
    for robot in robots():
        manifest = json.loads((GENERATED / robot / "manifest.json").read_text())
        section = manifest.get("firmware") or {"functions": {}}
        hashes = source_hashes(robot_files(GENERATED / robot))
        for fn in manifest["functions"]:
            recorded = section["functions"].get(fn["name"])
            assert recorded is not None, f"{fn['name']}: no firmware figures; run `derive firmware-check --record {robot}`"
            assert recorded["source_sha256"] == hashes[fn["name"]], fn["name"]
            for build in BUILDS:  # a stack figure per level (0 for a leaf that needs none at -O2), text at -O2
                figures = recorded[build.target][build.precision]
                assert figures[f"stack_{build.level}"] >= 0 and figures["text_O2"] > 0, (fn["name"], build)


def test_a_warning_fails_the_check_in_one_line(tmp_path, monkeypatch, capsys):
    need("arm-none-eabi-gcc")
    out = tmp_path / "generated"
    shutil.copytree(GENERATED / "planar_2r", out / "planar_2r")
    shutil.copy(GENERATED / "MANIFEST.json", out / "MANIFEST.json")
    victim = out / "planar_2r" / "c" / "planar_2r_gravity.c"
    victim.write_text(victim.read_text().replace("{\n", "{\n    g[0] = p[0] * 0.5;\n", 1))  # float * double
    monkeypatch.setattr(firmware, "BUILDS", (Build("cortex-m4f", "float", "O2"),))
    assert main(["firmware-check", "planar_2r", "--out", str(out)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert err[0].startswith("derive: firmware-check: not clean: planar_2r: c/planar_2r_gravity.c (cortex-m4f, float, -O2): ")
    assert "double-promotion" in err[0]


def test_missing_toolchain_is_one_line_naming_the_packages(tmp_path, monkeypatch, capsys):
    monkeypatch.setenv("PATH", str(tmp_path))
    assert main(["firmware-check", "planar_2r", "--out", str(GENERATED)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["derive: error: firmware-check: arm-none-eabi-gcc is not on PATH; install the ARM cross toolchain "
                   "(Debian/Ubuntu: apt-get install gcc-arm-none-eabi libnewlib-arm-none-eabi)"]


@pytest.mark.parametrize("argv, message", [
    (["firmware-check", "no_such_robot"], "firmware-check: no robot 'no_such_robot' in the models file"),
    (["firmware-check", "planar_2r", "--out", str(GENERATED), "--jobs", "0"], "firmware-check: --jobs must be at least 1, got 0"),
    (["firmware-check", "planar_2r", "--out", "/nonexistent/generated"], "is not generated; run `derive generate` first"),
])
def test_bad_command_lines_are_one_line(argv, message, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("derive: error: ") and message in err[0], err


# ---- the record: firmware.json -> manifest.json, kept while the source is unchanged ----

def test_recorded_figures_follow_their_source(tmp_path):
    """record_firmware writes firmware.json and the manifest; generate reproduces the manifest from the
    record (fresh or not), keeps only the functions whose translation unit is unchanged, and check
    names a manifest whose figures differ from the record."""
    models = {"planar_2r": robots()["planar_2r"]}
    out, record = tmp_path / "generated", tmp_path / "firmware.json"
    generate(models, out, log=lambda s: None, firmware=record)
    hashes = source_hashes(robot_files(out / "planar_2r"))
    figures = {"cortex-m4f": {"float": {"stack_O0": 3, "stack_O2": 2, "text_O2": 1}}}
    entry = {"toolchain": "test", "flags": [], "functions": {
        "planar_2r_gravity": {"source_sha256": hashes["planar_2r_gravity"], **figures},
        "planar_2r_mass_matrix": {"source_sha256": "0" * 64, **figures}}}  # a source since changed
    record_firmware(out, {"planar_2r": entry}, record, log=lambda s: None)
    section = json.loads((out / "planar_2r" / "manifest.json").read_text())["firmware"]
    assert list(section["functions"]) == ["planar_2r_gravity"] and section["toolchain"] == "test"
    assert check(models, out, firmware=record) == []
    assert check(models, out, firmware=tmp_path / "none.json") == [
        f"{out / 'planar_2r' / 'manifest.json'} (its firmware figures differ from {tmp_path / 'none.json'})"]
    before = {k: hashlib.sha256(v).hexdigest() for k, v in robot_files(out / "planar_2r").items()}
    generate(models, out, log=lambda s: None, firmware=record)  # kept as it is
    fresh = tmp_path / "fresh"
    generate(models, fresh, use_cache=False, log=lambda s: None, firmware=record)  # rederived: the same bytes
    for folder in (out, fresh):
        assert {k: hashlib.sha256(v).hexdigest() for k, v in robot_files(folder / "planar_2r").items()} == before
    assert (fresh / "MANIFEST.json").read_bytes() == (out / "MANIFEST.json").read_bytes()
    logs: list[str] = []
    generate(models, out, log=logs.append, firmware=tmp_path / "none.json")  # no record: no figures
    assert "firmware" not in json.loads((out / "planar_2r" / "manifest.json").read_text())
    assert any("firmware figures updated" in line for line in logs)
    assert check(models, out, firmware=tmp_path / "none.json") == []


ARM = """\
robots:
  arm:
    links:
      - {name: base}
      - {name: upper, mass: 1.2, com: [0.2, 0, 0], inertia: [0.001, 0.02, 0.02]}
      - {name: fore, mass: 0.7, com: [0.15, 0, 0], inertia: [0.001, 0.01, 0.01]}
    joints:
      - {name: shoulder, type: revolute, parent: base, child: upper, axis: [0, 1, 0]}
      - {name: elbow, type: revolute, parent: upper, child: fore, axis: [0, 1, 0], origin: {xyz: [0.4, 0, 0]}}
    frames:
      - {name: tcp, link: fore, xyz: [0.3, 0, 0]}
"""


def test_figures_survive_a_model_edit_that_leaves_the_code_alone(tmp_path):
    """A new frame changes the model hash in every banner but not the mass matrix's code: its figures
    stay; a new mass changes the code: they go."""
    out, record = tmp_path / "generated", tmp_path / "firmware.json"
    generate(parse_models(ARM), out, log=lambda s: None, firmware=record)
    hashes = source_hashes(robot_files(out / "arm"))
    figures = {"cortex-m7": {"double": {"stack_O0": 3, "stack_O2": 2, "text_O2": 1}}}
    record_firmware(out, {"arm": {"toolchain": "test", "functions": {
        "arm_mass_matrix": {"source_sha256": hashes["arm_mass_matrix"], **figures}}}}, record, log=lambda s: None)
    framed = ARM + "      - {name: elbow_marker, link: upper, xyz: [0.4, 0, 0]}\n"
    generate(parse_models(framed), out, log=lambda s: None, firmware=record)
    assert json.loads((out / "arm" / "manifest.json").read_text())["firmware"]["functions"]["arm_mass_matrix"]["cortex-m7"] == figures["cortex-m7"]
    assert check(parse_models(framed), out, firmware=record) == []
    heavier = framed.replace("mass: 0.7", "mass: 0.8")
    generate(parse_models(heavier), out, log=lambda s: None, firmware=record)
    assert "firmware" not in json.loads((out / "arm" / "manifest.json").read_text())


def test_a_malformed_record_is_one_line(tmp_path, capsys):
    (tmp_path / "models.yaml").write_text(ARM)
    (tmp_path / "firmware.json").write_text("{not json")
    assert main(["--models", str(tmp_path / "models.yaml"), "generate", "--out", str(tmp_path / "gen")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"derive: error: {tmp_path / 'firmware.json'}: not valid JSON"), err
    assert not (tmp_path / "gen").exists()


def test_record_refuses_a_hand_edited_folder(tmp_path):
    models = {"planar_2r": robots()["planar_2r"]}
    out, record = tmp_path / "generated", tmp_path / "firmware.json"
    generate(models, out, log=lambda s: None, firmware=record)
    (out / "planar_2r" / "c" / "planar_2r_gravity.c").write_text("/* edited */\n")
    with pytest.raises(Exception, match="not as `derive generate` wrote it"):
        record_firmware(out, {"planar_2r": {"functions": {}}}, record, log=lambda s: None)
    assert not record.exists()


def test_manifest_lists_the_build_files():
    manifest = json.loads((GENERATED / "panda" / "manifest.json").read_text())
    build = {s["file"]: s for s in manifest["support"] if "build" in s}
    assert build["c/CMakeLists.txt"]["target"] == "panda_derive"
    assert "PANDA_DERIVE_SRC" in build["c/panda.mk"]["variables"]
    assert build["c/example/main.c"]["build"] == "example"
    files = json.loads((GENERATED / "MANIFEST.json").read_text())["robots"]["panda"]["files"]
    assert {"c/CMakeLists.txt", "c/panda.mk", "c/example/main.c"} <= set(files)


def test_functions_that_rely_on_infinities_or_check_inputs_say_what_fast_math_does():
    for header in sorted((GENERATED / "panda" / "c").glob("panda_manipulability_*.h")) + [
            GENERATED / "panda" / "c" / "panda_ik_tcp.h"]:
        assert "-ffast-math" in header.read_text(), header


# ---- the drop-in build files and the example ----

def load_python(folder: Path, robot: str):
    module = load_module(folder / robot / "python" / f"{robot}.py", f"fw_{robot}_{abs(hash(folder))}")
    return module


def example_in_python(py, nq: int, nv: int, floating: bool) -> list[float]:
    """example/main.c's numbers, from the generated Python: M[0][0], tau[0], qdd[0] asked and back,
    |qd| before and after 1000 ticks."""
    x = np.concatenate([0.1 * np.arange(1, nq + 1), np.full(nv, 0.1)])
    if floating:
        x[3:7] = [0.0, 0.0, 0.0, 1.0]
    M = py.mass_matrix(x[:nq])
    qdd = -5.0 * x[nq:]
    tau = py.inverse_dynamics(x[:nq], x[nq:], qdd)
    back = py.forward_dynamics(x[:nq], x[nq:], tau)
    speed0 = math.sqrt(sum(v * v for v in x[nq:]))
    for _ in range(1000):
        x = py.rk4_step(x, py.inverse_dynamics(x[:nq], x[nq:], -5.0 * x[nq:]), [0.001])
    return [M[0, 0], tau[0], qdd[0], back[0], speed0, math.sqrt(sum(v * v for v in x[nq:]))]


EXAMPLE_LINES = [r"M\[0\]\[0\] (\S+)", r"tau\[0\] (\S+)", r"qdd\[0\] (\S+) asked, (\S+) from forward_dynamics",
                 r"\|qd\| (\S+) at the start, (\S+) after 1000 ticks of 0\.001 s"]


def example_output(text: str) -> list[float]:
    """M[0][0], tau[0], qdd[0] asked and back, |qd| at the start and at the end, as printed."""
    lines = text.splitlines()
    assert len(lines) == 1 + len(EXAMPLE_LINES), text
    numbers = []
    for pattern, line in zip(EXAMPLE_LINES, lines[1:]):
        m = re.fullmatch(pattern, line)
        assert m, (pattern, line)
        numbers += [float(v) for v in m.groups()]
    return numbers


def assert_example_agrees(stdout: str, folder: Path, robot: str, precision: str) -> None:
    manifest = json.loads((folder / robot / "manifest.json").read_text())
    assert stdout.splitlines()[0] == f"{robot} (nq {manifest['nq']}, nv {manifest['nv']}, {precision})"
    got = example_output(stdout)
    want = example_in_python(load_python(folder, robot), manifest["nq"], manifest["nv"], manifest["base"] == "floating")
    rtol = 1e-8 if precision == "double" else 1e-3  # 9 digits printed; float arithmetic
    np.testing.assert_allclose(got, want, rtol=rtol, atol=1e-12 if precision == "double" else 1e-6)
    assert got[5] < 0.02 * got[4]  # damped: exp(-5) of the speed is left after 1 s


def tree(folder: Path) -> dict[str, str]:
    return {p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.mark.parametrize("robot, precision", [("planar_2r", "double"), ("planar_2r", "float")])
def test_cmake_project_outside_the_repo_links_the_library_and_runs_the_example(robot, precision, tmp_path):
    """add_subdirectory(generated/<robot>/c) in a user's project, link <robot>_derive, build example/main.c
    (-O0: the CMake default) under -Werror, run it; nothing is written into generated/."""
    cmake = need("cmake")
    cdir = GENERATED / robot / "c"
    before = tree(cdir)
    project = tmp_path / "user_project"
    project.mkdir()
    (project / "CMakeLists.txt").write_text(
        "cmake_minimum_required(VERSION 3.13)\nproject(user_firmware C)\n"
        f"add_subdirectory(\"${{DERIVE_C}}\" {robot}_derive)\n"
        "add_executable(control_loop \"${DERIVE_C}/example/main.c\")\n"
        f"target_link_libraries(control_loop PRIVATE {robot}_derive)\n")
    build = tmp_path / "build"
    flag = "ON" if precision == "float" else "OFF"
    configure = subprocess.run([cmake, "-S", str(project), "-B", str(build), f"-DDERIVE_C={cdir}",
                                f"-D{robot.upper()}_DERIVE_FLOAT={flag}", f"-DCMAKE_C_FLAGS={' '.join(CFLAGS[1:])}"],
                               capture_output=True, text=True)
    assert configure.returncode == 0, configure.stdout[-2000:] + configure.stderr[-2000:]
    made = subprocess.run([cmake, "--build", str(build), "-j", str(os.cpu_count() or 1)], capture_output=True, text=True)
    assert made.returncode == 0, made.stdout[-3000:] + made.stderr[-3000:]
    assert (build / f"{robot}_derive" / f"lib{robot}_derive.a").is_file()
    run = subprocess.run([str(build / "control_loop")], capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, run.stdout + run.stderr
    assert_example_agrees(run.stdout, GENERATED, robot, precision)
    assert tree(cdir) == before


@pytest.mark.parametrize("precision", ["double", "float"])
def test_makefile_fragment_builds_the_example_from_a_users_makefile(precision, tmp_path):
    make, cc = need("make"), shutil.which("cc") or need("gcc")
    cdir = GENERATED / "planar_2r" / "c"
    before = tree(cdir)
    (tmp_path / "Makefile").write_text(
        f"include {cdir}/planar_2r.mk\n"
        f"CC = {cc}\n"
        f"CFLAGS = {' '.join(CFLAGS)} -O1 $(PLANAR_2R_DERIVE_CFLAGS)\n"
        "control_loop: $(PLANAR_2R_DERIVE_EXAMPLE) $(PLANAR_2R_DERIVE_SRC)\n"
        "\t$(CC) $(CFLAGS) -o $@ $^ $(PLANAR_2R_DERIVE_LDLIBS)\n")
    extra = ["PLANAR_2R_DERIVE_FLOAT=1"] if precision == "float" else []
    made = subprocess.run([make, "-C", str(tmp_path), *extra], capture_output=True, text=True)
    assert made.returncode == 0, made.stdout[-3000:] + made.stderr[-3000:]
    run = subprocess.run([str(tmp_path / "control_loop")], capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, run.stdout + run.stderr
    assert_example_agrees(run.stdout, GENERATED, "planar_2r", precision)
    assert tree(cdir) == before


def test_example_runs_on_a_floating_base(tmp_path):
    """The same example/main.c on a floating base: q holds the base quaternion (identity at the start)."""
    cc = shutil.which("cc") or need("gcc")
    models = parse_models(FLOATING)
    generate(models, tmp_path / "generated", log=lambda s: None, firmware=tmp_path / "none.json")
    cdir = tmp_path / "generated" / "hopper" / "c"
    assert "x[6] = DERIVE_LIT(1.0);" in (cdir / "example" / "main.c").read_text()
    for precision in ("double", "float"):
        exe = tmp_path / f"example_{precision}"
        flags = ["-DDERIVE_FLOAT"] if precision == "float" else []
        used = [cdir / f"hopper_{name}.c" for name in ("mass_matrix", "inverse_dynamics", "forward_dynamics", "rk4_step", "ode_rhs")]
        subprocess.run([cc, *CFLAGS, "-O1", *flags, f"-I{cdir}", "-o", str(exe), str(cdir / "example" / "main.c"),
                        *map(str, used), "-lm"], check=True, capture_output=True, text=True)
        run = subprocess.run([str(exe)], capture_output=True, text=True, timeout=60)
        assert run.returncode == 0, run.stdout + run.stderr
        assert_example_agrees(run.stdout, tmp_path / "generated", "hopper", precision)
