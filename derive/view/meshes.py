"""The links' looks for ``derive view``: models.yaml ``visual:`` items as triangle meshes in their frames.

Every :class:`~derive.description.robot.Visual` of a link becomes one or more :class:`Part`: vertices
(V, 3) in the link frame's coordinates (the visual's origin and scale applied), triangles (F, 3) and
one colour, so that p_world = world_T_link(q) p_link moves it with the joints, as every other primitive
of :mod:`derive.view.scene`. Primitive shapes (box, cylinder, sphere, capsule) are built here with
numpy; mesh files (STL binary or ASCII, OBJ, DAE) are read by trimesh (and pycollada for DAE), the
``viewer`` extra. Without it, or for a file that is not there or does not read, the mesh is left out
with one warning line per kind of problem and the rest is drawn (the skeleton always is).

A mesh file made of sub-meshes of several colours (a DAE's materials) gives one part per colour; a
visual's own ``color`` paints all of it. :func:`simplify` thins a part to a triangle budget by vertex
clustering (numpy only), for the self-contained page (:mod:`derive.view.page`).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from derive.description.robot import Robot, Visual
from derive.description.urdf import ERD_PREFIX, example_robot_data_dir
from derive.reference.rnea import rpy_matrix

GREY = (0.7, 0.7, 0.72, 1.0)
"""The colour of a visual that has none (and of a mesh file without materials)."""
EXTRA = "pip install 'derive-robotics[viewer]'"
ROUND = 24
"""Segments around a cylinder, sphere or capsule."""


@dataclass(frozen=True)
class Part:
    """One colour of one visual: ``vertices`` (V, 3) float in frame ``frame``'s coordinates (an index
    into the scene's frames), ``faces`` (F, 3) int, ``color`` (r, g, b, a) in 0..1, ``name`` for messages
    and the live viewer's scene tree."""

    frame: int
    vertices: np.ndarray
    faces: np.ndarray
    color: tuple[float, float, float, float]
    name: str


# --------------------------------------------------------------------------- primitive shapes


def _lathe(profile: list[tuple[float, float]], n: int = ROUND) -> tuple[np.ndarray, np.ndarray]:
    """The surface of revolution about z of ``profile`` [(r, z), ...] (first and last r = 0: the poles)."""
    angles = 2 * math.pi * np.arange(n) / n
    ring = np.column_stack([np.cos(angles), np.sin(angles)])
    verts = [[0.0, 0.0, profile[0][1]]]
    for r, z in profile[1:-1]:
        verts.extend(np.column_stack([r * ring, np.full(n, z)]).tolist())
    verts.append([0.0, 0.0, profile[-1][1]])
    rings = len(profile) - 2
    faces = []
    k = np.arange(n)
    nxt = (k + 1) % n
    faces += np.column_stack([np.zeros(n, int), 1 + nxt, 1 + k]).tolist()  # the bottom cap, facing -z
    for i in range(rings - 1):
        a, b = 1 + i * n, 1 + (i + 1) * n
        faces += np.column_stack([a + k, a + nxt, b + nxt]).tolist()
        faces += np.column_stack([a + k, b + nxt, b + k]).tolist()
    top, last = len(verts) - 1, 1 + (rings - 1) * n
    faces += np.column_stack([np.full(n, top), last + k, last + nxt]).tolist()
    return np.array(verts, dtype=float), np.array(faces, dtype=np.int64)


def shape_mesh(visual: Visual) -> tuple[np.ndarray, np.ndarray]:
    """(vertices, faces) of a primitive ``visual`` in its own frame, centred on its origin."""
    size = visual.size
    if visual.shape == "box":
        corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float)
        faces = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                          [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
        return corners * (0.5 * np.array(size)), faces
    if visual.shape == "cylinder":
        r, h = size
        return _lathe([(0.0, -h / 2), (r, -h / 2), (r, h / 2), (0.0, h / 2)])
    r = size[0]
    half = 0.0 if visual.shape == "sphere" else size[1] / 2
    steps = ROUND // 4
    cap = [(r * math.sin(a), r * math.cos(a)) for a in np.linspace(0, math.pi / 2, steps + 1)[1:]]
    profile = [(0.0, -half - r)] + [(x, -half - z) for x, z in cap[:-1]] + [(r, -half)]
    profile += ([(r, half)] if half > 0 else []) + [(x, half + z) for x, z in reversed(cap[:-1])] + [(0.0, half + r)]
    return _lathe(profile)


# --------------------------------------------------------------------------- mesh files


class MeshLibraryMissing(ImportError):
    """trimesh (the ``viewer`` extra) is not installed."""


def mesh_path(mesh: str, robot: Robot) -> Path | None:
    """The file a models.yaml ``mesh`` names: ``example-robot-data:...`` in the installed package (None
    without it), an absolute path, or a path relative to the folder of the models file the robot was
    read from (the working folder for a robot not read from a file)."""
    if mesh.startswith(ERD_PREFIX):
        erd = example_robot_data_dir()
        return None if erd is None else erd / mesh[len(ERD_PREFIX):].lstrip("/")
    if mesh.startswith("package://"):
        return None
    path = Path(mesh)
    if not path.is_absolute():
        path = (Path(robot.file).parent if robot.file else Path(".")) / path
    return Path(os.path.normpath(path))


def read_mesh(path: Path) -> list[tuple[np.ndarray, np.ndarray, tuple | None]]:
    """The triangles of a mesh file as [(vertices, faces, rgba or None)] in metres, one item per colour (a
    DAE scene's sub-meshes placed by its node transforms, scaled by its ``<unit>``). Raises :class:`MeshLibraryMissing` without
    trimesh, ValueError (one line) for a file it cannot read."""
    try:
        import trimesh  # noqa: PLC0415 (the optional viewer extra)
    except ImportError:
        raise MeshLibraryMissing(EXTRA) from None
    try:
        loaded = trimesh.load(str(path))
    except ImportError as exc:  # a DAE without pycollada
        raise MeshLibraryMissing(f"{EXTRA} ({exc.name or 'a reader'} is missing)") from None
    except Exception as exc:  # noqa: BLE001 (trimesh's readers raise anything on a bad file)
        raise ValueError(f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else 'unreadable'}") from None
    unit = 1.0  # a DAE's <unit meter=...> (0.001 for millimetres), which RViz applies too
    if getattr(loaded, "units", None) not in (None, "m", "meters"):
        try:
            unit = float(trimesh.units.unit_conversion(loaded.units, "meters"))
        except (ValueError, TypeError, KeyError):
            raise ValueError(f"unknown length unit {loaded.units!r}") from None
    if isinstance(loaded, trimesh.Scene):
        items = []
        for node in loaded.graph.nodes_geometry:
            transform, name = loaded.graph[node]
            geometry = loaded.geometry[name]
            if isinstance(geometry, trimesh.Trimesh):
                items.append((trimesh.transform_points(geometry.vertices, transform), geometry))
    elif isinstance(loaded, trimesh.Trimesh):
        items = [(loaded.vertices, loaded)]
    else:
        raise ValueError(f"no triangles in it ({type(loaded).__name__})")
    by_colour: dict[tuple | None, list] = {}
    for vertices, geometry in items:
        if len(geometry.faces):
            by_colour.setdefault(_colour(geometry), []).append((unit * np.asarray(vertices, float),
                                                                np.asarray(geometry.faces)))
    out = []
    for colour, pieces in by_colour.items():
        offsets = np.cumsum([0] + [len(v) for v, _ in pieces[:-1]])
        out.append((np.concatenate([v for v, _ in pieces]), np.concatenate([f + o for (_, f), o in zip(pieces, offsets)]),
                    colour))
    if not out:
        raise ValueError("no triangles in it")
    return out


def _colour(geometry) -> tuple | None:
    """The main colour of a trimesh geometry (its material's, or its own colours'), or None if it has none."""
    visual = geometry.visual
    material = getattr(visual, "material", None)
    colour = getattr(material, "main_color", None) if material is not None else None
    if colour is None and getattr(visual, "kind", None) in ("face", "vertex"):
        colour = visual.main_color
    if colour is None:
        return None
    return tuple(round(float(c) / 255.0, 3) for c in colour[:4])


# --------------------------------------------------------------------------- the robot's parts


def visual_parts(robot: Robot, frames: tuple[str, ...], warn: Callable[[str], None]) -> list[Part]:
    """Every link's visuals of ``robot`` as :class:`Part` (frames: the scene's frame names). Problems are
    gathered into one warning line per kind (``warn``): a missing mesh library, files not found, files
    that do not read."""
    index = {name: k for k, name in enumerate(frames)}
    parts: list[Part] = []
    cache: dict[Path, list] = {}
    missing, unreadable, library = [], [], None
    for link in robot.links:
        for k, visual in enumerate(link.visual):
            name = f"{link.name}_{k}"
            place = np.eye(4)
            place[:3, :3] = rpy_matrix(*visual.origin.rpy)
            place[:3, 3] = visual.origin.xyz
            if visual.shape != "mesh":
                pieces = [shape_mesh(visual) + (None,)]
            else:
                if library is not None:
                    continue
                path = mesh_path(visual.mesh, robot)
                if path is None or not path.is_file():
                    missing.append(visual.mesh)
                    continue
                if path not in cache:
                    try:
                        cache[path] = read_mesh(path)
                    except MeshLibraryMissing as exc:
                        library = str(exc)
                        continue
                    except ValueError as exc:
                        unreadable.append(f"{visual.mesh} ({exc})")
                        cache[path] = []
                pieces = cache[path]
            for i, (vertices, faces, colour) in enumerate(pieces):
                v = (vertices * np.array(visual.scale)) @ place[:3, :3].T + place[:3, 3]
                if np.prod(np.sign(visual.scale)) < 0:  # a mirroring scale turns the triangles inside out
                    faces = faces[:, ::-1]
                parts.append(Part(index[link.name], v, np.asarray(faces, dtype=np.int64),
                                  tuple(visual.color or colour or GREY), name + (f"_{i}" if len(pieces) > 1 else "")))
    who = f"derive view {robot.name}"
    if library is not None:
        warn(f"warning: {who}: reading mesh files needs the viewer extra (trimesh, pycollada): {library}; the meshes "
             "are left out")
    if missing:
        warn(f"warning: {who}: {len(missing)} mesh file{'s' * (len(missing) > 1)} not found, left out: {missing[0]}"
             + (f" and {len(missing) - 1} more" if len(missing) > 1 else "")
             + (f" (relative to {Path(robot.file).parent})" if robot.file and not Path(missing[0]).is_absolute()
                and not missing[0].startswith((ERD_PREFIX, "package://")) else ""))
    if unreadable:
        warn(f"warning: {who}: {len(unreadable)} mesh file{'s' * (len(unreadable) > 1)} could not be read, left out: "
             + unreadable[0] + (f" and {len(unreadable) - 1} more" if len(unreadable) > 1 else ""))
    return parts


def simplify(vertices: np.ndarray, faces: np.ndarray, limit: int) -> tuple[np.ndarray, np.ndarray]:
    """At most ``limit`` triangles by vertex clustering: vertices snapped to a grid of cubes merge into
    their mean, collapsed and repeated triangles go; the grid (cubes of 1/1024 of the largest extent,
    coarsened as a surface's triangle count asks) is the first that meets the budget. Unchanged when
    it is met already."""
    if len(faces) <= limit:
        return vertices, faces
    lo = vertices.min(axis=0)
    extent = max(float(np.ptp(vertices, axis=0).max()), 1e-12)
    cells = 1024.0
    while True:
        key = np.floor((vertices - lo) / extent * cells).astype(np.int64)
        code = (key[:, 0] * (int(cells) + 1) + key[:, 1]) * (int(cells) + 1) + key[:, 2]
        _, inverse = np.unique(code, return_inverse=True)
        inverse = inverse.reshape(-1)
        count = np.bincount(inverse)
        merged = np.column_stack([np.bincount(inverse, vertices[:, i]) / count for i in range(3)])
        f = inverse[faces]
        f = f[(f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])]
        ordered, n = np.sort(f, axis=1), np.int64(len(merged))
        _, first = np.unique((ordered[:, 0] * n + ordered[:, 1]) * n + ordered[:, 2], return_index=True)
        f = f[np.sort(first)]
        if len(f) <= limit or cells <= 1:
            used, f = np.unique(f, return_inverse=True)
            return merged[used], f.reshape(-1, 3)
        cells = max(1.0, cells * min(0.95, 0.95 * math.sqrt(limit / len(f))))  # a surface: F ~ cells^2
