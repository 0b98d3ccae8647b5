"""Simulation benchmark: ``derive bench simulate``.

Wall time and energy drift of the generated RK4 step (dt = 1e-3) against scipy's
DOP853 (rtol 1e-10) on the generated ``ode_rhs``, both sampled every 1e-3 s from
q0 = 0.5 rad per joint without torque, measured in the same run, for pendulum,
planar_2r, ur5 and panda (the checkout's generated/).
"""

from __future__ import annotations

from derive.description.model import load_models
from derive.resources import CHECKOUT
from derive.solvers.simulate import simulate

ROOT = CHECKOUT
ROBOTS = ("pendulum", "planar_2r", "ur5", "panda")


def bench_simulate(args) -> str:
    """RK4 (generated rk4_step) vs scipy DOP853 on the generated ode_rhs: wall time and energy drift."""
    import scipy.integrate  # noqa: F401  (keeps the import out of the first timing)

    robots = load_models(getattr(args, "models", None))
    t_end = 1.0 if args.quick else 10.0
    generated = ROOT / "generated"
    rows = ["## Simulation with the generated Python (no torque)", "",
            f"{t_end:g} s from q0 = 0.5 rad per joint, samples every 1e-3 s; drift = max |E - E0| / max(|E0|, max T).",
            "", "| robot | RK4 dt = 1e-3 | drift | DOP853 rtol 1e-10 | drift | RK4 time / DOP853 time |", "|---|---|---|---|---|---|"]
    for name in ROBOTS:
        robot = robots[name]
        rk4 = simulate(robot, [0.5] * robot.nv, t_end=t_end, generated=generated)
        dop = simulate(robot, [0.5] * robot.nv, t_end=t_end, method="DOP853", generated=generated)
        rows.append(f"| {name} | {rk4.wall_time:.2f} s | {rk4.energy_drift:.1e} | {dop.wall_time:.2f} s | "
                    f"{dop.energy_drift:.1e} | {rk4.wall_time / dop.wall_time:.2f} |")
    return "\n".join(rows) + "\n"


def benchmarks() -> dict:
    return {"simulate": bench_simulate}
