"""Trajectory optimisation benchmark: ``derive bench trajopt``.

Solve time (IPOPT's t_wall_total, best of 3; one run with --quick), iterations and the
independent integration check of the optimiser's examples (derive.solvers.trajopt_examples):
the cart-pole and pendulum swing-ups and the Panda's rest-to-rest move, for every
transcription (hermite-simpson only with --quick), against the targets of ../shared/TARGETS.md.
The check integrates the checkout's generated/ Python forward dynamics.
"""

from __future__ import annotations

import numpy as np

from derive.description.model import load_models
from derive.resources import CHECKOUT
from derive.solvers.trajopt import METHODS, TrajectoryOptimizer, generated_forward_dynamics
from derive.solvers.trajopt_examples import (PANDA_GOAL, PANDA_READY, SWING_UPS, point_to_point_duration, swing_up,
                                             velocity_reversals)

ROOT = CHECKOUT


def bench_trajopt(args) -> str:
    """Solve time (IPOPT's t_wall_total, best of ``repeat``) and iterations of the three examples."""
    robots = load_models(getattr(args, "models", None))
    quick = getattr(args, "quick", False)
    repeat, methods = (1, ("hermite-simpson",)) if quick else (3, METHODS)
    rows = ["| case | method | N | T [s] | success | iterations | solve [s] | target [s] | solve / target "
            "| first build [s] | integration error, per interval / open loop | notes |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, target in (("cartpole", 0.3), ("pendulum", None), ("panda", 2.0)):
        robot = robots[name]
        p = np.array([x.default for x in robot.parameters])
        fd = generated_forward_dynamics(robot, p, root=ROOT / "generated")
        opt = TrajectoryOptimizer(robot, forward_dynamics=fd)
        duration = point_to_point_duration(opt, PANDA_READY, PANDA_GOAL) if name == "panda" else None
        for method in methods:
            runs = [opt.solve(PANDA_READY, PANDA_GOAL, method=method, duration=duration, accel_weight=1.0)
                    if name == "panda" else swing_up(opt, method=method) for _ in range(repeat)]
            r = min(runs, key=lambda x: x.stats["solve_time"])
            st = r.stats
            effort = opt.limits(SWING_UPS.get(name, {}).get("torque_limit", lambda o: None)(opt))["effort"]
            notes = f"max \\|tau\\| / limit {np.max(np.abs(r.tau) / effort):.3f}"
            if name != "panda":
                notes += f"; velocity reversals {velocity_reversals(r.qd[:, -1])}"
            ratio = f"{st['solve_time'] / target:.2f}" if target else "-"
            rows.append(f"| {name} | {method} | {len(r.t) - 1} | {r.duration:.3f} | {r.success} | {st['iterations']} "
                        f"| {st['solve_time']:.3f} | {target or '-'} | {ratio} | {runs[0].stats['build_time']:.2f} "
                        f"| {r.integration_error:.1e} / {r.drift:.1e} | {notes} |")
    return ("## Trajectory optimisation (CasADi Opti + IPOPT/MUMPS, implicit RNEA dynamics)\n\n"
            "cartpole and pendulum: `derive trajopt <robot> --swing-up`; panda: rest to rest from "
            f"{list(PANDA_READY)} to {list(PANDA_GOAL)}, N = 50, w_A = 1. Solve time is IPOPT's "
            f"t_wall_total, best of {repeat}; integration error: the generated Python forward dynamics, "
            "RK4 with 20 steps per interval, against the optimised knots (rad or m).\n\n" + "\n".join(rows) + "\n")


def benchmarks() -> dict:
    return {"trajopt": bench_trajopt}
