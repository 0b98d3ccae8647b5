"""Function specs: the only hand-off from the maths to the backends.

A :class:`FunctionSpec` names a generated function, its ordered inputs and outputs
(name, SX) and its docstring: one expression graph, printed by each backend.
A :class:`TemplateFunction` is a function whose body is a template (loops, calls to
other generated functions, a fixed support algorithm) rather than one graph.

Both are language-free: names are the function's short name ``<quantity>[_<frame>]``
(each backend adds its own prefix or namespace), numbers are plain floats and ints,
and nothing here knows C, Python or any other target.
"""

from __future__ import annotations

from dataclasses import dataclass

import casadi as ca


class Named:
    """``<robot>_<quantity>[_<frame>]`` naming shared by every generated function."""

    robot: str
    quantity: str
    frame: str | None

    @property
    def short_name(self) -> str:
        """Name without the robot prefix (the Python function name)."""
        return self.quantity + (f"_{self.frame}" if self.frame else "")

    @property
    def name(self) -> str:
        return f"{self.robot}_{self.short_name}"


@dataclass(frozen=True)
class FunctionSpec(Named):
    """One expression function: outputs as SX expressions of the inputs (SX symbols)."""

    robot: str
    quantity: str
    frame: str | None
    inputs: tuple[tuple[str, ca.SX], ...]
    outputs: tuple[tuple[str, ca.SX], ...]
    doc: str
    manifest: tuple[tuple[str, object], ...] = ()  # extra plain-data facts for manifest.json (e.g. the regressor's pi)


@dataclass(frozen=True)
class TemplateFunction(Named):
    """A generated function whose body is a template (loops, calls), not one expression graph.

    Each backend renders it with its template named ``template`` (e.g. ``rk4_step``) and this
    function's plain-data ``context``. ``calls`` maps a role in the template to the short name
    of a generated function it calls (each backend spells the full name). ``support`` names
    fixed, robot-independent algorithms (``"ik"``, ``"manipulability"``) whose support files
    each backend copies verbatim into the robot's output; the templates only lay out the
    call with this robot's sizes, limits and functions. ``optional`` inputs may be omitted
    by the caller (NULL in C, None in Python); ``status`` functions return an int code.
    """

    robot: str
    quantity: str
    frame: str | None
    inputs: tuple[tuple[str, tuple[int, int]], ...]
    outputs: tuple[tuple[str, tuple[int, int]], ...]
    doc: str
    template: str
    calls: tuple[tuple[str, str], ...] = ()
    context: tuple[tuple[str, object], ...] = ()  # plain data, as pairs to stay hashable
    support: tuple[str, ...] = ()
    optional: tuple[str, ...] = ()
    status: bool = False
    manifest: tuple[tuple[str, object], ...] = ()  # extra plain-data facts for manifest.json (e.g. task_rows)

    @property
    def callees(self) -> tuple[str, ...]:
        """Short names of the generated functions this one calls."""
        return tuple(short for _, short in self.calls)
