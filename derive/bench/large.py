"""Benchmark of large robots (issue "Large robots"): generation and compilation against dof.

``large``: generic chains (random placements, axes cycling z, y, x) of growing size: wall time to
derive and render the whole set, the operations of the largest functions, and the time and peak
memory (per process) of compiling every generated C file with ``cc -O2`` (two at a time).

``big``: robots as people have them (iCub, the Unitree H1-2 with hands, a Kinova Gen3 with a 2F-85
and a wrist camera), fixed and floating, with the default selection of big robots
(:attr:`derive.description.robot.Robot.function_frames`, ``function_quantities``): functions,
files and sizes, ``derive generate`` time of that robot alone, the first (compiling) and a cached
import of its generated Python module in a fresh process, and the first call of its forward dynamics
(compiling the part file that defines it lazily, see :data:`derive.codegen.backends.python.EAGER_OPS`). URDFs that no package ships are
read from the paths in :data:`BIG_URDF_VARIABLES` (never committed); without them the row says so.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from derive.codegen.backends.c import printer as c_printer
from derive.codegen.backends.python import EAGER_OPS, WHOLE_OPS
from derive.codegen.generate import generate
from derive.description.model import parse_models, parse_robot
from derive.description.urdf import import_urdf_named

SIZES = (6, 12, 20, 40)
QUICK_SIZES = (6, 12)
SHOWN = ("inverse_dynamics", "mass_matrix", "forward_dynamics", "coriolis_matrix", "inverse_dynamics_derivatives",
         "ode_jac_x")


def generic_chain(n: int, seed: int = 0) -> str:
    """models.yaml text of an n-joint chain ``chain<n>`` with random placements and mass properties."""
    rng = np.random.default_rng(seed)
    axes = ("[0, 0, 1]", "[0, 1, 0]", "[1, 0, 0]")
    links = ["      - {name: base}"]
    joints = []
    for i in range(1, n + 1):
        c, xyz, rpy = rng.uniform(-0.1, 0.1, 3), rng.uniform(-0.2, 0.2, 3), rng.uniform(-1, 1, 3)
        links.append(f"      - {{name: l{i}, mass: {rng.uniform(0.5, 2):.3f}, com: [{c[0]:.3f}, {c[1]:.3f}, {c[2]:.3f}], "
                     "inertia: [0.02, 0.03, 0.04]}")
        joints.append(f"      - {{name: q{i}, type: revolute, parent: {'base' if i == 1 else f'l{i - 1}'}, child: l{i}, "
                      f"axis: {axes[i % 3]}, origin: {{xyz: [{xyz[0]:.3f}, {xyz[1]:.3f}, {xyz[2]:.3f}], "
                      f"rpy: [{rpy[0]:.3f}, {rpy[1]:.3f}, {rpy[2]:.3f}]}}}}")
    return (f"robots:\n  chain{n}:\n    links:\n" + "\n".join(links) + "\n    joints:\n" + "\n".join(joints)
            + f"\n    frames:\n      - {{name: tcp, link: l{n}, xyz: [0.1, 0, 0]}}\n")


def _compile(source: Path, include: Path) -> tuple[float, int]:
    """(seconds, peak resident kB of the compiler) of ``cc -O2 -c source``."""
    start = time.perf_counter()
    out = subprocess.run(["/usr/bin/time", "-f", "%M", "cc", "-O2", "-std=c99", "-c", f"-I{include}", "-o", os.devnull,
                          str(source)], capture_output=True, text=True, check=True)
    return time.perf_counter() - start, int(out.stderr.strip().splitlines()[-1])


def bench_large(args) -> str:
    rows = ["## Large robots: generation and compilation against dof (generic chains)", "",
            "| dof | generate s | " + " | ".join(f"{q} ops" for q in SHOWN) + " | C files | compile s (2 jobs) "
            "| slowest file s | peak MB per compiler | parts |",
            "|---|---|" + "---|" * len(SHOWN) + "---|---|---|---|---|"]
    have_time = Path("/usr/bin/time").is_file()
    with tempfile.TemporaryDirectory() as tmp:
        for n in QUICK_SIZES if args.quick else SIZES:
            # the whole set and the tcp alone, at every size: a chain above BIG_NV would get the lean default
            robot = parse_models(generic_chain(n) + "    generate: {frames: [tcp], quantities: all}\n")[f"chain{n}"]
            start = time.perf_counter()
            generate({robot.name: robot}, Path(tmp), use_cache=False, log=lambda s: None)
            gen = time.perf_counter() - start
            folder = Path(tmp) / robot.name
            manifest = json.loads((folder / "manifest.json").read_text())
            ops = {f["quantity"]: f["ops"]["total"] if f["ops"] else "loops" for f in manifest["functions"] if not f["frame"]}
            sources = sorted((folder / "c").glob("*.c"))
            parts = sum((folder / "c" / s.name).read_text().count("DERIVE_NOINLINE void") for s in sources)
            if have_time:
                start = time.perf_counter()
                with ThreadPoolExecutor(2) as pool:
                    results = list(pool.map(lambda s: _compile(s, folder / "c"), sources))
                wall = time.perf_counter() - start
                slowest, peak = max(r[0] for r in results), max(r[1] for r in results) / 1024
                compiled = f"{wall:.1f} | {slowest:.1f} | {peak:.0f}"
            else:
                compiled = "n/a | n/a | n/a"
            rows.append(f"| {n} | {gen:.1f} | " + " | ".join(str(ops.get(q, "")) for q in SHOWN)
                        + f" | {len(sources)} | {compiled} | {parts} |")
    rows += ["", f"Functions above {c_printer.SPLIT_ABOVE} instructions and output entries are split into parts of at "
             f"most {c_printer.PART_SIZE} instructions or output stores (`parts`: their number over the robot), which the "
             "compiler handles in time and",
             "memory linear in the size; outputs mostly of zeros have those written by a loop. Before the split, gcc -O2",
             "did not finish a 20-dof chain's C within 600 s and took about 10 GB per process (the issue's figures).",
             "Above 12 joints the forward dynamics are the articulated-body algorithm (O(n)), and the Coriolis matrix",
             "and inverse_dynamics_derivatives come from the analytic RNEA derivatives (O(n) per body plus a dot",
             "product per ancestor pair) instead of automatic differentiation, and the ODE Jacobians are loops",
             "(`loops`: M's LTDL factor and solve) around calls of forward_dynamics, inverse_dynamics_derivatives",
             "and mass_matrix instead of an unrolled O(n^3) solve; manifest.json's `algorithm` and `c.form` say",
             "which form each function takes. Measured on a shared 2-core machine: times are indicative."]
    return "\n".join(rows)


BIG_URDF_VARIABLES = {"h1_2": "DERIVE_BENCH_H1_2_URDF", "gen3_2f85": "DERIVE_BENCH_GEN3_2F85_URDF"}
"""Environment variables naming the URDFs of ``big`` that no installed package ships: the H1-2 with
hands (unitree_ros robots/h1_2_description/h1_2.urdf) and the Gen3 with a 2F-85 and a wrist camera
(ros2_kortex kortex_description/robots/gen3_2f85.urdf); meshes are not needed."""
BIG_ROBOTS = (
    # (label, URDF or variable, --tip, bases, also the named frames' full set for comparison)
    ("iCub", "example-robot-data:icub_description/robots/icub.urdf", None, ("fixed", "floating"), False),
    ("Unitree H1-2 with hands", "h1_2", None, ("fixed", "floating"), False),
    ("Kinova Gen3 + 2F-85 + camera", "gen3_2f85", "gen3_end_effector_link", ("fixed",), True),
)
IMPORT_SCRIPT = ("import sys, time, numpy; sys.path.insert(0, sys.argv[1]); t = time.perf_counter(); "
                 "m = __import__(sys.argv[2]); print(time.perf_counter() - t)\n"
                 "if len(sys.argv) > 3:\n"
                 "    f, args = getattr(m, sys.argv[3]), [numpy.full(int(n), 0.5) for n in sys.argv[4:]]\n"
                 "    t = time.perf_counter(); f(*args); print(time.perf_counter() - t)")
"""Import the module (and call a function once on inputs of 0.5: a unit quaternion for a floating base);
print the seconds of each."""


def import_seconds(folder: Path, module: str, cache: Path | None, call: tuple[str, list[int]] | None = None):
    """Seconds to import the generated module ``module`` from ``folder`` in a fresh interpreter
    (numpy already imported): with ``cache`` None, compiling its source (no bytecode written or read,
    a first import); else with bytecode under ``cache`` (PYTHONPYCACHEPREFIX). With ``call`` (a
    function and its inputs' sizes), (import seconds, seconds of that function's first call)."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONDONTWRITEBYTECODE", "PYTHONPYCACHEPREFIX")}
    env.update({"PYTHONDONTWRITEBYTECODE": "1"} if cache is None else {"PYTHONPYCACHEPREFIX": str(cache)})
    extra = [call[0], *map(str, call[1])] if call else []
    out = subprocess.run([sys.executable, "-c", IMPORT_SCRIPT, str(folder), module, *extra], capture_output=True,
                         text=True, check=True, env=env)
    seconds = [float(line) for line in out.stdout.strip().splitlines()[-2 if call else -1:]]
    return tuple(seconds) if call else seconds[0]


def _megabytes(paths) -> float:
    return sum(p.stat().st_size for p in paths if p.is_file()) / 1e6


def bench_big(args) -> str:
    runs = 1 if args.quick else 2
    imports = 1 if args.quick else 3
    rows = ["## Big robots with the default selection (iCub, Unitree H1-2, Gen3 + 2F-85)", "",
            "| robot | base | nv | named frames | frames with functions | functions | files (C) | C MB | Python MB "
            "(imported) | JAX MB | generate s | first import s | cached import s | first FD call s |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    with tempfile.TemporaryDirectory() as tmp:
        for label, source, tip, bases, compare in BIG_ROBOTS:
            variable = BIG_URDF_VARIABLES.get(source)
            path = os.environ.get(variable, "") if variable else source
            if variable and not (path and Path(path).is_file()):
                rows.append(f"| {label} | {', '.join(bases)} | | | | | | | | | not measured: URDF not present "
                            f"(set {variable}) | | | |")
                continue
            for base in bases:
                with contextlib.redirect_stderr(io.StringIO()):  # the URDFs' rounded-angle warnings
                    name, entry = import_urdf_named(path, tip, floating=base == "floating")
                selections = [("default", entry)]
                if compare:
                    selections.append(("every named frame", {**entry, "generate": {
                        "frames": [f["name"] for f in entry["frames"]], "quantities": "all"}}))
                for how, spec in selections:
                    robot = parse_robot(name, spec)
                    out = Path(tmp) / f"{name}_{base}_{len(rows)}"
                    best = float("inf")
                    for _ in range(runs):
                        start = time.perf_counter()
                        generate({name: robot}, out, use_cache=False, log=lambda s: None)
                        best = min(best, time.perf_counter() - start)
                    folder = out / name
                    manifest = json.loads((folder / "manifest.json").read_text())
                    files = [p for p in folder.rglob("*") if p.is_file()]
                    c_files = [p for p in (folder / "c").rglob("*") if p.is_file()]
                    first = min(import_seconds(folder / "python", name, None) for _ in range(imports))
                    cache = Path(tmp) / f"pycache_{len(rows)}"
                    import_seconds(folder / "python", name, cache)  # writes the bytecode
                    cached = min(import_seconds(folder / "python", name, cache) for _ in range(imports))
                    fd = next(f for f in manifest["functions"] if f["quantity"] == "forward_dynamics")
                    sizes = [i["shape"][0] for i in fd["inputs"] if i["name"] != "p"]
                    call = min(import_seconds(folder / "python", name, None, ("forward_dynamics", sizes))[1]
                               for _ in range(runs))
                    python = list((folder / "python").rglob("*.py"))
                    rows.append(f"| {label}{'' if how == 'default' else f' ({how}, as before)'} | {base} | {robot.nv} "
                                f"| {len(robot.frames)} | {len(robot.function_frames)} | {len(manifest['functions'])} "
                                f"| {len(files)} ({len(c_files)}) | {_megabytes(c_files):.1f} "
                                f"| {_megabytes(python):.1f} ({_megabytes([folder / 'python' / f'{name}.py']):.1f}) "
                                f"| {_megabytes((folder / 'jax').rglob('*.py')):.1f} | {best:.1f} | {first:.1f} "
                                f"| {cached:.2f} | {call:.2f} |")
    rows += ["", "Each robot imported whole (`derive import-urdf FILE [--floating]`; the Gen3 with `--tip "
             "gen3_end_effector_link`) and generated with the default selection of big robots: per-frame functions "
             "for the tcp, the wrench frames and the leaves of the tree only; above 30 velocities also without the "
             "Coriolis matrix, dID/dx, the ODE, its Jacobians and RK4, and the regressors (docs/large-robots.md). "
             "generate s: `derive generate` of that robot alone (C, Python and JAX), no cache. first import: a fresh "
             "interpreter importing the generated Python module with no bytecode (it compiles the source, as a "
             "first import does); cached import: the same with the bytecode Python wrote on a previous import; "
             f"both best of {imports}. Python MB: the module and the part files of its largest functions, which it "
             "compiles on their first call (imported: the module alone, what an import compiles: at most "
             f"{EAGER_OPS:,} operations in a module of more than {WHOLE_OPS:,}, docs/large-robots.md); "
             "first FD call: forward_dynamics called once in a "
             "fresh interpreter after a first import, compiling its part if it has one. Generation best of "
             f"{runs} run{'s' * (runs > 1)}, on a shared 2-core machine. The H1-2 and Gen3 URDFs come "
             "from the vendors' public repositories (unitree_ros, ros2_kortex) and are not part of derive: "
             f"set {' and '.join(BIG_URDF_VARIABLES.values())} to their paths."]
    return "\n".join(rows)


def benchmarks() -> dict:
    return {"large": bench_large, "big": bench_big}
