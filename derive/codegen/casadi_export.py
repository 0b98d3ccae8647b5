"""Serialised CasADi Functions of a robot's generated functions: what acados and CasADi-based MPC stacks load.

Each expression function of the catalogue (:func:`~derive.codegen.catalogue.function_specs`, with models.yaml's
``generate: {quantities: ...}`` selection and, where M(q) is singular, without those that need M^-1) becomes one
``casadi.Function`` of the same name, inputs and outputs (names as in manifest.json; matrices as matrices, not
flattened), saved with ``Function.save`` as ``<name>.casadi``; ``casadi.Function.load`` reads it back. rk4_step is
built from ode_rhs (the same four stages and, for a floating base, the quaternion renormalised). The other template
functions (the IK loop, manipulability, the loop forms of ode_jac_x / ode_jac_u) are not expressions and are not
exported; :func:`casadi_functions` names them.

The files are written on request (``derive export-casadi``), not into generated/: the largest (solo12's
contact dynamics derivatives) are megabytes. For the same CasADi version they are byte-identical across runs.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import casadi as ca

from derive.codegen.catalogue import function_specs, selected, template_functions
from derive.codegen.checks import check_mass_matrix
from derive.description.robot import Robot
from derive.errors import DeriveError
from derive.filesystem import write_atomically
from derive.symbolic.model import SXModel

SUFFIX = ".casadi"


def _rk4(robot: Robot, ode: ca.Function) -> ca.Function:
    """x_next = x + dt/6 (k1 + 2 k2 + 2 k3 + k4) with ode_rhs; a floating base's quaternion divided by its norm
    (the generated rk4_step's steps)."""
    n_in = ode.n_in()
    x, u, dt = ca.SX.sym("x", ode.size1_in(0)), ca.SX.sym("u", ode.size1_in(1)), ca.SX.sym("dt")
    extra = [ca.SX.sym(ode.name_in(k), ode.sparsity_in(k)) for k in range(2, n_in)]
    f = lambda xx: ode(xx, u, *extra)  # noqa: E731
    k1 = f(x)
    k2 = f(x + dt / 2 * k1)
    k3 = f(x + dt / 2 * k2)
    k4 = f(x + dt * k3)
    nxt = x + dt / 6 * (k1 + 2 * k2 + 2 * k3 + k4)
    if robot.floating and not robot.closed:
        quat = nxt[3:7]
        nxt = ca.vertcat(nxt[0:3], quat / ca.norm_2(quat), nxt[7:])
    name = ode.name().removesuffix("ode_rhs") + "rk4_step"
    return ca.Function(name, [x, u, dt, *extra], [nxt], ["x", "u", "dt", *[ode.name_in(k) for k in range(2, n_in)]], ["x_next"])


def casadi_functions(robot: Robot, names: list[str] | None = None) -> tuple[list[ca.Function], list[str]]:
    """(the robot's functions as CasADi Functions, the names of the template functions not exported). ``names``:
    only these (full names, ``<robot>_<quantity>[_<frame>]``; the robot's prefix may be left off); an unknown
    one is a DeriveError naming the known ones."""
    model = SXModel(robot)
    forward = not check_mass_matrix(model, strict=False)
    specs, templates = selected(robot, function_specs(model, forward=forward), template_functions(model, forward=forward))
    functions = {}
    for spec in specs:
        outs = ca.cse([ca.densify(e) for _, e in spec.outputs])
        functions[spec.name] = ca.Function(spec.name, [x for _, x in spec.inputs], outs,
                                           [n for n, _ in spec.inputs], [n for n, _ in spec.outputs])
    skipped = []
    for t in templates:
        ode = functions.get(f"{robot.name}_ode_rhs")
        if t.quantity == "rk4_step" and ode is not None:
            functions[t.name] = _rk4(robot, ode)
        else:
            skipped.append(t.name)
    if names is None:
        return list(functions.values()), skipped
    wanted = [n if n in functions or n in skipped else f"{robot.name}_{n}" for n in names]
    for given, name in zip(names, wanted):
        if name in skipped:
            raise DeriveError(f"export-casadi {robot.name}: {given}: a loop (template) function, not an expression; "
                              "it has no CasADi form")
        if name not in functions:
            raise DeriveError(f"export-casadi {robot.name}: unknown function '{given}' (known: "
                              f"{', '.join(functions)})")
    return [functions[n] for n in dict.fromkeys(wanted)], []


def export_casadi(robot: Robot, out: Path, names: list[str] | None = None) -> tuple[list[Path], list[str]]:
    """Write ``out/<name>.casadi`` for each function of :func:`casadi_functions` (each file atomically, all built
    before the first is written); returns (the paths written, the template functions not exported)."""
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise DeriveError(f"{out}: cannot write the CasADi functions (not a folder)")
    functions, skipped = casadi_functions(robot, names)
    blobs = []
    with tempfile.TemporaryDirectory() as tmp:
        for f in functions:
            path = os.path.join(tmp, f.name() + SUFFIX)
            f.save(path)
            blobs.append((out / (f.name() + SUFFIX), Path(path).read_bytes()))
    out.mkdir(parents=True, exist_ok=True)
    return [write_atomically(path, data, "a CasADi function") for path, data in blobs], skipped
