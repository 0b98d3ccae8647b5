"""``derive bench``: run the benchmarks and write bench/results.md."""

from __future__ import annotations

from derive import bench


def add_parser(sub) -> None:
    bench.add_parser(sub)  # moving here
