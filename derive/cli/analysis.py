"""Commands of the kinematic toolkit: dof, fk, workspace, singularities, manipulability, plan.

Each command reads its robot (or mechanism file), calls :mod:`derive.analysis` for the
numbers and :mod:`derive.plot` for the figures (``--png``), and prints the results.
"""

from __future__ import annotations

from pathlib import Path
from typing import Mapping

import numpy as np

from derive.analysis.frames import frame_poses
from derive.analysis.grubler import closed_report, mechanism_from_robot, parse_mechanism, read_yaml, report
from derive.analysis.manipulability import MAX_POSES, Manipulability, default_poses
from derive.analysis.planning import MAX_LENGTH, MAX_NODES, parse_obstacle, plan
from derive.analysis.singularity import MAX_STARTS, TaskJacobian, analyse, find_singularities, redundancy
from derive.analysis.workspace import MAX_SAMPLES, Arm, workspace
from derive.cli.common import Progress, check_count, check_number, check_seed, integer, parse_vector, png_path, vector_help
from derive.description.model import load_models, load_robot
from derive.description.robot import Robot
from derive.errors import DeriveError
from derive.plot.manipulability import plot_manipulability
from derive.plot.planning import plot_plan
from derive.plot.workspace import plot_workspace


def fmt(v) -> str:
    """A vector as ``[a, b, ...]`` with 6 significant digits per entry."""
    return "[" + ", ".join(f"{x:.6g}" for x in np.asarray(v).reshape(-1)) + "]"


def parse_q(robot: Robot, text, option: str = "--q") -> np.ndarray:
    """q from "0.1,pi/2" or from a list of such pieces (the command line's words), read by
    :func:`derive.cli.common.parse_vector` (the convention of every vector option)."""
    try:
        q = np.array(parse_vector(text, option))
    except DeriveError as exc:
        raise DeriveError(f"robot '{robot.name}': {exc}") from None
    text = text if isinstance(text, str) else " ".join(text)
    if q.shape[0] != robot.nv:
        raise DeriveError(f"robot '{robot.name}': {option} '{text}': expected {robot.nv} values "
                          f"({', '.join(c.name for c in robot.coordinates)}), got {q.shape[0]}")
    if not np.all(np.isfinite(q)):
        bad = robot.coordinates[int(np.argmin(np.isfinite(q)))].name
        raise DeriveError(f"robot '{robot.name}': {option} '{text}': {bad} = {q[np.argmin(np.isfinite(q))]:g} is not a finite number")
    return q


# --------------------------------------------------------------------------- fk


def fk_command(args) -> int:
    """world_T_frame (and with --jacobian J) of the frames asked (default: every link and named frame)."""
    robot = load_robot(args.robot_name, args.models)
    if args.q is None:
        q = np.zeros(robot.nq)
        if robot.floating:
            q[6] = 1.0  # the identity quaternion (x, y, z, w)
    else:
        try:
            q = np.array(parse_vector(args.q, "--q"))
        except DeriveError as exc:
            raise DeriveError(f"robot '{robot.name}': {exc}") from None
        if q.shape[0] != robot.nq or not np.all(np.isfinite(q)):
            raise DeriveError(f"robot '{robot.name}': --q: expected {robot.nq} finite values "
                              f"({', '.join(c.name for c in robot.coordinates)}), "
                              f"got {' '.join(args.q)}")
    frames = [f for text in args.frame or () for f in text.split(",") if f] or None
    poses = frame_poses(robot, q, frames, jacobian=args.jacobian)
    print(f"{robot.name}: world_T_frame at q = {fmt(q)}" + (" and J (6x" f"{robot.nv}, [linear; angular], "
                                                            "LOCAL_WORLD_ALIGNED)" if args.jacobian else ""))
    for name, (T, J) in poses.items():
        alias = robot.frame_aliases.get(name)
        print(f"{name}" + (f" (alias of {alias})" if alias else "") + ":")
        for row in T:
            print("  " + " ".join(f"{x + 0.0: .12g}" for x in row))  # + 0.0: no -0
        if J is not None:
            print("  J:")
            for row in J:
                print("  " + " ".join(f"{x + 0.0: .12g}" for x in row))  # + 0.0: no -0
    return 0


# --------------------------------------------------------------------------- dof


def dof_command(args) -> int:
    target = args.target
    path = Path(target)
    if path.suffix in (".yaml", ".yml") or path.is_file():
        if not path.is_file():
            raise DeriveError(f"mechanism {target}: no such file")
        data = read_yaml(path)
        if isinstance(data, Mapping) and "robots" in data:  # a models file: every robot in it
            for robot in load_models(path).values():
                print(robot_dof(robot))
            return 0
        print(report(parse_mechanism(data, str(path))))
        return 0
    robot = load_robot(target, args.models)
    print(robot_dof(robot))
    return 0


def robot_dof(robot) -> str:
    """Grübler's count of a robot; with loops also the mobility from the rank of K."""
    mech = mechanism_from_robot(robot)
    text = report(mech, robot.nv)
    return text + "\n" + closed_report(robot, mech) if robot.loops else text


# --------------------------------------------------------------------------- workspace


def workspace_command(args) -> int:
    robot = load_robot(args.robot_name, args.models)
    if args.samples < 2:
        raise DeriveError(f"--samples: need at least 2, got {args.samples}")
    check_count(args.samples, "--samples", 2, MAX_SAMPLES, "FK of each sample costs microseconds: 1e7 take minutes",
                f"robot '{robot.name}'")
    check_seed(args.seed)
    progress = Progress(f"workspace {robot.name}")
    ws = workspace(robot, args.frame, args.samples, args.method, args.seed,
                   progress=lambda done, total: progress(done, total, f"{done} of {total} configurations"))
    print(ws.summary())
    if args.png:
        print(f"wrote {plot_workspace(ws, args.png)}")
    return 0


# --------------------------------------------------------------------------- singularities


def singularities_command(args) -> int:
    robot = load_robot(args.robot_name, args.models)
    q = parse_q(robot, args.q) if args.q else None  # every option is checked before anything is printed
    if q is None:
        check_count(args.starts, "--starts", 1, MAX_STARTS, "each start is a Newton search", f"robot '{robot.name}'")
    check_seed(args.seed)
    tj = TaskJacobian(robot, args.frame, args.task)
    names = [c.name for c in robot.coordinates]
    print(f"{robot.name}/{args.frame}: task rows {tj.row_names} (k = {tj.k}), nv = {tj.nv}")
    print(redundancy(tj))
    if q is not None:
        info = analyse(tj(q), q)
        print(f"at q = {fmt(q)}: rank {info.rank} of {len(info.singular_values)}"
              f"{' (SINGULAR)' if info.singular else ''}, singular values {fmt(info.singular_values)}")
        for k in range(info.null_space.shape[1]):
            print(f"  null space: qd = {fmt(info.null_space[:, k])}  ({', '.join(names)})")
        for k in range(info.lost_directions.shape[1]):
            print(f"  cannot move along: {fmt(info.lost_directions[:, k])}  ({tj.row_names})")
        return 0
    print(f"searching singular configurations from {args.starts} random starts ...", flush=True)
    progress = Progress(f"singularities {robot.name}")
    found, free = find_singularities(tj, args.starts, args.seed,
                                     progress=lambda n, total, q, s: progress(n, total, f"{n} of {total} starts"))
    if free:
        print(f"  the singular values do not depend on {', '.join(names[i] for i in free)} (set to 0 below)")
    if not found:
        print("no singular configuration found")
    for c in found:
        where = "" if c.within_limits else "  (outside the joint limits)"
        print(f"  singular at q = {fmt(c.q)}: singular values {fmt(c.singular_values)}{where}")
    return 0


# --------------------------------------------------------------------------- manipulability


def manipulability_command(args) -> int:
    robot = load_robot(args.robot_name, args.models)
    if not args.q:
        check_count(args.poses, "--poses", 1, MAX_POSES, "each pose is printed; the figure maps mu3 over the "
                    "whole workspace", f"robot '{robot.name}'")
    qs = [parse_q(robot, text) for text in args.q] if args.q else list(default_poses(robot, args.poses))
    man = Manipulability(robot, args.frame, args.task)
    print(f"{robot.name}/{args.frame}: task rows {man.tj.row_names} (k = {man.tj.k}), nv = {robot.nv}; "
          "mu1 = sqrt(lmax/lmin), mu2 = lmax/lmin, mu3 = sqrt(det(J J^T))")
    for q in qs:
        info = man.at(q)
        print(f"q = {fmt(q)}: mu1 = {info.mu[0]:.6g}, mu2 = {info.mu[1]:.6g}, mu3 = {info.mu[2]:.6g}")
        for name, (rows, semi, axes) in info.parts.items():
            print(f"  {name} ellipsoid ({rows}): semi-axes {fmt(semi)} along {', '.join(fmt(a) for a in axes.T)}")
    if args.png:
        print(f"wrote {plot_manipulability(man, args.png, np.array(qs))}")
    return 0


# --------------------------------------------------------------------------- plan


def plan_command(args) -> int:
    robot = load_robot(args.robot_name, args.models)
    start, goal = parse_q(robot, args.start, "--start"), parse_q(robot, args.goal, "--goal")
    obstacles = [parse_obstacle(o) for o in args.obstacle or []]
    if args.resolution is not None and args.resolution < 2:
        raise DeriveError(f"robot '{robot.name}': --resolution must be at least 2 grid points per joint, "
                          f"got {args.resolution}")
    if args.resolution is not None and args.resolution ** robot.nv > MAX_NODES:
        most = int(round(MAX_NODES ** (1 / robot.nv)))
        while most ** robot.nv > MAX_NODES:
            most -= 1
        raise DeriveError(f"robot '{robot.name}': --resolution {args.resolution} gives {args.resolution}^{robot.nv} grid "
                          f"nodes, more than {MAX_NODES}; at most {most} per joint for {robot.nv} joints")
    if args.check_step is not None and not (np.isfinite(args.check_step) and args.check_step > 0):
        raise DeriveError(f"robot '{robot.name}': --check-step must be a finite length > 0 m, got {args.check_step:g}")
    check_number(args.margin, "--margin", 0.0, MAX_LENGTH, unit="m", who=f"robot '{robot.name}'")
    arm = Arm(robot, args.frame)
    progress = Progress(f"plan {robot.name}")
    result = plan(robot, start, goal, obstacles, args.frame, args.resolution,
                  "axis" if args.connectivity == 4 else "full", args.margin, arm, args.check_step,
                  progress=lambda done, total: progress(done, total, f"{done} of {total} grid nodes checked"))
    print(f"{robot.name}: {result.message}")
    print(f"collision checks: {result.resolution}")
    if result.success:
        print(f"path length: {result.length:.6g} (joint space)")
    if args.png:
        print(f"wrote {plot_plan(robot, result, start, goal, obstacles, args.png, args.frame, arm)}")
    return 0 if result.success else 1


# --------------------------------------------------------------------------- parsers


def add_parser(sub) -> None:
    p = sub.add_parser("dof", help="degrees of freedom by Grübler's formula (robot or mechanism YAML)",
                       description="DOF = m (N - 1 - J) + sum f_i for a robot of models.yaml or a mechanism file "
                                   "(see examples/grubler_example2.yaml).")
    p.add_argument("target", help="robot name in models.yaml, or a mechanism .yaml file")
    p.set_defaults(func=dof_command)

    p = sub.add_parser("fk", help="world pose (and Jacobian) of any link, frame or alias at q",
                       description="Print world_T_frame (4x4) of each frame asked, by default every link and named "
                                   "frame, at q (default: zero, a floating base at the origin); with --jacobian also "
                                   "the 6 x nv geometric Jacobian [linear; angular], LOCAL_WORLD_ALIGNED. No code is "
                                   "generated: any link works, not only the frames with generated functions.")
    p.add_argument("robot_name")
    p.add_argument("--q", nargs="+", help=vector_help("configuration (nq values)"))
    p.add_argument("--frame", action="append", help="link, frame or alias (repeatable, or comma-separated)")
    p.add_argument("--jacobian", action="store_true", help="also print J")
    p.set_defaults(func=fk_command)

    p = sub.add_parser("workspace", help="sample the configuration space through FK; plot both spaces",
                       description="Sample q in the joint box (grid or random), map through FK, print the "
                                   "workspace's extent and optionally draw both spaces side by side.")
    p.add_argument("robot_name")
    p.add_argument("--frame", default="tcp", help="frame whose positions form the workspace (default tcp)")
    p.add_argument("--samples", type=integer, default=40000,
                   help=f"number of configurations, 2 .. {MAX_SAMPLES:.0e} (default 40000)")
    p.add_argument("--method", choices=("grid", "random"), default="grid")
    p.add_argument("--seed", type=integer, default=0, help="seed of the random sampling (>= 0)")
    p.add_argument("--png", type=png_path, help="write configuration space | workspace to this .png file")
    p.set_defaults(func=workspace_command)

    p = sub.add_parser("singularities", help="rank, singular values and null space of J; search for singularities",
                       description="With --q: rank, singular values, null space of the task Jacobian at q. "
                                   "Without: redundancy and a search for singular configurations.")
    p.add_argument("robot_name")
    p.add_argument("--frame", default="tcp")
    p.add_argument("--task", default="position", help="position (default) | orientation | full | rows such as x,y,wz")
    p.add_argument("--q", nargs="+", help=vector_help("configuration"))
    p.add_argument("--starts", type=integer, default=24, help=f"random starts of the search (1 .. {MAX_STARTS}, default 24)")
    p.add_argument("--seed", type=integer, default=0, help="seed of the random starts (>= 0)")
    p.set_defaults(func=singularities_command)

    p = sub.add_parser("manipulability", help="manipulability ellipsoids and measures mu1, mu2, mu3 (eq. 30)",
                       description="Print the measures and ellipsoids at configurations; draw ellipses along "
                                   "the arm and mu3 over the workspace (lecture figure 9).")
    p.add_argument("robot_name")
    p.add_argument("--frame", default="tcp")
    p.add_argument("--task", default="position", help="position (default) | orientation | full | rows such as x,y")
    p.add_argument("--q", action="append", nargs="+", help=vector_help("configuration, repeatable"))
    p.add_argument("--poses", type=integer, default=6,
                   help=f"without --q: this many poses across the joint box (1 .. {MAX_POSES}, default 6)")
    p.add_argument("--png", type=png_path, help="write the ellipses and the mu3 map to this .png file")
    p.set_defaults(func=manipulability_command)

    p = sub.add_parser("plan", help="A* over a configuration-space grid around workspace obstacles",
                       description="Collision-free joint path by A* (Euclidean cost and heuristic) on a grid over "
                                   "the joint box; obstacles are circles/boxes in the workspace checked against "
                                   "the links, at the grid nodes and along the edges (no point of the arm moves "
                                   "more than --check-step between checks). Exit status 1 when there is no path "
                                   "or it cannot be certified.")
    p.add_argument("robot_name")
    p.add_argument("--start", required=True, nargs="+", help=vector_help("start configuration"))
    p.add_argument("--goal", required=True, nargs="+", help=vector_help("goal configuration"))
    p.add_argument("--obstacle", action="append", help="circle:x,y,r | box:xmin,ymin,xmax,ymax (3-D forms too; repeatable)")
    p.add_argument("--frame", default="tcp", help="the chain to this frame is checked (default tcp)")
    p.add_argument("--resolution", type=integer, help=f"grid points per joint, >= 2, at most {MAX_NODES} nodes in all "
                   "(default: about 40000 nodes)")
    p.add_argument("--connectivity", type=int, choices=(4, 8), default=8,
                   help="8: all neighbours incl. diagonals (default); 4: along the axes only")
    p.add_argument("--margin", type=float, default=0.0, help=f"clearance added to every obstacle [m], 0 .. {MAX_LENGTH:g}")
    p.add_argument("--check-step", type=float, help="largest motion of any point of the arm between two collision "
                   "checks along an edge [m], > 0 (default 0.01, or half the smallest obstacle if smaller)")
    p.add_argument("--png", type=png_path, help="write the path in configuration space | workspace to this .png file")
    p.set_defaults(func=plan_command)
