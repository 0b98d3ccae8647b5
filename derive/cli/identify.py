"""Identification commands: ``derive identify ROBOT DATA.csv`` and ``derive excite ROBOT``.

    derive base-parameters panda [--latex]    the identifiable combinations (ZZR_panda_link1 = Izz_... + ...)
    derive excite panda                       optimised excitation: excite_out/panda/excitation.csv and .png
    derive identify panda data.csv            base parameters, std devs, residuals; panda_identified.yaml
    derive --models panda_identified.yaml generate      the identified robot's code
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import casadi as ca
import numpy as np

from derive.cli.common import path_arg
from derive.description.files import load_yaml, read_text
from derive.description.model import default_models_path, load_robot, parse_models, parse_robot
from derive.description.robot import robot_name
from derive.description.urdf import dump_entry
from derive.errors import DeriveError
from derive.filesystem import write_atomically
from derive.plot.excite import render_excitation
from derive.solvers.excite import check_options, excite
from derive.solvers.identify import (closed_regressor_along, identified_entry, identify_file, open_measurements,
                                     regressor_along, scan_measurements)
from derive.symbolic.base_parameters import base_parameters
from derive.symbolic.closed_regressor import closed_regressor
from derive.symbolic.dynamics import NewtonEuler
from derive.symbolic.regressor import Regressor
from derive.symbolic.symbols import make_symbols


def add_parser(sub) -> None:
    i = sub.add_parser("identify", help="identify the base dynamic parameters from measured q, (qd, qdd,) tau",
                       description="Weighted least squares of the base parameters (Gautier's numerical QR) on a CSV "
                                   "with columns t, q_<c>..., [qd_<c>..., qdd_<c>...,] tau_<c>... (simulate's, trajopt's and "
                                   "excite's CSV; missing qd and qdd are filtered and differentiated from q). Prints "
                                   "each base parameter with its standard deviation, the condition number and the "
                                   "torque residual per joint, and writes the robot with the identified values as a "
                                   "models file that `derive --models FILE generate` uses.")
    i.add_argument("robot_name", metavar="ROBOT")
    i.add_argument("data", metavar="DATA.csv", type=path_arg)
    i.add_argument("--physical", action="store_true",
                   help="physically consistent standard parameters (pseudo-inertia LMI per body, actuators >= 0)")
    i.add_argument("--out", metavar="MODELS", type=path_arg,
                   help="models file to write (default ./<robot>_identified.yaml)")
    i.add_argument("--name", help="name of the identified robot (default <robot>_identified)")
    i.set_defaults(func=cmd_identify)

    b = sub.add_parser("base-parameters", help="the identifiable combinations of a robot's dynamic parameters",
                       description="Gautier's numerical QR on the regressor stacked at seeded random states: each base "
                                   "parameter as a linear combination of the standard ones (10 per body, then armature, "
                                   "viscous and Coulomb friction per coordinate), with its value at the model's "
                                   "parameters; --latex prints an align* environment for papers.")
    b.add_argument("robot_name", metavar="ROBOT")
    b.add_argument("--latex", action="store_true", help="LaTeX (align*) instead of text")
    b.set_defaults(func=cmd_base_parameters)

    e = sub.add_parser("excite", help="an excitation trajectory for identification (Fourier series, min cond)",
                       description="A periodic finite Fourier series per coordinate whose coefficients minimise the "
                                   "condition number of the stacked base regressor within the position, velocity, "
                                   "acceleration (2x the velocity limit per s) and effort limits; writes the CSV a "
                                   "controller can play (t, q, qd, qdd, tau) and a plot.")
    e.add_argument("robot_name", metavar="ROBOT")
    e.add_argument("--period", type=float, default=10.0, help="period T in s (default 10)")
    e.add_argument("--harmonics", type=int, default=5, help="Fourier harmonics per coordinate (default 5)")
    e.add_argument("--samples", type=int, default=100, help="samples of one period in the objective (default 100)")
    e.add_argument("--seed", type=int, default=0, help="seed of the random start (default 0)")
    e.add_argument("--iterations", type=int, default=200, help="SLSQP iterations at most (default 200)")
    e.add_argument("--out", type=path_arg, help="output folder (default ./excite_out/<robot>/)")
    e.set_defaults(func=cmd_excite)


def regressor_of(robot) -> tuple[Regressor, object]:
    """The symbolic regressor of ``robot`` and its base parameters (their near-dependencies, if any, as one
    warning line on stderr); a closed chain's are those of its Y_y (:mod:`derive.symbolic.closed_regressor`)."""
    return identification_model(robot)[:2]


def identification_model(robot) -> tuple[Regressor, object, object]:
    """:func:`regressor_of` and the regressor along samples (:func:`~derive.solvers.identify.regressor_along`):
    of (q, qd, qdd) for a tree, of (y, yd, ydd) for a closed chain."""
    if robot.closed:
        cr, red, bp = closed_regressor(robot)
        reg, along = cr.reg, lambda: closed_regressor_along(cr, red, robot)
    else:
        reg = Regressor(NewtonEuler(robot, make_symbols(robot)))
        bp = base_parameters(robot, regressor=reg)
        along = lambda: regressor_along(reg, robot)  # noqa: E731
    if bp.near:
        print(f"warning: robot '{robot.name}': {bp.near_text()}", file=sys.stderr)
    return reg, bp, along


def cmd_base_parameters(args) -> int:
    robot = load_robot(args.robot_name, args.models)
    reg, bp = regressor_of(robot)
    if args.latex:
        sys.stdout.write(bp.latex())
        return 0
    values = bp.K @ np.asarray(reg.values(), dtype=float)
    print(f"{robot.name}: {len(bp.names)} base parameters of {len(reg.names)} standard ones"
          + (f" (the closed chain's, in y = {', '.join(robot.independent)})" if robot.closed else "")
          + (f" (never identifiable: {', '.join(bp.unidentifiable)})" if bp.unidentifiable else ""))
    for equation, value in zip(bp.equations(), values):
        print(f"  {equation}    [{value:.6g}]")
    return 0


def _output_path(out: Path, command: str, what: str) -> Path:
    """Refuse, before the work, an output path that cannot be written: a folder, or below a file."""
    if out.is_dir():
        raise DeriveError(f"{command}: {out}: is a folder; --out names the {what} to write")
    for parent in out.parents:
        if parent.exists():
            if not parent.is_dir():
                raise DeriveError(f"{command}: {out}: {parent} is not a folder")
            break
    return out


def _same_file(a: Path, b: Path) -> bool:
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def cmd_identify(args) -> int:
    robot = load_robot(args.robot_name, args.models)
    if robot.floating:
        raise DeriveError(f"identify {robot.name}: floating bases are not supported by the CSV reader yet")
    source_path = Path(args.models) if args.models else default_models_path()
    models = load_yaml(read_text(source_path, "models file"), f"models file {source_path}")
    raw = models.get("robots") if isinstance(models, dict) else None
    raw = raw.get(robot.name) if isinstance(raw, dict) else None
    if not isinstance(raw, dict):  # load_robot read it a moment ago
        raise DeriveError(f"identify {robot.name}: {source_path} changed while it was read: run again")
    name = robot_name(args.name) if args.name is not None else f"{robot.name}_identified"
    out = _output_path(Path(args.out) if args.out else Path(f"{robot.name}_identified.yaml"), "identify",
                       "models file")
    if _same_file(out, Path(args.data)):
        raise DeriveError(f"identify: --out {out} is the data file {args.data}: choose another --out")
    if _same_file(out, source_path):
        raise DeriveError(f"identify: --out {out} is the models file {source_path} that holds {robot.name} (its "
                          "other robots would be lost): choose another --out")
    log = lambda m: print(m, file=sys.stderr, flush=True)  # noqa: E731
    coordinates = list(robot.independent if robot.closed else robot.velocity_names)  # a closed chain's data is in y
    mf = open_measurements(args.data, coordinates)
    if mf.derives:
        scan_measurements(mf, log)
    reg, bp, along = identification_model(robot)
    pi0 = np.asarray(reg.values(), dtype=float)
    result = identify_file(along(), bp, pi0, mf, physical=args.physical, bodies=len(reg.bodies), log=log,
                           closed=robot.closed)
    print(result.report(coordinates))
    shown = " ".join(str(args.data).replace("`", "'").split())  # the entry's source and comments: one line each
    command = f"derive identify {robot.name} {shown}" + (" --physical" if args.physical else "")
    entry = identified_entry(raw, robot, list(reg.names), result.standard, f"{shown}, identified by `{command}`")
    try:
        parse_robot(name, entry)
    except DeriveError as exc:
        fix = "check the data's units" if args.physical else \
            "rerun with --physical (physically consistent values), or check the data's units"
        raise DeriveError(f"identify {robot.name}: {args.data}: the standard parameters reproducing the identified "
                          f"base parameters do not make a valid model ({exc}); {fix}") from None
    text = "robots:\n" + dump_entry(name, entry, generator="derive identify")
    if name not in parse_models(text, source=str(out)):  # what is written loads back
        raise DeriveError(f"identify {robot.name}: the models file for {out} does not hold robot '{name}'")
    if not out.parent.is_dir():
        try:
            out.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise DeriveError(f"identify: {out.parent}: cannot create the folder ({exc.strerror or exc})") from None
    write_atomically(out, text, "models file")
    print(f"wrote {out} (robot '{name}'): derive --models {out} generate")
    return 0


def cmd_excite(args) -> int:
    robot = load_robot(args.robot_name, args.models)
    check_options(robot.name, args.period, args.harmonics, args.samples, args.seed, args.iterations)
    robot.require_fixed_base("derive excite")
    if robot.closed:
        raise DeriveError(f"excite {robot.name}: robot '{robot.name}' has loops: excite plans a tree's joints within "
                          "their limits, not a closed chain's y within its assembly (not supported yet); identify reads "
                          "a closed chain's motion in y (docs/closed-chains.md, Identification)")
    out = Path(args.out) if args.out else Path("excite_out") / robot.name
    if out.exists() and not out.is_dir():
        raise DeriveError(f"excite {robot.name}: --out {out} is a file; it names the folder to write "
                          "excitation.csv and excitation.png into")
    _output_path(out / "excitation.csv", f"excite {robot.name}", "folder")
    print(f"deriving the base regressor of {robot.name} ...", file=sys.stderr, flush=True)
    reg, bp = regressor_of(robot)
    s = reg.sym
    p = ca.DM([robot.parameter_defaults[n] for n in s.parameter_names]) if s.p.numel() else None
    Yb = reg.matrix[:, list(bp.columns)]
    tau_id = NewtonEuler(robot, s).inverse_dynamics()
    if p is not None:
        Yb, tau_id = ca.substitute(Yb, s.p, p), ca.substitute(tau_id, s.p, p)
    ex = excite(robot, Yb, s.q, s.qd, s.qdd, tau_id, period=args.period, harmonics=args.harmonics,
                samples=args.samples, seed=args.seed, max_iterations=args.iterations,
                log=lambda m: print(m, file=sys.stderr, flush=True), names=bp.names)
    csv, png = ex.csv(), render_excitation(ex)  # both made before either is written
    if not out.is_dir():
        try:
            out.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise DeriveError(f"excite {robot.name}: {out}: cannot create the folder ({exc.strerror or exc})") from None
    csv_path = write_atomically(out / "excitation.csv", csv, "excitation CSV")
    png_path = write_atomically(out / "excitation.png", png, "excitation plot")
    print(ex.summary())
    print(f"wrote {csv_path} and {png_path}")
    return 0 if ex.limits_ok else 1
