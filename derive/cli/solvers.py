"""Commands that solve: ik, simulate, trajopt."""

from __future__ import annotations

from derive.solvers import ik, simulate, trajopt_examples


def add_parser(sub) -> None:
    for module in (simulate, ik, trajopt_examples):  # moving here
        module.add_parser(sub)
