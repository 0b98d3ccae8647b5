"""``derive generate``: models file -> generated/ (C, Python, manifest)."""

from __future__ import annotations

import sys
from pathlib import Path

from derive.cli.common import robots_of
from derive.codegen.generate import check, generate
from derive.resources import CHECKOUT

DEFAULT_OUT = CHECKOUT / "generated"


def cmd_generate(args) -> int:
    robots = robots_of(args)
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



def add_parser(sub) -> None:
    g = sub.add_parser("generate", help="regenerate generated/ from models.yaml")
    g.add_argument("--robot", action="append", help="only this robot (repeatable)")
    g.add_argument("--out", help="output folder (default: generated/)")
    g.add_argument("--check", action="store_true", help="exit 1 and name the stale files if generated/ is out of date")
    g.add_argument("--no-cache", action="store_true", help="rederive every robot even if unchanged")
    g.set_defaults(func=cmd_generate)
