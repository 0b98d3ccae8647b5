"""The generated Python of a robot as a module: ``derive.generated("panda")``.

The module is <folder>/<robot>/python/<robot>.py, imported by path (it is not a package of its
own); the folder is the one given, else ./generated, else the generated/ shipped with derive (a
source checkout's). Imported once per file version: a call after ``derive generate`` rewrote the
file imports the new one.
"""

from __future__ import annotations

import importlib.util
import re
import types
from pathlib import Path

from derive.errors import DeriveError
from derive.runtime.build import default_generated
from derive.resources import data_path

_IMPORTED: dict[tuple[str, int], types.ModuleType] = {}  # (resolved path, mtime_ns) -> module


def candidates(robot: str, folder: str | Path | None = None) -> list[Path]:
    """Where the module of ``robot`` is looked for, in order."""
    folders = [Path(folder)] if folder is not None else [default_generated(), data_path("generated")]
    return [f / robot / "python" / f"{robot}.py" for f in dict.fromkeys(folders)]


def generated(robot: str, folder: str | Path | None = None) -> types.ModuleType:
    """The generated Python module of ``robot``: its functions (``mass_matrix(q, p)``, ``fk_tcp(q)``,
    ``rk4_step(x, u, dt)``...) and constants (``NQ``, ``NV``, ``JOINTS``, ``DEFAULT_P``).

    ``folder`` holds <robot>/python/ (default: ./generated, then the generated/ shipped with derive).
    A one-line DeriveError names the places looked in when there is none (run ``derive generate``).
    """
    if not isinstance(robot, str) or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", robot):
        raise DeriveError(f"derive.generated: {robot!r} is not a robot name (letters, digits and _, as in models.yaml)")
    places = candidates(robot, folder)
    path = next((p for p in places if p.is_file()), None)
    if path is None:
        raise DeriveError(f"robot '{robot}': no generated Python at {' or '.join(map(str, places))} "
                          "(run `derive generate` first)")
    path = path.resolve()
    key = (str(path), path.stat().st_mtime_ns)
    if key not in _IMPORTED:
        spec = importlib.util.spec_from_file_location(f"derive_generated_{robot}", path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        _IMPORTED[key] = module
    return _IMPORTED[key]
