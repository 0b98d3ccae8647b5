"""``derive firmware-check``: cross-compile the generated C for microcontrollers (the work is
:mod:`derive.bench.firmware`'s), print text and stack, and with ``--record`` keep the figures."""

from __future__ import annotations

import os
import sys
from pathlib import Path

from derive.bench import firmware
from derive.cli.common import path_arg, robots_of
from derive.codegen.generate import default_output, firmware_record_path, record_firmware
from derive.description.model import local_models_path
from derive.errors import DeriveError


def cmd_firmware_check(args) -> int:
    robots = robots_of(args)
    out = Path(args.out) if args.out else default_output()
    names = args.robots or list(robots)
    unknown = [r for r in names if r not in robots]
    if unknown:
        raise DeriveError(f"firmware-check: no robot '{unknown[0]}' in the models file (known: {', '.join(robots)})")
    if args.jobs is not None and args.jobs < 1:
        raise DeriveError(f"firmware-check: --jobs must be at least 1, got {args.jobs}")
    missing = [r for r in names if not (out / r / "manifest.json").is_file()]
    if missing:
        raise DeriveError(f"firmware-check: {out / missing[0]} is not generated; run `derive generate` first")
    if args.record and args.models is None and local_models_path() is None:
        raise DeriveError("firmware-check --record writes firmware.json beside your models file: run it where your "
                          "models.yaml is, pass --models FILE or set DERIVE_MODELS")
    record = firmware_record_path(args.models)
    result = firmware.measure(out, {r: None for r in names}, builds=firmware.BUILDS, jobs=args.jobs,
                              log=lambda s: print(s, flush=True))
    if result.failures:
        first = result.failures[0]
        more = f" (and {len(result.failures) - 1} more)" if len(result.failures) > 1 else ""
        print(f"derive: firmware-check: not clean: {first}{more}", file=sys.stderr)
        return 1
    print("largest text at -O2 / stack at -O2 / stack at -O0 (bytes) per robot:")
    for row in firmware.summary_rows(result):
        print(row)
    if args.functions:
        for robot, figures in result.figures.items():
            print(f"\n{robot}:")
            for row in firmware.function_rows(figures):
                print(row)
    debug = firmware.worst_debug_stack(result)
    print((f"largest -O0 stack: {debug[0]} bytes ({debug[1]}, {debug[2]}); " if debug else "")
          + f"{result.builds} clean builds in {result.seconds:.0f} s")
    if args.record:
        record_firmware(out, firmware.record_entries(out, result), record, log=lambda s: print(s, flush=True))
        print(f"recorded into {record} and the robots' manifest.json")
        return 0
    stale = firmware.differences(out, result)
    if stale:
        print(f"{len(stale)} figure(s) differ from those in manifest.json (first: {stale[0]}); "
              "`derive firmware-check --record` records them")
    else:
        print("the figures in manifest.json are this run's")
    return 0


def add_parser(sub) -> None:
    f = sub.add_parser("firmware-check", help="cross-compile the generated C for Cortex-M4F/M7: warnings, text, stack",
                       description="Cross-compile every generated C file of the robots (default: all of the models "
                                   "file) with arm-none-eabi-gcc for a Cortex-M4F and a Cortex-M7, in double and float, "
                                   "at -O2 and -O0, under -Werror -pedantic -Wdouble-promotion (exit 1 on any warning), "
                                   "and print text and stack per robot. --record keeps the figures in firmware.json "
                                   "beside the models file and in each robot's manifest.json.")
    f.add_argument("robots", nargs="*", metavar="ROBOT", help="robots to check (default: all of the models file)")
    f.add_argument("--out", type=path_arg, help="the generated folder (default: ./generated)")
    f.add_argument("--record", action="store_true",
                   help="write the figures into firmware.json and the manifests (derive generate keeps them "
                        "while a function's source is unchanged)")
    f.add_argument("--functions", action="store_true", help="also print every function's figures")
    f.add_argument("--jobs", "-j", type=int, help=f"compilers at a time (default and most: the CPU count, {os.cpu_count()})")
    f.set_defaults(func=cmd_firmware_check)
