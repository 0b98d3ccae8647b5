"""``derive generate`` and ``derive init``: a models file -> generated/ (C, Python, manifest)."""

from __future__ import annotations

import re
import sys
from pathlib import Path

from derive.cli.common import path_arg, robots_of
from derive.description.model import MODELS_FILE, load_models, local_models_path
from derive.errors import DeriveError
from derive.filesystem import write_atomically
from derive.resources import EXAMPLE_MODELS

ROBOT_KEY = re.compile(r"^  ([A-Za-z_][A-Za-z0-9_]*):\s*$")


def _models_named(args) -> None:
    """generate works on the user's own models: refuse to fall back to the shipped examples silently."""
    if args.models is None and local_models_path() is None:
        raise DeriveError(f"no {MODELS_FILE} in {Path.cwd()}: write one (`derive init` starts one from the "
                          "shipped robots), pass --models FILE, or set DERIVE_MODELS")


def cmd_generate(args) -> int:
    _models_named(args)
    robots = robots_of(args)
    # here, not at the top: a models file with a mistake is refused before CasADi and jinja2 load
    from derive.codegen.generate import check, default_output, firmware_record_path, generate
    out = Path(args.out) if args.out else default_output()
    if args.check:
        problems = check({k: v for k, v in robots.items() if not args.robot or k in args.robot}, out,
                         prune=args.prune and not args.robot, firmware=firmware_record_path(args.models))
        if problems:
            print(f"{out} is stale; run `make derive` (or `derive generate`). {len(problems)} problem(s):",
                  file=sys.stderr)
            for p in problems:
                print(f"  {p}", file=sys.stderr)
            return 1
        print(f"{out} is up to date with {args.models or local_models_path()} ({len(robots)} robots)")
        return 0
    if args.prune and args.robot:
        raise DeriveError("generate: --prune removes every robot not in the models file; it cannot be "
                          "combined with --robot")
    generate(robots, out, only=args.robot or None, use_cache=not args.no_cache,
             log=lambda s: print(s, flush=True), prune=args.prune, firmware=firmware_record_path(args.models),
             strict=args.strict)
    return 0


def cmd_init(args) -> int:
    """Write ./models.yaml (or --out) with shipped example robots to start from."""
    target = Path(args.out or MODELS_FILE)
    if target.is_dir():
        raise DeriveError(f"{target}: is a folder; --out names the models file to write (e.g. {target / MODELS_FILE})")
    if target.exists() and not args.force:
        raise DeriveError(f"{target}: exists already; choose another --out, or --force to overwrite it")
    shipped = load_models(EXAMPLE_MODELS)
    unknown = [r for r in args.robot or () if r not in shipped]
    if unknown:
        raise DeriveError(f"init: no shipped robot '{unknown[0]}' (shipped: {', '.join(shipped)})")
    text = EXAMPLE_MODELS.read_text()
    if args.robot:
        text = _select(text, args.robot)
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise DeriveError(f"{target}: cannot write the models file ({exc.strerror or exc})") from None
    write_atomically(target, text, "the models file")
    names = ", ".join(load_models(target))
    print(f"wrote {target} with {names}; edit it, then run `derive generate`")
    return 0


def _select(text: str, names: list[str]) -> str:
    """The shipped models file cut down to ``names`` (in file order): its header, then each robot's
    block as written, with the comment lines just above it."""
    lines = text.splitlines(keepends=True)
    start = next(i for i, line in enumerate(lines) if line.rstrip() == "robots:") + 1
    body = lines[start:]
    keys = [(i, m.group(1)) for i, line in enumerate(body) if (m := ROBOT_KEY.match(line))]
    starts = []
    for i, _ in keys:
        while i > 0 and body[i - 1].startswith("  #"):
            i -= 1
        starts.append(i)
    blocks = {name: body[s:e] for (_, name), s, e in zip(keys, starts, starts[1:] + [len(body)])}
    chosen = [name for _, name in keys if name in names]
    return "".join(lines[:start]) + "".join("".join(blocks[n]).rstrip("\n") + "\n\n" for n in chosen).rstrip("\n") + "\n"


def add_parser(sub) -> None:
    g = sub.add_parser("generate", help="write generated/ from the models file",
                       description="Derive and write C and Python for the robots of the models file into "
                                   "./generated (or --out). Other robots already in that folder are left as "
                                   "they are; --prune removes those the models file no longer names.")
    g.add_argument("--robot", action="append", help="only this robot (repeatable)")
    g.add_argument("--out", type=path_arg, help="output folder (default: ./generated)")
    g.add_argument("--check", action="store_true", help="exit 1 and name the stale files if the output is out of date")
    g.add_argument("--prune", action="store_true",
                   help="remove (with --check: report) robots in the output folder that the models file does not name")
    g.add_argument("--no-cache", action="store_true", help="rederive every robot even if unchanged")
    g.add_argument("--strict", action="store_true",
                   help="refuse a robot whose M(q) is singular (a coordinate that moves no mass or inertia) instead of "
                        "generating it without forward dynamics, the ODE and its Jacobians")
    g.set_defaults(func=cmd_generate)

    i = sub.add_parser("init", help="start a models.yaml from the shipped example robots",
                       description="Write ./models.yaml (or --out) holding shipped robots (all, or those named "
                                   "with --robot) to edit into your own.")
    i.add_argument("--robot", action="append", help="a shipped robot to include (repeatable; default: all)")
    i.add_argument("--out", type=path_arg, help=f"file to write (default: ./{MODELS_FILE})")
    i.add_argument("--force", action="store_true", help="overwrite an existing file")
    i.set_defaults(func=cmd_init)
