"""Simulation with the generated forward dynamics (``derive simulate ROBOT`` on the command line).

Integrates x' = f(x, u), x = [q; qd], u = tau held constant, with the code
under <generated>/<robot>/python/ (the same functions as the C; <generated> is
./generated unless a folder is given): classical RK4
through its ``rk4_step`` at a fixed step, or scipy's adaptive integrators
(RK45, DOP853, LSODA, Radau, BDF) on ``ode_rhs``, the implicit ones with the
generated ``ode_jac_x`` as their Jacobian.

Energy E = T + U comes from the independent numpy reference
(derive.reference), U = -sum m g . p_com (zero with every COM at the world
origin). A constant torque does the work tau . (q - q0) and friction and damping
dissipate W_d(t) = int_0^t qd . f(qd) dt >= 0 (the reference's smooth friction, the
forward dynamics' own; corrected trapezoidal rule over the samples, :func:`dissipated_work`), so
E - tau . (q - q0) + W_d is conserved; its drift, relative to max(|E0|, max T), is
the check on the integration (and on the generated dynamics). The dissipated work
is reported apart: it is physics, not error.

The CSV has the columns every command shares (:func:`csv_header`):
t, q_<c>..., qd_<c>..., qdd_<c>..., tau_<c>... (qdd from the generated ODE at each sample,
tau the torque integrated with), then T, U, E; ``derive identify`` reads it as it is.
Positions outside a joint's limits are reported once per joint (:attr:`Trajectory.crossings`):
the model's limits are not enforced by the dynamics.

A continuous joint's angle is integrated as it winds (the work tau . (q - q0) counts the turns)
and drawn so; the CSV gives it wrapped to (-pi, pi] (:attr:`Trajectory.q_wrapped`).

The figure of a run is :func:`derive.plot.simulate.plot_simulation`; its benchmark
is in :mod:`derive.bench.simulate`.
"""

from __future__ import annotations

import csv
import dataclasses
import importlib.util
import inspect
import io
import json
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from derive.codegen.generate import default_output, model_hash
from derive.description.joints import wrap_angle
from derive.description.model import check_values
from derive.description.robot import ModelError, Parameter, Robot
from derive.errors import DeriveError
from derive.filesystem import write_chunks_atomically
from derive.reference import NumericRobot
from derive.reference.rnea import require_forward_dynamics

METHODS = ("rk4", "RK45", "DOP853", "LSODA", "Radau", "BDF")
IMPLICIT = ("LSODA", "Radau", "BDF")


@dataclass
class Trajectory:
    """A simulated run: samples every dt from 0 to t_end.

    t (N,), q, qd and qdd (N, nv), kinetic T, potential U and E = T + U (N,), the work
    ``dissipated`` by friction and damping up to each sample (N,);
    ``balance`` = E - tau . (q - q0) + dissipated, constant for exact dynamics.
    ``names`` are the coordinates (the CSV's column suffixes); ``crossings`` the first sample of
    each coordinate outside its limits: (index, time, value, bound).
    ``q`` is the integration state: a continuous joint's angle as it winds up (the work
    tau . (q - q0) needs the turns); ``continuous`` indexes those angles, which
    :meth:`q_wrapped` (and so the CSV) gives in (-pi, pi].
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
    continuous: tuple[int, ...] = ()
    qdd: np.ndarray | None = None
    dissipated: np.ndarray | None = None
    names: tuple[str, ...] = ()
    crossings: tuple[tuple[int, float, float, float], ...] = ()

    @property
    def q_wrapped(self) -> np.ndarray:
        """q with the continuous joints' angles wrapped to (-pi, pi] (what the joint reads)."""
        q = np.array(self.q, dtype=float, copy=True)
        if self.continuous:
            q[:, list(self.continuous)] = wrap_angle(q[:, list(self.continuous)])
        return q

    @property
    def energy(self) -> np.ndarray:
        return self.kinetic + self.potential

    @property
    def balance(self) -> np.ndarray:
        held = self.energy - (self.q - self.q[0]) @ self.tau
        return held if self.dissipated is None else held + self.dissipated

    @property
    def energy_scale(self) -> float:
        """max(|E0|, max T): the datum of U is arbitrary, the kinetic energy exchanged is not."""
        return max(abs(self.energy[0]), float(self.kinetic.max()), np.finfo(float).tiny)

    @property
    def energy_drift(self) -> float:
        """max_t |balance(t) - balance(0)| / energy_scale."""
        return float(np.abs(self.balance - self.balance[0]).max() / self.energy_scale)


def load_generated(robot: str, generated: str | Path | None = None):
    """The generated Python module of ``robot`` (<generated>/<robot>/python/<robot>.py), imported by path.

    ``generated`` defaults to ./generated (:func:`derive.codegen.generate.default_output`).
    """
    path = Path(generated or default_output()) / robot / "python" / f"{robot}.py"
    if not path.is_file():
        raise DeriveError(f"robot '{robot}': no generated code at {path} (run `make derive` or `derive generate`)")
    spec = importlib.util.spec_from_file_location(f"derive_generated_{robot}", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def is_stale(robot: Robot, generated: Path) -> bool:
    """Whether <generated>/<robot>/ is missing its manifest or was generated from another version of ``robot``."""
    try:
        manifest = json.loads((generated / robot.name / "manifest.json").read_text())
    except (OSError, ValueError):
        return True
    return manifest.get("model_hash") != model_hash(robot)[:16]


def check_vector(values, n: int, what: str, robot: str) -> np.ndarray:
    """``values`` (None: zeros) as n finite floats, one per joint; DeriveError naming ``what`` otherwise."""
    v = np.zeros(n) if values is None else np.asarray(values, dtype=float).reshape(-1)
    if v.shape != (n,):
        raise DeriveError(f"robot '{robot}': {what} needs {n} value{'s' * (n != 1)} (one per joint), got {v.size}")
    if not np.all(np.isfinite(v)):
        raise DeriveError(f"robot '{robot}': {what} must be finite numbers, got {v.tolist()}")
    return v


MAX_STEPS = 10_000_000
"""Most samples a run may produce (t / dt): at tens of microseconds per step, hours of work."""
MEMORY_BUDGET = 2**30
"""Bytes the samples of one run may take (t, q, qd, qdd, the energies, the dissipated power and their temporaries: 8 (4 nv + 7) per sample)."""


def sample_bytes(nv: int) -> int:
    """Bytes a run holds per sample of an nv-joint robot (see MEMORY_BUDGET)."""
    return 8 * (4 * nv + 7)


def check_times(robot: str, t_end: float, dt: float, rtol: float = 1e-10, atol: float = 1e-12, nv: int = 1) -> int:
    """The number of steps t_end / dt, after checking t, dt, rtol and atol and that the samples of an
    ``nv``-joint robot fit MEMORY_BUDGET; DeriveError naming the bad one."""
    for name, v in (("t", t_end), ("dt", dt), ("rtol", rtol), ("atol", atol)):
        if not (math.isfinite(v) and v > 0):
            raise DeriveError(f"robot '{robot}': simulate --{name} must be positive and finite, got {v:g}")
    if dt > t_end:
        raise DeriveError(f"robot '{robot}': simulate --dt {dt:g} is longer than --t {t_end:g}: no step to take")
    ratio = t_end / dt
    steps = int(round(ratio)) if ratio < 2**62 else 2**62
    if steps > MAX_STEPS:
        raise DeriveError(f"robot '{robot}': simulate --t {t_end:g} / --dt {dt:g} = {ratio:.3g} steps, "
                          f"more than {MAX_STEPS:.0e}; shorten --t or lengthen --dt")
    need = (steps + 1) * sample_bytes(nv)
    if need > MEMORY_BUDGET:
        raise DeriveError(f"robot '{robot}': simulate --t {t_end:g} / --dt {dt:g} = {steps} steps: {steps + 1} samples "
                          f"of {nv} joints would hold {need / 2**30:.2g} GiB (more than the budget of {MEMORY_BUDGET / 2**30:g} GiB); "
                          "shorten --t or lengthen --dt")
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
    try:
        check_values(new)  # the physical checks models.yaml passes through
    except ModelError as exc:
        given = ", ".join(f"{k}={v:g}" for k, v in params.items())
        raise DeriveError(f"{exc} (with --param {given})") from None
    return new


def numeric_reference(robot: Robot, q0, params: dict[str, float] | None = None) -> NumericRobot:
    """The numpy reference of ``robot`` with ``params`` (the energies of a run), once M(q0) is found invertible.

    x' = f(x, u) solves M(q) qdd = ...: coordinates that move no mass (M singular at every q,
    :func:`require_forward_dynamics`) or a singular mass matrix at q0 (a massless chain) is a
    DeriveError, as is a parameter set the reference rejects.
    """
    try:
        ref = NumericRobot(robot, params)
    except ValueError as exc:
        raise DeriveError(str(exc)) from None
    require_forward_dynamics(ref, "simulate")
    M0 = ref.crba(np.asarray(q0, dtype=float))
    if not (np.all(np.isfinite(M0)) and np.linalg.eigvalsh(0.5 * (M0 + M0.T))[0] > 1e-12 * max(np.abs(M0).max(), 1e-300)):
        raise DeriveError(f"robot '{robot.name}': the mass matrix at q0 is singular (massless links?)"
                          + (f" with --param {', '.join(f'{k}={v:g}' for k, v in params.items())}" if params else ""))
    return ref


PROGRESS_STEPS = 2000
"""The progress callback of :func:`simulate` is called every this many steps (or right-hand sides)."""


def simulate(robot: Robot, q0, qd0=None, tau=None, t_end: float = 10.0, dt: float = 1e-3, method: str = "rk4",
             params: dict[str, float] | None = None, generated: str | Path | None = None,
             rtol: float = 1e-10, atol: float = 1e-12,
             progress: Callable[[str, float], None] | None = None) -> Trajectory:
    """Integrate the generated ODE from (q0, qd0) over [0, t_end] with constant tau; samples every dt.

    Args:
        robot: the model (for names, parameters and the reference energies).
        method: "rk4" (fixed step dt, the generated rk4_step) or a scipy.integrate.solve_ivp method
            (adaptive, rtol/atol; the solution is sampled every dt).
        params: parameter overrides, name -> value (the rest keep their defaults).
        generated: folder holding <robot>/ (default: ./generated, :func:`derive.codegen.generate.default_output`).
        progress: called now and then as progress(stage, fraction done): stage "integrating" or "energies".

    A state, an energy or a drift that is no longer finite (a torque of 1e300, a run that
    diverges) is a DeriveError naming the time: every number of a returned Trajectory is finite.
    """
    if robot.closed:  # its generated ODE is in x = (y, yd), not the tree's (q, qd)
        return simulate_closed(robot, q0, qd0, tau, t_end, dt, method, params, generated, rtol, atol, progress)
    robot.require_fixed_base("derive simulate")
    if method not in METHODS:
        raise DeriveError(f"simulate: unknown method {method!r} (known: {', '.join(METHODS)})")
    steps = check_times(robot.name, t_end, dt, rtol, atol, robot.nv)
    mod = load_generated(robot.name, generated)
    if mod.NQ != mod.NV:
        raise DeriveError(f"robot '{robot.name}': simulate needs nq == nv, got nq = {mod.NQ}, nv = {mod.NV}")
    n = mod.NV
    q0, qd0, tau = (check_vector(v, n, w, robot.name) for v, w in ((q0, "q0"), (qd0, "qd0"), (tau, "tau")))
    with_parameters(robot, params)
    ref = numeric_reference(robot, q0, params)
    p = np.array([ref.params[par.name] for par in robot.parameters])
    extra = (p,) if p.size else ()
    t = np.arange(steps + 1) * dt
    x0 = np.concatenate([q0, qd0])
    report = progress or (lambda stage, done: None)
    start = time.perf_counter()
    # overflow to inf or nan is checked below, once: numpy's warnings would only repeat it
    with np.errstate(all="ignore"):
        try:
            xs = _integrate(mod, method, x0, tau, t, dt, extra, rtol, atol, robot.name, report)
        except DeriveError:
            raise
        except (ZeroDivisionError, OverflowError, FloatingPointError, ValueError) as exc:  # math.sin(inf), x / 0
            raise DeriveError(f"robot '{robot.name}': the generated dynamics failed during the run ({method}, "
                              f"dt = {dt:g}): {type(exc).__name__}: {exc}; nothing written") from None
        wall = time.perf_counter() - start
        bad = ~np.all(np.isfinite(xs), axis=1)
        if bad.any():
            raise DeriveError(f"robot '{robot.name}': the state is no longer finite at t = {t[np.argmax(bad)]:g} s "
                              f"({method}, dt = {dt:g}); nothing written")
        q, qd = xs[:, :n], xs[:, n:]
        qdd = np.asarray(mod.ode_rhs(xs, tau, *extra), dtype=float).reshape(len(t), 2 * n)[:, n:]  # one batch call
        kinetic, potential, power = np.empty(len(t)), np.empty(len(t)), np.zeros(len(t))
        rubs = any(np.any(f) for f in (*ref.body_viscous, *ref.body_coulomb))
        for k in range(len(t)):
            try:
                kinetic[k], potential[k] = ref.kinetic_energy(q[k], qd[k]), ref.potential_energy(q[k])
                if rubs:  # the power friction and damping take out of the motion
                    power[k] = qd[k] @ ref.friction(qd[k], smooth=True)
            except (OverflowError, ValueError, ZeroDivisionError):
                kinetic[k] = potential[k] = power[k] = math.nan
            if k % PROGRESS_STEPS == 0:
                report("energies", k / len(t))
        dissipated = dissipated_work(t, power)
        traj = Trajectory(robot.name, tuple(mod.JOINTS), method, tau, t, q, qd, kinetic, potential, wall,
                          robot.continuous_indices, qdd, dissipated, tuple(robot.velocity_names),
                          limit_crossings(robot, t, q))
        _check_finite(traj, dt)
    return traj


def simulate_closed(robot: Robot, y0, yd0=None, tau=None, t_end: float = 10.0, dt: float = 1e-3, method: str = "rk4",
                    params: dict[str, float] | None = None, generated: str | Path | None = None,
                    rtol: float = 1e-10, atol: float = 1e-12,
                    progress: Callable[[str, float], None] | None = None) -> Trajectory:
    """:func:`simulate` of a closed chain (a robot with loops) in its independent coordinates y: the generated
    ODE in x = [y; yd] (``rk4_step``, or ``ode_rhs`` and ``ode_jac_x``), u = tau_y held constant; y0, yd0 and
    tau have one value per coordinate of y. The energies are the tree's (numpy reference) at the closed
    q = closure(y) and qd = velocity_map(y) yd; the Trajectory's q, qd, qdd are y, yd, ydd (the CSV's columns
    q_<c>, ... for c in y: what ``derive identify`` reads)."""
    if method not in METHODS:
        raise DeriveError(f"simulate: unknown method {method!r} (known: {', '.join(METHODS)})")
    ny = len(robot.independent)
    steps = check_times(robot.name, t_end, dt, rtol, atol, ny)
    mod = load_generated(robot.name, generated)
    y0, yd0, tau = (check_vector(v, ny, w, robot.name) for v, w in ((y0, "q0"), (yd0, "qd0"), (tau, "tau")))
    with_parameters(robot, params)
    try:
        ref = NumericRobot(robot, params)
    except ValueError as exc:
        raise DeriveError(str(exc)) from None
    p = np.array([ref.params[par.name] for par in robot.parameters])
    extra = (p,) if p.size else ()
    names = [c.name for c in robot.coordinates]
    z_ref = np.array([robot.reference_q[names.index(c)] for c in robot.dependent])
    newton = "z0" in inspect.signature(mod.closure).parameters  # the Newton closure starts from z0

    def closed(ys: np.ndarray) -> np.ndarray:  # q = gamma(y) of every sample (Newton: from the reference's z)
        args = (ys, np.broadcast_to(z_ref, (len(ys), len(z_ref)))) if newton else (ys,)
        return np.asarray(mod.closure(*args, *extra)[0], dtype=float).reshape(len(ys), -1)

    with np.errstate(all="ignore"):
        if not np.isfinite(closed(y0[None])).all():
            raise DeriveError(f"robot '{robot.name}': the loops do not close at q0 = y = {y0.tolist()} (no assembly); "
                              f"y is ({', '.join(robot.independent)})")
    t = np.arange(steps + 1) * dt
    x0 = np.concatenate([y0, yd0])
    report = progress or (lambda stage, done: None)
    start = time.perf_counter()
    with np.errstate(all="ignore"):
        try:
            xs = _integrate(mod, method, x0, tau, t, dt, extra, rtol, atol, robot.name, report)
        except DeriveError:
            raise
        except (ZeroDivisionError, OverflowError, FloatingPointError, ValueError) as exc:  # math.sqrt(-1): no assembly
            raise DeriveError(f"robot '{robot.name}': the generated dynamics failed during the run ({method}, "
                              f"dt = {dt:g}): {type(exc).__name__}: {exc} (the loops cannot close?); nothing written") from None
        wall = time.perf_counter() - start
        bad = ~np.all(np.isfinite(xs), axis=1)
        if bad.any():
            raise DeriveError(f"robot '{robot.name}': the state is no longer finite at t = {t[np.argmax(bad)]:g} s "
                              f"({method}, dt = {dt:g}; the loops cannot close?); nothing written")
        y, yd = xs[:, :ny], xs[:, ny:]
        ydd = np.asarray(mod.ode_rhs(xs, tau, *extra), dtype=float).reshape(len(t), 2 * ny)[:, ny:]
        q = closed(y)
        G = np.asarray(mod.velocity_map(y, *extra), dtype=float).reshape(len(t), q.shape[1], ny)
        qd = np.einsum("kij,kj->ki", G, yd)
        kinetic, potential, power = np.empty(len(t)), np.empty(len(t)), np.zeros(len(t))
        rubs = any(np.any(f) for f in (*ref.body_viscous, *ref.body_coulomb))
        for k in range(len(t)):
            try:
                kinetic[k], potential[k] = ref.kinetic_energy(q[k], qd[k]), ref.potential_energy(q[k])
                if rubs:  # the closed chain's friction: sign(qd), not smoothed (its inverse dynamics')
                    power[k] = qd[k] @ ref.friction(qd[k])
            except (OverflowError, ValueError, ZeroDivisionError):
                kinetic[k] = potential[k] = power[k] = math.nan
            if k % PROGRESS_STEPS == 0:
                report("energies", k / len(t))
        index = [names.index(c) for c in robot.independent]
        crossings = tuple((index.index(i), time_, value, bound) for i, time_, value, bound in
                          limit_crossings(robot, t, q) if i in index)
        traj = Trajectory(robot.name, tuple(robot.independent), method, tau, t, y, yd, kinetic, potential, wall,
                          tuple(index.index(i) for i in robot.continuous_indices if i in index), ydd,
                          dissipated_work(t, power), tuple(robot.independent), crossings)
        _check_finite(traj, dt)
    return traj


def dissipated_work(t: np.ndarray, power: np.ndarray) -> np.ndarray:
    """W_d(t_k) = int_0^t_k P dt on equally spaced samples: the cumulative trapezoidal rule with its
    Euler-Maclaurin end correction - h^2/12 (P'(t_k) - P'(0)) (P' by second-order differences), so the
    quadrature's error is O(h^4), far below the integrator's drift (plain trapezoids left 2e-7 of it)."""
    if len(t) < 3:
        return np.concatenate([[0.0], np.cumsum(0.5 * (power[1:] + power[:-1]) * np.diff(t))])[:len(t)]
    h = t[1] - t[0]
    trapezoids = np.concatenate([[0.0], np.cumsum(0.5 * h * (power[1:] + power[:-1]))])
    rate = np.gradient(power, h, edge_order=2)
    return trapezoids - h * h / 12.0 * (rate - rate[0])


def _check_finite(traj: Trajectory, dt: float) -> None:
    """A DeriveError naming the first time where an energy, the balance or the drift is not a finite number."""
    for what, values in (("the kinetic energy", traj.kinetic), ("the potential energy", traj.potential),
                         ("the energy E = T + U", traj.energy), ("the energy balance E - tau.(q - q0) + W_d", traj.balance)):
        bad = ~np.isfinite(values)
        if bad.any():
            raise DeriveError(f"robot '{traj.robot}': {what} is no longer a finite number at t = {traj.t[np.argmax(bad)]:g} s "
                              f"({traj.method}, dt = {dt:g}, tau = {np.array2string(traj.tau, precision=3)}); "
                              "nothing written")
    if not (math.isfinite(traj.energy_scale) and math.isfinite(traj.energy_drift)):
        raise DeriveError(f"robot '{traj.robot}': the energy drift is not a finite number (energies up to "
                          f"{np.abs(traj.energy).max():.3g} J); nothing written")


def _integrate(mod, method: str, x0: np.ndarray, tau: np.ndarray, t: np.ndarray, dt: float, extra: tuple,
               rtol: float, atol: float, robot: str, report: Callable[[str, float], None]) -> np.ndarray:
    """States (len(t), 2 nv) from x0 by the generated rk4_step or scipy's solve_ivp on ode_rhs.

    RK4 stops at the first state that is not finite (the rest stays nan)."""
    n, steps = len(x0) // 2, len(t) - 1
    if method == "rk4":
        xs = np.full((steps + 1, 2 * n), np.nan)
        xs[0] = x = x0
        for k in range(1, steps + 1):
            xs[k] = x = mod.rk4_step(x, tau, dt, *extra)
            if not np.isfinite(x).all():
                break
            if k % PROGRESS_STEPS == 0:
                report("integrating", k / steps)
        return xs
    from scipy.integrate import solve_ivp

    calls = [0]

    def rhs(time_, x):
        calls[0] += 1
        if calls[0] % PROGRESS_STEPS == 0:
            report("integrating", time_ / t[-1])
        return mod.ode_rhs(x, tau, *extra)

    jac = {"jac": lambda _, x: mod.ode_jac_x(x, tau, *extra)} if method in IMPLICIT else {}
    sol = solve_ivp(rhs, (0.0, t[-1]), x0, method=method, t_eval=t, rtol=rtol, atol=atol, **jac)
    if not sol.success:
        raise DeriveError(f"robot '{robot}': {method} failed at t = {sol.t[-1]:g}: {sol.message}; nothing written")
    return sol.y.T


CSV_CHUNK = 10_000
"""Rows formatted at a time when a CSV is written."""


def csv_header(traj: Trajectory) -> list[str]:
    """Columns t, q_<c>..., qd_<c>..., qdd_<c>..., tau_<c>... (the schema of trajopt's, excite's and
    identify's CSV, c the coordinates), then T, U, E."""
    names = traj.names or traj.joints
    return ["t", *(f"{k}_{c}" for k in ("q", "qd", "qdd", "tau") for c in names), "T", "U", "E"]


def write_csv(traj: Trajectory, path: str | Path) -> Path:
    """Columns :func:`csv_header` (one row per sample; a continuous joint's angle wrapped to
    (-pi, pi], :attr:`Trajectory.q_wrapped`; tau the constant input), written atomically: the rows go, a chunk
    at a time, into a temporary file beside ``path`` that then replaces it (an old file stays as it
    was on any failure; the DeriveError names ``path``)."""

    q = traj.q_wrapped

    def chunks():  # CSV_CHUNK rows at a time: the text of a long run need not fit in memory
        buffer = io.StringIO()
        csv.writer(buffer).writerow(csv_header(traj))
        yield buffer.getvalue()
        for k in range(0, len(traj.t), CSV_CHUNK):
            part = slice(k, k + CSV_CHUNK)
            qdd = traj.qdd[part] if traj.qdd is not None else np.full_like(traj.qd[part], np.nan)
            rows = np.column_stack([traj.t[part], q[part], traj.qd[part], qdd,
                                    np.broadcast_to(traj.tau, traj.qd[part].shape), traj.kinetic[part],
                                    traj.potential[part], traj.energy[part]])
            buffer = io.StringIO()
            w = csv.writer(buffer)
            for row in rows:
                w.writerow([repr(float(v)) for v in row])
            yield buffer.getvalue()

    return write_chunks_atomically(Path(path), chunks(), "CSV", make_folder=True)


def limit_crossings(robot: Robot, t: np.ndarray, q: np.ndarray) -> tuple[tuple[int, float, float, float], ...]:
    """(coordinate index, time, value, bound) of the first sample at which each coordinate is outside
    its position limits (none for a coordinate without limits)."""
    found = []
    for i, c in enumerate(robot.coordinates):
        for bound, outside in ((c.limits.lower, lambda v, b: v < b), (c.limits.upper, lambda v, b: v > b)):
            if bound is None or not math.isfinite(float(bound)):
                continue
            hit = outside(q[:, i], float(bound))
            if hit.any():
                k = int(np.argmax(hit))
                found.append((i, float(t[k]), float(q[k, i]), float(bound), k))
                break
    found.sort(key=lambda x: (x[4], x[0]))
    return tuple(x[:4] for x in found)


def warnings(traj: Trajectory) -> list[str]:
    """One line per coordinate that crossed a joint limit, at its first crossing."""
    names = traj.names or traj.joints
    return [f"warning: {traj.robot}: {names[i]} = {value:.6g} at t = {time_:.4g} s is beyond its limit {bound:+.6g} "
            "(the model's limits are not enforced by the dynamics)" for i, time_, value, bound in traj.crossings]


def summary(traj: Trajectory) -> str:
    """Samples, method and wall time; the energy balance and its relative drift; the work dissipated by
    friction and damping (where there is any)."""
    e = traj.balance
    what = "E" if not traj.tau.any() else "E - tau.(q - q0)"
    lost = traj.dissipated[-1] if traj.dissipated is not None else 0.0
    if lost:
        what += " + W_d"
    text = (f"{traj.robot}: {len(traj.t) - 1} samples to t = {traj.t[-1]:g} s with {traj.method} in "
            f"{traj.wall_time:.2f} s\n"
            f"  energy {what}: initial {e[0]:.9g} J, final {e[-1]:.9g} J, "
            f"max relative drift {traj.energy_drift:.2e} (of max(|E0|, max T) = {traj.energy_scale:.4g} J)")
    if lost:
        text += f"\n  dissipated by friction and damping: W_d = {lost:.6g} J (not part of the drift)"
    return text
