"""Specs -> files: every backend's sources plus one language-free manifest.json per robot.

Emitting is a pure function of the spec list and the backends: each expression spec
becomes a Program (CasADi CSE, SSA temporaries), each backend's printer turns it into
(lhs, rhs) pairs, and jinja2 templates lay them out. Nothing here knows mechanics or
any one language. Algorithms that are not one expression graph (IK's solver, the
singular values) are fixed support files of each backend, copied verbatim into each
robot's output (listed under "support" in its manifest.json); templates only lay out
the calls.
"""

from __future__ import annotations

import functools
import json

import jinja2

from derive.codegen.backends import backends as registered_backends
from derive.codegen.backends.base import Backend, Function, RobotContext, ops_comment, shape_text
from derive.codegen.catalogue import CLOSED_LEFT_OUT
from derive.codegen.program import build_program
from derive.codegen.spec import FunctionSpec, TemplateFunction
from derive.description.robot import Robot
from derive.description.expr import evaluate
from derive.resources import TEMPLATES

SHARED_TEMPLATES = ("manifest", "latex")
"""Language-free template folders of templates/: the manifest and the LaTeX document."""


def environment(backends: list[Backend] | None = None) -> jinja2.Environment:
    """The one jinja2 environment: templates are named ``<folder>/<file>`` (``c/function.c.jinja``).
    One per set of template folders, kept for the process: jinja2 compiles each template once in an
    environment (and recompiles one whose file changed), and a robot's templates took a fifth of
    rendering it when each robot had its own."""
    folders = {name: str(TEMPLATES / name) for name in SHARED_TEMPLATES}
    for b in registered_backends() if backends is None else backends:
        folders[b.name] = str(b.templates)
    return _environment(tuple(folders.items()))


@functools.lru_cache(maxsize=16)
def _environment(folders: tuple[tuple[str, str], ...]) -> jinja2.Environment:
    return jinja2.Environment(
        loader=jinja2.PrefixLoader({name: jinja2.FileSystemLoader(path) for name, path in folders}, delimiter="/"),
        undefined=jinja2.StrictUndefined,
        trim_blocks=True,
        lstrip_blocks=True,
        keep_trailing_newline=True,
        autoescape=False,
    )


def _io_lines(inputs, outputs) -> list[str]:
    return [f"in  {n} [{shape_text(s)}]" for n, s in inputs] + [f"out {n} [{shape_text(s)}]" for n, s in outputs]


def expression_function(spec: FunctionSpec, progress=None) -> Function:
    """An expression spec with its SSA program and language-free context."""
    prog = build_program(list(spec.inputs), list(spec.outputs))
    if progress:
        progress(spec, prog)
    ops = prog.ops()
    inputs = [(n, x.shape) for n, x in spec.inputs]
    outputs = [(n, e.shape) for n, e in spec.outputs]
    return Function(spec, prog, {
        "name": spec.name, "short_name": spec.short_name, "quantity": spec.quantity, "frame": spec.frame,
        "doc_lines": [spec.doc], "io_lines": _io_lines(inputs, outputs), "ops": ops, "ops_comment": ops_comment(ops),
        "calls": [], "manifest": spec.manifest,
        "inputs": [{"name": n, "shape": list(s)} for n, s in inputs],
        "outputs": [{"name": n, "shape": list(s)} for n, s in outputs]})


def template_function(t: TemplateFunction) -> Function:
    """A template-bodied function with its language-free context."""
    calls = [f"{t.robot}_{short}" for short in t.callees]
    return Function(t, None, {
        "name": t.name, "short_name": t.short_name, "quantity": t.quantity, "frame": t.frame,
        "doc_lines": [t.doc], "io_lines": _io_lines(t.inputs, t.outputs), "ops": None,
        "ops_comment": f"cost: the arithmetic of {', '.join(calls)} per call, plus loops" if calls else "cost: loops",
        "calls": calls, "manifest": t.manifest,
        "inputs": [{"name": n, "shape": list(s)} for n, s in t.inputs],
        "outputs": [{"name": n, "shape": list(s)} for n, s in t.outputs]})


CONVENTIONS = {
    "jacobian": "6 x nv, rows [linear; angular], world-aligned at the frame origin (Pinocchio LOCAL_WORLD_ALIGNED)",
    "frame_acceleration": "[classical linear; angular] acceleration of the frame origin, world-aligned, without "
                          "gravity (Pinocchio getFrameClassicalAcceleration, LOCAL_WORLD_ALIGNED); jdot_qd at qdd = 0",
    "wrenches": "w = [force; torque] at each wrench frame's origin, world-aligned, 6 per frame in wrench_frames "
                "order; tau = ID - sum J_f^T w_f",
    "com": "centre of mass of the moving bodies (a fixed base's root link is the world and does not count); "
           "centroidal_map A_G: A_G qd = [linear; angular] momentum about the CoM, world axes",
    "matrices": "row-major",
}
FLOATING_CONVENTION = ("q = [base position (3, world); base orientation quaternion (x, y, z, w); joints], "
                       "qd = [base linear velocity (3); base angular velocity (3); joint rates], both in the base "
                       "frame; tau[0:6] = [force; torque] on the base at its origin, base frame (Pinocchio "
                       "JointModelFreeFlyer); rk4_step renormalises the quaternion after each step")


ACTUATOR_CONVENTION = ("M includes the armature (reflected rotor inertia armature + gear_ratio^2 motor_inertia) on its "
                       "diagonal; inverse_dynamics adds viscous qd + coulomb sign(qd); forward_dynamics, the ODE and its "
                       "Jacobians subtract viscous qd + coulomb tanh(qd / coulomb_smoothing); a mimic joint's own "
                       "actuator is in its leader's entry (a^2 armature and viscous, |a| coulomb, a its multiplier)")


CONTINUOUS_CONVENTION = ("continuous joints ({names}): unbounded revolute joints, one angle each in q (q and q + 2 pi "
                        "are one configuration); every function takes any angle; ik_<frame> returns them wrapped to "
                        "(-pi, pi] (fmod, exact), as do derive ik and the CSVs of derive simulate and trajopt")


def actuator_table(robot: Robot) -> dict:
    """Per entry of v, the actuator values at the parameter defaults (a floating base's six are 0)."""
    env = robot.parameter_defaults
    nb = robot.nv - len(robot.joint_coordinates)

    def num(v) -> float:
        return float(evaluate(v, env))

    acts = [c.actuator for c in robot.joint_coordinates]
    table = {"coulomb_smoothing": robot.smoothing,
             "armature": [0.0] * nb + [num(a.armature) + num(a.gear_ratio) ** 2 * num(a.motor_inertia) for a in acts],
             "viscous": [0.0] * nb + [num(a.viscous) for a in acts],
             "coulomb": [0.0] * nb + [num(a.coulomb) for a in acts]}
    # a mimic joint's own actuator acts on its leader's entry through G: a^2 armature and viscous, |a| coulomb
    column = {c.name: nb + i for i, c in enumerate(robot.joint_coordinates)}
    for joint, a in robot.mimic_actuators:
        k, m = column[joint.mimic.joint], float(joint.mimic.multiplier)
        table["armature"][k] += m * m * (num(a.armature) + num(a.gear_ratio) ** 2 * num(a.motor_inertia))
        table["viscous"][k] += m * m * num(a.viscous)
        table["coulomb"][k] += abs(m) * num(a.coulomb)
    return table


def closed_chain_entry(robot: Robot, functions: list[Function]) -> dict:
    """manifest.json's ``loops`` (each loop's two frames with their generated fk_<frame>, kind, axis or
    length, and the coordinates of its cycle) and ``closed_chain`` (y, z, the closure, what is left out)."""
    generated = {fn.common["name"] for fn in functions}
    closure = next((dict(fn.common["manifest"]).get("closure") for fn in functions
                    if fn.common["quantity"] == "closure"), None)

    def fk(frame: str) -> str | None:
        name = f"{robot.name}_fk_{frame}"
        return name if name in generated else None

    loops = []
    for lp in robot.loops:
        entry = {"frames": [{"name": lp.a, "fk": fk(lp.a)}, {"name": lp.b, "fk": fk(lp.b)}], "kind": lp.kind,
                 "rows": lp.rows}
        if lp.kind in ("hinge", "planar"):
            entry["normal" if lp.kind == "planar" else "axis"] = [float(x) for x in lp.axis]
        if lp.kind == "planar":
            entry["rotation"] = lp.rotation
        if lp.kind == "distance":
            entry["length"] = lp.length if isinstance(lp.length, str) else float(lp.length)
        loops.append(entry)
    out = {"loops": loops, "closed_chain": {
        "independent": list(robot.independent), "dependent": list(robot.dependent),
        "reference_y": [float(robot.reference_q[[c.name for c in robot.coordinates].index(c)]) for c in robot.independent],
        "independent_chosen": "by pivoting on K" if robot.independent_chosen else "models.yaml's independent",
        "kept_rows": list(robot.loop_rows), "closure": closure,
        "coordinates": "functions marked coordinates 'q' are the spanning tree's, in q = (y, z) (the loops not "
                       "imposed); those marked 'y' are the closed chain's, in y with q = gamma(y) inside",
        "left_out": sorted(CLOSED_LEFT_OUT),
        "left_out_reason": "the tree's forward dynamics, ODE and their derivatives ignore the loops; the tree's "
                           "regressors, IK, manipulability, centroidal map, external wrenches and control bundles "
                           "are not generated for a closed chain (its own versions are not available yet)"}}
    if robot.outputs:  # models.yaml's outputs: the motor <-> joint maps
        names = [c.name for c in robot.coordinates]
        method = next((dict(fn.common["manifest"]).get("closure") for fn in functions
                       if fn.common["quantity"] == "joint_to_motor_position"), None)
        out["closed_chain"]["motor_joint_maps"] = {
            "motors": list(robot.independent), "joints": list(robot.outputs),
            "reference_joints": [float(robot.reference_q[names.index(c)]) for c in robot.outputs],
            "joint_to_motor": method,
            "coordinates": "motor_to_joint_* take y (the motors, coordinates 'y'); joint_to_motor_* take o (the "
                           "joints, coordinates 'outputs'); J = d o / d y: od = J yd, tau_y = J^T tau_o"}
    return out


def function_aliases(robot: Robot, functions: list[tuple[str, str | None]]) -> tuple[tuple[str, str], ...]:
    """(alias, function) short names, e.g. ``("fk_tool_frame", "fk_tcp")``: per generated function
    ``<quantity>_<frame>`` of a named frame with aliases, one per alias. One set of functions, the
    other names spelled as references to it (a C #define, a Python name bound to the same function)."""
    named = {f.name: f.aliases for f in robot.frames if f.aliases}
    return tuple((f"{quantity}_{alias}", f"{quantity}_{frame}") for quantity, frame in functions
                 if quantity != "bundle" and frame in named for alias in named[frame])


def render_robot(robot: Robot, specs: list[FunctionSpec], model_hash: str, progress=None,
                 templates: list[TemplateFunction] = (), backends: list[Backend] | None = None,
                 left_out: dict | None = None) -> dict[str, str]:
    """All files of one robot, as {path relative to generated/<robot>/: text}.

    ``left_out``: the functions of the robot's set that were not generated and why (plain data,
    ``{"functions": [...], "coordinates": [...], "reason": "..."}``), recorded in manifest.json."""
    backends = registered_backends() if backends is None else backends
    env = environment(backends)
    functions = [expression_function(s, progress) for s in specs] + [template_function(t) for t in templates]
    aliases = function_aliases(robot, [(fn.common["quantity"], fn.common["frame"]) for fn in functions])
    ctx = RobotContext(robot.name, model_hash, [c.name for c in robot.coordinates], robot.nq, robot.nv,
                       [(p.name, p.default) for p in robot.parameters],
                       tuple(n[len(robot.name) + 1:] for n in (left_out or {}).get("functions", ())),
                       (left_out or {}).get("reason", ""), aliases)
    files: dict[str, str] = {}
    continuous = [robot.coordinates[i].name for i in robot.continuous_indices]
    per_backend = {}
    for b in backends:
        contexts = [b.function_context(fn) if fn.program is not None else b.template_context(fn) for fn in functions]
        per_backend[b.name] = contexts
        files.update(b.render(env, ctx, contexts))
    manifest = {
        "robot": robot.name,
        "model_hash": model_hash,
        "nq": robot.nq,
        "nv": robot.nv,
        "base": robot.base,
        "velocities": list(robot.velocity_names),
        "wrench_frames": list(robot.wrench_frames),
        "conventions": CONVENTIONS | ({"floating_base": FLOATING_CONVENTION} if robot.floating else {})
        | ({"actuators": ACTUATOR_CONVENTION} if robot.actuated else {})
        | ({"continuous_joints": CONTINUOUS_CONVENTION.format(names=", ".join(continuous))} if continuous else {}),
        **({"actuators": actuator_table(robot)} if robot.actuated else {}),
        **({"continuous": continuous} if continuous else {}),
        "joints": [{"name": j.name, "type": j.type, "lower": j.limits.lower, "upper": j.limits.upper,
                    "velocity": j.limits.velocity, "effort": j.limits.effort} for j in robot.coordinates],
        "frames": list(robot.function_frames),
        **({"selection": robot.selection} if robot.selection else {}),
        **({"aliases": robot.frame_aliases} if robot.frame_aliases else {}),
        "parameters": [{"name": p.name, "default": p.default} for p in robot.parameters],
        "support": [entry for b in backends for entry in b.manifest_support(ctx, per_backend[b.name])],
        "functions": [{
            "name": fn.common["name"], "quantity": fn.common["quantity"], "frame": fn.common["frame"],
            "inputs": fn.common["inputs"], "outputs": fn.common["outputs"],
            **{b.name: b.manifest_entry(ctx, per_backend[b.name][k]) for b in backends},
            "ops": {k: fn.common["ops"][k] for k in ("total", "mul", "add", "div", "trig")} if fn.common["ops"] else None,
            "calls": fn.common["calls"],
            **dict(fn.common["manifest"]),
        } for k, fn in enumerate(functions)],
        **({"left_out": left_out} if left_out else {}),
        **(closed_chain_entry(robot, functions) if robot.closed else {}),
    }
    files["manifest.json"] = env.get_template("manifest/manifest.json.jinja").render(
        manifest_json=json.dumps(manifest, indent=2))
    return files
