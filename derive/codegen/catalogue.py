"""The catalogue: which functions every robot gets, as language-free specs in a fixed order.

Generated functions are ``<robot>_<quantity>[_<frame>]``. Code uses the recursive
forms (RNEA, CRBA, LDL^T), which the tests prove equal to the Lagrangian; they are
several times leaner after CSE. A new quantity is one more ``add(...)`` in
:func:`function_specs` (an expression) or one more entry of :func:`template_functions`
(a loop or a call of a fixed algorithm).
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from derive.description.robot import FUNCTION_QUANTITIES, MOTOR_MAP_QUANTITIES, Robot
from derive.errors import DeriveError
from derive.symbolic.base_parameters import base_parameters
from derive.symbolic.ik import ATTEMPT, LAMBDA0, LAMBDA_MIN, LAMBDA_STALL, TOL_POSITION, TOL_ROTATION, joint_ranges
from derive.symbolic.dynamics import graph_cost
from derive.symbolic.model import SXModel
from derive.symbolic import derivatives
from derive.symbolic.ode import AD_MODES, inverse_dynamics_jacobian, ode_jacobians
from derive.symbolic.regressor import Regressor, body_links
from derive.symbolic.closure import ASSEMBLED_TOL, NEWTON_STEPS, ClosedChainModel
from derive.symbolic.closed_regressor import ClosedRegressor, closed_base_parameters
from derive.symbolic.motor_map import motor_joint_maps
from derive.symbolic import contact
from derive.codegen.checks import NEEDS_INVERSE_MASS
from derive.codegen.program import build_program
from derive.codegen.spec import FunctionSpec, TemplateFunction

QUANTITIES = FUNCTION_QUANTITIES  # every quantity of a generated function

IK_FRAMES = ("tcp",)      # the frames that have a generated fk_jacobian
IK_MAX_ITERATIONS = 5000  # the generated solver's iteration cap
IK_LAMBDA_MIN_FLOAT = 1e-5  # smallest damping in single precision
IK_LIMIT = 1e30           # a missing joint limit: finite in float too, and never reached
POSITION_ROWS = (0, 1, 2)


def parameter_input(model: SXModel) -> tuple[tuple, str]:
    """The input every expression function ends with where the robot has parameters, ``(("p", p),)``
    (else ``()``), and the sentence its docstring ends with."""
    s = model.sym
    if not s.p.numel():
        return (), ""
    return (("p", s.p),), f" p ({s.p.numel()}): parameters {', '.join(s.parameter_names)}."


def function_specs(model: SXModel, forward: bool = True) -> list[FunctionSpec]:
    """Every expression function generated for a robot, in a fixed order.

    ``forward``: False for a robot whose M(q) is singular (a coordinate that moves no mass,
    :func:`~derive.codegen.checks.check_mass_matrix`): the functions that need M^-1
    (:data:`~derive.codegen.checks.NEEDS_INVERSE_MASS`) are left out, every other one is kept."""
    robot: Robot = model.robot
    s = model.sym
    n, nq = robot.nv, robot.nq
    wb = model.whole_body
    extra, pdoc = parameter_input(model)
    q, qd, qdd, tau = ("q", s.q), ("qd", s.qd), ("qdd", s.qdd), ("tau", s.tau)
    ne = model.newton_euler
    specs: list[FunctionSpec] = []
    need = wanted(robot)

    def add(quantity, frame, inputs, outputs, doc, manifest=()):
        if robot.closed:  # the spanning tree's functions, in q: the loops are not imposed
            doc += " Of the spanning tree, in its coordinates q (the loops are not imposed)."
            manifest = tuple(manifest) + (("coordinates", "q"),)
        specs.append(FunctionSpec(robot.name, quantity, frame, tuple(inputs) + extra, tuple(outputs), doc + pdoc,
                                  tuple(manifest)))

    for f in robot.function_frames:  # the named frames, or models.yaml's generate: {frames: [...]} (links too)
        add("fk", f, [q], [("T", model.fk(f))],
            f"world_T_{f}: 4x4 homogeneous transform of frame '{f}' in the world (root) frame, row-major.")
        add("jacobian", f, [q], [("J", model.jacobian(f))],
            f"Geometric Jacobian of frame '{f}', 6x{n} row-major, rows [linear; angular], "
            "world-aligned at the frame origin (LOCAL_WORLD_ALIGNED): [v; w] = J qd.")
        add("jdot_qd", f, [q, qd], [("a", wb.jdot_qd(f))],
            f"J'(q, qd) qd of frame '{f}' (6): its classical acceleration [linear; angular] at qdd = 0, "
            "world-aligned, without gravity: the bias of task-space control.")
        add("frame_acceleration", f, [q, qd, qdd], [("a", wb.frame_acceleration(f))],
            f"Classical acceleration of frame '{f}' (6): [d/dt of its origin's world velocity; angular "
            "acceleration], world-aligned, without gravity: J qdd + J' qd (Pinocchio's "
            "getFrameClassicalAcceleration, LOCAL_WORLD_ALIGNED).")
    if "tcp" in robot.function_frames:
        add("fk_jacobian", "tcp", [q], [("T", model.fk("tcp")), ("J", model.jacobian("tcp"))],
            "world_T_tcp (4x4) and its geometric Jacobian (6x{n}, [linear; angular], LOCAL_WORLD_ALIGNED) "
            "in one pass, sharing the transforms: what IK and control loops need each step.".format(n=n))
    links = robot.link_names
    add("fk_all", None, [q], [("T", ca.vertcat(*(model.fk(link) for link in links)))],
        f"world_T_<link> of all {len(links)} links in one pass, stacked ({4 * len(links)}x4, row-major): rows 4k..4k+3 "
        f"are link k's 4x4 homogeneous transform (as fk_<link> would give it), links in tree order: "
        f"{', '.join(links)} (manifest.json's links).", (("links", list(links)),))
    add("mass_matrix", None, [q], [("M", ne.mass_matrix)],
        f"Joint-space mass matrix M(q) ({n}x{n}, row-major) of M qdd + C qd + g = tau; composite-rigid-body algorithm.",
        (("algorithm", "CRBA"),))
    if need("coriolis_matrix") and not robot.floating:
        C = ne.coriolis_matrix
        how = ("from the Christoffel symbols of M" if ne.coriolis_algorithm == "Christoffel symbols of M" else
               f"of the Christoffel symbols of M, as {ne.coriolis_algorithm}")
        add("coriolis_matrix", None, [q, qd], [("C", C)],
            f"Coriolis matrix C(q, qd) ({n}x{n}, row-major) {how}; Mdot - 2C is skew-symmetric.",
            (("algorithm", ne.coriolis_algorithm),))
    elif need("coriolis_matrix"):  # the Christoffel symbols need qd = dq/dt; the spatial factorisation does not
        add("coriolis_matrix", None, [q, qd], [("C", wb.coriolis_matrix)],
            f"Coriolis matrix C(q, qd) ({n}x{n}, row-major) by the spatial factorisation sum_i J_i^T (I_i Jdot_i + "
            "B_i J_i) (Pinocchio's computeCoriolisMatrix): C qd = the velocity terms of ID, Mdot - 2C skew-symmetric.",
            (("algorithm", "spatial factorisation"),))
    add("gravity", None, [q], [("g", ne.gravity_vector)],
        "Gravity torques g(q) = dU/dq = rnea(q, 0, 0).")
    add("bias", None, [q, qd], [("h", ne.inverse_dynamics(ca.SX.zeros(n, 1)))],
        "Bias torques h(q, qd) = C(q, qd) qd + g(q) (plus the actuators' friction, if any) = inverse_dynamics(q, qd, 0), "
        "so that tau = M(q) qdd + h: what computed-torque and task-space control need besides M.")
    add("inverse_dynamics", None, [q, qd, qdd], [("tau", ne.inverse_dynamics())],
        "Inverse dynamics tau = M(q) qdd + C(q, qd) qd + g(q), recursive Newton-Euler.", (("algorithm", "RNEA"),))
    if robot.closed:  # the tree functions above in q, then the closed chain's in y; none that ignores the loops
        add("com", None, [q], [("c", wb.com)], "Centre of mass of the moving bodies, world coordinates (3).")
        add("com_jacobian", None, [q], [("J", wb.com_jacobian)],
            f"Jacobian of the centre of mass (3x{n}, row-major): its world velocity is J qd.")
        closed_chain_specs(model, specs, need)
        return specs
    if need("inverse_dynamics_derivatives"):  # the costly ones are derived only where a selection keeps them
        specs.append(inverse_dynamics_derivatives_spec(model))
    qdd_fd = model.forward_dynamics() if forward and need("forward_dynamics", "ode_rhs", "ode_jac_x", "ode_jac_u") else None
    fd_how = (("algorithm", model.forward_dynamics_algorithm),)
    if qdd_fd is not None:
        add("forward_dynamics", None, [q, qd, tau], [("qdd", qdd_fd)],
            f"Forward dynamics qdd = M(q)^-1 (tau - C(q, qd) qd - g(q)) by {FD_DOC[model.forward_dynamics_algorithm]}.", fd_how)
    frames = robot.wrench_frames
    if frames and need("inverse_dynamics_fext", "forward_dynamics_fext"):
        k = len(frames)
        w = ca.SX.sym("w", 6 * k)
        wrench_doc = (f"w ({6 * k}): the external wrenches [force; torque] acting at the origins of the frames "
                      f"{', '.join(frames)} (6 each, in that order), in world-aligned axes")
        jtw = wb.wrench_torques(w)
        add("inverse_dynamics_fext", None, [q, qd, qdd, ("w", w)], [("tau", ne.inverse_dynamics() - jtw)],
            f"Inverse dynamics with external wrenches tau = ID(q, qd, qdd) - sum_f J_f^T w_f; {wrench_doc}.")
        if forward and need("forward_dynamics_fext"):
            add("forward_dynamics_fext", None, [q, qd, tau, ("w", w)],
                [("qdd", model.forward_dynamics(extra_torque=jtw))],
                f"Forward dynamics with external wrenches qdd = M^-1 (tau + sum_f J_f^T w_f - C qd - g); {wrench_doc}.", fd_how)
    com_doc = ("the moving bodies (the floating base included)" if robot.floating else
               "the moving bodies (the root link is the world and does not count, as in Pinocchio)")
    add("com", None, [q], [("c", wb.com)], f"Centre of mass of {com_doc}, world coordinates (3).")
    add("com_jacobian", None, [q], [("J", wb.com_jacobian)],
        f"Jacobian of the centre of mass (3x{n}, row-major): its world velocity is J qd.")
    add("centroidal_map", None, [q], [("A", wb.centroidal_map)],
        f"Centroidal momentum matrix A_G (6x{n}, row-major): A_G qd = [linear; angular] momentum about the centre "
        "of mass, world axes (Pinocchio's computeCentroidalMap).")
    if robot.contacts:
        contact_specs(model, add, need, forward)
    if forward and need("ode_rhs", "ode_jac_x", "ode_jac_u"):
        ode_specs(model, qdd_fd, add, extra, fd_how)
    if need("regressor", "base_regressor"):
        regressor_specs(model, add)
    if need("bundle"):
        bundle_specs(model, specs, add)
    return specs


def contact_specs(model: SXModel, add, need, forward: bool) -> None:
    """The centroidal terms, then per contact set (:attr:`Robot.stances`) the contact and impulse dynamics and
    their derivatives (:mod:`derive.symbolic.contact`); those that need M^-1 only where M(q) is regular."""
    robot, s = model.robot, model.sym
    n, nq = robot.nv, robot.nq
    q, qd, qdd, tau = ("q", s.q), ("qd", s.qd), ("qdd", s.qdd), ("tau", s.tau)
    if need("centroidal_map_dot_qd"):
        add("centroidal_map_dot_qd", None, [q, qd], [("dh", contact.centroidal_map_dot_qd(model))],
            "A_G'(q, qd) qd (6): the rate of the centroidal momentum [linear; angular] about the centre of mass, world "
            "axes, at qdd = 0, so that dh_G/dt = A_G qdd + A_G' qd (Pinocchio's computeCentroidalMomentumTimeVariation "
            "at a = 0, its dhg).")
    if need("com_acceleration"):
        add("com_acceleration", None, [q, qd, qdd], [("a", contact.com_acceleration(model))],
            "Acceleration of the centre of mass (3), world coordinates: (A_G qdd + A_G' qd)[0:3] / m "
            "(Pinocchio's centerOfMass(q, v, a), its acom).")
    if need("centroidal_inertia"):
        add("centroidal_inertia", None, [q], [("I", contact.centroidal_inertia(model))],
            "Composite rotational inertia I_G(q) (3x3, row-major) of the robot locked at q, about the centre of mass, "
            "world axes: with the total mass, the single-rigid-body model at this posture (Pinocchio's ccrba, the "
            "rotational block of data.Ig).")
    for stance in robot.stances:  # RNEA and a 6 x 6 solve: no M^-1, so also where M(q) is singular
        cm = contact.ContactModel(model, stance)
        if need("contact_inverse_dynamics") and cm.base_determined:
            m = cm.rows
            tau_c, lam, status = cm.inverse
            listed = ", ".join(f"{f} ({robot.contact(f).kind}, {robot.contact(f).rows})" for f in stance.frames)
            add("contact_inverse_dynamics", stance.name, [q, qd, qdd], [("tau", tau_c), ("lam", lam), ("status", status)],
                f"Contact-consistent inverse dynamics of the stance '{stance.name}' ({listed}) for the desired qdd: "
                f"tau ({n}, its six base entries 0) and lam ({m}) with M qdd + h = tau + J^T lam, lam the minimum-norm "
                "solution of the base rows J_b^T lam = ID(q, qd, qdd)[0:6] (J_b = J[:, 0:6]; lam = J_b (J_b^T J_b)^-1 "
                "ID[0:6], numpy's lstsq), tau = ID - J^T lam on the joints; lam world-aligned at each frame origin as "
                "in contact_dynamics. status 1 where J_b has rank 6 (every pivot of J_b^T J_b's LDL^T above "
                f"{contact.PIVOT_TOL:g} times its diagonal), else 0: the stance cannot hold the base, the other "
                "outputs solve nothing. The contacts' acceleration J qdd + J' qd is not imposed: where it is 0, "
                "contact_dynamics at tau gives back qdd.",
                (("contacts", [{"frame": f, "kind": robot.contact(f).kind, "rows": robot.contact(f).rows}
                               for f in stance.frames]),
                 ("algorithm", "RNEA, minimum-norm lambda of the base rows by LDL^T of J_b^T J_b")))
    if not forward:
        return
    e = ca.SX.sym("e")
    quaternion = (", the base quaternion's four included: those of the rotation it stands for, zero along the "
                  "quaternion itself" if robot.floating else "")
    wrt = f"columns [d/dq ({nq}{quaternion}), d/dqd ({n})"
    for stance in robot.stances:
        cm = contact.ContactModel(model, stance)
        m = cm.rows
        listed = ", ".join(f"{f} ({robot.contact(f).kind}, {robot.contact(f).rows})" for f in stance.frames)
        facts = (("contacts", [{"frame": f, "kind": robot.contact(f).kind, "rows": robot.contact(f).rows}
                               for f in stance.frames]),
                 ("algorithm", "LTDL of M along the tree, LDL^T of the Schur complement J M^-1 J^T"))
        status_doc = (f"status 1 where the contact rows are independent (every pivot of the Schur complement's LDL^T "
                      f"above {contact.PIVOT_TOL:g} times its diagonal), else 0: redundant contacts, nothing is "
                      "regularised and the other outputs solve nothing.")
        if need("contact_dynamics"):
            qdd_c, lam, status = cm.forward
            add("contact_dynamics", stance.name, [q, qd, tau], [("qdd", qdd_c), ("lam", lam), ("status", status)],
                f"Contact forward dynamics of the stance '{stance.name}' ({listed}): qdd ({n}) and the contact forces "
                f"lam ({m}) of [M J^T; J 0] [qdd; -lam] = [tau - h; -J' qd], i.e. M qdd + h = tau + J^T lam with the "
                "contacts held (a point's classical acceleration zero, a surface's spatial one); lam world-aligned at "
                "each frame origin, [f] per point, [f; torque] per surface (Pinocchio's constraintDynamics, "
                f"LOCAL_WORLD_ALIGNED). LTDL of M, then LDL^T of J M^-1 J^T, no KKT inverse; {status_doc}", facts)
        if need("contact_dynamics_baumgarte") and cm.points_only:
            anchor, gains = ca.SX.sym("anchor", m), ca.SX.sym("gains", 2)
            qdd_b, lam_b, status_b = cm.stabilised(anchor, gains)
            add("contact_dynamics_baumgarte", stance.name, [q, qd, tau, ("anchor", anchor), ("gains", gains)],
                [("qdd", qdd_b), ("lam", lam_b), ("status", status_b)],
                f"contact_dynamics_{stance.name} with Baumgarte stabilisation: the contacts' constraint is "
                "J qdd + J' qd = -kp (p - anchor) - kd J qd, p the contact points (world, 3 each), anchor "
                f"({m}) where they are held, gains = [kp, kd] (Pinocchio's BaumgarteCorrectorParameters with "
                f"joint2_placement at the anchor); {status_doc}", facts)
        if need("contact_dynamics_derivatives"):
            dqdd, dlam = cm.forward_derivatives
            add("contact_dynamics_derivatives", stance.name, [q, qd, tau], [("dqdd", dqdd), ("dlam", dlam)],
                f"Partial derivatives of contact_dynamics_{stance.name}: dqdd ({n}x{nq + 2 * n}) and dlam "
                f"({m}x{nq + 2 * n}), row-major, {wrt}, d/dtau ({n})] (Pinocchio's computeConstraintDynamicsDerivatives "
                "after multiplying d/dq by dq/d(tangent)); the implicit-function theorem on the KKT residual, "
                "solved by the same factors.", facts)
        if need("impulse_dynamics"):
            v_plus, imp, status = cm.impulse(e)
            add("impulse_dynamics", stance.name, [q, qd, ("e", e)],
                [("v_plus", v_plus), ("impulse", imp), ("status", status)],
                f"Impulse dynamics at touchdown of the stance '{stance.name}' ({listed}): the velocity after impact "
                f"v_plus ({n}) and the contact impulse ({m}) of [M J^T; J 0] [v_plus; -impulse] = [M qd; -e J qd] for "
                "the velocity before impact qd and the restitution coefficient e (0: plastic; Pinocchio's "
                f"impulseDynamics, LOCAL_WORLD_ALIGNED); {status_doc}", facts)
        if need("impulse_dynamics_derivatives"):
            dv, dimp = cm.impulse_derivatives(e)
            add("impulse_dynamics_derivatives", stance.name, [q, qd, ("e", e)], [("dv_plus", dv), ("dimpulse", dimp)],
                f"Partial derivatives of impulse_dynamics_{stance.name}: dv_plus ({n}x{nq + n}) and dimpulse "
                f"({m}x{nq + n}), row-major, {wrt}] (Pinocchio's computeImpulseDynamicsDerivatives: its ddq_dv is "
                "d v_plus/d qd - I).", facts)


CLOSED_LEFT_OUT = ("inverse_dynamics_derivatives", "forward_dynamics", "inverse_dynamics_fext", "forward_dynamics_fext",
                   "centroidal_map", "regressor", "base_regressor", "bundle", "ik", "manipulability")
"""The tree functions a robot with loops does not get: the tree's forward dynamics (and its ODE and
derivatives) ignore the loops; regressors, IK, manipulability and the control bundles of the tree would
mislead without them (closed-chain versions of IK and the bundles are future work). Its ode_rhs, ode_jac_x,
ode_jac_u and rk4_step are the closed chain's, in x = (y, yd); its regressor_y and base_regressor_y replace
the tree's regressors."""


def closed_chain_specs(model: SXModel, specs: list[FunctionSpec], need) -> None:
    """The functions of a closed chain in its independent coordinates y (:meth:`~derive.symbolic.closure.
    ClosedChainModel.in_y`): closure, velocity_map (G), mass_matrix_y, bias_y, inverse_dynamics_y,
    forward_dynamics_y, constraint_forces, the ODE in x = (y, yd) with its Jacobians, then the regressors
    regressor_y and base_regressor_y."""
    robot = model.robot
    extra, pdoc = parameter_input(model)
    ccm = ClosedChainModel(robot, model)
    red = ccm.in_y()
    ny, nq, nz = ccm.ny, ccm.nq, len(ccm.z)
    y, yd, ydd, tau = ("y", red.y), ("yd", ccm.yd), ("ydd", ccm.ydd), ("tau_y", ccm.tau_y)
    ys = ", ".join(robot.independent)
    method = (("coordinates", "y"), ("closure", red.method))

    def add(quantity, inputs, outputs, doc, manifest=()):
        if need(quantity):
            specs.append(FunctionSpec(robot.name, quantity, None, tuple(inputs) + extra, tuple(outputs), doc + pdoc,
                                      method + tuple(manifest)))

    closure_in = [y] if red.z0 is None else [y, ("z0", red.z0)]
    how = (f"{red.method} (exact up to rounding)" if red.z0 is None else
           f"{red.method}, from z0 (the last z, or the reference configuration's)")
    add("closure", closure_in, [("q", red.q), ("status", red.status), ("residual", red.residual)],
        f"Loop closure z = gamma(y): the tree configuration q ({nq}) of y = ({ys}) by {how}; status 1 where "
        f"max |phi(q)| <= {ASSEMBLED_TOL:g} (float builds too), else 0 (no assembly: q is NaN or off the loops); residual = max |phi(q)|.")
    at = ("q = gamma(y) by the closed form inside" if red.z0 is None else
          f"q = gamma(y) inside by {NEWTON_STEPS} Newton steps from the reference configuration (call closure "
          "for the status)")
    add("velocity_map", [y], [("G", red.projection)],
        f"Velocity map G(y) ({nq}x{ny}, row-major): qd = G yd, G = [I; -K_z^-1 K_y] in q's order; {at}.")
    add("mass_matrix_y", [y], [("M_y", red.mass_matrix)],
        f"Reduced mass matrix M_y = G^T M G ({ny}x{ny}, row-major) of M_y ydd + h_y = tau_y; {at}.")
    add("bias_y", [y, yd], [("h_y", red.bias)],
        f"Reduced bias h_y = G^T (C qd + g + M Gdot yd) ({ny}), qd = G yd; {at}.")
    add("inverse_dynamics_y", [y, yd, ydd], [("tau_y", red.inverse_dynamics)],
        f"Constrained inverse dynamics tau_y = G^T rnea(q, G yd, G ydd + Gdot yd) ({ny}): the torques on y "
        f"that give ydd with the loops closed; {at}.")
    add("forward_dynamics_y", [y, yd, tau], [("ydd", red.forward_dynamics)],
        f"Constrained forward dynamics ydd = M_y^-1 (tau_y - h_y) ({ny}), LDL^T of M_y; {at}.")
    add("constraint_forces", [y, yd, tau], [("lam", red.constraint_forces)],
        f"Loop forces lam = lambda ({nz}, one per kept row of phi) of M qdd + h = S^T tau_y + K^T lambda at the "
        f"forward dynamics' qdd (the tree's KKT multiplier); {at}.")
    if robot.outputs and need(*MOTOR_MAP_QUANTITIES):
        motor_map_specs(ccm, red, specs, need, closure_in, at)
    if need("ode_rhs", "ode_jac_x", "ode_jac_u", "rk4_step"):
        closed_ode_specs(ccm, red, add, at)
    if need("regressor_y", "base_regressor_y"):
        closed_regressor_specs(model, ccm, red, add, at)


def closed_ode_specs(ccm: ClosedChainModel, red, add, at: str) -> None:
    """The closed chain's ``ode_rhs``, ``ode_jac_x`` and ``ode_jac_u`` in x = (y, yd), u = tau_y."""
    ny = ccm.ny
    x, u = ca.SX.sym("x", 2 * ny), ca.SX.sym("u", ny)
    f = ca.vertcat(ccm.yd, red.forward_dynamics)
    sub_from, sub_to = ca.vertcat(red.y, ccm.yd, ccm.tau_y), ca.vertcat(x, u)
    f = ca.substitute(f, sub_from, sub_to)
    doc = (f"First-order ODE x' = f(x, u) of the closed chain, x = [y; yd] ({2 * ny}), u = tau_y ({ny}): "
           f"f = [yd; forward_dynamics_y]; {at}")
    add("ode_rhs", [("x", x), ("u", u)], [("xdot", f)], doc + ".")
    add("ode_jac_x", [("x", x), ("u", u)], [("A", ca.jacobian(f, x))],
        ODE_JAC_DOC["ode_jac_x"].format(nx=2 * ny) + " Closed chain, x = [y; yd].", (("algorithm", "forward AD"),))
    add("ode_jac_u", [("x", x), ("u", u)], [("B", ca.jacobian(f, u))],
        ODE_JAC_DOC["ode_jac_u"].format(nx=2 * ny, n=ny) + " Closed chain, x = [y; yd].", (("algorithm", "forward AD"),))


def closed_regressor_specs(model: SXModel, ccm: ClosedChainModel, red, add, at: str) -> None:
    """``regressor_y`` (Y_y = G^T Y(q, G yd, G ydd + Gdot yd), every standard parameter) and ``base_regressor_y``
    (its base columns: the closed chain's own base parameters, :mod:`derive.symbolic.closed_regressor`)."""
    robot, ny = model.robot, ccm.ny
    cr = ClosedRegressor(ccm)
    pi = cr.reg.values()
    base = closed_base_parameters(cr, red)
    Y = cr.in_y(red)
    y, yd, ydd = ("y", red.y), ("yd", ccm.yd), ("ydd", ccm.ydd)
    values = " (numbers at the parameters' defaults)" if model.sym.p.numel() else ""
    add("regressor_y", [y, yd, ydd], [("Y_y", Y)],
        f"Closed-chain regressor Y_y(y, yd, ydd) = G^T Y(q, G yd, G ydd + Gdot yd) ({ny}x{cr.reg.size}, row-major): "
        f"inverse_dynamics_y = Y_y pi, pi the tree's standard parameters (per body ({', '.join(body_links(robot))}) "
        "[m, m c_x, m c_y, m c_z, I_xx, I_xy, I_yy, I_xz, I_yz, I_zz] about the body origin, body axes; then per "
        "coordinate [armature, viscous, coulomb]); pi's names and the model's values in manifest.json "
        f"(regressor_parameters){values}; {at}.",
        (("regressor_parameters", [{"name": k, "value": float(v)} for k, v in zip(cr.reg.names, pi)]),))
    add("base_regressor_y", [y, yd, ydd], [("Y_b", Y[:, list(base.columns)])],
        f"Closed-chain base regressor Y_b(y, yd, ydd) ({ny}x{base.rank}, row-major): the {base.rank} independent columns "
        "of regressor_y (the closed chain's base parameters, fewer than or as many as the tree's), so that "
        "inverse_dynamics_y = Y_b pi_b, pi_b = pi_1 + beta pi_2 (Gautier's QR on Y_y stacked at seeded closed "
        f"states); names, values, columns and combinations in manifest.json (base_parameters){values}; {at}.",
        (("rank", base.rank), ("base_parameters", base.manifest(pi))))


def motor_map_specs(ccm: ClosedChainModel, red, specs: list[FunctionSpec], need, closure_in: list, at: str) -> None:
    """The motor <-> joint maps of a closed chain with ``outputs`` (:mod:`derive.symbolic.motor_map`): the
    motors are y, the joints the outputs o; J = d o / d y = G's output rows."""
    robot = ccm.robot
    extra, pdoc = parameter_input(ccm.model)
    mm = motor_joint_maps(ccm, red)
    ys, os_ = ", ".join(robot.independent), ", ".join(robot.outputs)
    y, yd, tau = ("y", red.y), ("yd", ccm.yd), ("tau_y", ccm.tau_y)
    o, od, tau_o = ("o", mm.o), ("od", mm.od), ("tau_o", mm.tau_o)
    ny = ccm.ny
    o_at = ("q = gamma_o(o) by the closed form inside" if mm.w0 is None else
            f"q = gamma_o(o) inside by {NEWTON_STEPS} Newton steps from the reference configuration")

    def add(quantity, coordinates, inputs, outputs, doc):
        if need(quantity):
            how = red.method if coordinates == "y" else mm.method
            specs.append(FunctionSpec(robot.name, quantity, None, tuple(inputs) + extra, tuple(outputs), doc + pdoc,
                                      (("coordinates", coordinates), ("closure", how), ("motors", list(robot.independent)),
                                       ("joints", list(robot.outputs)))))

    add("motor_to_joint_position", "y", closure_in,
        [("o", mm.joint_position), ("status", red.status), ("residual", red.residual)],
        f"Motor -> joint position: the joints o = ({os_}) ({ny}) of the motors y = ({ys}), the closure's q at "
        f"the joints' rows, with its status and residual (as closure's: status 1 where max |phi| <= {ASSEMBLED_TOL:g}).")
    add("motor_to_joint_velocity", "y", [y, yd], [("od", mm.joint_velocity)],
        f"Motor -> joint velocity: od = J yd ({ny}), J = d o / d y = G's rows of ({os_}); {at}.")
    add("motor_to_joint_torque", "y", [y, tau], [("tau_o", mm.joint_torque)],
        f"Motor -> joint torque: tau_o = J^-T tau_y ({ny}), the torques on the joints ({os_}) that the motor "
        f"torques tau_y exert (the same power: tau_o . od = tau_y . yd); {at}.")
    w0 = [] if mm.w0 is None else [("w0", mm.w0)]
    start = ("" if mm.w0 is None else f", from w0 (the last values of the coordinates not in o, or the "
             "reference configuration's)")
    add("joint_to_motor_position", "outputs", [o, *w0],
        [("y", mm.motor_position), ("status", mm.motor_status), ("residual", mm.motor_residual)],
        f"Joint -> motor position: the motors y = ({ys}) ({ny}) that put the joints at o = ({os_}), by "
        f"{mm.method}{start}; status 1 where max |phi(q)| <= {ASSEMBLED_TOL:g}, else 0 (out of reach: y is "
        "NaN or off the loops); residual = max |phi(q)|.")
    add("joint_to_motor_velocity", "outputs", [o, od], [("yd", mm.motor_velocity)],
        f"Joint -> motor velocity: yd = J^-1 od ({ny}), J = d o / d y; {o_at}.")
    add("joint_to_motor_torque", "outputs", [o, tau_o], [("tau_y", mm.motor_torque)],
        f"Joint -> motor torque: tau_y = J^T tau_o ({ny}), the motor torques that exert the joint torques tau_o "
        f"on ({os_}) (the same power; a wanted ankle torque to motor commands); {o_at}.")


def ode_specs(model: SXModel, qdd_fd: ca.SX, add, extra: tuple, fd_how: tuple) -> None:
    """``ode_rhs`` and (below :data:`AD_COMPARE_MAX_NV`, see :func:`ode_by_template`) ``ode_jac_x``,
    ``ode_jac_u`` of x' = f(x, u) = [dq/dt; forward_dynamics(q, qd, u)]."""
    robot, s, ne = model.robot, model.sym, model.newton_euler
    n, nq = robot.nv, robot.nq
    x, u = ca.SX.sym("x", nq + n), ca.SX.sym("u", n)
    f = ca.vertcat(model.configuration_rate, qdd_fd)
    sub_from, sub_to = ca.vertcat(s.q, s.qd, s.tau), ca.vertcat(x, u)

    def in_xu(e: ca.SX) -> ca.SX:
        return ca.substitute(e, sub_from, sub_to)

    if robot.floating:
        ode_doc = (f"First-order ODE x' = f(x, u) with x = [q; qd] ({nq + n}), u = tau ({n}): f = [dq/dt; qdd], "
                   "dq/dt = [R(quat) v; 1/2 quat (x) (w, 0); joint rates] for the base velocity [v; w] (base frame); "
                   "the quaternion's norm is not kept by f itself (rk4_step renormalises it).")
    else:
        ode_doc = f"First-order ODE x' = f(x, u) with x = [q; qd] ({2 * n}), u = tau ({n}): f = [qd; qdd]."
    add("ode_rhs", None, [("x", x), ("u", u)], [("xdot", in_xu(f))], ode_doc, fd_how)
    if not ode_by_template(model):  # else template_functions: loops around calls
        A, B, mode = cheaper_ode_jacobians(model, qdd_fd, [("x", x), ("u", u), *extra], in_xu)
        add("ode_jac_x", None, [("x", x), ("u", u)], [("A", in_xu(A))], ODE_JAC_DOC["ode_jac_x"].format(nx=nq + n),
            (("algorithm", f"-M^-1 dID/dx at qdd = FD, dID/dx by {DID_DX[mode]}"),))
        add("ode_jac_u", None, [("x", x), ("u", u)], [("B", in_xu(B))], ODE_JAC_DOC["ode_jac_u"].format(nx=nq + n, n=n),
            (("algorithm", "M^-1 by " + ("LDL^T" if ne.dof_parents is None else "LTDL along the tree")),))


AD_COMPARE_MAX_NV = 12
"""Up to this many velocities the ODE's A is built with each way of computing dID/dx and the one with
fewer operations kept (:func:`cheaper_ode_jacobians`). Above it, the analytic derivatives where they
apply (a fixed base without mimic joints: a 20-joint chain's dID/dx 33 028 operations against
91 738 by reverse AD, tiago_dual's 125 864 against 189 833), else reverse mode; comparing costs a
CSE of each (a 20-joint chain: 5.7 s per candidate)."""


ODE_JAC_DOC = {"ode_jac_x": "df/dx ({nx}x{nx}, row-major) of the ODE x' = f(x, u): the linearisation's A.",
               "ode_jac_u": "df/du ({nx}x{n}, row-major) of the ODE x' = f(x, u): the linearisation's B."}
"""The ODE Jacobians' docstrings, the same whichever form computes them."""


def ode_by_template(model: SXModel) -> bool:
    """Whether ode_jac_x and ode_jac_u are template functions (:func:`ode_jacobian_templates`): above
    :data:`AD_COMPARE_MAX_NV` velocities where the analytic derivatives apply (a fixed base without mimic
    joints). Their closed forms hold the whole LDL^T solve of 2 nv right-hand sides unrolled, O(nv^3)
    straight-line operations (a 40-joint chain's A: 453 095, 56 s of gcc -O2; tiago_dual's 482 079, 74 s),
    where the template calls forward_dynamics, inverse_dynamics_derivatives and mass_matrix and factors
    and solves in loops."""
    return model.robot.nv > AD_COMPARE_MAX_NV and derivatives.supported(model.newton_euler)


def inverse_dynamics_derivatives_spec(model: SXModel) -> FunctionSpec:
    """``inverse_dynamics_derivatives(q, qd, qdd)``: dID/dx (:func:`inverse_dynamics_derivatives`)."""
    robot, s = model.robot, model.sym
    n, nq = robot.nv, robot.nq
    dID, mode = inverse_dynamics_derivatives(model)
    extra, pdoc = parameter_input(model)
    doc = (f"Partial derivatives of the inverse dynamics dtau = [dtau/dq, dtau/dqd] ({n}x{nq + n}, row-major) at "
           "(q, qd, qdd)" + (" with respect to the coordinates q (the base quaternion's four included)" if robot.floating else "")
           + ("; the actuators' Coulomb friction differentiated as its smoothing tanh(qd / eps), as forward_dynamics "
              "and the ODE use it" if robot.actuated else "") + " (Pinocchio's computeRNEADerivatives).")
    return FunctionSpec(robot.name, "inverse_dynamics_derivatives", None,
                        (("q", s.q), ("qd", s.qd), ("qdd", s.qdd)) + extra, (("dtau", dID),), doc + pdoc,
                        (("algorithm", DID_DX[mode]),))


def inverse_dynamics_derivatives(model: SXModel) -> tuple[ca.SX, str]:
    """dID/dx at the symbol qdd and how it was computed (a mode of
    :func:`~derive.symbolic.ode.inverse_dynamics_jacobian`): up to :data:`AD_COMPARE_MAX_NV` velocities
    the one of fewer instructions after CSE of reverse AD, forward AD and (from
    :data:`~derive.symbolic.derivatives.WORTH_FROM_NV`) the analytic form; above it, the analytic form
    where it applies, else reverse AD."""
    ne, s = model.newton_euler, model.sym
    analytic = derivatives.worth_trying(ne)
    if model.robot.nv > AD_COMPARE_MAX_NV:
        mode = "analytic" if analytic else "reverse"
        return inverse_dynamics_jacobian(ne, mode, s.qdd), mode
    candidates = [(inverse_dynamics_jacobian(ne, mode, s.qdd), mode) for mode in (*AD_MODES, *(("analytic",) if analytic else ()))]
    return min(candidates, key=lambda c: graph_cost(c[0], s.q, s.qd, s.qdd))  # ties: the first


FD_DOC = {"CRBA, then LDL^T": "an unrolled LDL^T solve", "CRBA, then LTDL along the tree": "an unrolled LTDL solve along the tree",
          "articulated-body algorithm": "the articulated-body algorithm"}
"""The forward dynamics' docstring words per :attr:`~derive.symbolic.model.SXModel.forward_dynamics_algorithm`."""


DID_DX = {"reverse": "reverse-mode automatic differentiation", "forward": "forward-mode automatic differentiation",
          "analytic": "the analytic RNEA derivatives"}
"""How dID/dx was computed, for manifest.json, per mode of :func:`inverse_dynamics_jacobian`."""


def cheaper_ode_jacobians(model: SXModel, qdd_fd: ca.SX, inputs: list, in_xu) -> tuple[ca.SX, ca.SX, str]:
    """The ODE's (A, B) with dID/dx by the way (:func:`~derive.symbolic.ode.inverse_dynamics_jacobian`)
    whose A has fewer operations in the generated code (up to :data:`AD_COMPARE_MAX_NV` velocities)."""
    ne, s, robot = model.newton_euler, model.sym, model.robot
    q_rate = model.configuration_rate if robot.floating else None
    analytic = derivatives.worth_trying(ne)

    def jacobians(mode: str) -> tuple[ca.SX, ca.SX]:
        dID = inverse_dynamics_jacobian(ne, mode, qdd_fd)
        return ode_jacobians(ne.mass_matrix, dID, s.q, s.qd, q_rate, ne.dof_parents)

    if robot.nv > AD_COMPARE_MAX_NV:
        mode = "analytic" if analytic else "reverse"
        return (*jacobians(mode), mode)
    candidates = [(*jacobians(mode), mode) for mode in ("reverse", "forward") + (("analytic",) if analytic else ())]
    return min(candidates, key=lambda c: build_program(inputs, [("A", in_xu(c[0]))]).ops()["total"])  # ties: the first


def bundle_specs(model: SXModel, specs: list[FunctionSpec], add) -> None:
    """``bundle_<name>`` for each of the robot's control-tick bundles (:attr:`Robot.control_bundles`):
    the outputs of the functions it names, as one graph of their joint inputs, so CSE computes every
    shared transform, sine, cosine and the RNEA's forward pass once."""
    robot, wb = model.robot, model.whole_body
    by_name = {spec.short_name: spec for spec in specs}
    frame_quantity = {"fk": model.fk, "jacobian": model.jacobian, "jdot_qd": wb.jdot_qd,
                      "frame_acceleration": wb.frame_acceleration}
    s = model.sym
    frame_inputs = {"fk": [("q", s.q)], "jacobian": [("q", s.q)], "jdot_qd": [("q", s.q), ("qd", s.qd)],
                    "frame_acceleration": [("q", s.q), ("qd", s.qd), ("qdd", s.qdd)]}
    order = ("q", "qd", "qdd", "tau", "w")
    zero = ca.SX.zeros(robot.nv, 1)
    ne = model.newton_euler
    split = {"bias": lambda: ne.inverse_dynamics(zero, split=True),  # share the frames' gravity-free forward pass
             "inverse_dynamics": lambda: ne.inverse_dynamics(split=True)}
    for bundle in robot.control_bundles:
        inputs: dict[str, ca.SX] = {}
        outputs, parts = [], []
        for quantity in bundle.quantities:
            spec = by_name.get(quantity)
            if spec is not None and len(spec.outputs) == 1:
                ins = [(n, x) for n, x in spec.inputs if n != "p"]
                expression = split[quantity]() if quantity in split else spec.outputs[0][1]
                parts.append({"output": quantity, "quantity": spec.quantity, "frame": spec.frame})
            else:
                prefix = next((p for p in frame_quantity if quantity.startswith(p + "_")
                               and quantity[len(p) + 1:] in model.kinematics.poses), None)
                if prefix is None and quantity in NEEDS_INVERSE_MASS:
                    raise DeriveError(f"robot '{robot.name}': bundle '{bundle.name}' holds {quantity}, which is not "
                                      "generated: M(q) is singular (a coordinate moves no mass or inertia)")
                if prefix is None:  # the description checked the names; a whole-robot function absent here
                    raise ValueError(f"bundle '{bundle.name}': no generated function '{quantity}' for robot '{robot.name}'")
                ins, expression = frame_inputs[prefix], frame_quantity[prefix](quantity[len(prefix) + 1:])
                parts.append({"output": quantity, "quantity": prefix, "frame": quantity[len(prefix) + 1:]})
            inputs.update(ins)
            outputs.append((quantity, expression))
        listed = ", ".join(f"{name} ({'x'.join(map(str, e.shape)) if e.shape[1] > 1 else e.shape[0]})"
                           for name, e in outputs)
        add("bundle", bundle.name, [(k, inputs[k]) for k in order if k in inputs], outputs,
            f"Control tick '{bundle.name}': {listed} in one pass that computes every shared transform, sine and "
            "cosine once; each output equals the generated function of its name.",
            manifest=(("bundle", parts),))


def regressor_specs(model: SXModel, add) -> None:
    """``regressor`` (Y, every standard parameter) and ``base_regressor`` (Y_b, its base columns), with pi's
    names and values and the base parameters' combinations in the manifest."""
    robot, n = model.robot, model.robot.nv
    s = model.sym
    q, qd, qdd = ("q", s.q), ("qd", s.qd), ("qdd", s.qdd)
    reg = Regressor(model.newton_euler)
    pi = reg.values()
    at = " (numbers at the parameters' defaults)" if s.p.numel() else ""
    bodies = ", ".join(body_links(robot))
    add("regressor", None, [q, qd, qdd], [("Y", reg.matrix)],
        f"Inertial-parameter regressor Y(q, qd, qdd) ({n}x{reg.size}, row-major): inverse_dynamics = Y pi, "
        f"pi = per body ({bodies}) [m, m c_x, m c_y, m c_z, I_xx, I_xy, I_yy, I_xz, I_yz, I_zz] (first moment and "
        "inertia about the body origin, body axes: Pinocchio's toDynamicParameters), then per joint coordinate "
        "[armature, viscous, coulomb] (columns qdd, qd, sign(qd)); pi's names and the model's values in "
        f"manifest.json (regressor_parameters){at}.",
        manifest=(("regressor_parameters", [{"name": k, "value": float(v)} for k, v in zip(reg.names, pi)]),))
    base = base_parameters(robot, regressor=reg)
    add("base_regressor", None, [q, qd, qdd], [("Y_b", reg.matrix[:, list(base.columns)])],
        f"Base regressor Y_b(q, qd, qdd) ({n}x{base.rank}, row-major): the {base.rank} independent columns of "
        "regressor, so that inverse_dynamics = Y_b pi_b with the base parameters pi_b = pi_1 + beta pi_2 (the "
        "parameters of those columns plus the others regrouped into them, Gautier's QR); names, values, "
        f"columns and combinations in manifest.json (base_parameters){at}.",
        manifest=(("rank", base.rank), ("base_parameters", base.manifest(pi))))


def template_parameter(model: SXModel) -> tuple:
    """A template function's last input where the robot has parameters, ``(("p", (np, 1)),)``, else ``()``."""
    np_ = model.sym.p.numel()
    return (("p", (np_, 1)),) if np_ else ()


def template_functions(model: SXModel, forward: bool = True) -> list[TemplateFunction]:
    """Functions built from templates on top of the expression functions, in a fixed order; without
    ``forward`` (M(q) singular, see :func:`function_specs`) those that call the forward dynamics are left out."""
    robot = model.robot
    n = robot.nq + robot.nv
    extra = template_parameter(model)
    rk4 = TemplateFunction(
        robot.name, "rk4_step", None,
        (("x", (n, 1)), ("u", (robot.nv, 1)), ("dt", (1, 1))) + extra, (("x_next", (n, 1)),),
        "One classical Runge-Kutta step of x' = f(x, u) with u held constant over dt: "
        "x_next = x + dt/6 (k1 + 2 k2 + 2 k3 + k4), k_i from ode_rhs" + (
            "; then the base quaternion x_next[3:7] is divided by its norm (projected back onto the unit sphere)."
            if robot.floating else "."),
        "rk4_step", calls=(("ode", "ode_rhs"),), context=(("n", n), ("quaternion", 3 if robot.floating else -1)))
    if robot.closed:  # the closed chain's RK4 in x = (y, yd): the closure inside ode_rhs, nothing drifts
        ny = len(robot.independent)
        return [TemplateFunction(
            robot.name, "rk4_step", None, (("x", (2 * ny, 1)), ("u", (ny, 1)), ("dt", (1, 1))) + extra,
            (("x_next", (2 * ny, 1)),),
            "One classical Runge-Kutta step of the closed chain's x' = f(x, u), x = [y; yd], u = tau_y held "
            "constant over dt: x_next = x + dt/6 (k1 + 2 k2 + 2 k3 + k4), k_i from ode_rhs (q = gamma(y) inside "
            "each: the loops stay closed, nothing drifts).",
            "rk4_step", calls=(("ode", "ode_rhs"),), context=(("n", 2 * ny), ("quaternion", -1)),
            manifest=(("coordinates", "y"),))] if forward else []
    manipulability = [t for f in robot.function_frames if (t := manipulability_function(model, f))]
    dynamics = ode_jacobian_templates(model) + [rk4] if forward else []
    return dynamics + ik_functions(model) + manipulability


def ode_jacobian_templates(model: SXModel) -> list[TemplateFunction]:
    """``ode_jac_x`` and ``ode_jac_u`` as loops around calls, where :func:`ode_by_template`: A = [[0, I],
    -M^-1 dID/dx] at qdd = forward_dynamics(q, qd, u) with dID/dx from inverse_dynamics_derivatives, and
    B = [[0], M^-1]; M from mass_matrix is factored M = L^T D L along the tree (Featherstone's LTDL, no
    fill-in; ``parents`` the coordinates' parents) and the right-hand sides solved row by row. The
    backends' ``ltdl`` support holds the factor and the solve; both write only into the output, the
    rows of A and B that are zeros and ones serving as the factor's scratch until they are filled."""
    if not ode_by_template(model):
        return []
    robot = model.robot
    n = robot.nv
    parents = model.newton_euler.dof_parents or tuple(range(-1, n - 1))
    extra = template_parameter(model)
    inputs = (("x", (2 * n, 1)), ("u", (n, 1))) + extra
    context = (("n", n), ("parents", parents))
    solve = "M = L^T D L along the tree (LTDL) and its solve in loops"
    return [
        TemplateFunction(robot.name, "ode_jac_x", None, inputs, (("A", (2 * n, 2 * n)),),
                         ODE_JAC_DOC["ode_jac_x"].format(nx=2 * n), "ode_jac_x",
                         calls=(("fd", "forward_dynamics"), ("did", "inverse_dynamics_derivatives"), ("mass", "mass_matrix")),
                         context=context, support=("ltdl",),
                         manifest=(("algorithm", "-M^-1 dID/dx at qdd = FD: calls forward_dynamics, "
                                                 f"inverse_dynamics_derivatives and mass_matrix, then {solve}"),)),
        TemplateFunction(robot.name, "ode_jac_u", None, inputs, (("B", (2 * n, n)),),
                         ODE_JAC_DOC["ode_jac_u"].format(nx=2 * n, n=n), "ode_jac_u",
                         calls=(("mass", "mass_matrix"),), context=context, support=("ltdl",),
                         manifest=(("algorithm", f"M^-1: calls mass_matrix, then {solve}"),))]


def ik_functions(model: SXModel) -> list[TemplateFunction]:
    """``<robot>_ik_<frame>``: the same Levenberg-Marquardt as :mod:`derive.solvers.ik` (method "lm")
    with a fixed iteration cap, a fixed restart sequence (xorshift32) and the limits as constants;
    no allocation. The algorithm is each backend's fixed ``ik`` support file."""
    robot = model.robot
    lo, hi, slo, shi = joint_ranges(robot)
    n = model.sym.nv
    extra = template_parameter(model)
    out = []
    for frame in IK_FRAMES if not robot.floating else ():  # IK moves joints; a floating base has no limits to keep
        if frame not in robot.function_frames or not model.kinematics.ancestors[frame]:
            continue
        context = {"n": n, "frame": frame, "max_iterations": IK_MAX_ITERATIONS, "attempt": ATTEMPT,
                   "tol_position": TOL_POSITION, "tol_rotation": TOL_ROTATION, "lambda0": LAMBDA0,
                   "lambda_min": LAMBDA_MIN, "lambda_min_float": IK_LAMBDA_MIN_FLOAT, "lambda_stall": LAMBDA_STALL}
        for key, values in (("lower", lo), ("upper", hi), ("sample_lower", slo), ("sample_upper", shi)):
            context[key] = tuple(float(np.clip(v, -IK_LIMIT, IK_LIMIT)) for v in values)
        context["wrap"] = robot.continuous_indices  # entries of q returned wrapped to (-pi, pi]
        out.append(TemplateFunction(
            robot.name, "ik", frame,
            (("T", (4, 4)), ("q0", (n, 1)), ("w", (6, 1))) + extra, (("q", (n, 1)), ("residual", (2, 1))),
            f"Inverse kinematics of frame '{frame}': q within the joint limits with world_T_{frame}(q) = T "
            f"(4x4), Levenberg-Marquardt on e = [p_T - p; log(R_T R^T)] weighted by w (6; position only: "
            f"1 1 1 0 0 0) with seeded restarts, at most {IK_MAX_ITERATIONS} iterations. residual = "
            f"[position error (m), rotation error (rad)] of the weighted rows; success when below "
            f"{TOL_POSITION:g} m and {TOL_ROTATION:g} rad." + (
                f" The angles of the continuous joints ({', '.join(robot.coordinates[i].name for i in robot.continuous_indices)}) "
                "are returned wrapped to (-pi, pi]." if robot.continuous_indices else ""),
            "ik", calls=(("fkj", f"fk_jacobian_{frame}"),), context=tuple(context.items()),
            support=("ik",), optional=("q0", "w"), status=True))
    return out


def manipulability_function(model: SXModel, frame: str) -> TemplateFunction | None:
    """The generated ``<robot>_manipulability_<frame>``, or None when the frame's position never
    moves (a frame fixed to the base) or cannot span its task (nv < k)."""
    robot = model.robot
    rows = tuple(r for r in POSITION_ROWS if r in model.kinematics.moving_rows(frame))
    if not rows or robot.nv < len(rows):
        return None
    k = len(rows)
    row_names = ",".join("xyz"[r] for r in rows)
    doc = (f"Manipulability of frame '{frame}' (lecture eq. 30) for its position rows with motion "
           f"({row_names}): mu = [mu1, mu2, mu3], mu1 = sqrt(lmax/lmin), mu2 = lmax/lmin, "
           f"mu3 = sqrt(det(J J^T)) (Yoshikawa; = sqrt(lmax lmin) for k = 2), l_i the eigenvalues of J J^T "
           f"with J the {k}x{robot.nv} task rows of jacobian_{frame}; mu1 = mu2 = inf at a singularity.")
    return TemplateFunction(
        robot.name, "manipulability", frame, (("q", (robot.nq, 1)),) + template_parameter(model), (("mu", (3, 1)),), doc,
        "manipulability", calls=(("jacobian", f"jacobian_{frame}"),),
        context=(("k", k), ("nv", robot.nv), ("rows", rows),
                 ("jacobian_size", 6 * robot.nv), ("task_size", k * robot.nv)),  # work buffers (reals)
        support=("manipulability",), manifest=(("task_rows", rows),))


CALLS = {"ik": ("fk_jacobian",), "rk4_step": ("ode_rhs",), "manipulability": ("jacobian",),
         "ode_jac_x": ("forward_dynamics", "inverse_dynamics_derivatives", "mass_matrix"), "ode_jac_u": ("mass_matrix",)}
"""The quantities a template function of each quantity may call: derived along with it under a
selection (:func:`selected` then keeps exactly the functions called)."""


def wanted(robot: Robot):
    """``need(*quantities)``: whether any of them is to be derived: always where
    :attr:`~derive.description.robot.Robot.function_quantities` is None (no ``generate: {quantities:
    [...]}``, at most BIG_NV velocities), else those chosen and what their templates call (:data:`CALLS`)."""
    chosen = robot.function_quantities
    if chosen is None:
        return lambda *quantities: True
    derived = set(chosen) | {c for q in chosen for c in CALLS.get(q, ())}
    return lambda *quantities: any(q in derived for q in quantities)


def selected(robot: Robot, specs: list[FunctionSpec], templates: list[TemplateFunction]
             ) -> tuple[list[FunctionSpec], list[TemplateFunction]]:
    """The functions of models.yaml's ``generate: {quantities: [...]}`` (all without it), in the
    catalogue's order: those of the quantities listed, plus the expression functions the kept
    template functions call (ik_tcp keeps fk_jacobian_tcp, rk4_step ode_rhs); a big robot's lean
    default likewise (:attr:`~derive.description.robot.Robot.function_quantities`)."""
    wanted = robot.function_quantities
    if wanted is None:
        return specs, templates
    templates = [t for t in templates if t.quantity in wanted]
    called = {short for t in templates for short in t.callees}
    missing = called - {s.short_name for s in specs}
    if missing:  # CALLS lacks an entry: a template would call a function that was not derived
        raise DeriveError(f"robot '{robot.name}': internal: {', '.join(sorted(missing))} called but not derived (CALLS)")
    return [s for s in specs if s.quantity in wanted or s.short_name in called], templates
