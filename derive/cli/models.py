"""Commands on models files: ``derive info`` and ``derive import-urdf``."""

from __future__ import annotations

import sys

from derive.cli.common import robots_of
from derive.description.urdf import ERD_PREFIX, append_entry, dump_entry, import_urdf_named


def cmd_import_urdf(args) -> int:
    """``derive import-urdf FILE [--tip LINK | --chain LINK] [--lock J,...] [--floating] [--no-friction] [--name NAME] [--out models.yaml]``."""
    name, entry = import_urdf_named(args.file, getattr(args, "tip", None), lock=getattr(args, "lock", None),
                                    name=getattr(args, "name", None), chain=getattr(args, "chain", None),
                                    floating=bool(getattr(args, "floating", False)),
                                    friction=not getattr(args, "no_friction", False))
    if args.out:
        append_entry(args.out, name, entry)
        print(f"appended robot '{name}' to {args.out}", file=sys.stderr)
    else:
        sys.stdout.write(dump_entry(name, entry))
    return 0


def cmd_info(args) -> int:
    robots = robots_of(args)
    for name in args.robot or robots:
        r = robots[name]
        base = f", nv = {r.nv}, floating base ({', '.join(c.name for c in r.base_coordinates)})" if r.floating else ""
        print(f"{r.name}: nq = {r.nq}{base}, joints {', '.join(j.summary for j in r.moving_joints)}")
        for j in r.moving_joints:
            if j.mimic is not None:
                print(f"  mimic: {j.name} = {j.mimic.multiplier:g} {j.mimic.joint} + {j.mimic.offset:g} (no entry in q)")
        for j in r.moving_joints:
            if j.gimbal_lock:
                print(f"  gimbal lock: {j.gimbal_lock}")
        print(f"  frames: {', '.join(f.name for f in r.frames)}")
        if r.wrench_frames:
            print(f"  wrench frames (the *_fext functions): {', '.join(r.wrench_frames)}")
        if r.parameters:
            print(f"  parameters: {', '.join(f'{p.name} = {p.default:g}' for p in r.parameters)}")
        if r.source:
            print(f"  source: {r.source}")
    return 0



def add_parser(sub) -> None:
    u = sub.add_parser("import-urdf", help="turn a URDF into a models.yaml entry",
                       description="Convert a URDF into a models.yaml robot entry (printed, or appended with --out): "
                                   "every moving joint of the tree (depth-first, Pinocchio's order) unless locked; "
                                   "links behind fixed joints become named frames; moving branches without any mass "
                                   "are dropped (named in the description). "
                                   f"FILE may be '{ERD_PREFIX}<path under robots/>' for the installed "
                                   "example-robot-data URDFs.")
    u.add_argument("file", metavar="FILE")
    u.add_argument("--tip", metavar="LINK", help="URDF link that becomes the frame 'tcp' (none without it)")
    u.add_argument("--chain", metavar="LINK", help="import only the root-to-LINK chain (the frame 'tcp' at LINK): "
                                                   "moving branches off it with mass must be locked, massless ones are dropped "
                                                   "(--tip, if given too, must name the same link)")
    u.add_argument("--lock", metavar="JOINT[=VALUE],...", help="joints to make fixed (default value 0)")
    u.add_argument("--no-friction", action="store_true",
                   help="ignore the URDF's <dynamics damping friction> (by default: viscous and Coulomb friction)")
    u.add_argument("--floating", action="store_true",
                   help="floating base: the URDF root link moves freely (base: floating, Pinocchio's JointModelFreeFlyer)")
    u.add_argument("--name", help="robot name (default: the URDF robot name made a C identifier)")
    u.add_argument("--out", metavar="MODELS", help="append to this models file instead of printing (created if missing)")
    u.set_defaults(func=cmd_import_urdf)

    i = sub.add_parser("info", help="summarise robots of models.yaml")
    i.add_argument("robot", nargs="*")
    i.set_defaults(func=cmd_info)
