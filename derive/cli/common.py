"""What every command module shares: reading the robots a command names, checking option values, progress lines."""

from __future__ import annotations

import argparse
import math
import os
import re
import sys
import time
from pathlib import Path

from derive.description import expr
from derive.description.model import default_models_path, load_models
from derive.description.robot import ModelError
from derive.errors import DeriveError


def robots_of(args) -> dict:
    """The robots of ``args.models`` (all, checked against ``args.robot`` when given)."""
    robots = load_models(args.models)
    if getattr(args, "robot", None):
        missing = [r for r in args.robot if r not in robots]
        if missing:
            source = args.models or default_models_path()
            raise ModelError(missing[0], "robots", f"no such robot in {source} (known: {', '.join(robots)})")
    return robots


def path_arg(text: str) -> str:
    """argparse ``type=`` of a file or folder argument: an empty or blank path is refused (it would
    otherwise read as "not given" and fall back to the default)."""
    if not text.strip():
        raise argparse.ArgumentTypeError("empty path")
    return text


# --------------------------------------------------------------------------- option values
# Shared by the command modules: argparse parses (``type=``), these check the
# range of a value in one line that names the option, before any work is done.

SEED_LIMIT = 2**64
"""Seeds are integers in [0, SEED_LIMIT): numpy's generators take no negative seed."""
PROGRESS_INTERVAL = 2.0
"""Seconds between two progress lines on stderr (the first comes after that long: short work prints none)."""


def integer(text: str) -> int:
    """argparse ``type=`` of a count or a seed: an integer, also written 1e6 (an integral number)."""
    try:
        return int(text)
    except ValueError:
        pass
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if not (math.isfinite(value) and value == int(value)):
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}")
    return int(value)


def png_path(text: str) -> str:
    """argparse ``type=`` of a ``--png`` option: a file name ending in .png, not a folder.

    "wsplot" or "w.txt" (matplotlib would pick the format from the suffix, or add one), "DIR/" and an
    existing folder are refused in one line, so "wrote X" always names the very file written.
    """
    text = path_arg(text)
    if text.endswith(("/", os.sep)) or os.path.isdir(text):
        raise argparse.ArgumentTypeError(f"{text!r} is a folder: give a file name ending in .png")
    if Path(text).suffix.lower() != ".png":
        raise argparse.ArgumentTypeError(f"{text!r} does not end in .png (the figure is a PNG)")
    return text


def check_count(value: int, option: str, least: int | None, most: int, why: str = "", who: str = "") -> int:
    """``value`` if least <= value <= most (``least`` None: the domain checks it); else a DeriveError
    naming ``who`` (e.g. "robot 'panda'"), ``option`` and why there is a limit."""
    where = f"{who}: " if who else ""
    if least is not None and value < least:
        raise DeriveError(f"{where}{option} must be at least {least}, got {value}")
    if value > most:
        raise DeriveError(f"{where}{option} must be at most {most}{f' ({why})' if why else ''}, got {value}")
    return value


def check_seed(value: int, option: str = "--seed") -> int:
    """``value`` if it is a seed numpy takes (0 <= seed < 2^64); else a DeriveError naming ``option``."""
    if not 0 <= value < SEED_LIMIT:
        raise DeriveError(f"{option} must be an integer from 0 to 2^64 - 1, got {value}")
    return value


def check_number(value: float | None, option: str, least: float | None = None, most: float | None = None,
                 strict: bool = False, unit: str = "", who: str = "") -> float | None:
    """``value`` (None passes) if finite and within [least, most] (``strict``: value > least); else a
    DeriveError naming ``who`` and ``option``."""
    if value is None:
        return None
    where = f"{who}: " if who else ""
    bounds = []
    if least is not None:
        bounds.append(f"{'>' if strict else '>='} {least:g}")
    if most is not None:
        bounds.append(f"<= {most:g}")
    ok = math.isfinite(value) and (least is None or (value > least if strict else value >= least)) \
        and (most is None or value <= most)
    if not ok:
        raise DeriveError(f"{where}{option} must be a finite number{' ' + ' and '.join(bounds) if bounds else ''}"
                          f"{' ' + unit if unit else ''}, got {value:g}")
    return value


# --------------------------------------------------------------------------- vectors
# One convention for every vector option (ik --xyz, simulate --q0, trajopt --from, plan --start...):
# the values may be given as separate words (--q0 1 2 3), comma-separated (--q0 1,2,3) or both,
# quoted or not (--q0 "1, 2, 3"), each a number or an expression of pi ("pi/2", "-3*pi/4").

NEGATIVE = re.compile(r"^-(\.?\d|pi\b)")
"""What argparse must read as a value, not an option: "-1,2", "-1e-3", "-pi/2" (Python 3.11's own test
takes only plain negative numbers such as "-1" and "-0.5"; later versions widened it the same way)."""


def number(text: str) -> float:
    """One value of a vector: a float ("1e-3", "nan" passes, for the command to name it) or an expression of pi."""
    try:
        return float(text)
    except ValueError:
        pass
    try:
        return float(expr.evaluate(text, {}))
    except Exception:  # noqa: BLE001 (any parse error: not a number)
        raise ValueError(text) from None


def parse_vector(pieces: str | list[str], option: str, count: int | None = None, names: tuple[str, ...] = ()) -> list[float]:
    """The numbers of ``pieces`` (words of the command line, each holding values separated by commas
    and/or blanks); a DeriveError naming ``option`` for a value that is not a number or, ``count``
    given, a wrong number of values (``names`` says which)."""
    text = (pieces if isinstance(pieces, str) else " ".join(pieces)).strip()
    parts = [part.strip() for part in text.split(",")]
    if len(parts) > 1 and not all(parts):
        raise DeriveError(f"{option}: an empty value in {text!r} (values separated by commas or blanks)")
    words = [w for part in parts for w in part.split()]
    values = []
    for w in words:
        try:
            values.append(number(w))
        except ValueError:
            raise DeriveError(f"{option}: {w!r} is not a number (values separated by commas or blanks; "
                              "pi allowed: pi/2)") from None
    if count is not None and len(values) != count:
        what = f" ({' '.join(names)})" if names else ""
        raise DeriveError(f"{option} needs {count} values{what}, got {len(values)}")
    if not values:
        raise DeriveError(f"{option}: no values")
    return values


class Vector(argparse.Action):
    """argparse action of a vector option: ``nargs="+"`` words parsed by :func:`parse_vector` into a
    list of floats; ``count`` fixes the length (checked here), else the command checks it."""

    def __init__(self, option_strings, dest, count: int | None = None, names: tuple[str, ...] = (), **kwargs):
        kwargs.setdefault("nargs", "+")
        if names and "metavar" not in kwargs:
            kwargs["metavar"] = " ".join(names)
        self.count, self.names = count, tuple(names)
        super().__init__(option_strings, dest, **kwargs)

    def __call__(self, parser, namespace, values, option_string=None):
        try:
            setattr(namespace, self.dest, parse_vector(values, option_string or self.dest, self.count, self.names))
        except DeriveError as exc:
            raise argparse.ArgumentError(None, str(exc)) from None


class HelpFormatter(argparse.HelpFormatter):
    """argparse's formatter, with a vector option shown as "--xyz X Y Z" or "--q0 Q0..." (not
    "--q0 Q0 [Q0 ...]")."""

    def _format_args(self, action, default_metavar):
        if isinstance(action, Vector):
            metavar = action.metavar or default_metavar
            return metavar if action.count is not None else f"{metavar}..."
        return super()._format_args(action, default_metavar)


def vector_help(text: str) -> str:
    """``text`` followed by the vector convention, for an option's help."""
    return f"{text} (separated by blanks or commas; pi/2 allowed)"


class Progress:
    """Progress lines on stderr, "<what>: 40 % (...)", at most one every PROGRESS_INTERVAL seconds."""

    def __init__(self, what: str):
        self.what = what
        self.next = time.monotonic() + PROGRESS_INTERVAL

    def __call__(self, done: float, total: float = 1.0, detail: str = "") -> None:
        now = time.monotonic()
        if now < self.next or total <= 0:
            return
        self.next = now + PROGRESS_INTERVAL
        print(f"{self.what}: {100 * done / total:.0f} %{f' ({detail})' if detail else ''}", file=sys.stderr, flush=True)
