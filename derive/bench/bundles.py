"""Benchmark of the control-tick bundles (issue "Firmware-grade package").

``bundles``: for every shipped robot and bundle, the generated C bundle against the separate
generated functions it replaces (one call each, the same inputs), both compiled with ``cc -O2``
in the same run: arithmetic ops (after CSE, from manifest.json), callgrind instructions per call
(repeatable) and wall time per call (median of 5 runs). Target: bundle <= 0.7x the separate calls.
"""

from __future__ import annotations

import json
import statistics
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from derive.bench.codegen import callgrind_instructions
from derive.description.model import load_models
from derive.resources import CHECKOUT

ROOT = CHECKOUT
TARGET = 0.7

PROGRAM = r"""#define _POSIX_C_SOURCE 199309L
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
%(includes)s

int main(int argc, char **argv)
{
    long n = argc > 1 ? atol(argv[1]) : 1000, k;
    int i;
    double sum = 0.0;
    struct timespec t0, t1;
%(buffers)s
    clock_gettime(CLOCK_MONOTONIC, &t0);
    for (k = 0; k < n; ++k) {
%(perturb)s
%(calls)s
        sum += %(touch)s;
    }
    clock_gettime(CLOCK_MONOTONIC, &t1);
    printf("%%.3f %%g\n", ((t1.tv_sec - t0.tv_sec) * 1e9 + (t1.tv_nsec - t0.tv_nsec)) / (n > 0 ? n : 1), sum);
    return 0;
}
"""


def _program(manifest: dict, calls: list[dict]) -> str:
    """A C program calling ``calls`` (manifest entries) n times on shared inputs, perturbed each time."""
    inputs: dict[str, int] = {}
    for fn in calls:
        for item in fn["inputs"]:
            inputs[item["name"]] = max(1, int(np.prod(item["shape"])))
    buffers = [f"    double {name}[{size}];\n    for (i = 0; i < {size}; ++i) {name}[i] = 0.1 + 0.01 * i;"
               for name, size in inputs.items()]
    lines, touch = [], []
    for k, fn in enumerate(calls):
        outs = []
        for j, item in enumerate(fn["outputs"]):
            outs.append(f"out{k}_{j}")
            buffers.append(f"    double out{k}_{j}[{max(1, int(np.prod(item['shape'])))}];")
            touch.append(f"out{k}_{j}[0]")
        lines.append(f"        {fn['name']}({', '.join([i['name'] for i in fn['inputs']] + outs)});")
    perturb = [f"        {name}[0] += 1e-9;" for name in inputs]
    includes = "\n".join(f'#include "{fn["name"]}.h"' for fn in calls)
    return PROGRAM % {"includes": includes, "buffers": "\n".join(buffers), "perturb": "\n".join(perturb),
                      "calls": "\n".join(lines), "touch": " + ".join(touch)}


def _measure(exe: Path, calls: int, reps: int) -> tuple[float, float]:
    """(callgrind instructions per call, median over 5 runs of the ns per call)."""
    i1, i0 = callgrind_instructions(exe, calls), callgrind_instructions(exe, 0)
    instr = (i1 - i0) / calls if i1 is not None and i0 is not None else float("nan")
    times = [float(subprocess.run([str(exe), str(reps)], capture_output=True, text=True, check=True).stdout.split()[0])
             for _ in range(5)]
    return instr, statistics.median(times)


def bench_bundles(args) -> str:
    calls = 200 if args.quick else 1000
    rows = ["## Control-tick bundles against the separate calls (same run)", "",
            "| robot | bundle | separate calls | ops bundle / separate | ratio | instr/call bundle / separate | ratio "
            "| ns/call bundle / separate | ratio |",
            "|---|---|---|---|---|---|---|---|---|"]
    worst = {"ops": 0.0, "instr": 0.0, "ns": 0.0}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for robot in load_models(ROOT / "models.yaml"):
            manifest = json.loads((ROOT / "generated" / robot / "manifest.json").read_text())
            by_name = {f["name"]: f for f in manifest["functions"]}
            cdir = ROOT / "generated" / robot / "c"
            for fn in (f for f in manifest["functions"] if f["quantity"] == "bundle"):
                parts = [by_name.get(f"{robot}_{part['output']}") for part in fn["bundle"]]
                if any(p is None for p in parts):
                    continue  # a link's quantity with no separate generated function
                measured = {}
                for label, called in (("bundle", [fn]), ("separate", parts)):
                    src = tmp / f"{label}.c"
                    src.write_text(_program(manifest, called))
                    sources = [str(cdir / f["c"]["source"].split("/")[-1]) for f in called]
                    subprocess.run(["cc", "-O2", "-std=c99", f"-I{cdir}", "-o", str(tmp / label), str(src), *sources,
                                    "-lm"], check=True)
                    measured[label] = _measure(tmp / label, calls, 20000 if args.quick else 200000)
                ops_b, ops_s = fn["ops"]["total"], sum(p["ops"]["total"] for p in parts)
                (ib, nb), (is_, ns) = measured["bundle"], measured["separate"]
                ratios = {"ops": ops_b / ops_s, "instr": ib / is_, "ns": nb / ns}
                worst = {k: max(worst[k], ratios[k]) for k in worst}
                rows.append(f"| {robot} | {fn['frame']} | {', '.join(p['output'] for p in fn['bundle'])} | "
                            f"{ops_b} / {ops_s} | {ratios['ops']:.2f} | {ib:.0f} / {is_:.0f} | {ratios['instr']:.2f} | "
                            f"{nb:.1f} / {ns:.1f} | {ratios['ns']:.2f} |")
    met = {k: "met" if v <= TARGET else "NOT met" for k, v in worst.items()}
    rows += ["", f"Worst ratios: ops {worst['ops']:.2f} ({met['ops']}), instructions {worst['instr']:.2f} "
                 f"({met['instr']}), time {worst['ns']:.2f} ({met['ns']}); target <= {TARGET}.",
             "Each side is one C program (cc -O2) calling the bundle, or each separate generated function once, per",
             "iteration on the same inputs; instructions by valgrind --tool=callgrind (repeatable), time the median",
             "of 5 runs of 200 000 iterations (noisy on shared machines). The bundle's saving is mostly the sines and",
             "cosines (each separate function computes its own) and the RNEA's forward pass that the bias and J'qd",
             "share; M (composite rigid bodies) and the bias (Newton-Euler) share little else, which bounds the ops."]
    return "\n".join(rows)


def benchmarks() -> dict:
    return {"bundles": bench_bundles}
