"""Checks of a derived robot before its code is written: refusals of models whose code could not run.

- :func:`check_mass_matrix`: M(q) singular at every q (a coordinate that moves no mass), where
  forward dynamics and the ODE do not exist: refused under ``strict``, else the coordinates returned,
  so that generation leaves out :data:`NEEDS_INVERSE_MASS` and keeps everything else.
- :func:`check_constants`: a non-finite constant in a generated program.
"""

from __future__ import annotations

import math

import casadi as ca
import numpy as np

from derive.description.robot import FREE_FLYER, Robot
from derive.description.urdf import relock_command
from derive.errors import DeriveError
from derive.symbolic.model import SXModel


NEEDS_INVERSE_MASS = ("forward_dynamics", "forward_dynamics_fext", "ode_rhs", "ode_jac_x", "ode_jac_u", "rk4_step")
"""The generated functions that need M(q)^-1 (qdd = M^-1 (tau - h)): left out where M is singular."""


def unmoved_reason(names: list[str]) -> str:
    """Why the functions of :data:`NEEDS_INVERSE_MASS` are missing, for the warning, the manifest and the
    runtime's one-line errors: ``coordinates q4, q5 move no mass or inertia, so M(q) is singular``."""
    who = f"coordinate {names[0]} moves" if len(names) == 1 else f"coordinates {', '.join(names)} move"
    return f"{who} no mass or inertia, so M(q) is singular"


def check_mass_matrix(model: SXModel, samples: int = 3, strict: bool = True) -> list[str]:
    """The coordinates whose M(q)_ii is 0 at every q (they move no mass or inertia), where M is singular
    and forward dynamics and the ODE do not exist (their code would divide by zero).

    A diagonal entry counts as 0 at most 1e-12 of the largest, at ``samples`` seeded configurations.
    ``strict``: refuse such a robot (DeriveError naming the first coordinate), else return their names
    (empty for a robot whose M is regular). A non-finite M, or one singular at every q though every
    coordinate moves mass (two coordinates that move the same way), is refused either way."""
    robot = model.robot
    s = model.sym
    f = ca.Function("M", [s.q, s.p], [model.newton_euler.mass_matrix])
    lo, hi = robot.joint_box()
    rng = np.random.default_rng(0)
    p = np.array([par.default for par in robot.parameters], dtype=float)
    Ms = []
    for _ in range(samples):
        q = rng.uniform(lo, hi)
        if robot.floating:  # a unit quaternion
            q[3:7] = rng.normal(size=4)
            q[3:7] /= np.linalg.norm(q[3:7])
        Ms.append(np.array(f(q, p)))
    diag = np.min([np.diag(M) for M in Ms], axis=0)
    scale = max(float(np.max(np.abs(diag), initial=0.0)), 1e-300)
    where = f"{robot.file}: robot '{robot.name}'" if robot.file else f"robot '{robot.name}'"  # the models file
    unmoved = []
    # the entries of v, M's rows (a floating base's 6 velocities before the joints', not q's 7 entries)
    velocities = [(name, FREE_FLYER) for name in robot.velocity_names[:6]] if robot.floating else []
    velocities += [(c.name, c.joint) for c in robot.joint_coordinates]
    for (name, joint), d in zip(velocities, diag, strict=True):
        if not np.isfinite(d):
            raise DeriveError(f"{where}: joints ({joint}): M(q) is not finite at the default "
                              "parameters (overflowing masses, inertias or lengths?)")
        if d <= 1e-12 * scale:
            if not strict:
                unmoved.append(name)
                continue
            relock = relock_command(robot.source, [joint]) if joint != FREE_FLYER else None
            fix = f", or import it with the joint locked: {relock}" if relock else ""
            raise DeriveError(f"{where}: joints ({joint}): coordinate '{name}' moves no mass or "
                              "inertia, so M(q) is singular and forward dynamics do not exist; give the links it "
                              f"moves a mass (links[i].mass) or inertia about its axis{fix}")
    if unmoved:  # M is singular for that alone; the eigenvectors below would only name them again
        return unmoved
    if all(np.isfinite(M).all() for M in Ms):
        eig = [np.linalg.eigh(M) for M in Ms]
        if all(w[0] <= 1e-12 * max(w[-1], 1e-300) for w, _ in eig):
            v = eig[0][1]
            names = robot.velocity_names
            moving = [names[int(k)] for k in np.argsort(-np.abs(v[:, 0]))[:3] if abs(v[int(k), 0]) > 1e-6]
            raise DeriveError(f"{where}: M(q) is singular at every q tried: the coordinates "
                              f"{', '.join(moving)} move the same way (e.g. a joint about the same axis through the "
                              "same point as a massless floating base's turn), so forward dynamics do not exist")
    return []


def check_constants(robot: Robot, spec, prog) -> None:
    """Refuse code with a non-finite constant (it would print DERIVE_LIT(inf) in C, a bare inf in Python)."""
    for ins in prog.body:
        for a in ins.args:
            if a[0] == "c" and not math.isfinite(a[1]):
                raise DeriveError(f"robot '{robot.name}': {spec.name}: a constant of the derived expression is "
                                  f"{a[1]} (overflowing or degenerate numbers in the model)")
    for _, _, a in prog.results:
        if a[0] == "c" and not math.isfinite(a[1]):
            raise DeriveError(f"robot '{robot.name}': {spec.name}: an output is the constant {a[1]} "
                              "(overflowing or degenerate numbers in the model)")
