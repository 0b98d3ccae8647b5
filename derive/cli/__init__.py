"""Command line: ``derive <command>`` (also ``python -m derive``).

Each command group is one module of this package with ``add_parser(subparsers)``
(argument parsing and printing only; the work is done by the domain packages).
Bad input ends with one line on stderr naming the robot, the field and the
problem, exit status 2, and no traceback; nothing is written.
"""

from __future__ import annotations

import argparse
import importlib
import os
import sys

from derive.errors import DeriveError

COMMAND_MODULES: list[str] = ["derive.cli.generate", "derive.cli.models", "derive.cli.inspect", "derive.cli.analysis",
                              "derive.cli.solvers", "derive.cli.bench"]
"""The command groups; imported when the parser is built."""


class UsageError(DeriveError):
    """A command line argparse rejects (unknown option, missing or malformed value)."""


class ArgumentParser(argparse.ArgumentParser):
    """argparse, but a bad command line is one line too (not usage + error): exit status 2."""

    def error(self, message: str):
        command = self.prog.partition(" ")[2]
        raise UsageError(f"{command + ': ' if command else ''}{message} (see `{self.prog} --help`)")


def build_parser() -> argparse.ArgumentParser:
    parser = ArgumentParser(prog="derive", description=__doc__.splitlines()[0])
    models_help = "models file (default: $DERIVE_MODELS, else ./models.yaml, else the shipped example robots)"
    parser.add_argument("--models", help=models_help)
    # --models is accepted after the subcommand too: every subparser inherits it
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--models", default=argparse.SUPPRESS, help=models_help)
    sub = parser.add_subparsers(dest="command", required=True)
    add_parser = sub.add_parser
    sub.add_parser = lambda *a, **k: add_parser(*a, parents=[common, *k.pop("parents", [])], **k)
    for module in COMMAND_MODULES:
        importlib.import_module(module).add_parser(sub)
    return parser


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
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


if __name__ == "__main__":
    sys.exit(main())
