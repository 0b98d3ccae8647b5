"""Simulation with the generated forward dynamics: ``derive simulate ROBOT``.

Integrates x' = f(x, u), x = [q; qd], u = tau held constant, with the code
under generated/<robot>/python/ (the same functions as the C): classical RK4
through its ``rk4_step`` at a fixed step, or scipy's adaptive integrators
(RK45, DOP853, LSODA, Radau, BDF) on ``ode_rhs``, the implicit ones with the
generated ``ode_jac_x`` as their Jacobian.

Energy E = T + U comes from the independent numpy reference
(derive.reference), U = -sum m g . p_com (zero with every COM at the world
origin). Without friction a constant torque does the work tau . (q - q0), so
E - tau . (q - q0) is conserved; its drift, relative to max(|E0|, max T), is
the check on the integration (and on the generated dynamics).
"""

from __future__ import annotations

import csv
import dataclasses
import importlib.util
import json
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from derive.errors import DeriveError
from derive.resources import CHECKOUT
from derive.description.model import load_robot
from derive.description.robot import ModelError, Parameter, Robot

GENERATED = CHECKOUT / "generated"
METHODS = ("rk4", "RK45", "DOP853", "LSODA", "Radau", "BDF")
IMPLICIT = ("LSODA", "Radau", "BDF")


@dataclass
class Trajectory:
    """A simulated run: samples every dt from 0 to t_end.

    t (N,), q and qd (N, nv), kinetic T, potential U and E = T + U (N,);
    ``balance`` = E - tau . (q - q0), constant for exact dynamics without friction.
    """

    robot: str
    joints: tuple[str, ...]
    method: str
    tau: np.ndarray
    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    kinetic: np.ndarray
    potential: np.ndarray
    wall_time: float

    @property
    def energy(self) -> np.ndarray:
        return self.kinetic + self.potential

    @property
    def balance(self) -> np.ndarray:
        return self.energy - (self.q - self.q[0]) @ self.tau

    @property
    def energy_scale(self) -> float:
        """max(|E0|, max T): the datum of U is arbitrary, the kinetic energy exchanged is not."""
        return max(abs(self.energy[0]), float(self.kinetic.max()), np.finfo(float).tiny)

    @property
    def energy_drift(self) -> float:
        """max_t |balance(t) - balance(0)| / energy_scale."""
        return float(np.abs(self.balance - self.balance[0]).max() / self.energy_scale)


def load_generated(robot: str, generated: str | Path | None = None):
    """The generated Python module of ``robot`` (generated/<robot>/python/<robot>.py), imported by path."""
    path = Path(generated or GENERATED) / robot / "python" / f"{robot}.py"
    if not path.is_file():
        raise DeriveError(f"robot '{robot}': no generated code at {path} (run `make derive` or `derive generate`)")
    spec = importlib.util.spec_from_file_location(f"derive_generated_{robot}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _stale(robot: Robot, generated: Path) -> bool:
    from derive.codegen.generate import model_hash

    try:
        manifest = json.loads((generated / robot.name / "manifest.json").read_text())
    except (OSError, ValueError):
        return True
    return manifest.get("model_hash") != model_hash(robot)[:16]


def _vector(values, n: int, what: str, robot: str) -> np.ndarray:
    v = np.zeros(n) if values is None else np.asarray(values, dtype=float).reshape(-1)
    if v.shape != (n,):
        raise DeriveError(f"robot '{robot}': {what} needs {n} value{'s' * (n != 1)} (one per joint), got {v.size}")
    if not np.all(np.isfinite(v)):
        raise DeriveError(f"robot '{robot}': {what} must be finite numbers, got {v.tolist()}")
    return v


MAX_STEPS = 10_000_000
"""Most samples a run may produce (t / dt): the CSV of a longer run would not fit in memory."""


def check_times(robot: str, t_end: float, dt: float, rtol: float = 1e-10, atol: float = 1e-12) -> int:
    """The number of steps t_end / dt, after checking t, dt, rtol and atol; DeriveError naming the bad one."""
    for name, v in (("t", t_end), ("dt", dt), ("rtol", rtol), ("atol", atol)):
        if not (math.isfinite(v) and v > 0):
            raise DeriveError(f"robot '{robot}': simulate --{name} must be positive and finite, got {v:g}")
    if dt > t_end:
        raise DeriveError(f"robot '{robot}': simulate --dt {dt:g} is longer than --t {t_end:g}: no step to take")
    steps = int(round(t_end / dt))
    if steps > MAX_STEPS:
        raise DeriveError(f"robot '{robot}': simulate --t {t_end:g} / --dt {dt:g} = {steps:.3g} steps, "
                          f"more than {MAX_STEPS:.0e}; shorten --t or lengthen --dt")
    return steps


def with_parameters(robot: Robot, params: dict[str, float] | None) -> Robot:
    """``robot`` with its parameter defaults replaced by ``params``, re-validated like models.yaml.

    Masses must stay >= 0, inertias physical and every value finite (the checks of
    derive.model), and a parameter may not change the sign of a nonzero default: a length
    or a mass that turns negative is not a robot (the model file can declare a signed one).
    """
    if not params:
        return robot
    known = {p.name: p.default for p in robot.parameters}
    unknown = sorted(set(params) - set(known))
    if unknown:
        raise DeriveError(f"robot '{robot.name}' has no parameter(s) {', '.join(unknown)} "
                          f"(parameters: {', '.join(known) or 'none'})")
    for name, value in params.items():
        if not math.isfinite(value):
            raise DeriveError(f"robot '{robot.name}': --param {name}={value:g}: must be a finite number")
        if known[name] * value < 0:
            raise DeriveError(f"robot '{robot.name}': --param {name}={value:g}: changes the sign of the "
                              f"model's value {known[name]:g}")
    new = dataclasses.replace(robot, parameters=tuple(Parameter(p.name, float(params.get(p.name, p.default)))
                                                      for p in robot.parameters))
    from derive.description.model import check_values  # the physical checks models.yaml passes through

    try:
        check_values(new)
    except ModelError as exc:
        given = ", ".join(f"{k}={v:g}" for k, v in params.items())
        raise DeriveError(f"{exc} (with --param {given})") from None
    return new


def simulate(robot: Robot, q0, qd0=None, tau=None, t_end: float = 10.0, dt: float = 1e-3, method: str = "rk4",
             params: dict[str, float] | None = None, generated: str | Path | None = None,
             rtol: float = 1e-10, atol: float = 1e-12) -> Trajectory:
    """Integrate the generated ODE from (q0, qd0) over [0, t_end] with constant tau; samples every dt.

    Args:
        robot: the model (for names, parameters and the reference energies).
        method: "rk4" (fixed step dt, the generated rk4_step) or a scipy.integrate.solve_ivp method
            (adaptive, rtol/atol; the solution is sampled every dt).
        params: parameter overrides, name -> value (the rest keep their defaults).
        generated: folder holding generated/<robot>/ (default: the project's).
    """
    from derive.reference import NumericRobot

    if method not in METHODS:
        raise DeriveError(f"simulate: unknown method {method!r} (known: {', '.join(METHODS)})")
    steps = check_times(robot.name, t_end, dt, rtol, atol)
    mod = load_generated(robot.name, generated)
    if mod.NQ != mod.NV:
        raise DeriveError(f"robot '{robot.name}': simulate needs nq == nv, got nq = {mod.NQ}, nv = {mod.NV}")
    n = mod.NV
    q0, qd0, tau = (_vector(v, n, w, robot.name) for v, w in ((q0, "q0"), (qd0, "qd0"), (tau, "tau")))
    with_parameters(robot, params)
    try:
        ref = NumericRobot(robot, params)
    except ValueError as exc:
        raise DeriveError(str(exc)) from None
    p = np.array([ref.params[par.name] for par in robot.parameters])
    extra = (p,) if p.size else ()
    t = np.arange(steps + 1) * dt
    x0 = np.concatenate([q0, qd0])
    M0 = ref.crba(q0)  # x' = f(x, u) solves M(q) qdd = ...: M must be invertible (a massless chain is not)
    if not (np.all(np.isfinite(M0)) and np.linalg.eigvalsh(0.5 * (M0 + M0.T))[0] > 1e-12 * max(np.abs(M0).max(), 1e-300)):
        raise DeriveError(f"robot '{robot.name}': the mass matrix at q0 is singular (massless links?)"
                          + (f" with --param {', '.join(f'{k}={v:g}' for k, v in params.items())}" if params else ""))
    start = time.perf_counter()
    try:
        xs = _integrate(mod, method, x0, tau, t, dt, extra, rtol, atol, robot.name)
    except DeriveError:
        raise
    except (ZeroDivisionError, OverflowError, FloatingPointError, ValueError) as exc:  # math.sin(inf), x / 0
        raise DeriveError(f"robot '{robot.name}': the generated dynamics failed during the run ({method}, "
                          f"dt = {dt:g}): {type(exc).__name__}: {exc}") from None
    wall = time.perf_counter() - start
    bad = ~np.all(np.isfinite(xs), axis=1)
    if bad.any():
        raise DeriveError(f"robot '{robot.name}': the state is no longer finite at t = {t[np.argmax(bad)]:g} s "
                          f"({method}, dt = {dt:g}); nothing written")
    q, qd = xs[:, :n], xs[:, n:]
    kinetic = np.array([ref.kinetic_energy(a, b) for a, b in zip(q, qd)])
    potential = np.array([ref.potential_energy(a) for a in q])
    return Trajectory(robot.name, tuple(mod.JOINTS), method, tau, t, q, qd, kinetic, potential, wall)


def _integrate(mod, method: str, x0: np.ndarray, tau: np.ndarray, t: np.ndarray, dt: float, extra: tuple,
               rtol: float, atol: float, robot: str) -> np.ndarray:
    """States (len(t), 2 nv) from x0 by the generated rk4_step or scipy's solve_ivp on ode_rhs."""
    n, steps = len(x0) // 2, len(t) - 1
    if method == "rk4":
        xs = np.empty((steps + 1, 2 * n))
        xs[0] = x = x0
        for k in range(1, steps + 1):
            xs[k] = x = mod.rk4_step(x, tau, dt, *extra)
    else:
        from scipy.integrate import solve_ivp

        jac = {"jac": lambda _, x: mod.ode_jac_x(x, tau, *extra)} if method in IMPLICIT else {}
        sol = solve_ivp(lambda _, x: mod.ode_rhs(x, tau, *extra), (0.0, t[-1]), x0, method=method, t_eval=t,
                        rtol=rtol, atol=atol, **jac)
        if not sol.success:
            raise DeriveError(f"robot '{robot}': {method} failed at t = {sol.t[-1]:g}: {sol.message}")
        xs = sol.y.T
    return xs


def write_csv(traj: Trajectory, path: str | Path) -> Path:
    """Columns t, q..., dq..., T, U, E (one row per sample)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["t", *traj.joints, *(f"d{j}" for j in traj.joints), "T", "U", "E"])
        for row in np.column_stack([traj.t, traj.q, traj.qd, traj.kinetic, traj.potential, traj.energy]):
            w.writerow([repr(float(v)) for v in row])
    return path


def plot(traj: Trajectory, path: str | Path) -> Path:
    """q(t), qd(t) and the relative energy drift, one panel each (matplotlib Agg)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 1, figsize=(8, 8), sharex=True)
    for k, name in enumerate(traj.joints):
        axes[0].plot(traj.t, traj.q[:, k], label=name)
        axes[1].plot(traj.t, traj.qd[:, k], label=f"d{name}")
    axes[2].plot(traj.t, (traj.balance - traj.balance[0]) / traj.energy_scale)
    axes[0].set_ylabel("q")
    axes[1].set_ylabel("qd")
    axes[2].set_ylabel("energy drift (rel.)")
    axes[2].set_xlabel("t [s]")
    for ax in axes[:2]:
        ax.legend(loc="upper right", fontsize="small", ncol=min(len(traj.joints), 4))
    for ax in axes:
        ax.grid(True, alpha=0.3)
    fig.suptitle(f"{traj.robot}: {traj.method}, tau = {np.array2string(traj.tau, precision=3)}")
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)
    return path


def summary(traj: Trajectory) -> str:
    e = traj.balance
    what = "E" if not traj.tau.any() else "E - tau.(q - q0)"
    return (f"{traj.robot}: {len(traj.t) - 1} samples to t = {traj.t[-1]:g} s with {traj.method} in "
            f"{traj.wall_time:.2f} s\n"
            f"  energy {what}: initial {e[0]:.9g} J, final {e[-1]:.9g} J, "
            f"max relative drift {traj.energy_drift:.2e} (of max(|E0|, max T) = {traj.energy_scale:.4g} J)")


# ---- command line ----

def add_parser(sub) -> None:
    p = sub.add_parser("simulate", help="integrate a robot's generated forward dynamics; CSV, plot, energy drift")
    p.add_argument("robot_name")
    p.add_argument("--q0", type=float, nargs="+", required=True, help="initial joint positions (one per joint)")
    p.add_argument("--qd0", type=float, nargs="+", help="initial joint velocities (default 0)")
    p.add_argument("--tau", type=float, nargs="+", help="constant joint torques/forces (default 0)")
    p.add_argument("--t", type=float, default=10.0, help="duration in s (default 10)")
    p.add_argument("--dt", type=float, default=1e-3, help="RK4 step and sample interval in s (default 1e-3)")
    p.add_argument("--method", choices=METHODS, default="rk4", help="integrator (default rk4)")
    p.add_argument("--rtol", type=float, default=1e-10, help="adaptive integrators' rtol (default 1e-10)")
    p.add_argument("--atol", type=float, default=1e-12, help="adaptive integrators' atol (default 1e-12)")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE", help="override a parameter")
    p.add_argument("--out", help="output folder (default: simulate_out/<robot>/)")
    p.add_argument("--generated", help="folder holding generated/<robot>/ (default: the project's generated/)")
    p.set_defaults(func=cmd_simulate)


def _params(items: list[str]) -> dict[str, float]:
    out = {}
    for item in items:
        name, sep, value = item.partition("=")
        try:
            out[name.strip()] = float(value)
        except ValueError:
            sep = ""
        if not sep or not name.strip():
            raise DeriveError(f"simulate: --param expects NAME=VALUE, got {item!r}")
    return out


def cmd_simulate(args) -> int:
    robot = load_robot(args.robot_name, args.models)
    # every option is checked before anything is printed, run or written
    check_times(robot.name, args.t, args.dt, args.rtol, args.atol)
    for values, what in ((args.q0, "q0"), (args.qd0, "qd0"), (args.tau, "tau")):
        _vector(values, robot.nv, what, robot.name)
    with_parameters(robot, _params(args.param))
    generated = Path(args.generated) if args.generated else GENERATED
    if not generated.is_dir():
        raise DeriveError(f"robot '{robot.name}': --generated {generated}: no such folder "
                          "(`derive generate --out FOLDER` writes one)")
    code = generated / robot.name / "python" / f"{robot.name}.py"
    if not code.is_file():  # say so now, not "generated from another version"
        raise DeriveError(f"robot '{robot.name}': no generated code at {code} (run `make derive` or `derive generate`)")
    if _stale(robot, generated):
        print(f"warning: {generated / robot.name} was generated from another version of '{robot.name}' "
              "(run `make derive`)", file=sys.stderr)
    print(f"simulating {robot.name} for {args.t:g} s ({args.method}) ...", flush=True)
    traj = simulate(robot, args.q0, args.qd0, args.tau, t_end=args.t, dt=args.dt, method=args.method,
                    params=_params(args.param), generated=generated, rtol=args.rtol, atol=args.atol)
    out = Path(args.out) if args.out else Path("simulate_out") / robot.name
    csv_path = write_csv(traj, out / f"{robot.name}.csv")
    png_path = plot(traj, out / f"{robot.name}.png")
    print(summary(traj))
    print(f"wrote {csv_path} and {png_path}")
    return 0


# ---- benchmarks ----

def benchmarks() -> dict:
    return {"simulate": bench_simulate}


def bench_simulate(args) -> str:
    """RK4 (generated rk4_step) vs scipy DOP853 on the generated ode_rhs: wall time and energy drift."""
    import scipy.integrate  # noqa: F401  (keeps the import out of the first timing)

    from derive.description.model import load_models

    robots = load_models(getattr(args, "models", None))
    t_end = 1.0 if args.quick else 10.0
    rows = ["## Simulation with the generated Python (no torque)", "",
            f"{t_end:g} s from q0 = 0.5 rad per joint, samples every 1e-3 s; drift = max |E - E0| / max(|E0|, max T).",
            "", "| robot | RK4 dt = 1e-3 | drift | DOP853 rtol 1e-10 | drift | RK4 time / DOP853 time |", "|---|---|---|---|---|---|"]
    for name in ("pendulum", "planar_2r", "ur5", "panda"):
        robot = robots[name]
        rk4 = simulate(robot, [0.5] * robot.nv, t_end=t_end)
        dop = simulate(robot, [0.5] * robot.nv, t_end=t_end, method="DOP853")
        rows.append(f"| {name} | {rk4.wall_time:.2f} s | {rk4.energy_drift:.1e} | {dop.wall_time:.2f} s | "
                    f"{dop.energy_drift:.1e} | {rk4.wall_time / dop.wall_time:.2f} |")
    return "\n".join(rows) + "\n"
