"""Command line: derive <command> (also python -m derive).

Each command group is one module of this package with ``add_parser(subparsers)``
(argument parsing and printing only; the work is done by the domain packages).
Bad input ends with one line on stderr naming the robot, the field and the
problem, exit status 2, and no traceback; nothing is written.

SIGINT (Ctrl-C), SIGTERM and SIGHUP end every command within a fraction of a second with
130, 143 or 129, nothing left behind (see :mod:`derive.cli.signals`).
"""

from __future__ import annotations

import argparse
import importlib
import os
import signal
import sys

import derive
from derive.cli.common import NEGATIVE, HelpFormatter
from derive.cli.signals import MESSAGES, EndOnSignals
from derive.errors import DeriveError

COMMANDS: dict[str, str] = {
    "generate": "derive.cli.generate", "init": "derive.cli.generate",
    "import-urdf": "derive.cli.models", "import-mjcf": "derive.cli.models", "info": "derive.cli.models",
    "export": "derive.cli.export", "export-casadi": "derive.cli.casadi_export",
    "eom": "derive.cli.inspect", "latex": "derive.cli.inspect",
    "dof": "derive.cli.analysis", "fk": "derive.cli.analysis", "workspace": "derive.cli.analysis",
    "singularities": "derive.cli.analysis", "manipulability": "derive.cli.analysis", "plan": "derive.cli.analysis",
    "simulate": "derive.cli.solvers", "ik": "derive.cli.solvers", "trajopt": "derive.cli.solvers",
    "identify": "derive.cli.identify", "base-parameters": "derive.cli.identify", "excite": "derive.cli.identify",
    "firmware-check": "derive.cli.firmware", "bench": "derive.cli.bench", "view": "derive.cli.view",
}
"""Command -> the module that adds it (tests/test_conventions.py checks it against the full parser). A
command line that names one builds the parser of that command alone: the others' modules import
CasADi, sympy and matplotlib, about a second of CPU before the first line of work (or of error)."""

COMMAND_MODULES: list[str] = list(dict.fromkeys(COMMANDS.values()))
"""The command groups, in the order ``derive --help`` lists their commands."""


def _command_of(argv: list[str]) -> str | None:
    """The command ``argv`` names (its first word that is neither an option nor --models' value);
    None where it names none ("--version" alone, "--help", nothing)."""
    words = iter(argv)
    for word in words:
        if word == "--models":
            next(words, None)
        elif not word.startswith("-"):
            return word
    return None


class UsageError(DeriveError):
    """A command line argparse rejects (unknown option, missing or malformed value)."""


class ArgumentParser(argparse.ArgumentParser):
    """argparse, but a bad command line is one line too (not usage + error): exit status 2."""

    def __init__(self, *args, **kwargs):
        kwargs.setdefault("formatter_class", HelpFormatter)
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = NEGATIVE  # "-1,2" and "-pi/2" are values of a vector option

    def error(self, message: str):
        command = self.prog.partition(" ")[2]
        raise UsageError(f"{command + ': ' if command else ''}{message} (see `{self.prog} --help`)")


def build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """The command line's parser: every command's, or where ``argv`` names a known command (or asks only
    for --version), just what parsing it needs."""
    parser = ArgumentParser(prog="derive", description="Symbolic derivation and code generation for robot "
                            "manipulators. `derive COMMAND --help` explains a command.")
    models_help = "models file (default: $DERIVE_MODELS, else ./models.yaml, else the shipped example robots)"
    parser.add_argument("--models", help=models_help)
    parser.add_argument("--version", action="version", version=f"derive {derive.__version__}")
    # --models is accepted after the subcommand too: every subparser inherits it
    common = argparse.ArgumentParser(add_help=False)
    common.add_argument("--models", default=argparse.SUPPRESS, help=models_help)
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND", title="commands")
    add_parser = sub.add_parser
    sub.add_parser = lambda *a, **k: add_parser(*a, parents=[common, *k.pop("parents", [])], **k)
    command = None if argv is None else _command_of(argv)
    if command in COMMANDS:
        modules = [COMMANDS[command]]
    elif argv is not None and command is None and "--version" in argv and not {"-h", "--help"} & set(argv):
        modules = []
    else:
        modules = COMMAND_MODULES
    for module in modules:
        importlib.import_module(module).add_parser(sub)
    return parser


# ---- signals: SIGINT, SIGTERM (and SIGHUP) end every command at once ----
#
# What runs when a signal arrives: CPython's C-level handler only sets a flag and writes the
# signal's number to the wakeup fd; the Python handler runs later, in the main thread, at the
# next bytecode boundary or wherever C code calls PyErr_CheckSignals. Inside CasADi that is too
# late or never: IPOPT's iteration callback calls it and turns the KeyboardInterrupt into a
# failed solve (the IK restarts and exits 0, or exit 1 "after -2033791744 iterations"), and
# pure C++ work (a jacobian, a Function of a big graph, a fold) never calls it, for seconds or
# minutes. So the Python handler does not raise: it ends the process itself (_end). For C code
# that stays away from Python, a watchdog thread waits on the wakeup fd and ends the process
# GRACE s after the signal if the main thread has not; it can, because CasADi's SWIG layer
# releases the GIL around its C++ calls (as numpy's loops, ctypes' CDLL calls and waits do).


def main(argv: list[str] | None = None) -> int:
    """Run one command. Exit status: 0 done, 1 ran but found no solution (or stale output for
    ``generate --check``), 2 bad input (one line on stderr), 3 a fault
    of derive itself (one line; DERIVE_DEBUG=1 shows the traceback), 130 / 143 / 129 ended by SIGINT /
    SIGTERM / SIGHUP."""
    ending = EndOnSignals()
    try:
        argv = sys.argv[1:] if argv is None else list(argv)
        args = build_parser(argv).parse_args(argv)
        return args.func(args)
    except DeriveError as exc:
        print(f"derive: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # main() called from another thread: no handler of ours
        print(MESSAGES[signal.SIGINT].decode().rstrip(), file=sys.stderr)
        return 128 + signal.SIGINT
    except BrokenPipeError:  # output piped into `head` and friends: stop quietly
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except OSError as exc:  # a file the command writes or reads: name it
        where = f"{exc.filename}: " if exc.filename else ""
        print(f"derive: error: {where}{exc.strerror or exc}", file=sys.stderr)
        return 2
    except (RecursionError, MemoryError) as exc:
        print(f"derive: error: the input is too large or too deeply nested ({type(exc).__name__})", file=sys.stderr)
        return 2
    except Exception as exc:  # noqa: BLE001 (the promise is one line, never a traceback)
        if os.environ.get("DERIVE_DEBUG"):
            raise
        text = " ".join(str(exc).split())[:300]
        print(f"derive: internal error: {type(exc).__name__}: {text} (a bug in derive: please report it with the "
              "command; DERIVE_DEBUG=1 shows the traceback)", file=sys.stderr)
        return 3
    finally:
        ending.close()


if __name__ == "__main__":
    sys.exit(main())
