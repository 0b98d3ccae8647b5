"""``derive view ROBOT``: the robot in the browser, live (viser) or as one HTML page.

    derive view panda                          live viewer: joint sliders, IK gizmo (Ctrl-C ends it)
    derive view panda --csv run.csv            ... plus playback of a trajectory CSV
    derive view panda --html panda.html        one self-contained page (no viser, no network)
    derive view panda --csv run.csv --html run.html   the page with play controls
    derive --models arm.yaml view arm --no-meshes     the model alone, without its links' meshes
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np

from derive.cli.common import Vector, path_arg, vector_help
from derive.description.model import load_robot
from derive.errors import DeriveError
from derive.filesystem import write_atomically
from derive.view.meshes import visual_parts
from derive.view.page import PAGE_TRIANGLES, render_page
from derive.view.scene import Kinematics, frames_to_show, geometry, initial_q, read_trajectory
from derive.view.server import import_viser, serve


def add_parser(sub) -> None:
    v = sub.add_parser("view", help="show a robot in the browser: meshes, skeleton, axes, frames, CoM, inertia boxes",
                       description="Shows ROBOT: its links' meshes and shapes where models.yaml has them (visual:, "
                                   "as import-urdf and import-mjcf keep them; mesh files need the viewer extra), and "
                                   "from the model alone the skeleton between the joint "
                                   "origins, joint axes, link and named frames, a CoM sphere (a steel ball of the "
                                   "link's mass) and the equivalent-inertia box of every link. Live (the viewer "
                                   "extra, viser): joint sliders within the limits, playback of a trajectory CSV "
                                   "(t, q_<joint>, qd_<joint>, qdd_<joint>, tau_<joint>, as simulate, trajopt and "
                                   "excite write it) and the IK target as a gizmo solved by the generated IK; Ctrl-C "
                                   "ends it. --html writes one self-contained page instead (no viser needed).")
    v.add_argument("robot_name", metavar="ROBOT")
    v.add_argument("--q", action=Vector, metavar="Q", help=vector_help("the configuration shown (nq values; default "
                                                                       "0 clipped into the joint limits)"))
    v.add_argument("--csv", type=path_arg, metavar="FILE", help="a trajectory CSV to play")
    v.add_argument("--html", type=path_arg, metavar="FILE",
                   help="write one self-contained HTML page (offline, no WebGL) and exit")
    v.add_argument("--host", default="127.0.0.1", help="address the live viewer listens on (default 127.0.0.1)")
    v.add_argument("--port", type=int, default=8080, help="port of the live viewer (default 8080)")
    v.add_argument("--ik", metavar="FRAME", help="frame of the IK gizmo (default tcp, else the first with ik_<frame>)")
    v.add_argument("--no-meshes", action="store_true",
                   help="leave out the links' meshes and shapes (models.yaml visual:), drawing the model alone")
    v.set_defaults(func=cmd_view)


def cmd_view(args) -> int:
    if args.html is None:
        import_viser()  # before the work: without the extra, one line at once
    robot = load_robot(args.robot_name, args.models)
    if args.html is not None:
        out = Path(args.html)
        if args.html.endswith(("/", os.sep)) or out.is_dir():
            raise DeriveError(f"view {robot.name}: --html {args.html} is a folder: give the file name of the page")
    if not 0 < args.port < 65536:
        raise DeriveError(f"view {robot.name}: --port must be from 1 to 65535, got {args.port}")
    q0 = initial_q(robot)
    if args.q is not None:
        if len(args.q) != robot.nq:
            raise DeriveError(f"view {robot.name}: --q needs {robot.nq} values (one per coordinate: "
                              f"{', '.join(c.name for c in robot.coordinates)}), got {len(args.q)}")
        q0 = np.array(args.q, dtype=float)
        if not np.all(np.isfinite(q0)):
            raise DeriveError(f"view {robot.name}: --q must be finite numbers, got {args.q}")
    trajectory = read_trajectory(robot, args.csv) if args.csv else None
    kin = Kinematics(robot)
    if args.ik is not None and args.ik not in kin.ik_frames:
        have = ", ".join(kin.ik_frames) or "none: run `derive generate` for the generated IK"
        raise DeriveError(f"view {robot.name}: --ik {args.ik}: no generated ik_{args.ik} (frames with IK: {have})")
    geo = geometry(robot, kin)
    parts = [] if args.no_meshes else visual_parts(robot, geo.frames, lambda line: print(line, file=sys.stderr))
    if args.html is None:
        serve(robot, kin, geo, q0, trajectory, args.host, args.port, args.ik,
              lambda line: print(line, flush=True), parts)
        return 0
    if trajectory is None:
        poses, times = kin.poses(q0)[None], None
        note = f"q = ({', '.join(f'{x:.4g}' for x in q0)})"
    else:
        shown = frames_to_show(trajectory)
        poses = np.array([kin.poses(trajectory.q[k]) for k in shown])
        times = trajectory.t[shown]
        note = f"{Path(args.csv).name}: {len(trajectory.t)} samples, {times[0]:g} .. {times[-1]:g} s"
    text = render_page(geo, poses, times, note=f"{note}; poses from the {kin.source}", parts=parts)
    path = write_atomically(Path(args.html), text, "viewer page")
    triangles = sum(len(p.faces) for p in parts)
    meshes = "" if not parts else f", {triangles} mesh triangles" + (
        f" thinned to at most {PAGE_TRIANGLES}" if triangles > PAGE_TRIANGLES else "")
    print(f"wrote {path} ({len(text.encode()) / 1024:.0f} KiB{'' if times is None else f', {len(times)} frames'}{meshes})")
    return 0
