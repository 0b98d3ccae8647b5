"""``derive export-casadi ROBOT [--out DIR] [--functions NAME ...]``: a robot's generated functions as serialised
CasADi Functions (:mod:`derive.codegen.casadi_export`), what acados and CasADi-based MPC load."""

from __future__ import annotations

import sys
from pathlib import Path

from derive.cli.common import path_arg
from derive.codegen.casadi_export import export_casadi
from derive.description.model import load_robot


def cmd_export_casadi(args) -> int:
    robot = load_robot(args.robot_name, args.models)
    out = Path(args.out) if args.out else Path("casadi") / robot.name
    written, skipped = export_casadi(robot, out, args.functions)
    if skipped:
        print(f"note: robot '{robot.name}': not exported (loops, no CasADi expression): {', '.join(skipped)}",
              file=sys.stderr)
    print(f"wrote {len(written)} CasADi function(s) to {out}/ (casadi.Function.load reads each)", file=sys.stderr)
    return 0


def add_parser(sub) -> None:
    c = sub.add_parser("export-casadi", help="write a robot's generated functions as serialised CasADi Functions",
                       description="Write each generated expression function of a robot (and rk4_step) as a "
                                   "serialised casadi.Function, <name>.casadi, what acados and CasADi-based MPC "
                                   "load with casadi.Function.load: same inputs and outputs as the generated code "
                                   "(matrices as matrices). models.yaml's generate: {quantities: ...} selects as "
                                   "for generate.")
    c.add_argument("robot_name", metavar="ROBOT")
    c.add_argument("--out", metavar="DIR", type=path_arg, help="folder to write into (default: casadi/ROBOT)")
    c.add_argument("--functions", metavar="NAME", nargs="+", help="only these (e.g. contact_dynamics_stance; "
                                                                   "the robot's prefix may be left off)")
    c.set_defaults(func=cmd_export_casadi)
