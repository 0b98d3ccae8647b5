"""Commands of the kinematic toolkit: dof, workspace, singularities, manipulability, plan."""

from __future__ import annotations

from derive.analysis import grubler, manipulability, planning, singularity, workspace


def add_parser(sub) -> None:
    for module in (grubler, workspace, singularity, manipulability, planning):  # moving here
        module.add_parser(sub)
