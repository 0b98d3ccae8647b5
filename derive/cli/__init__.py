"""Command line: ``derive <command>`` (also ``python -m derive``).

Bad input ends with one line on stderr naming the robot, the field and the
problem, exit status 2, and no traceback; nothing is written.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from derive.errors import DeriveError
from derive.resources import CHECKOUT
from derive.description.model import load_models
from derive.description.robot import ModelError

DEFAULT_OUT = CHECKOUT / "generated"


def _robots(args) -> dict:
    robots = load_models(args.models)
    if getattr(args, "robot", None):
        missing = [r for r in args.robot if r not in robots]
        if missing:
            raise ModelError(missing[0], "robots", f"no such robot in {args.models or 'models.yaml'} (known: {', '.join(robots)})")
    return robots


def cmd_generate(args) -> int:
    from derive.codegen.generate import check, generate

    robots = _robots(args)
    out = Path(args.out) if args.out else DEFAULT_OUT
    if args.check:
        problems = check({k: v for k, v in robots.items() if not args.robot or k in args.robot}, out)
        if args.robot:
            problems = [p for p in problems if any(f"/{r}/" in p or p.endswith(f"/{r}") for r in args.robot)]
        if problems:
            print(f"{out} is stale; run `make derive` (or `derive generate`). {len(problems)} problem(s):",
                  file=sys.stderr)
            for p in problems:
                print(f"  {p}", file=sys.stderr)
            return 1
        print(f"{out} is up to date with models.yaml ({len(robots)} robots)")
        return 0
    generate(robots, out, only=args.robot or None, use_cache=not args.no_cache,
             log=lambda s: print(s, flush=True))
    return 0


def cmd_import_urdf(args) -> int:
    from derive.description.urdf import import_urdf_command

    return import_urdf_command(args) or 0


def cmd_info(args) -> int:
    robots = _robots(args)
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


def cmd_eom(args) -> int:
    import sympy as sp

    from derive.inspect.sympy_model import load

    m = load(args.robot_name, args.models, method="newton-euler")
    quantities = {"M(q)": m.mass_matrix, "C(q, qd)": m.coriolis_matrix, "g(q)": m.gravity_vector}
    if m.nv <= 2:
        for label, value in quantities.items():
            print(f"{label} =\n{sp.pretty(value)}\n")
        return 0
    # written out, 3+ joints run to megabytes: print with common subexpressions instead
    subs, reduced = sp.cse(list(quantities.values()), symbols=sp.numbered_symbols("t"), optimizations="basic")
    print(f"# {m.robot.name}: {len(subs)} common subexpressions t_k, then M, C, g (newton-euler route)")
    for sym, value in subs:
        print(f"{sym} = {value}")
    for label, value in zip(quantities, reduced):
        print(f"\n{label} =\n{value}")
    return 0


class UsageError(DeriveError):
    """A command line argparse rejects (unknown option, missing or malformed value)."""


class ArgumentParser(argparse.ArgumentParser):
    """argparse, but a bad command line is one line too (not usage + error): exit status 2."""

    def error(self, message: str):
        command = self.prog.partition(" ")[2]
        raise UsageError(f"{command + ': ' if command else ''}{message} (see `{self.prog} --help`)")


def build_parser() -> argparse.ArgumentParser:
    parser = ArgumentParser(prog="derive", description=__doc__.splitlines()[0])
    models_help = "models file (default: models.yaml of the project, or $DERIVE_MODELS)"
    parser.add_argument("--models", help=models_help)
    # --models is accepted after the subcommand too: every subparser inherits it
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--models", default=argparse.SUPPRESS, help=models_help)
    sub = parser.add_subparsers(dest="command", required=True)
    add_parser = sub.add_parser
    sub.add_parser = lambda *a, **k: add_parser(*a, parents=[common, *k.pop("parents", [])], **k)

    g = sub.add_parser("generate", help="regenerate generated/ from models.yaml")
    g.add_argument("--robot", action="append", help="only this robot (repeatable)")
    g.add_argument("--out", help="output folder (default: generated/)")
    g.add_argument("--check", action="store_true", help="exit 1 and name the stale files if generated/ is out of date")
    g.add_argument("--no-cache", action="store_true", help="rederive every robot even if unchanged")
    g.set_defaults(func=cmd_generate)

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

    e = sub.add_parser("eom", help="print M, C and g of a robot (sympy)")
    e.add_argument("robot_name")
    e.set_defaults(func=cmd_eom)

    # Feature modules register their own subcommands: each has add_parser(subparsers),
    # which adds a parser with set_defaults(func=...). Imported lazily by name.
    import importlib

    for module in COMMAND_MODULES:
        importlib.import_module(module).add_parser(sub)
    return parser


COMMAND_MODULES: list[str] = ["derive.bench", "derive.analysis.grubler", "derive.analysis.workspace",
                              "derive.inspect.latex", "derive.solvers.simulate", "derive.solvers.ik",
                              "derive.analysis.singularity", "derive.analysis.manipulability",
                              "derive.analysis.planning", "derive.solvers.trajopt_examples"]
"""Modules under derive/ that contribute subcommands through add_parser(subparsers)."""


def main(argv: list[str] | None = None) -> int:
    try:
        args = build_parser().parse_args(argv)
        return args.func(args)
    except DeriveError as exc:
        print(f"derive: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("derive: interrupted; generated/ left as it was", file=sys.stderr)
        return 130
    except BrokenPipeError:  # output piped into `head` and friends: stop quietly
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


if __name__ == "__main__":
    sys.exit(main())
