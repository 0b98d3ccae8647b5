"""Commands that solve: ``derive simulate``, ``derive ik`` and ``derive trajopt``.

    derive simulate ROBOT --q0 ...          integrate the generated dynamics: CSV, PNG, energy drift
    derive ik ROBOT --xyz X Y Z [--rpy ...] one IK target: print q and the residuals (exit 1 if unsolved)
    derive trajopt pendulum --swing-up      torque limit 0.25 m g l: several pumps, free final time
    derive trajopt cartpole --swing-up      pole from down (theta = 0) to up (pi), cart back to 0
    derive trajopt panda --from Q0 --to Q1  rest to rest, full dynamics, the model's limits

simulate writes <out>/<robot>.csv (t, q_<joint>..., qd_..., qdd_..., tau_..., then T, U, E) and
<out>/<robot>.png (<out> defaults to ./simulate_out/<robot>/);
trajopt writes <out>/trajectory.csv (t, q_<joint>..., qd_..., qdd_..., tau_...) and
<out>/trajectory.png (q, qd, tau over time), <out> defaulting to ./trajopt_out/<robot>/.
"""

from __future__ import annotations

import io
import sys
import time
from pathlib import Path

import casadi as ca
import numpy as np

from derive.cli.common import (Progress, Vector, check_count, check_number, check_seed, integer, parse_vector,
                               path_arg, vector_help)
from derive.codegen.generate import default_output, generate
from derive.description.files import read_bytes, read_text
from derive.description.model import load_models, load_robot
from derive.errors import DeriveError
from derive.filesystem import temporary_directory, write_atomically
from derive.plot.figure import write_png
from derive.plot.simulate import simulation_png
from derive.plot.trajopt import trajopt_png
from derive.solvers.ik import problem, solve_ik
from derive.solvers.simulate import METHODS as SIMULATE_METHODS
from derive.solvers.simulate import (check_times, check_vector, is_stale, numeric_reference, simulate, summary,
                                     warnings, with_parameters, write_csv)
from derive.solvers.trajopt import MAX_INTERVALS, MAX_SUBSTEPS
from derive.solvers.trajopt import METHODS as TRAJOPT_METHODS
from derive.solvers.trajopt import TrajectoryOptimizer, Waypoint
from derive.solvers.trajopt_examples import SWING_UPS, point_to_point_duration, swing_up, velocity_reversals
from derive.symbolic.ik import TOL_POSITION, TOL_ROTATION
from derive.symbolic.spatial import rpy

TRAJOPT_DESCRIPTION = "Optimise a trajectory on the derived dynamics (CasADi Opti + IPOPT): swing-ups and point-to-point moves."


def add_parser(sub) -> None:
    add_simulate(sub)
    add_ik(sub)
    add_trajopt(sub)


# ---- derive simulate ROBOT --q0 ... ----

def add_simulate(sub) -> None:
    p = sub.add_parser("simulate", help="integrate a robot's generated forward dynamics; CSV, plot, energy drift")
    p.add_argument("robot_name")
    p.add_argument("--q0", action=Vector, required=True, help=vector_help("initial joint positions (one per joint)"))
    p.add_argument("--qd0", action=Vector, help=vector_help("initial joint velocities (default 0)"))
    p.add_argument("--tau", action=Vector, help=vector_help("constant joint torques/forces (default 0)"))
    p.add_argument("--t", type=float, default=10.0, help="duration in s (default 10)")
    p.add_argument("--dt", type=float, default=1e-3, help="RK4 step and sample interval in s (default 1e-3)")
    p.add_argument("--method", choices=SIMULATE_METHODS, default="rk4", help="integrator (default rk4)")
    p.add_argument("--rtol", type=float, default=1e-10, help="adaptive integrators' rtol (default 1e-10)")
    p.add_argument("--atol", type=float, default=1e-12, help="adaptive integrators' atol (default 1e-12)")
    p.add_argument("--param", action="append", default=[], metavar="NAME=VALUE", help="override a parameter")
    p.add_argument("--out", type=path_arg, help="output folder (default: simulate_out/<robot>/)")
    p.add_argument("--generated", type=path_arg, help="folder holding <robot>/python/ (default: ./generated; where it lacks the current model, the code is generated afresh into a temporary folder)")
    p.set_defaults(func=cmd_simulate)


def parse_params(items: list[str]) -> dict[str, float]:
    """``--param NAME=VALUE`` items as {name: value}; a one-line DeriveError for a malformed one."""
    out = {}
    for item in items:
        name, sep, value = item.partition("=")
        try:
            out[name.strip()] = float(value)
        except ValueError:
            sep = ""
        if not sep or not name.strip():
            raise DeriveError(f"simulate: --param expects NAME=VALUE, got {item!r}")
    return out


def _generated_for(robot, folder: str | None, scratch: Path) -> Path:
    """The folder holding the robot's generated Python: ``--generated`` as given (stale code is used
    with a warning), else ./generated when it holds this very model, else a fresh generation into
    ``scratch`` (so a simulation never runs code of another version of the model)."""
    if folder:
        generated = Path(folder)
        if not generated.is_dir():
            raise DeriveError(f"robot '{robot.name}': --generated {generated}: no such folder "
                              "(`derive generate --out FOLDER` writes one)")
        code = generated / robot.name / "python" / f"{robot.name}.py"
        if not code.is_file():  # say so now, not "generated from another version"
            raise DeriveError(f"robot '{robot.name}': no generated code at {code} (run `derive generate`)")
        if is_stale(robot, generated):
            print(f"warning: {generated / robot.name} was generated from another version of '{robot.name}' "
                  "(run `derive generate`)", file=sys.stderr)
        return generated
    generated = default_output()
    if (generated / robot.name / "python" / f"{robot.name}.py").is_file() and not is_stale(robot, generated):
        return generated
    print(f"note: {generated / robot.name} is missing or from another version of '{robot.name}': generating it "
          "into a temporary folder (`derive generate` writes it to ./generated)", file=sys.stderr)
    generate({robot.name: robot}, scratch, log=lambda s: None)
    return scratch


def cmd_simulate(args) -> int:
    """Run the simulation, draw it, then write <out>/<robot>.csv and .png (each atomically): a run or a
    figure that fails writes nothing."""
    robot = load_robot(args.robot_name, args.models)
    # every option is checked before anything is printed, run or written
    n = len(robot.independent) if robot.closed else robot.nv  # a closed chain's q0, qd0, tau are in y
    check_times(robot.name, args.t, args.dt, args.rtol, args.atol, n)
    for values, what in ((args.q0, "q0"), (args.qd0, "qd0"), (args.tau, "tau")):
        check_vector(values, n, what, robot.name)
    params = parse_params(args.param)
    with_parameters(robot, params)
    if not robot.closed:  # a closed chain's M_y is checked along the run (a singular one is no longer finite)
        numeric_reference(robot, check_vector(args.q0, robot.nv, "q0", robot.name), params)
    out = Path(args.out) if args.out else Path("simulate_out") / robot.name
    if out.exists() and not out.is_dir():
        raise DeriveError(f"simulate --out {out}: not a folder")
    progress = Progress(f"simulate {robot.name}")
    with temporary_directory(prefix="derive-simulate-") as scratch:  # removed on SIGTERM too
        generated = _generated_for(robot, args.generated, scratch)
        print(f"simulating {robot.name} for {args.t:g} s ({args.method}) ...", flush=True)
        traj = simulate(robot, args.q0, args.qd0, args.tau, t_end=args.t, dt=args.dt, method=args.method,
                        params=params, generated=generated, rtol=args.rtol, atol=args.atol,
                        progress=lambda stage, done: progress(done, 1.0, f"{stage}, t = {done * args.t:.4g} of {args.t:g} s"))
    for line in warnings(traj):  # one line per joint, at its first crossing
        print(line, file=sys.stderr)
    png = simulation_png(traj)  # drawn before anything is written
    text = summary(traj)
    csv_path = write_csv(traj, out / f"{robot.name}.csv")
    png_path = write_png(out / f"{robot.name}.png", png)
    print(text)
    print(f"wrote {csv_path} and {png_path}")
    return 0


# ---- derive ik ROBOT --xyz X Y Z [--rpy R P Y] [--q0 ...] ----

MAX_MAGNITUDE = 1e6
"""Largest |value| of an IK option: a target coordinate (m, beyond any arm's reach), an angle, a joint
value (rad or m) or a weight; their squares stay finite and the steps of the solver above rounding."""


def add_ik(sub) -> None:
    k = sub.add_parser("ik", help="inverse kinematics of one target: print q and the residuals",
                       description="Solve world_T_frame(q) = target within the joint limits. "
                                   "--xyz alone is a position-only target; with --rpy (URDF roll-pitch-yaw, "
                                   "R = Rz(Y) Ry(P) Rx(R)) a full pose. Exit 0 if solved, 1 if not.")
    k.add_argument("robot_name", metavar="ROBOT")
    k.add_argument("--xyz", action=Vector, count=3, names=("X", "Y", "Z"), required=True,
                   help=vector_help(f"position (m, within {MAX_MAGNITUDE:g})"))
    k.add_argument("--rpy", action=Vector, count=3, names=("R", "P", "Y"),
                   help=vector_help("orientation (rad)"))
    k.add_argument("--q0", action=Vector, help=vector_help("start (default: mid-range)"))
    k.add_argument("--frame", default="tcp", help="frame to place (default: tcp)")
    k.add_argument("--weights", action=Vector, count=6, metavar="W1..W6",
                   help=vector_help("6 row weights of [dp; dtheta]"))
    k.add_argument("--method", choices=("auto", "lm", "opti"), default="auto")
    k.add_argument("--rest", action=Vector, help=vector_help("rest posture to stay near (redundant arms)"))
    k.add_argument("--timeout", type=float, default=0.1, help="wall-time cap in s (default 0.1)")
    k.add_argument("--seed", type=integer, default=0, help="seed of the restarts (>= 0)")
    k.set_defaults(func=cmd_ik)


def cmd_ik(args) -> int:
    """Solve one target and print q (per joint) and the residuals; exit 1 when the solve fails."""
    robot = load_robot(args.robot_name, args.models)
    if not (np.isfinite(args.timeout) and args.timeout > 0):
        raise DeriveError(f"robot '{robot.name}': --timeout must be a finite number of seconds > 0, got {args.timeout:g}")
    who = f"robot '{robot.name}'"
    for v in args.xyz:  # nan and inf: solve_ik's check of the target
        if np.isfinite(v):
            check_number(v, "--xyz", -MAX_MAGNITUDE, MAX_MAGNITUDE, unit="m", who=who)
    for values, option in ((args.rpy, "--rpy"), (args.q0, "--q0"), (args.rest, "--rest")):
        for v in values or ():
            check_number(v, option, -MAX_MAGNITUDE, MAX_MAGNITUDE, who=who)
    for v in args.weights or ():
        check_number(v, "--weights", 0.0, MAX_MAGNITUDE, who=who)
    check_seed(args.seed)
    if args.rpy is None and args.weights is None:
        target, what = np.array(args.xyz), "position"
    else:
        target = np.eye(4)
        target[:3, :3] = np.array(ca.DM(rpy(*args.rpy))) if args.rpy else np.eye(3)
        target[:3, 3] = args.xyz
        what = "pose"
    if args.rpy is None and args.weights is not None:
        what = "position (orientation identity, weighted)"
    problem(robot, args.frame)   # built once per process: not part of the solve time
    t0 = time.perf_counter()
    result = solve_ik(robot, target, q0=args.q0, frame=args.frame, weights=args.weights, method=args.method,
                      rest=args.rest, timeout=args.timeout, seed=args.seed)
    elapsed = time.perf_counter() - t0
    names = [c.name for c in robot.coordinates]
    width = max(map(len, names))
    print(f"{robot.name}: {what} target for frame '{args.frame}': "
          f"{'solved' if result.success else 'NOT solved (best q found)'}")
    for i, (name, value) in enumerate(zip(names, result.q)):
        wrapped = i in robot.continuous_indices
        print(f"  {name:<{width}} = {value: .9f}" + ("  (continuous: wrapped to (-pi, pi])" if wrapped else ""))
    print(f"position error {result.position_error:.3e} m, rotation error {result.rotation_error:.3e} rad "
          f"(tolerances {TOL_POSITION:g} m, {TOL_ROTATION:g} rad)")
    print(f"{result.iterations} iterations, {result.restarts} restarts, {1e3 * elapsed:.2f} ms")
    return 0 if result.success else 1


# ---- derive trajopt ROBOT (--swing-up | --from Q0 --to Q1) ----

def add_trajopt(sub) -> None:
    t = sub.add_parser("trajopt", help="optimise a trajectory on the derived dynamics (CasADi + IPOPT)",
                       description=TRAJOPT_DESCRIPTION)
    t.add_argument("robot")
    t.add_argument("--swing-up", action="store_true", help=f"the swing-up example ({', '.join(SWING_UPS)})")
    t.add_argument("--from", dest="start", action=Vector, metavar="Q",
                   help=vector_help("start joint positions, one per coordinate of q (at rest)"))
    t.add_argument("--to", dest="goal", action=Vector, metavar="Q", help=vector_help("goal joint positions (at rest)"))
    t.add_argument("--method", choices=TRAJOPT_METHODS, help="transcription (default hermite-simpson)")
    t.add_argument("--intervals", type=integer, help=f"N, 2 .. {MAX_INTERVALS} (default 100 for swing-ups, 50 otherwise)")
    t.add_argument("--duration", type=float, help="final time T, or its first guess with --free-time")
    t.add_argument("--free-time", action="store_true", help="optimise T too")
    t.add_argument("--time-weight", type=float, help="w_T of the cost w_T T + integral |tau|^2 (needs --free-time)")
    t.add_argument("--accel-weight", type=float, help="w_A of the regulariser w_A integral |qdd|^2 "
                                                      "(default 1 for --from/--to, 0 for swing-ups)")
    t.add_argument("--torque-limit", action=Vector, metavar="TAU",
                   help=vector_help("override the model's effort limits: one value or one per joint"))
    t.add_argument("--passive", help="unactuated joints (or single coordinates of multi-DOF joints), comma-separated")
    t.add_argument("--waypoint", action="append", help="S:X,Y,Z[@FRAME]: FRAME (default tcp) at X,Y,Z at time S*T")
    t.add_argument("--guess", type=path_arg, help="initial path: .npy or .csv of joint positions (M x nq), e.g. a planner's")
    t.add_argument("--substeps", type=integer,
                   help=f"RK4 steps per interval of the independent check, 1 .. {MAX_SUBSTEPS} (default 20)")
    t.add_argument("--out", type=path_arg, help="output folder (default ./trajopt_out/<robot>/)")
    t.set_defaults(func=cmd_trajopt)


def parse_floats(text: str, what: str) -> list[float]:
    """Numbers separated by commas or blanks (:func:`derive.cli.common.parse_vector`); a one-line
    DeriveError naming ``what`` otherwise."""
    return parse_vector(text, f"trajopt: {what}")


def parse_waypoint(text: str) -> Waypoint:
    """S:X,Y,Z[@FRAME]."""
    body, _, frame = text.partition("@")
    s, sep, xyz = body.partition(":")
    pos = parse_floats(xyz, "--waypoint X,Y,Z")
    if not sep or len(pos) != 3:
        raise DeriveError(f"trajopt: --waypoint must be S:X,Y,Z[@FRAME], got {text!r}")
    return Waypoint(parse_floats(s, "--waypoint S")[0], tuple(pos), frame or "tcp")


def read_path(file: str, joints: tuple[str, ...]) -> np.ndarray:
    """An (M, nv) path from .npy or .csv; a CSV with q_<joint> columns (as trajopt writes) gives those.

    The file is read through the input guards (a regular file of bounded size: a FIFO or /dev/zero is
    refused at once). Anything else (text that is not comma-separated numbers under an optional header,
    a pickled .npy) is a one-line DeriveError; the shape is checked by the optimiser.
    """
    path = Path(file)
    if not path.exists():
        raise DeriveError(f"trajopt: --guess {file}: no such file")
    try:
        if path.suffix == ".npy":
            return np.load(io.BytesIO(read_bytes(path, "--guess path")), allow_pickle=False)
        lines = [line for line in read_text(path, "--guess path").splitlines() if line.strip()]
        if not lines:
            raise ValueError("empty")
        head = [x.strip() for x in lines[0].split(",")]
        try:
            [float(x) for x in head]
            return np.loadtxt(lines, delimiter=",", ndmin=2)
        except ValueError:
            if len(lines) < 2:  # a header alone (np.loadtxt would warn "input contained no data")
                raise ValueError("no rows") from None
            data = np.loadtxt(lines[1:], delimiter=",", ndmin=2)
            if not data.size:
                raise ValueError("no rows") from None
    except DeriveError as exc:
        raise DeriveError(f"trajopt: --guess: {exc}") from None
    except (OSError, ValueError, UnicodeDecodeError, EOFError):
        raise DeriveError(f"trajopt: --guess {file}: not a .npy array or a CSV of numbers "
                          f"(M rows of {len(joints)} joint positions, optionally under a header)") from None
    cols = [head.index(f"q_{j}") for j in joints if f"q_{j}" in head]
    return data[:, cols] if len(cols) == len(joints) else data


def cmd_trajopt(args) -> int:
    robots = load_models(args.models)
    if args.robot not in robots:
        raise DeriveError(f"trajopt: no robot {args.robot!r} (known: {', '.join(robots)})")
    # sizes before the (slow) optimiser is built; the lower bounds and the other numbers (duration,
    # weights, torque limits, waypoints) are checked by TrajectoryOptimizer.solve before it transcribes
    if args.intervals is not None:
        check_count(args.intervals, "--intervals", None, MAX_INTERVALS, who=f"trajopt {args.robot}")
    if args.substeps is not None:
        check_count(args.substeps, "--substeps", None, MAX_SUBSTEPS, who=f"trajopt {args.robot}")
    out = Path(args.out) if args.out else Path("trajopt_out") / args.robot
    if out.exists() and not out.is_dir():
        raise DeriveError(f"trajopt --out {out}: not a folder")
    progress = Progress(f"trajopt {args.robot}")
    opt = TrajectoryOptimizer(robots[args.robot], log=lambda s: print(s, flush=True),
                              progress=lambda i, most: progress(i, most, f"IPOPT iteration {i}, at most {most}"))
    options = {k: v for k, v in {
        "method": args.method, "intervals": args.intervals, "duration": args.duration,
        "time_weight": args.time_weight, "accel_weight": args.accel_weight, "substeps": args.substeps,
        "torque_limit": args.torque_limit,
        "passive": tuple(x.strip() for x in args.passive.split(",") if x.strip()) if args.passive else None,
        "waypoints": tuple(parse_waypoint(w) for w in args.waypoint or ()) or None,
        "guess": read_path(args.guess, opt.joints) if args.guess else None}.items() if v is not None}
    if args.free_time:
        options["free_time"] = True
    if args.swing_up:
        if args.start or args.goal:
            raise DeriveError("trajopt: give either --swing-up or --from/--to")
        res = swing_up(opt, **options)
    else:
        if not (args.start and args.goal):
            raise DeriveError(f"trajopt {args.robot}: give --from Q0 --to Q1 (or --swing-up)")
        start, goal = opt.vector(args.start, "--from"), opt.vector(args.goal, "--to")
        if "duration" not in options:
            options["duration"] = point_to_point_duration(opt, start, goal)
        options.setdefault("accel_weight", 1.0)
        res = opt.solve(start, goal, **options)
    if not res.success:  # well formed but not met (infeasible, not converged): exit 1, nothing written
        print(f"derive: trajopt {args.robot}: no solution: {res.reason}", file=sys.stderr)
        return 1
    # everything computed (the CSV text, the figure) before anything is written; each file atomically
    text = res.csv_text()
    png = trajopt_png(res, dict(zip(opt.joints, opt.limits(options.get("torque_limit"))["effort"])))
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise DeriveError(f"trajopt --out {out}: cannot create the folder ({exc.strerror or exc})") from None
    csv_path = write_atomically(out / "trajectory.csv", text, "CSV")
    png_path = write_png(out / "trajectory.png", png)
    if args.swing_up:
        print(f"velocity reversals (pumps): {', '.join(f'{j} {velocity_reversals(res.qd[:, i])}' for i, j in enumerate(opt.joints))}")
    print(f"wrote {csv_path} and {png_path}")
    return 0
