"""``derive bench zoo``: every example-robot-data URDF imported whole, derived and generated.

One row per URDF that Pinocchio loads, imported with no tip and no lock (the whole tree, as
``derive import-urdf example-robot-data:<path>``), with a fixed base, and a second row with a
floating base (``--floating``) for the legged robots, humanoids and flying robots. Each row gives
nq, nv, the number of frames, the time of deriving and rendering the robot's whole function set
(C + Python + JAX, what ``derive generate`` does) and the arithmetic after CSE of the generated
inverse dynamics, mass matrix and forward dynamics (the op counts of manifest.json).

The whole set includes ode_jac_x, whose cost grows fast with nv; above :data:`WHOLE_SET_MAX_NV`
only ID, M and FD are derived, CSE'd and rendered, and the time column says so.
"""

from __future__ import annotations

import contextlib
import importlib
import io
import json
import os
import platform
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterable

import numpy as np

from derive.codegen.checks import check_constants, check_mass_matrix
from derive.codegen.generate import render
from derive.codegen.render import render_robot
from derive.codegen.spec import FunctionSpec
from derive.description.model import parse_robot
from derive.description.robot import ModelError
from derive.description.urdf import example_robot_data_dir, example_robot_data_version, import_urdf_named
from derive.errors import DeriveError
from derive.reference import NumericRobot
from derive.symbolic.model import SXModel

TITLE = "## example-robot-data: whole trees"

WHOLE_SET_MAX_NV = 30
"""Largest nv whose whole function set is rendered. Above it, only ID, M and FD (see the module
docstring). Measured on the 2 shared cores of the machine that wrote bench/results.md: whole set of
g1 fixed (nv 29) 34 s, talos_reduced fixed (nv 32) 62 s, talos_reduced floating (nv 38) 103 s;
the ~30 imports above nv 30 would add half an hour, while with this cut-off the bench takes ~9 minutes
(a cut-off of 32 would add the 7 imports of nv 31-32, about 8 minutes)."""

FLOATING = (
    # legged robots
    "a1_description/urdf/a1.urdf",
    "alexander_description/urdf/alexander_v1.lowerBodyOnly.urdf",
    "anymal_b_simple_description/robots/anymal-kinova.urdf",
    "anymal_b_simple_description/robots/anymal.urdf",
    "anymal_c_simple_description/urdf/anymal.urdf",
    "b1_description/urdf/b1-z1.urdf",
    "b1_description/urdf/b1.urdf",
    "bolt_description/robots/bolt.urdf",
    "centauro_description/urdf/centauro.urdf",
    "go1_description/urdf/go1.urdf",
    "go2_description/urdf/go2.urdf",
    "hyq_description/robots/hyq_no_sensors.urdf",
    "laikago_description/urdf/laikago.urdf",
    "quadruped_description/urdf/quadruped.urdf",
    "solo_description/robots/solo.urdf",
    "solo_description/robots/solo12.urdf",
    # humanoids
    "g1_description/urdf/g1_29dof_rev_1_0.urdf",
    "g1_description/urdf/g1_29dof_with_hand_rev_1_0.urdf",
    "human_description/robots/human.urdf",
    "icub_description/robots/icub.urdf",
    "icub_description/robots/icub_reduced.urdf",
    "romeo_description/urdf/romeo.urdf",
    "romeo_description/urdf/romeo_laas_small.urdf",
    "romeo_description/urdf/romeo_small.urdf",
    "simple_humanoid_description/urdf/simple_humanoid.urdf",
    "simple_humanoid_description/urdf/simple_humanoid_classical.urdf",
    "talos_data/robots/talos_full_v2.urdf",
    "talos_data/robots/talos_full_v2_box.urdf",
    "talos_data/robots/talos_reduced.urdf",
    "talos_data/robots/talos_reduced_box.urdf",
    "talos_data/robots/talos_reduced_corrected.urdf",
    # flying robots (the quadrotor bodies alone have no moving joint: floating only)
    "borinot_description/urdf/borinot_flying_arm_2.urdf",
    "hector_description/robots/quadrotor_base.urdf",
    "hextilt_description/urdf/hextilt_flying_arm_5.urdf",
    "iris_description/robots/iris.urdf",
    "iris_description/robots/iris_simple.urdf",
)
"""URDFs (under example-robot-data's robots/) that get a floating-base row as well."""

QUICK = (
    "double_pendulum_description/urdf/double_pendulum_simple.urdf",
    "ur_description/urdf/ur5_robot.urdf",
    "solo_description/robots/solo12.urdf",
    "panda_description/urdf/panda.urdf",
    "hector_description/robots/quadrotor_base.urdf",
    "bolt_description/robots/bolt.urdf",
)
"""The handful of URDFs of ``--quick``: small ones, a mimic joint, a floating-only body and a refusal."""

QUANTITIES = ("inverse_dynamics", "mass_matrix", "forward_dynamics")


@dataclass
class Row:
    urdf: str
    floating: bool
    nq: int = 0
    nv: int = 0
    frames: int = 0
    seconds: float = 0.0
    whole: bool = True
    functions: int = 0
    mimic: int = 0  # joints that follow another (no entry in q)
    ops: dict[str, int] = field(default_factory=dict)
    refused: str | None = None  # the one-line ModelError / DeriveError
    error: float = float("nan")  # worst relative error of the generated Python's ID, M, FD against the reference


def erd_urdfs(loads: Callable[[Path], bool] | None = None) -> tuple[list[str], list[str]]:
    """(URDFs of example-robot-data that Pinocchio loads, those it does not), as paths under robots/."""
    root = example_robot_data_dir()
    if root is None:
        return [], []
    ok, bad = [], []
    for path in sorted(root.rglob("*.urdf")):
        rel = path.relative_to(root).as_posix()
        (ok if loads is None or loads(path) else bad).append(rel)
    return ok, bad


def pinocchio_loads(pin) -> Callable[[Path], bool]:
    def loads(path: Path) -> bool:
        try:
            with _quiet_fd(2):  # urdfdom prints its complaint on the C stderr
                pin.buildModelFromUrdf(str(path))
        except (RuntimeError, ValueError):
            return False
        return True
    return loads


@contextlib.contextmanager
def _quiet_fd(fd: int):
    saved = os.dup(fd)
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), fd)
        yield
    finally:
        os.dup2(saved, fd)
        os.close(saved)


def id_m_fd_specs(model: SXModel) -> list[FunctionSpec]:
    """The catalogue's mass_matrix, inverse_dynamics and forward_dynamics specs alone (the same
    expressions, inputs and order as :func:`derive.codegen.catalogue.function_specs`)."""
    robot, s, ne = model.robot, model.sym, model.newton_euler
    extra = (("p", s.p),) if s.p.numel() else ()
    q, qd, qdd, tau = ("q", s.q), ("qd", s.qd), ("qdd", s.qdd), ("tau", s.tau)
    return [FunctionSpec(robot.name, "mass_matrix", None, (q,) + extra, (("M", ne.mass_matrix),), "M(q)."),
            FunctionSpec(robot.name, "inverse_dynamics", None, (q, qd, qdd) + extra,
                         (("tau", ne.inverse_dynamics()),), "tau = ID(q, qd, qdd)."),
            FunctionSpec(robot.name, "forward_dynamics", None, (q, qd, tau) + extra,
                         (("qdd", model.forward_dynamics()),), "qdd = FD(q, qd, tau).")]


def measure(urdf: str, floating: bool, max_nv: int = WHOLE_SET_MAX_NV) -> Row:
    """Import ``urdf`` whole (``example-robot-data:<path>`` or a file) and time its derivation and rendering."""
    row = Row(urdf, floating)
    try:
        with contextlib.redirect_stderr(io.StringIO()):  # the importer's warnings about placeholder limits
            name, entry = import_urdf_named(urdf if Path(urdf).is_absolute() else "example-robot-data:" + urdf,
                                            floating=floating)
        # every named frame, as the rows measured before big robots had a default selection (docs/large-robots.md)
        robot = parse_robot(name, {**entry, "generate": {"frames": [f["name"] for f in entry["frames"]]}})
    except ModelError as exc:
        row.refused = str(exc)
        return row
    row.nq, row.nv, row.frames = robot.nq, robot.nv, len(robot.frames)
    row.mimic = sum(j.mimic is not None for j in robot.joints)
    row.whole = robot.nv <= max_nv
    try:
        start = time.perf_counter()
        if row.whole:
            files = render(robot, "0" * 64, lambda line: None)
        else:
            model = SXModel(robot)
            check_mass_matrix(model)
            files = render_robot(robot, id_m_fd_specs(model), "0" * 16,
                                 progress=lambda spec, prog: check_constants(robot, spec, prog))
        row.seconds = time.perf_counter() - start
    except DeriveError as exc:
        row.refused = str(exc)
        return row
    functions = json.loads(files["manifest.json"])["functions"]
    row.functions = len(functions)
    by_name = {f["name"]: f for f in functions}
    row.ops = {qty: by_name[f"{robot.name}_{qty}"]["ops"]["total"] for qty in QUANTITIES}
    row.error = check_against_reference(robot, files[f"python/{robot.name}.py"])
    return row


def check_against_reference(robot, module_text: str, states: int = 3) -> float:
    """Worst relative error (max |a - b| / max(1, max |b|)) of the generated Python's inverse dynamics,
    mass matrix and forward dynamics against the numpy reference at ``states`` seeded states (the
    reference itself is checked against Pinocchio on every URDF by tests/test_urdf_trees.py)."""
    namespace: dict = {"__name__": f"zoo_{robot.name}"}
    exec(compile(module_text, f"<generated {robot.name}>", "exec"), namespace)  # the text render just produced
    ref = NumericRobot(robot)
    rng = np.random.default_rng(0)
    worst = 0.0

    def rel(a, b) -> float:
        b = np.asarray(b, dtype=float)
        return float(np.abs(np.asarray(a, dtype=float).reshape(b.shape) - b).max() / max(1.0, np.abs(b).max()))

    for _ in range(states):
        q = ref.random_configuration(rng)
        qd, qdd, tau = rng.normal(size=(3, robot.nv))
        worst = max(worst, rel(namespace["inverse_dynamics"](q, qd, qdd), ref.rnea(q, qd, qdd)),
                    rel(namespace["mass_matrix"](q), ref.crba(q)), rel(namespace["forward_dynamics"](q, qd, tau),
                                                                        ref.aba(q, qd, tau)))
    return worst


def cases(urdfs: Iterable[str], floating: Iterable[str] = FLOATING) -> list[tuple[str, bool]]:
    floating = set(floating)
    return [(u, f) for u in urdfs for f in ((False, True) if u in floating else (False,))]


def table(rows: list[Row], max_nv: int = WHOLE_SET_MAX_NV) -> list[str]:
    out = ["| robot (URDF) | base | nq | nv | frames | derive + generate (s) | ID ops | M ops | FD ops | "
           "max rel. error |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        if r.refused:
            continue
        secs = f"{r.seconds:.1f} ({r.functions} functions)" if r.whole else f"ID/M/FD only: {r.seconds:.1f}"
        out.append(f"| {r.urdf} | {'floating' if r.floating else 'fixed'} | {r.nq} | {r.nv} | {r.frames} | {secs} | "
                   + " | ".join(str(r.ops[q]) for q in QUANTITIES) + f" | {r.error:.1e} |")
    return out


def refusals(rows: list[Row]) -> list[str]:
    """The refused imports, grouped by kind of reason, one markdown bullet per group."""
    groups: dict[str, dict[tuple[str, str], list[str]]] = {}
    for r in rows:
        if not r.refused:
            continue
        why = r.refused
        kind = ("a mimic of an unknown joint" if "mimic" in why else
                "no moving joint (a single rigid body; it imports with --floating)" if "no moving joint" in why else
                "impossible inertia" if "inertia" in why else "other")
        groups.setdefault(kind, {}).setdefault((r.urdf, why), []).append("floating" if r.floating else "fixed")
    return [f"- {kind} ({len(items)} URDF{'s' if len(items) > 1 else ''}): "
            + "; ".join(f"{urdf} ({' and '.join(bases)}): {why}" for (urdf, why), bases in items.items())
            for kind, items in groups.items()]


def section(rows: list[Row], not_loaded: list[str], seconds: float, quick: bool, max_nv: int = WHOLE_SET_MAX_NV) -> str:
    urdfs = sorted({r.urdf for r in rows})
    imported = sorted({r.urdf for r in rows if not r.refused})
    refused_all = sorted(u for u in urdfs if u not in imported)
    ok_rows = [r for r in rows if not r.refused]
    whole = [r for r in ok_rows if r.whole]
    biggest = max(whole, key=lambda r: (r.nv, r.seconds), default=None)
    version = example_robot_data_version() or "?"
    lines = [TITLE, "",
             f"Every URDF of example-robot-data {version} that Pinocchio loads"
             + (" (--quick: a handful only)" if quick else "")
             + ", imported whole (no tip, no lock; `derive import-urdf example-robot-data:<path>`), with a fixed base "
             "and, for the legged robots, humanoids and flying robots, with a floating base (`--floating`) as well. "
             "derive + generate: wall time of deriving and rendering the robot's whole function set in C, Python and "
             "JAX (what `derive generate` does; FK, Jacobians, J'qd and accelerations of every frame, M, C, g, ID, FD, "
             "CoM, centroidal map, ODE and its Jacobians, rk4_step, IK, manipulability). ops: arithmetic per call of "
             "the generated inverse dynamics, mass matrix and forward dynamics after CSE (manifest.json's counts). "
             "max rel. error: of those three generated Python functions against the numpy reference at 3 seeded "
             "states (max |a - b| / max(1, max |b|)); the reference matches Pinocchio on every one of these URDFs, "
             "fixed and floating (tests/test_urdf_trees.py).", "",
             *table(rows, max_nv), "",
             f"ID/M/FD only: above nv = {max_nv} the whole set is not rendered, to keep the bench near 10 minutes: "
             "its cost grows fast with nv, mostly through ode_jac_x (df/dx of the ODE). Measured alone on this machine "
             "while choosing the cut-off, the whole set of talos_reduced takes 62 s fixed (nv 32) and 103 s floating "
             "(nv 38); the ~30 imports above nv 30 would add about half an hour (a separate issue covers the robots "
             "of 20-100 dof). The time is then that of deriving M, ID and FD (with the check that M is "
             "regular), their CSE and rendering in the three languages."
             + (f" Largest nv with a whole-set time: {biggest.urdf} ({'floating' if biggest.floating else 'fixed'}, "
                f"nv {biggest.nv}): {biggest.seconds:.1f} s." if biggest else ""), "",
             f"{len(urdfs)} URDFs that Pinocchio loads ({len(rows)} imports, fixed and floating): {len(imported)} import "
             f"(in at least one base), {len(refused_all)} {'is' if len(refused_all) == 1 else 'are'} refused in every base"
             + (f" ({', '.join(refused_all)})" if refused_all else "")
             + f"; {len(ok_rows)} rows. Refused imports, by reason (one-line errors of the importer):"]
    lines += refusals(rows) or ["- none"]
    mimic = {r.urdf: r.mimic for r in ok_rows if r.mimic}
    if mimic:
        lines += ["", "Mimic joints follow another joint and have no coordinate, so nq and nv count the independent "
                  "ones only (Pinocchio's nv counts them too; massless moving branches are dropped at import as well): "
                  + ", ".join(f"{u} ({k})" for u, k in mimic.items()) + "."]
    constant = [f"{r.urdf} ({'floating' if r.floating else 'fixed'})" for r in ok_rows if r.ops["mass_matrix"] == 0]
    if constant:
        lines += ["", f"M ops 0 ({', '.join(constant)}): M does not depend on q there (a single rigid body, or "
                  "rotors spinning about their own axes of symmetry), so the generated mass matrix is constants only."]
    if not_loaded:
        lines += ["", f"Not measured: {len(not_loaded)} URDF(s) that Pinocchio does not load ({', '.join(not_loaded)})."]
    lines += ["", f"Machine: {_cpu() or platform.processor() or '?'} ({platform.machine()}), {os.cpu_count()} cores "
              f"(shared with other jobs), Python {platform.python_version()}; bench time {seconds:.0f} s in all."]
    return "\n".join(lines)


def _cpu() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return ""


def run_cases(todo: list[tuple[str, bool]], max_nv: int = WHOLE_SET_MAX_NV,
              log: Callable[[str], None] = print) -> list[Row]:
    rows = []
    for k, (urdf, floating) in enumerate(todo, 1):
        row = measure(urdf, floating, max_nv)
        base = "floating" if floating else "fixed"
        if row.refused:
            log(f"[zoo] {k}/{len(todo)} {urdf} {base}: refused: {row.refused}")
        else:
            what = "whole set" if row.whole else "ID/M/FD only"
            log(f"[zoo] {k}/{len(todo)} {urdf} {base}: nv {row.nv}, {what} {row.seconds:.1f} s, ops ID/M/FD "
                + "/".join(str(row.ops[q]) for q in QUANTITIES) + f", error {row.error:.1e}")
        rows.append(row)
    return rows


def bench_zoo(args) -> str:
    start = time.perf_counter()
    try:
        pin = importlib.import_module("pinocchio")
    except ImportError:
        raise DeriveError("bench zoo: needs pinocchio and example-robot-data (the pinocchio extra: make bench "
                          "installs them)") from None
    if example_robot_data_dir() is None:
        raise DeriveError("bench zoo: needs example-robot-data (pip install example-robot-data)")
    urdfs, not_loaded = erd_urdfs(pinocchio_loads(pin))
    if args.quick:
        urdfs = [u for u in urdfs if u in QUICK]
        not_loaded = []
    rows = run_cases(cases(urdfs), WHOLE_SET_MAX_NV, lambda line: print(line, flush=True))
    return section(rows, not_loaded, time.perf_counter() - start, args.quick)


def benchmarks() -> dict:
    return {"zoo": bench_zoo}
