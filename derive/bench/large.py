"""Benchmark of large robots (issue "Large robots"): generation and compilation against dof.

``large``: generic chains (random placements, axes cycling z, y, x) of growing size: wall time to
derive and render the whole set, the operations of the largest functions, and the time and peak
memory (per process) of compiling every generated C file with ``cc -O2`` (two at a time).
"""

from __future__ import annotations

import json
import os
import subprocess
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

from derive.codegen.backends.c import printer as c_printer
from derive.codegen.generate import generate
from derive.description.model import parse_models

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
            robot = parse_models(generic_chain(n))[f"chain{n}"]
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


def benchmarks() -> dict:
    return {"large": bench_large}
