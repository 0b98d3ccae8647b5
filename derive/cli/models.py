"""Commands on models files: ``derive info`` and ``derive import-urdf``."""

from __future__ import annotations

from derive.cli.common import robots_of
from derive.description.urdf import import_urdf_command


def cmd_import_urdf(args) -> int:
    return import_urdf_command(args) or 0


def cmd_info(args) -> int:
    robots = robots_of(args)
    for name in args.robot or robots:
        r = robots[name]
        print(f"{r.name}: nq = {r.nq}, joints {', '.join(j.summary for j in r.moving_joints)}")
        for j in r.moving_joints:
            if j.gimbal_lock:
                print(f"  gimbal lock: {j.gimbal_lock}")
        print(f"  frames: {', '.join(f.name for f in r.frames)}")
        if r.parameters:
            print(f"  parameters: {', '.join(f'{p.name} = {p.default:g}' for p in r.parameters)}")
        if r.source:
            print(f"  source: {r.source}")
    return 0



def add_parser(sub) -> None:
    u = sub.add_parser("import-urdf", help="turn a URDF into a models.yaml entry")
    u.add_argument("file")
    u.add_argument("--tip", required=True, help="link that becomes the 'tcp' frame")
    u.add_argument("--lock", help="joints to lock, comma-separated (JOINT or JOINT=VALUE)")
    u.add_argument("--name", help="robot name (default: the URDF's, made a C identifier)")
    u.add_argument("--out", help="append the entry to this models file instead of printing it")
    u.set_defaults(func=cmd_import_urdf)

    i = sub.add_parser("info", help="summarise robots of models.yaml")
    i.add_argument("robot", nargs="*")
    i.set_defaults(func=cmd_info)
