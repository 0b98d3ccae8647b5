"""The trajectory optimiser's worked examples, and the measures they are judged by.

- ``swing_up(opt)``: the pendulum (torque limit m g l / 4: several pumps, free final time) and
  the cart-pole (pole from down, theta = 0, to up, pi; cart back to 0), from SWING_UPS.
- PANDA_READY -> PANDA_GOAL: the Panda's rest-to-rest move with full dynamics and the model's
  limits, over :func:`point_to_point_duration`.
- :func:`velocity_reversals`: the pumps of a swing-up.

``derive trajopt`` runs them (:mod:`derive.cli.solvers`); ``derive bench trajopt`` times them
(:mod:`derive.bench.trajopt`).
"""

from __future__ import annotations

import math

import numpy as np

from derive.errors import DeriveError
from derive.solvers.trajopt import TrajectoryOptimizer, TrajoptResult

PANDA_READY = (0.0, -0.785, 0.0, -2.356, 0.0, 1.571, 0.785)
PANDA_GOAL = (1.0, 0.2, -0.5, -1.5, 0.5, 2.0, 0.0)


def _pendulum_limit(opt: TrajectoryOptimizer) -> float:
    """A quarter of m g l, the static torque that holds the pendulum horizontal (phi = pi/2)."""
    return 0.25 * abs(opt.gravity([math.pi / 2])[0])


SWING_UPS = {
    "pendulum": {"start": [0.0], "goal": [math.pi], "intervals": 100, "duration": 6.0, "free_time": True,
                 "time_weight": 10.0, "torque_limit": _pendulum_limit},
    "cartpole": {"start": [0.0, 0.0], "goal": [0.0, math.pi], "intervals": 100, "duration": 2.0,
                 "passive": ("theta",)},
}
"""Swing-up problems: the torque limit may be a function of the optimiser (of the model's numbers)."""


def swing_up(opt: TrajectoryOptimizer, **overrides) -> TrajoptResult:
    """The robot's swing-up example (SWING_UPS), with options overridden."""
    if opt.robot.name not in SWING_UPS:
        raise DeriveError(f"trajopt {opt.robot.name}: no swing-up example (known: {', '.join(SWING_UPS)})")
    problem = {**SWING_UPS[opt.robot.name], **overrides}
    if callable(problem.get("torque_limit")):
        problem["torque_limit"] = problem["torque_limit"](opt)
    return opt.solve(problem.pop("start"), problem.pop("goal"), **problem)


def point_to_point_duration(opt: TrajectoryOptimizer, start, goal) -> float:
    """T for a rest-to-rest move: twice what the velocity limits allow a quintic profile
    (peak speed 1.875 |dq| / T), at least 1 s."""
    v = opt.limits()["velocity"]
    need = 1.875 * np.abs(np.asarray(goal, float) - np.asarray(start, float)) / v
    return max(1.0, 2.0 * float(need.max(initial=0.0)))


def velocity_reversals(qd: np.ndarray) -> int:
    """Sign changes of a joint velocity, ignoring the resting end points: the pumps of a swing-up."""
    inner = np.sign(qd[1:-1])
    inner = inner[inner != 0]
    return int(np.count_nonzero(np.diff(inner)))
