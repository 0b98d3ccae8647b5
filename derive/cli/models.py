"""Commands on models files: ``derive info``, ``derive import-urdf`` and ``derive import-mjcf``."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import numpy as np

from derive.cli.common import path_arg, robots_of
from derive.description.closure import closure_note
from derive.description.mjcf import GENERATOR as MJCF_GENERATOR, import_mjcf_named
from derive.description.model import parse_robot
from derive.description.robot import FUNCTION_QUANTITIES
from derive.description.xacro_expand import EXTRA as XACRO_EXTRA
from derive.description.urdf import ERD_PREFIX, append_entry, dump_entry, import_urdf_named, relock_command, resolve_urdf
from derive.reference import NumericRobot


def warn_unmoved(name: str, entry: dict, shown: str, samples: int = 3) -> None:
    """One warning line if an imported entry has a coordinate that moves no mass or inertia (M(q) singular
    at every q: ``derive generate`` leaves out forward dynamics and the ODE, or refuses it with --strict; e.g. a
    massless path to a --tip),
    with the import command that locks its joint.

    The numeric reference's M(q) at ``samples`` seeded configurations, as
    :func:`derive.codegen.checks.check_mass_matrix` judges it: a diagonal entry at most 1e-12 of the largest.
    """
    robot = parse_robot(name, entry)
    ref = NumericRobot(robot)
    rng = np.random.default_rng(0)
    diag = np.min([np.diag(ref.crba(ref.random_configuration(rng))) for _ in range(samples)], axis=0)
    scale = max(float(np.max(np.abs(diag), initial=0.0)), 1e-300)
    joint_diag = diag[robot.nv - len(robot.joint_coordinates):]  # a floating base's six come first
    still = [c for c, d in zip(robot.joint_coordinates, joint_diag) if d <= 1e-12 * scale]
    if still:
        c = still[0]
        joints = list(dict.fromkeys(x.joint for x in still))
        others = f" (and {len(still) - 1} more)" if len(still) > 1 else ""
        relock = relock_command(entry.get("source", ""), joints)
        print(f"warning: {shown}: robot '{name}': joints ({c.joint}): coordinate '{c.name}'{others} moves no mass or "
              "inertia: M(q) is singular, so `derive generate` leaves out forward dynamics and the ODE (--strict refuses "
              "the robot); give the links "
              "it moves a mass in the URDF" + (f", or lock {'them' if len(joints) > 1 else 'it'}: {relock}" if relock else ""),
              file=sys.stderr)


def note_big(name: str, entry: dict, shown: str) -> None:
    """One line if an imported robot is big (:attr:`~derive.description.robot.Robot.big`): which frames
    ``derive generate`` gives per-frame functions by default, what it leaves out, and how to ask for more."""
    robot = parse_robot(name, entry)
    if not robot.big:
        return
    size = f"{len(robot.frames)} named frames, {len(robot.link_names)} links, nv = {robot.nv}"
    frames = robot.default_frames
    lean = robot.function_quantities
    left = [q for q in FUNCTION_QUANTITIES if q not in lean] if lean is not None else []
    print(f"note: {shown}: robot '{name}' is big ({size}): by default `derive generate` gives the per-frame functions "
          f"(fk_<frame>, jacobian_<frame>, ...) to {len(frames)} frames (the tcp, wrench frames and leaves: "
          f"{', '.join(frames)}; fk_all "
          "places every link)" + (f" and leaves out {', '.join(left)}" if left else "") + "; for more, add to its entry "
          "generate: {frames: all" + (", quantities: all" if left else "") + "} (or lists of frames and quantities)",
          file=sys.stderr)


def relative_meshes(entry: dict, models: str) -> dict:
    """``entry`` with its absolute mesh files written relative to the folder of the models file ``models``
    (what the viewer resolves them against): the models file and the meshes can move together."""
    folder = Path(os.path.abspath(models)).parent
    for link in entry.get("links", []):
        for item in link.get("visual", []):
            mesh = item.get("mesh")
            if mesh and Path(mesh).is_absolute():
                try:
                    item["mesh"] = Path(os.path.relpath(mesh, folder)).as_posix()
                except ValueError:  # another drive (Windows): stays absolute
                    pass
    return entry


def _write(args, name: str, entry: dict, generator: str = "derive import-urdf") -> str:
    """Append (or with --replace, replace in place) ``entry`` in ``args.out``: the line that says which."""
    entry = relative_meshes(entry, args.out)
    done = append_entry(args.out, name, entry, replace=bool(getattr(args, "replace", False)), generator=generator)
    return f"{done} robot '{name}' {'in' if done == 'replaced' else 'to'} {args.out}"


def cmd_import_urdf(args) -> int:
    """``derive import-urdf FILE [--tip LINK | --chain LINK] [--lock J,...] [--floating] [--no-friction]
    [--fix-inertia] [--snap-angles TOL] [--name NAME] [--arg NAME=VALUE ...] [--package-path NAME=DIR ...] [--out models.yaml]``."""
    name, entry = import_urdf_named(args.file, getattr(args, "tip", None), lock=getattr(args, "lock", None),
                                    name=getattr(args, "name", None), chain=getattr(args, "chain", None),
                                    floating=bool(getattr(args, "floating", False)),
                                    friction=not getattr(args, "no_friction", False),
                                    fix_inertia=bool(getattr(args, "fix_inertia", False)),
                                    xacro_args=getattr(args, "xacro_arg", None),
                                    package_paths=getattr(args, "package_path", None),
                                    snap_angles=getattr(args, "snap_angles", None),
                                    visuals=not getattr(args, "no_visuals", False))
    warn_unmoved(name, entry, resolve_urdf(args.file, name)[1])
    note_big(name, entry, resolve_urdf(args.file, name)[1])
    if args.out:
        print(_write(args, name, entry), file=sys.stderr)
    else:
        sys.stdout.write(dump_entry(name, entry))
    return 0


def cmd_import_mjcf(args) -> int:
    """``derive import-mjcf FILE [--floating | --fixed] [--no-actuators] [--independent J,...] [--keyframe NAME]
    [--name NAME] [--out models.yaml]``."""
    independent = [x.strip() for x in args.independent.split(",") if x.strip()] if args.independent else None
    name, entry = import_mjcf_named(args.file, name=args.name, floating=args.floating,
                                    actuators=not args.no_actuators, independent=independent,
                                    keyframe=args.keyframe, visuals=not args.no_visuals)
    warn_unmoved(name, entry, args.file)
    note_big(name, entry, args.file)
    if args.out:
        print(_write(args, name, entry, MJCF_GENERATOR), file=sys.stderr)
    else:
        sys.stdout.write(dump_entry(name, entry, generator=MJCF_GENERATOR))
    return 0


def cmd_info(args) -> int:
    robots = robots_of(args)
    for name in args.robot or robots:
        r = robots[name]
        base = f", nv = {r.nv}, floating base ({', '.join(c.name for c in r.base_coordinates)})" if r.floating else ""
        print(f"{r.name}: nq = {r.nq}{base}, joints {', '.join(j.summary for j in r.moving_joints)}")
        own = {j.name: a for j, a in r.mimic_actuators}
        for j in r.moving_joints:
            if j.mimic is not None:
                friction = (f"; its own actuator (viscous {own[j.name].viscous}, coulomb {own[j.name].coulomb}, armature "
                            f"{own[j.name].armature}) acts on {j.mimic.joint} through the mimic map") if j.name in own else ""
                print(f"  mimic: {j.name} = {j.mimic.multiplier:g} {j.mimic.joint} + {j.mimic.offset:g} (no entry in q)"
                      + friction)
        if r.loops:
            print(f"  closed chain: {closure_note(r)}")
            for i, lp in enumerate(r.loops):
                print(f"  loops[{i}]: {lp.summary}")
        for j in r.moving_joints:
            if j.gimbal_lock:
                print(f"  gimbal lock: {j.gimbal_lock}")
        named = [f.name + (" (alias " + ", ".join(f.aliases) + ")" if f.aliases else "") for f in r.frames]
        print(f"  frames: {', '.join(named)}")
        selection = r.selection
        if "frames" in selection:
            print(f"  per-frame functions for: {', '.join(r.function_frames)} ({selection['frames']}; "
                  "fk_all places every link)")
        if "quantities" in selection:
            print(f"  generated quantities: {', '.join(r.function_quantities)} ({selection['quantities']})")
        if r.wrench_frames:
            print(f"  wrench frames (the *_fext functions): {', '.join(r.wrench_frames)}")
        if r.contacts:
            print(f"  contacts: {', '.join(f'{c.frame} ({c.kind})' for c in r.contacts)}; stances (contact_dynamics_<name>, "
                  f"...): {'; '.join(f'{s.name}: ' + ', '.join(s.frames) for s in r.stances)}")
        if r.parameters:
            print(f"  parameters: {', '.join(f'{p.name} = {p.default:g}' for p in r.parameters)}")
        if r.source:
            print(f"  source: {r.source}")
    return 0



REPLACE_HELP = ("with --out: replace a robot of the same name in place (its lines and the generated comments above "
                "them; the other robots and comments stay as they are) instead of refusing it")


def add_parser(sub) -> None:
    u = sub.add_parser("import-urdf", help="turn a URDF into a models.yaml entry",
                       description="Convert a URDF into a models.yaml robot entry (printed, or appended with --out): "
                                   "every moving joint of the tree (depth-first, Pinocchio's order) unless locked; "
                                   "links behind fixed joints become named frames; moving branches without any mass "
                                   "are dropped (named in the description). "
                                   f"FILE may be '{ERD_PREFIX}<path under robots/>' for the installed "
                                   "example-robot-data URDFs. A xacro file (a .xacro name, or xacro elements or substitutions in it) is "
                                   f"expanded first, without ROS (needs the extra: {XACRO_EXTRA}).")
    u.add_argument("file", metavar="FILE", type=path_arg)
    u.add_argument("--tip", metavar="LINK", help="URDF link that becomes the frame 'tcp' (none without it)")
    u.add_argument("--chain", metavar="LINK", help="import only the root-to-LINK chain (the frame 'tcp' at LINK): "
                                                   "moving branches off it with mass must be locked, massless ones are dropped "
                                                   "(--tip, if given too, must name the same link)")
    u.add_argument("--lock", metavar="JOINT[=VALUE],...", help="joints to make fixed (default value 0)")
    u.add_argument("--no-friction", action="store_true",
                   help="ignore the URDF's <dynamics damping friction> (by default: viscous and Coulomb friction)")
    u.add_argument("--fix-inertia", action="store_true",
                   help="repair impossible inertias instead of refusing them, with one warning per link on stderr: a "
                        "massless link's inertia becomes zero; one that is not positive semi-definite or breaks the "
                        "triangle inequality becomes the nearest physical one (negative principal moments -> 0, the "
                        "two smaller raised equally until I1 + I2 >= I3)")
    u.add_argument("--snap-angles", metavar="TOL", type=float,
                   help="make every constant angle within TOL rad of a multiple of pi/2 exactly that multiple (e.g. "
                        "1e-4 for 1.5708 and 3.1416); by default angles are kept as written and those within 1e-4 of one "
                        "are listed in a warning")
    u.add_argument("--floating", action="store_true",
                   help="floating base: the URDF root link moves freely (base: floating, Pinocchio's JointModelFreeFlyer)")
    u.add_argument("--no-visuals", action="store_true",
                   help="leave out the links' <visual> meshes and shapes (by default each link keeps them as its "
                        "visual: list, for derive view; mesh files resolved now, written relative to --out)")
    u.add_argument("--arg", dest="xacro_arg", action="append", metavar="NAME=VALUE",
                   help="a xacro argument (xacro's NAME:=VALUE); repeat for more")
    u.add_argument("--package-path", dest="package_path", action="append", metavar="NAME=DIR",
                   help="the folder of ROS package NAME, for the xacro file's $(find NAME) and package://NAME; "
                        "repeat for more")
    u.add_argument("--name", help="robot name (default: the URDF robot name made a C identifier)")
    u.add_argument("--out", metavar="MODELS", type=path_arg,
                   help="append to this models file instead of printing (created if missing; written atomically: on "
                        "any failure the file is left as it was)")
    u.add_argument("--replace", action="store_true", help=REPLACE_HELP)
    u.set_defaults(func=cmd_import_urdf)

    # A command of its own rather than import-urdf guessing the format: the options differ (no --tip,
    # --chain, --lock, --fix-inertia: MuJoCo's compiler has already checked the file), the reader needs
    # the optional mujoco package, and import-urdf on a <mujoco> file names this command.
    x = sub.add_parser("import-mjcf", help="turn an MJCF (MuJoCo) file into a models.yaml entry",
                       description="Convert an MJCF file into a models.yaml robot entry (printed, or appended with "
                                   "--out), read from the model MuJoCo's own compiler builds (defaults, classes, "
                                   "includes and frames resolved): bodies, hinge/slide/ball/free joints, inertials, "
                                   "named sites as frames, armature/damping/frictionloss and gears as actuators, "
                                   "linear joint couplings as mimic joints, connect/weld equalities as closed-chain "
                                   "loops (point/weld). Needs the mujoco package "
                                   "(pip install 'derive-robotics[mjcf]').")
    x.add_argument("file", metavar="FILE", type=path_arg)
    base = x.add_mutually_exclusive_group()
    base.add_argument("--floating", dest="floating", action="store_const", const=True, default=None,
                      help="floating base (default: as the file says, i.e. where its top-level body has a free joint)")
    base.add_argument("--fixed", dest="floating", action="store_const", const=False,
                      help="fixed base: a free body is welded to the world at its initial pose")
    x.add_argument("--no-actuators", action="store_true",
                   help="leave out armature, damping, frictionloss and actuator gears (ideal joints)")
    x.add_argument("--independent", metavar="JOINT,...",
                   help="a closed chain's independent coordinates y (e.g. the motors; default: chosen by pivoting on "
                        "the constraint Jacobian at MuJoCo's qpos0, actuated joints kept independent where possible)")
    x.add_argument("--keyframe", metavar="NAME",
                   help="a closed chain's reference configuration: this keyframe's qpos (default: the keyframe named "
                        "'reference' where there is one, as derive export writes it, else qpos0)")
    x.add_argument("--no-visuals", action="store_true",
                   help="leave out the visible geoms (by default each link keeps its meshes and shapes as its visual: "
                        "list, for derive view)")
    x.add_argument("--name", help="robot name (default: the MJCF model name made a C identifier)")
    x.add_argument("--out", metavar="MODELS", type=path_arg,
                   help="append to this models file instead of printing (created if missing; written atomically)")
    x.add_argument("--replace", action="store_true", help=REPLACE_HELP)
    x.set_defaults(func=cmd_import_mjcf)

    i = sub.add_parser("info", help="summarise robots of models.yaml")
    i.add_argument("robot", nargs="*")
    i.set_defaults(func=cmd_info)
