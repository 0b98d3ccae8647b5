"""``derive bench``: run the benchmarks and write bench/results.md (the runner is :mod:`derive.bench`)."""

from __future__ import annotations

from derive import bench
from derive.cli.common import path_arg


def add_parser(sub) -> None:
    b = sub.add_parser("bench", help="run benchmarks and write bench/results.md")
    b.add_argument("names", nargs="*", help="benchmarks to run (default: all)")
    b.add_argument("--out", type=path_arg, help="results file (default: bench/results.md)")
    b.add_argument("--quick", action="store_true", help="smaller sample sizes, for a smoke run")
    b.set_defaults(func=bench.run)
