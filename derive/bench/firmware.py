"""Microcontroller builds: ``derive firmware-check`` and ``derive bench firmware``.

Every generated C file of a robot is cross-compiled with arm-none-eabi-gcc (Debian's
``gcc-arm-none-eabi`` with ``libnewlib-arm-none-eabi``) for a Cortex-M4F (single-precision FPU:
double is done in software) and a Cortex-M7 (double-precision FPU), each in double and in float
(``-DDERIVE_FLOAT``), at -O2 and at -O0 (a debug build), under ``-Werror -pedantic
-Wdouble-promotion``: any warning fails the check. Measured per function:

- ``text_O2``: the text of its object at -O2 (``arm-none-eabi-size``: code and read-only data), what
  linking its file adds, without the generated functions it calls (in their own files) and libm;
- ``stack_O2``, ``stack_O0``: the deepest chain of stack frames from the function down through
  derive's code (its file's static helpers and the generated functions it calls), in bytes, from
  ``-fstack-usage`` / ``-fcallgraph-info=su``; libm's frames are not included.

``example/main.c`` is compiled too (it must build clean), without figures. The figures are
recorded into firmware.json and the manifests by :func:`derive.codegen.generate.record_firmware`.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import subprocess
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor, as_completed
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from derive.codegen.generate import robot_files, source_hashes
from derive.description.model import load_models
from derive.errors import DeriveError
from derive.resources import CHECKOUT

DEBIAN_PACKAGES = ("gcc-arm-none-eabi", "libnewlib-arm-none-eabi")
COMMON_FLAGS = ("-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic", "-Wdouble-promotion", "-fstack-usage",
                "-ffunction-sections", "-fcallgraph-info=su")
TARGETS = {"cortex-m4f": ("-mcpu=cortex-m4", "-mthumb", "-mfloat-abi=hard", "-mfpu=fpv4-sp-d16"),
           "cortex-m7": ("-mcpu=cortex-m7", "-mthumb", "-mfloat-abi=hard", "-mfpu=fpv5-d16")}
PRECISIONS = {"double": (), "float": ("-DDERIVE_FLOAT",)}
LEVELS = ("O2", "O0")
MEASURES = {
    "text_O2": "bytes of the function's object at -O2 (arm-none-eabi-size text: code and read-only data), without "
               "the generated functions it calls and libm",
    "stack_O2": "bytes of stack at -O2: the deepest chain of frames through derive's code (its file's static "
                "helpers and the generated functions it calls; -fstack-usage, -fcallgraph-info=su), without libm",
    "stack_O0": "the same at -O0 (a debug build)",
}
EXAMPLE = "c/example/main.c"


@dataclass(frozen=True)
class Build:
    """One configuration: target, precision, optimisation level."""

    target: str
    precision: str
    level: str

    def flags(self) -> list[str]:
        return [*COMMON_FLAGS, *TARGETS[self.target], *PRECISIONS[self.precision], f"-{self.level}"]

    def __str__(self) -> str:
        return f"{self.target}, {self.precision}, -{self.level}"


BUILDS = tuple(Build(t, p, lv) for t in TARGETS for p in PRECISIONS for lv in LEVELS)


@dataclass(frozen=True)
class Toolchain:
    gcc: str
    size: str
    version: str


def find_toolchain() -> Toolchain:
    """arm-none-eabi-gcc and -size from PATH; a one-line error naming the Debian packages if absent."""
    gcc, size = shutil.which("arm-none-eabi-gcc"), shutil.which("arm-none-eabi-size")
    if not gcc or not size:
        missing = "arm-none-eabi-gcc" if not gcc else "arm-none-eabi-size"
        raise DeriveError(f"firmware-check: {missing} is not on PATH; install the ARM cross toolchain "
                          f"(Debian/Ubuntu: apt-get install {' '.join(DEBIAN_PACKAGES)})")
    out = subprocess.run([gcc, "--version"], capture_output=True, text=True)
    version = out.stdout.splitlines()[0].strip() if out.returncode == 0 and out.stdout else ""
    if not version:
        raise DeriveError(f"firmware-check: {gcc} --version failed: {out.stderr.strip()[:200]}")
    return Toolchain(gcc, size, version)


@dataclass
class Failure:
    """A build that is not clean: its first diagnostic."""

    robot: str
    source: str
    build: Build
    message: str

    def __str__(self) -> str:
        return f"{self.robot}: {self.source} ({self.build}): {self.message}"


@dataclass
class Measurement:
    """Figures of one run: ``figures[robot][function][target][precision][measure]`` (bytes), and the
    builds that were not clean."""

    toolchain: Toolchain
    figures: dict[str, dict[str, dict]] = field(default_factory=dict)
    failures: list[Failure] = field(default_factory=list)
    builds: int = 0
    seconds: float = 0.0


@dataclass
class _Job:
    robot: str
    folder: Path       # generated/<robot>
    source: str        # path under it, c/<file>.c
    build: Build
    work: Path         # where the object, .su and .ci go
    weight: int

    @property
    def obj(self) -> Path:
        return self.work / (Path(self.source).stem + ".o")


def _functions(folder: Path, robot: str) -> list[dict]:
    try:
        manifest = json.loads((folder / robot / "manifest.json").read_text())
    except (OSError, ValueError):
        raise DeriveError(f"{folder / robot}: no readable manifest.json; run `derive generate` first") from None
    return [fn for fn in manifest["functions"] if fn.get("c")]


def _selected(functions: list[dict], names: list[str] | None) -> list[dict]:
    """``names`` (all when None) and every generated function they call, directly or not."""
    if names is None:
        return functions
    by_name = {fn["name"]: fn for fn in functions}
    unknown = [n for n in names if n not in by_name]
    if unknown:
        raise DeriveError(f"firmware-check: no C function {unknown[0]!r}")
    todo, seen = list(names), set()
    while todo:
        name = todo.pop()
        if name not in seen:
            seen.add(name)
            todo += by_name[name].get("calls", [])
    return [fn for fn in functions if fn["name"] in seen]


def _first_diagnostic(text: str) -> str:
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    for ln in lines:
        if re.search(r"\b(error|warning)\b", ln):
            return ln[:300]
    return (lines[0] if lines else "failed without a message")[:300]


def _compile(tc: Toolchain, job: _Job) -> tuple[_Job, str | None, int | None]:
    """Compile one file: (job, first diagnostic or None, text bytes)."""
    job.work.mkdir(parents=True, exist_ok=True)
    cdir = job.folder / "c"
    source = Path(job.source).relative_to("c").as_posix()
    res = subprocess.run([tc.gcc, *job.build.flags(), "-I.", "-c", source, "-o", str(job.obj)],
                         cwd=cdir, capture_output=True, text=True)
    if res.returncode != 0 or res.stderr.strip():
        return job, _first_diagnostic(res.stderr), None
    size = subprocess.run([tc.size, str(job.obj)], capture_output=True, text=True)
    if size.returncode != 0:
        return job, f"arm-none-eabi-size failed: {_first_diagnostic(size.stderr)}", None
    return job, None, int(size.stdout.splitlines()[1].split()[0])


NODE = re.compile(r'node: \{ title: "([^"]+)" label: "[^"]*\\n(\d+) bytes \(([^)]*)\)"')
EDGE = re.compile(r'edge: \{ sourcename: "([^"]+)" targetname: "([^"]+)"')


def _stacks(ci_files: list[Path]) -> tuple[dict[str, int], list[str]]:
    """{function: deepest stack in bytes} over the call graphs of one robot's files in one build,
    and the problems found (unbounded frames, recursion)."""
    frames: dict[str, int] = {}
    calls: dict[str, set[str]] = {}
    problems = []
    for path in ci_files:
        text = path.read_text()
        for title, size, qualifier in NODE.findall(text):
            frames[title] = int(size)
            if "dynamic" in qualifier and "bounded" not in qualifier:
                problems.append(f"{title}: unbounded stack ({qualifier})")
        for src, dst in EDGE.findall(text):
            calls.setdefault(src, set()).add(dst)
    depth: dict[str, int] = {}

    def visit(name: str, trail: tuple[str, ...]) -> int:
        if name in trail:
            problems.append(f"recursion: {' -> '.join(trail + (name,))}")
            return 0
        if name not in depth:
            below = [visit(c, trail + (name,)) for c in sorted(calls.get(name, ())) if c in frames]
            depth[name] = frames[name] + max(below, default=0)
        return depth[name]

    return {name: visit(name, ()) for name in frames if ":" not in name}, problems


def measure(folder: Path, robots: dict[str, list[str] | None], builds: tuple[Build, ...] | dict = BUILDS,
            jobs: int | None = None, log: Callable[[str], None] = print, example: bool = True) -> Measurement:
    """Cross-compile the generated C of ``robots`` ({robot: function names, or None for all}) under
    ``folder`` in ``builds`` (or {robot: builds}), all in one pool, ``jobs`` at a time (at most
    os.cpu_count()); example/main.c too when ``example`` and all functions are asked for. Progress
    goes to ``log`` every few seconds."""
    tc = find_toolchain()
    cpus = os.cpu_count() or 1
    jobs = max(1, min(jobs or cpus, cpus))
    folder = Path(folder)
    start = time.perf_counter()
    result = Measurement(tc)
    with tempfile.TemporaryDirectory(prefix="derive-firmware-") as tmp:
        work = Path(tmp)
        todo: list[_Job] = []
        wanted: dict[str, list[dict]] = {}
        builds_of = {robot: builds[robot] if isinstance(builds, dict) else builds for robot in robots}
        for robot, names in robots.items():
            functions = _selected(_functions(folder, robot), names)
            wanted[robot] = functions
            sources = [fn["c"]["source"] for fn in functions]
            if example and names is None and (folder / robot / EXAMPLE).is_file():
                sources.append(EXAMPLE)
            for k, build in enumerate(builds_of[robot]):
                for source in sources:
                    weight = (folder / robot / source).stat().st_size * (4 if build.level != "O0" else 1)
                    todo.append(_Job(robot, folder / robot, source, build, work / robot / str(k), weight))
        todo.sort(key=lambda j: -j.weight)  # the longest first: the pool ends together
        log(f"[firmware] {len(todo)} builds of {len(robots)} robot(s) with {tc.version}, {jobs} at a time")
        texts: dict[tuple[str, Build, str], int] = {}
        last = time.perf_counter()
        with ThreadPoolExecutor(max_workers=jobs) as pool:
            futures = [pool.submit(_compile, tc, job) for job in todo]
            for done, future in enumerate(as_completed(futures), 1):
                job, problem, text = future.result()
                if problem:
                    result.failures.append(Failure(job.robot, job.source, job.build, problem))
                else:
                    texts[(job.robot, job.build, job.source)] = text
                if time.perf_counter() - last > 5 or done == len(todo):
                    last = time.perf_counter()
                    log(f"[firmware] {done}/{len(todo)} builds, {last - start:.0f} s")
        for robot, functions in wanted.items():
            figures: dict[str, dict] = {fn["name"]: {} for fn in functions}
            for k, build in enumerate(builds_of[robot]):
                stacks, problems = _stacks(sorted((work / robot / str(k)).glob("*.ci")))
                result.failures += [Failure(robot, "(call graph)", build, p) for p in problems]
                for fn in functions:
                    key = (robot, build, fn["c"]["source"])
                    if key not in texts or fn["name"] not in stacks:
                        continue
                    entry = figures[fn["name"]].setdefault(build.target, {}).setdefault(build.precision, {})
                    if build.level == "O2":
                        entry["text_O2"] = texts[key]
                    entry[f"stack_{build.level}"] = stacks[fn["name"]]
            result.figures[robot] = figures
    result.failures.sort(key=lambda f: (f.robot, f.source, str(f.build)))
    result.builds = len(todo)
    result.seconds = time.perf_counter() - start
    return result


def _sorted(d):
    return {k: _sorted(d[k]) for k in sorted(d)} if isinstance(d, dict) else d


def record_entries(folder: Path, result: Measurement) -> dict[str, dict]:
    """The firmware.json entries of a complete, clean run: per robot the toolchain, the flags and per
    function its figures against the sha256 of its translation unit."""
    entries = {}
    for robot, figures in result.figures.items():
        hashes = source_hashes(robot_files(Path(folder) / robot))
        entries[robot] = {
            "toolchain": result.toolchain.version,
            "flags": list(COMMON_FLAGS),
            "targets": {t: list(f) for t, f in TARGETS.items()},
            "precisions": {p: list(f) for p, f in PRECISIONS.items()},
            "measures": dict(MEASURES),
            "functions": {name: {"source_sha256": hashes[name], **_sorted(fig)} for name, fig in sorted(figures.items())},
        }
    return entries


def recorded(folder: Path, robot: str) -> dict | None:
    """The firmware section of ``folder/robot/manifest.json``, if any."""
    try:
        return json.loads((Path(folder) / robot / "manifest.json").read_text()).get("firmware")
    except (OSError, ValueError):
        return None


def differences(folder: Path, result: Measurement) -> list[str]:
    """Functions whose figures in the manifests differ from this run's (or are missing there), when
    measured with the same toolchain."""
    out = []
    for robot, figures in result.figures.items():
        section = recorded(folder, robot) or {}
        if section and section.get("toolchain") != result.toolchain.version:
            out.append(f"{robot}: recorded with {section.get('toolchain')}, measured with {result.toolchain.version}")
            continue
        for name, fig in figures.items():
            old = section.get("functions", {}).get(name)
            if old is None:
                out.append(f"{robot}: {name}: no recorded figures")
                continue
            for target, by_precision in fig.items():
                for precision, values in by_precision.items():
                    for measure, value in values.items():
                        was = old.get(target, {}).get(precision, {}).get(measure)
                        if was != value:
                            out.append(f"{robot}: {name}: {target} {precision} {measure} {value}, recorded {was}")
    return out


def worst(figures: dict[str, dict], target: str, precision: str, measure: str) -> tuple[int, str] | None:
    """(largest value, function) of one measure over a robot's functions; None where none was measured."""
    values = [(fig[target][precision][measure], name) for name, fig in figures.items()
              if measure in fig.get(target, {}).get(precision, {})]
    return max(values) if values else None


def configurations() -> list[tuple[str, str]]:
    return [(t, p) for t in TARGETS for p in PRECISIONS]


def summary_rows(result: Measurement) -> list[str]:
    """Markdown rows: per robot, the largest text and stacks in each target and precision."""
    rows = ["| robot | functions | " + " | ".join(f"{t} {p}" for t, p in configurations()) + " |",
            "|---|---|" + "---|" * len(configurations())]
    for robot, figures in result.figures.items():
        cells = []
        for t, p in configurations():
            cells.append(" / ".join(str(w[0]) if (w := worst(figures, t, p, m)) else "-" for m in MEASURES))
        rows.append(f"| {robot} | {len(figures)} | " + " | ".join(cells) + " |")
    return rows


def function_rows(figures: dict[str, dict]) -> list[str]:
    rows = ["| function | " + " | ".join(f"{t} {p}" for t, p in configurations()) + " |",
            "|---|" + "---|" * len(configurations())]
    for name, fig in sorted(figures.items()):
        rows.append(f"| {name} | " + " | ".join(
            " / ".join(str(fig.get(t, {}).get(p, {}).get(m, "-")) for m in MEASURES) for t, p in configurations()) + " |")
    return rows


def worst_debug_stack(result: Measurement) -> tuple[int, str, str] | None:
    """(bytes, function, target and precision) of the largest -O0 stack of the run; None if none was measured."""
    found = [(*w, f"{t} {p}") for figures in result.figures.values() for t, p in configurations()
             if (w := worst(figures, t, p, "stack_O0"))]
    return max(found) if found else None


# ---- derive bench firmware ----

def bench_firmware(args) -> str:
    """Cross-compiled text and stack of every shipped robot's functions (the project's generated/)."""
    title = "## Microcontroller builds: text and stack per function (arm-none-eabi-gcc)"
    folder = CHECKOUT / "generated"
    robots = [r for r in load_models(getattr(args, "models", None)) if (folder / r / "manifest.json").is_file()]
    try:
        result = measure(folder, {r: None for r in robots}, log=lambda s: print(s, flush=True))
    except DeriveError as exc:
        return f"{title}\n\nNot measured: {exc}\n"
    rows = [title, "", f"{result.toolchain.version}; every generated C file of each robot ({result.builds} builds in "
                       f"{result.seconds:.0f} s), flags `{' '.join(COMMON_FLAGS)}`, for the Cortex-M4F "
                       f"(`{' '.join(TARGETS['cortex-m4f'])}`: double in software) and the Cortex-M7 "
                       f"(`{' '.join(TARGETS['cortex-m7'])}`), double and float (`-DDERIVE_FLOAT`). Cells: "
                       "text at -O2 / stack at -O2 / stack at -O0, in bytes; text is the function's object "
                       "(code and read-only data, without its callees and libm), stack the deepest chain of "
                       "frames through derive's code (libm not included).", ""]
    if result.failures:
        rows += [f"**Not clean: {len(result.failures)} build(s).**", ""] + [f"- {f}" for f in result.failures[:20]] + [""]
    rows += ["Largest per robot (over its functions, each figure on its own):", ""] + summary_rows(result)
    if "panda" in result.figures:
        panda = result.figures["panda"]
        rows += ["", "Panda, every function:", ""] + function_rows(panda)
        jac = panda.get("panda_ode_jac_x", {})
        ratios = [f"{t} {p} {jac[t][p]['stack_O0']} / {jac[t][p]['stack_O2']} = "
                  f"{jac[t][p]['stack_O0'] / jac[t][p]['stack_O2']:.2f}" for t, p in configurations()
                  if jac.get(t, {}).get(p, {}).get("stack_O2")]
        if ratios:
            rows += ["", "Issue 16's target, Panda `ode_jac_x` at -O0 within 4x its -O2 stack: " + "; ".join(ratios) + "."]
        m4 = {k: panda.get(f"panda_{k}", {}).get("cortex-m4f", {}).get("float", {}).get("text_O2") for k in
              ("inverse_dynamics", "mass_matrix", "forward_dynamics")}
        if all(m4.values()):
            rows += ["", f"Cortex-M4F float -O2 text: ID {m4['inverse_dynamics']}, M {m4['mass_matrix']}, FD "
                     f"{m4['forward_dynamics']} bytes (CasADi's C from Pinocchio, as measured for issue 16: 8.0, 6.6 "
                     "and 16.3 kB)."]
    if (debug := worst_debug_stack(result)):
        rows += ["", f"Largest -O0 stack of any function: {debug[0]} bytes ({debug[1]}, {debug[2]})."]
    stale = differences(folder, result)
    rows += ["", "Recorded figures (firmware.json, manifest.json): " + (
        "the same as this run's." if not stale else f"{len(stale)} differ from this run's (first: {stale[0]}); "
        "`make firmware-check` records them.")]
    return "\n".join(rows) + "\n"


def benchmarks() -> dict:
    return {"firmware": bench_firmware}

