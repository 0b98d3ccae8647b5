"""`derive trajopt`: the trajectory optimiser's examples on the command line, and their benchmark.

    derive trajopt pendulum --swing-up      torque limit 0.25 m g l: several pumps, free final time
    derive trajopt cartpole --swing-up      pole from down (theta = 0) to up (pi), cart back to 0
    derive trajopt panda --from Q0 --to Q1  rest to rest, full dynamics, the model's limits

Each writes <out>/trajectory.csv (t, q_<joint>..., qd_..., qdd_..., tau_...) and
<out>/trajectory.png (q, qd, tau over time); <out> defaults to ./trajopt_out/<robot>/.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from derive.errors import DeriveError
from derive.description.model import load_models
from derive.solvers.trajopt import METHODS, TrajectoryOptimizer, TrajoptResult, Waypoint

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


# ---- command line ----

def _floats(text: str, what: str) -> list[float]:
    try:
        return [float(x) for x in text.replace(",", " ").split()]
    except ValueError:
        raise DeriveError(f"trajopt: {what} must be comma-separated numbers, got {text!r}") from None


def _waypoint(text: str) -> Waypoint:
    """S:X,Y,Z[@FRAME]."""
    body, _, frame = text.partition("@")
    s, sep, xyz = body.partition(":")
    pos = _floats(xyz, "--waypoint X,Y,Z")
    if not sep or len(pos) != 3:
        raise DeriveError(f"trajopt: --waypoint must be S:X,Y,Z[@FRAME], got {text!r}")
    return Waypoint(_floats(s, "--waypoint S")[0], tuple(pos), frame or "tcp")


def _path(file: str, joints: tuple[str, ...]) -> np.ndarray:
    """An (M, nv) path from .npy or .csv; a CSV with q_<joint> columns (as written here) gives those.

    Anything else (an unreadable file, text that is not comma-separated numbers under an optional
    header, a pickled .npy) is a one-line DeriveError; the shape is checked by the optimiser.
    """
    path = Path(file)
    if not path.is_file():
        raise DeriveError(f"trajopt: --guess {file}: no such file")
    try:
        if path.suffix == ".npy":
            return np.load(path, allow_pickle=False)
        lines = [line for line in path.read_text().splitlines() if line.strip()]
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
    except (OSError, ValueError, UnicodeDecodeError, EOFError):
        raise DeriveError(f"trajopt: --guess {file}: not a .npy array or a CSV of numbers "
                          f"(M rows of {len(joints)} joint positions, optionally under a header)") from None
    cols = [head.index(f"q_{j}") for j in joints if f"q_{j}" in head]
    return data[:, cols] if len(cols) == len(joints) else data


def run(args) -> int:
    robots = load_models(args.models)
    if args.robot not in robots:
        raise DeriveError(f"trajopt: no robot {args.robot!r} (known: {', '.join(robots)})")
    opt = TrajectoryOptimizer(robots[args.robot], log=lambda s: print(s, flush=True))
    options = {k: v for k, v in {
        "method": args.method, "intervals": args.intervals, "duration": args.duration,
        "time_weight": args.time_weight, "accel_weight": args.accel_weight, "substeps": args.substeps,
        "torque_limit": _floats(args.torque_limit, "--torque-limit") if args.torque_limit else None,
        "passive": tuple(x.strip() for x in args.passive.split(",") if x.strip()) if args.passive else None,
        "waypoints": tuple(_waypoint(w) for w in args.waypoint or ()) or None,
        "guess": _path(args.guess, opt.joints) if args.guess else None}.items() if v is not None}
    if args.free_time:
        options["free_time"] = True
    if args.swing_up:
        if args.start or args.goal:
            raise DeriveError("trajopt: give either --swing-up or --from/--to")
        res = swing_up(opt, **options)
    else:
        if not (args.start and args.goal):
            raise DeriveError(f"trajopt {args.robot}: give --from Q0 --to Q1 (or --swing-up)")
        start, goal = _floats(args.start, "--from"), _floats(args.goal, "--to")
        start, goal = opt._vector(start, "--from"), opt._vector(goal, "--to")
        if "duration" not in options:
            options["duration"] = point_to_point_duration(opt, start, goal)
        options.setdefault("accel_weight", 1.0)
        res = opt.solve(start, goal, **options)
    if not res.success:
        raise DeriveError(f"trajopt {args.robot}: {res.reason}")
    out = Path(args.out) if args.out else Path("trajopt_out") / args.robot
    out.mkdir(parents=True, exist_ok=True)
    res.write_csv(out / "trajectory.csv")
    res.plot(out / "trajectory.png", dict(zip(opt.joints, opt.limits(options.get("torque_limit"))["effort"])))
    if args.swing_up:
        print(f"velocity reversals (pumps): {', '.join(f'{j} {velocity_reversals(res.qd[:, i])}' for i, j in enumerate(opt.joints))}")
    print(f"wrote {out / 'trajectory.csv'} and {out / 'trajectory.png'}")
    return 0


def add_parser(sub) -> None:
    t = sub.add_parser("trajopt", help="optimise a trajectory on the derived dynamics (CasADi + IPOPT)",
                       description=__doc__.split("\n\n")[0])
    t.add_argument("robot")
    t.add_argument("--swing-up", action="store_true", help=f"the swing-up example ({', '.join(SWING_UPS)})")
    t.add_argument("--from", dest="start", help="start joint positions, one per coordinate of q, comma-separated (at rest)")
    t.add_argument("--to", dest="goal", help="goal joint positions, comma-separated (at rest)")
    t.add_argument("--method", choices=METHODS, help="transcription (default hermite-simpson)")
    t.add_argument("--intervals", type=int, help="N (default 100 for swing-ups, 50 otherwise)")
    t.add_argument("--duration", type=float, help="final time T, or its first guess with --free-time")
    t.add_argument("--free-time", action="store_true", help="optimise T too")
    t.add_argument("--time-weight", type=float, help="w_T of the cost w_T T + integral |tau|^2 (needs --free-time)")
    t.add_argument("--accel-weight", type=float, help="w_A of the regulariser w_A integral |qdd|^2 "
                                                      "(default 1 for --from/--to, 0 for swing-ups)")
    t.add_argument("--torque-limit", help="override the model's effort limits: one value or one per joint")
    t.add_argument("--passive", help="unactuated joints (or single coordinates of multi-DOF joints), comma-separated")
    t.add_argument("--waypoint", action="append", help="S:X,Y,Z[@FRAME]: FRAME (default tcp) at X,Y,Z at time S*T")
    t.add_argument("--guess", help="initial path: .npy or .csv of joint positions (M x nq), e.g. a planner's")
    t.add_argument("--substeps", type=int, help="RK4 steps per interval of the independent check (default 20)")
    t.add_argument("--out", help="output folder (default ./trajopt_out/<robot>/)")
    t.set_defaults(func=run)


# ---- benchmark ----

def benchmarks() -> dict:
    return {"trajopt": bench_trajopt}


def bench_trajopt(args) -> str:
    """Solve time (IPOPT's t_wall_total, best of ``repeat``) and iterations of the three examples."""
    robots = load_models(getattr(args, "models", None))
    quick = getattr(args, "quick", False)
    repeat, methods = (1, ("hermite-simpson",)) if quick else (3, METHODS)
    rows = ["| case | method | N | T [s] | success | iterations | solve [s] | target [s] | solve / target "
            "| first build [s] | integration error, per interval / open loop | notes |",
            "|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, target in (("cartpole", 0.3), ("pendulum", None), ("panda", 2.0)):
        opt = TrajectoryOptimizer(robots[name])
        duration = point_to_point_duration(opt, PANDA_READY, PANDA_GOAL) if name == "panda" else None
        for method in methods:
            runs = [opt.solve(PANDA_READY, PANDA_GOAL, method=method, duration=duration, accel_weight=1.0)
                    if name == "panda" else swing_up(opt, method=method) for _ in range(repeat)]
            r = min(runs, key=lambda x: x.stats["solve_time"])
            st = r.stats
            effort = opt.limits(SWING_UPS.get(name, {}).get("torque_limit", lambda o: None)(opt))["effort"]
            notes = f"max \\|tau\\| / limit {np.max(np.abs(r.tau) / effort):.3f}"
            if name != "panda":
                notes += f"; velocity reversals {velocity_reversals(r.qd[:, -1])}"
            ratio = f"{st['solve_time'] / target:.2f}" if target else "-"
            rows.append(f"| {name} | {method} | {len(r.t) - 1} | {r.duration:.3f} | {r.success} | {st['iterations']} "
                        f"| {st['solve_time']:.3f} | {target or '-'} | {ratio} | {runs[0].stats['build_time']:.2f} "
                        f"| {r.integration_error:.1e} / {r.drift:.1e} | {notes} |")
    return ("## Trajectory optimisation (CasADi Opti + IPOPT/MUMPS, implicit RNEA dynamics)\n\n"
            "cartpole and pendulum: `derive trajopt <robot> --swing-up`; panda: rest to rest from "
            f"{list(PANDA_READY)} to {list(PANDA_GOAL)}, N = 50, w_A = 1. Solve time is IPOPT's "
            f"t_wall_total, best of {repeat}; integration error: the generated Python forward dynamics, "
            "RK4 with 20 steps per interval, against the optimised knots (rad or m).\n\n" + "\n".join(rows) + "\n")
