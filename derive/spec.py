"""Function specs: the only hand-off from the maths to the emitters.

A FunctionSpec names a generated function, its ordered inputs and outputs
(name, shape) and its docstring, and carries the SX expressions. Emitters turn
a list of specs into files; they do no mechanics.

Generated functions are ``<robot>_<quantity>[_<frame>]``. Code uses the
recursive forms (RNEA, CRBA, LDL^T), which the tests prove equal to the
Lagrangian; they are several times leaner after CSE.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca

from .api import SXModel
from .model import Robot
from .ode import ode_jacobians

QUANTITIES = ("fk", "jacobian", "fk_jacobian", "mass_matrix", "coriolis_matrix", "gravity", "inverse_dynamics",
              "forward_dynamics", "ode_rhs", "ode_jac_x", "ode_jac_u")


class _Named:
    """``<robot>_<quantity>[_<frame>]`` naming shared by every generated function."""

    robot: str
    quantity: str
    frame: str | None

    @property
    def short_name(self) -> str:
        """Name without the robot prefix (the Python function name)."""
        return self.quantity + (f"_{self.frame}" if self.frame else "")

    @property
    def name(self) -> str:
        return f"{self.robot}_{self.short_name}"


@dataclass(frozen=True)
class FunctionSpec(_Named):
    robot: str
    quantity: str
    frame: str | None
    inputs: tuple[tuple[str, ca.SX], ...]
    outputs: tuple[tuple[str, ca.SX], ...]
    doc: str


@dataclass(frozen=True)
class TemplateFunction(_Named):
    """A generated function whose body is a template (loops, calls), not one expression graph.

    ``c_template`` and ``py_template`` are jinja templates under templates/ rendered with
    ``f`` (this function's plain-data context, ``context`` merged in) and the robot's
    context; ``calls`` names the generated functions it uses (their headers are included).
    Algorithms (solvers, decompositions) live in fixed, robot-independent support files
    (``c_support``, ``py_support``) that every robot's output gets verbatim; the templates only
    lay out the call with this robot's sizes, limits and functions.
    """

    robot: str
    quantity: str
    frame: str | None
    inputs: tuple[tuple[str, tuple[int, int]], ...]
    outputs: tuple[tuple[str, tuple[int, int]], ...]
    doc: str
    c_template: str
    py_template: str
    calls: tuple[str, ...] = ()
    context: tuple[tuple[str, object], ...] = ()  # plain data, as pairs to stay hashable
    c_support: tuple[str, ...] = ()   # files of templates/c/support/ the C source includes (copied verbatim)
    py_support: tuple[str, ...] = ()  # files of templates/python/support/ the Python body calls (inserted verbatim)


def template_functions(model: SXModel) -> list[TemplateFunction]:
    """Functions built from templates on top of the expression functions, in a fixed order."""
    from .ik import template_functions as ik_functions  # ik builds on this module
    from .manipulability import template_function as manipulability_function  # so does manipulability

    robot = model.robot
    n = 2 * robot.nv
    extra = (("p", (model.sym.p.numel(), 1)),) if model.sym.p.numel() else ()
    return [
        TemplateFunction(
            robot.name, "rk4_step", None,
            (("x", (n, 1)), ("u", (robot.nv, 1)), ("dt", (1, 1))) + extra, (("x_next", (n, 1)),),
            "One classical Runge-Kutta step of x' = f(x, u) with u held constant over dt: "
            "x_next = x + dt/6 (k1 + 2 k2 + 2 k3 + k4), k_i from ode_rhs.",
            "c/rk4_step.c.jinja", "python/rk4_step.py.jinja", calls=(f"{robot.name}_ode_rhs",),
            context=(("n", n), ("ode", f"{robot.name}_ode_rhs"))),
    ] + ik_functions(model) + [t for f in robot.frames if (t := manipulability_function(model, f.name))]


def function_specs(model: SXModel) -> list[FunctionSpec]:
    """Every function generated for a robot, in a fixed order."""
    robot: Robot = model.robot
    s = model.sym
    n = robot.nv
    extra = (("p", s.p),) if s.p.numel() else ()
    pdoc = f" p ({s.p.numel()}): parameters {', '.join(s.parameter_names)}." if extra else ""
    q, qd, qdd, tau = ("q", s.q), ("qd", s.qd), ("qdd", s.qdd), ("tau", s.tau)
    ne = model.newton_euler
    specs: list[FunctionSpec] = []

    def add(quantity, frame, inputs, outputs, doc):
        specs.append(FunctionSpec(robot.name, quantity, frame, tuple(inputs) + extra, tuple(outputs), doc + pdoc))

    for f in robot.frames:
        add("fk", f.name, [q], [("T", model.fk(f.name))],
            f"world_T_{f.name}: 4x4 homogeneous transform of frame '{f.name}' in the world (root) frame, row-major.")
        add("jacobian", f.name, [q], [("J", model.jacobian(f.name))],
            f"Geometric Jacobian of frame '{f.name}', 6x{n} row-major, rows [linear; angular], "
            "world-aligned at the frame origin (LOCAL_WORLD_ALIGNED): [v; w] = J qd.")
    if "tcp" in {f.name for f in robot.frames}:
        add("fk_jacobian", "tcp", [q], [("T", model.fk("tcp")), ("J", model.jacobian("tcp"))],
            "world_T_tcp (4x4) and its geometric Jacobian (6x{n}, [linear; angular], LOCAL_WORLD_ALIGNED) "
            "in one pass, sharing the transforms: what IK and control loops need each step.".format(n=n))
    add("mass_matrix", None, [q], [("M", ne.mass_matrix)],
        f"Joint-space mass matrix M(q) ({n}x{n}, row-major) of M qdd + C qd + g = tau; composite-rigid-body algorithm.")
    add("coriolis_matrix", None, [q, qd], [("C", ne.coriolis_matrix)],
        f"Coriolis matrix C(q, qd) ({n}x{n}, row-major) from the Christoffel symbols of M; Mdot - 2C is skew-symmetric.")
    add("gravity", None, [q], [("g", ne.gravity_vector)],
        "Gravity torques g(q) = dU/dq = rnea(q, 0, 0).")
    add("inverse_dynamics", None, [q, qd, qdd], [("tau", ne.inverse_dynamics())],
        "Inverse dynamics tau = M(q) qdd + C(q, qd) qd + g(q), recursive Newton-Euler.")
    qdd_fd = model.forward_dynamics()
    add("forward_dynamics", None, [q, qd, tau], [("qdd", qdd_fd)],
        "Forward dynamics qdd = M(q)^-1 (tau - C(q, qd) qd - g(q)) by an unrolled LDL^T solve.")
    x, u = ca.SX.sym("x", 2 * n), ca.SX.sym("u", n)
    f = ca.vertcat(s.qd, qdd_fd)
    sub_from, sub_to = ca.vertcat(s.q, s.qd, s.tau), ca.vertcat(x, u)

    def in_xu(e: ca.SX) -> ca.SX:
        return ca.substitute(e, sub_from, sub_to)

    add("ode_rhs", None, [("x", x), ("u", u)], [("xdot", in_xu(f))],
        f"First-order ODE x' = f(x, u) with x = [q; qd] ({2 * n}), u = tau ({n}): f = [qd; qdd].")
    A, B = ode_jacobians(ne.mass_matrix, ne.inverse_dynamics(), s.q, s.qd, s.qdd, qdd_fd)
    add("ode_jac_x", None, [("x", x), ("u", u)], [("A", in_xu(A))],
        f"df/dx ({2 * n}x{2 * n}, row-major) of the ODE x' = f(x, u): the linearisation's A.")
    add("ode_jac_u", None, [("x", x), ("u", u)], [("B", in_xu(B))],
        f"df/du ({2 * n}x{n}, row-major) of the ODE x' = f(x, u): the linearisation's B.")
    return specs
