"""Shared test helpers: seeded states, numeric evaluation of SX, relative comparison."""

from __future__ import annotations

from functools import lru_cache

import casadi as ca
import numpy as np

from derive.symbolic.model import SXModel
from derive.description.model import load_models
from derive.description.robot import Robot

N_STATES = 50
RTOL = 1e-9


@lru_cache(maxsize=None)
def robots() -> dict[str, Robot]:
    return load_models()


@lru_cache(maxsize=None)
def sx_model(name: str) -> SXModel:
    return SXModel(robots()[name])


def params(robot: Robot) -> np.ndarray:
    return np.array([p.default for p in robot.parameters], dtype=float)


def random_q(robot: Robot, rng: np.random.Generator) -> np.ndarray:
    """q uniformly within the joint limits (or [-pi, pi] / [-1, 1] m where a limit is missing)."""
    lo, hi = robot.joint_box()
    q = rng.uniform(lo, hi)
    if robot.floating:  # a random unit quaternion for the base
        quat = rng.normal(size=4)
        q[3:7] = quat / np.linalg.norm(quat)
    return q


def states(robot: Robot, seed: int = 0, n: int = N_STATES):
    """n seeded (q, qd, qdd) triples."""
    rng = np.random.default_rng(seed)
    for _ in range(n):
        yield random_q(robot, rng), rng.normal(size=robot.nv), rng.normal(size=robot.nv)


def sx_function(model: SXModel, expr: ca.SX, inputs=("q", "qd", "qdd", "tau", "p")) -> ca.Function:
    s = model.sym
    syms = [getattr(s, n) for n in inputs]
    return ca.Function("f", syms, [expr])


def evaluate(f: ca.Function, *args) -> np.ndarray:
    return np.array(f(*args)).squeeze()


def assert_close(actual, expected, rtol: float = RTOL, what: str = "") -> None:
    """max|a - e| <= rtol * max|e| (relative to the magnitude of the whole array)."""
    a, e = np.asarray(actual, dtype=float), np.asarray(expected, dtype=float)
    assert a.shape == e.shape, f"{what}: shape {a.shape} != {e.shape}"
    scale = max(np.abs(e).max(initial=0.0), 1e-12)
    err = np.abs(a - e).max(initial=0.0)
    assert err <= rtol * scale, f"{what}: max error {err:.3e} > {rtol:g} * {scale:.3e}"
