"""``derive export ROBOT --urdf FILE --mjcf FILE``: a models.yaml robot as URDF and/or MJCF."""

from __future__ import annotations

import sys
from pathlib import Path

from derive.cli.common import path_arg
from derive.description.export import export_mjcf, export_urdf
from derive.description.model import load_robot
from derive.errors import DeriveError
from derive.filesystem import write_atomically


def check_output(path: str, what: str) -> None:
    """Refuse, before anything is written, a path that cannot take a file: a folder, or below a non-folder."""
    if path == "-":
        return
    if Path(path).is_dir():
        raise DeriveError(f"{path}: cannot write {what} (is a folder); it is left as it was")
    parent = Path(path).parent
    if not parent.is_dir():
        raise DeriveError(f"{path}: cannot write {what} ({parent} is not a folder)")


def cmd_export(args) -> int:
    """Both documents are built and both paths checked before either is written; each is written
    atomically ("-": printed)."""
    if args.urdf is None and args.mjcf is None:
        raise DeriveError(f"export {args.robot_name}: give --urdf FILE and/or --mjcf FILE")
    robot = load_robot(args.robot_name, args.models)
    for path, what in ((args.urdf, "URDF"), (args.mjcf, "MJCF")):
        if path is not None:
            check_output(path, what)
    out = [(fmt, path, export(robot)) for fmt, path, export in (("URDF", args.urdf, export_urdf),
                                                                 ("MJCF", args.mjcf, export_mjcf)) if path is not None]
    for fmt, _, exported in out:
        for note in exported.notes:
            print(f"note: robot '{robot.name}': {fmt}: {note}", file=sys.stderr)
    for fmt, path, exported in out:
        if path == "-":
            sys.stdout.write(exported.text)
            continue
        write_atomically(path, exported.text, fmt)
        print(f"wrote {path}", file=sys.stderr)
    return 0


def add_parser(sub) -> None:
    e = sub.add_parser("export", help="write a robot as URDF and/or MJCF",
                       description="Write a models.yaml robot as URDF (--urdf) and/or MJCF (--mjcf), every parameter "
                                   "at its default. What a format cannot hold (URDF: gravity, rotor inertia; MJCF: "
                                   "velocity limits) is a comment in the file and a warning line. FILE '-' prints.")
    e.add_argument("robot_name", metavar="ROBOT")
    e.add_argument("--urdf", metavar="FILE", type=path_arg, help="the URDF to write (derive import-urdf reads it back)")
    e.add_argument("--mjcf", metavar="FILE", type=path_arg, help="the MJCF to write (MuJoCo's MjModel.from_xml_path "
                                                                  "loads it)")
    e.set_defaults(func=cmd_export)
