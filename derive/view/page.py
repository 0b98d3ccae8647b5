"""One self-contained HTML page of a robot (``derive view ROBOT --html FILE``), for papers and docs.

The page holds the :class:`~derive.view.scene.Geometry` and the frame poses of every sample shown
(12 numbers per frame: R row-major, then the origin, rounded to 0.1 mm and 1e-4; turned so that
up, against gravity, is the page's +z) as JSON, and a
small canvas renderer inline (derive/view/viewer.html): perspective projection, painter's order,
no WebGL and nothing fetched, so it opens offline and in a headless browser at once. A trajectory
adds play, pause and a time slider that plays it in real time.

The links' meshes and shapes (:mod:`derive.view.meshes`) ride along as triangles in their frames'
coordinates, drawn flat-shaded (a headlight) in the same painter's order: at most
:data:`PAGE_TRIANGLES` in all (more is thinned by :func:`~derive.view.meshes.simplify`, each part
in proportion to its share), vertices quantised to 16 bits of each part's bounding box (0.2 m: 3 um),
base64 in the JSON.
"""

from __future__ import annotations

import base64
import html
import json
import math
from pathlib import Path

import numpy as np

from derive.view.meshes import Part, simplify
from derive.view.scene import Geometry, upright

PAGE_TRIANGLES = 30_000
"""Most triangles the page draws (a canvas redraws them all, sorted, at every frame: about 0.1 s)."""

FOV = math.radians(40.0)
"""Vertical field of view of the page's camera."""
AZIMUTH, ELEVATION = math.radians(-55.0), math.radians(20.0)
"""Where the camera looks from: in front of the robot (+x) and to its right, a little above."""
TEMPLATE = Path(__file__).with_name("viewer.html")


def grid_step(size: float) -> float:
    """A round ground-grid spacing (1, 2 or 5 x 10^k m) near a fifth of ``size``."""
    raw = max(size, 1e-3) / 5.0
    k = math.floor(math.log10(raw))
    return min((m * 10.0 ** k for m in (1.0, 2.0, 5.0, 10.0)), key=lambda s: abs(math.log(s / raw)))


def thin(parts: list[Part] | tuple[Part, ...], budget: int = PAGE_TRIANGLES) -> list[Part]:
    """``parts`` with at most ``budget`` triangles in all: each part thinned to its share of the budget."""
    total = sum(len(p.faces) for p in parts)
    if total <= budget:
        return list(parts)
    out = []
    for p in parts:
        v, f = simplify(p.vertices, p.faces, max(12, int(budget * len(p.faces) / total)))
        out.append(Part(p.frame, v, f, p.color, p.name))
    return out


def _packed(part: Part) -> dict:
    """One part for the page: vertices as uint16 steps over its bounding box, faces uint16 or uint32."""
    lo = part.vertices.min(axis=0)
    step = np.maximum(np.ptp(part.vertices, axis=0), 1e-9) / 65535.0
    q = np.round((part.vertices - lo) / step).astype("<u2")
    wide = len(part.vertices) > 65535
    faces = part.faces.astype("<u4" if wide else "<u2")
    return {"frame": int(part.frame), "color": [round(float(c), 3) for c in part.color],
            "lo": [float(x) for x in lo], "step": [float(x) for x in step], "wide": wide,
            "v": base64.b64encode(q.tobytes()).decode("ascii"), "f": base64.b64encode(faces.tobytes()).decode("ascii")}


def page_data(geo: Geometry, poses: np.ndarray, times: np.ndarray | None = None, note: str = "",
              parts: list[Part] | tuple[Part, ...] = ()) -> dict:
    """The page's JSON: geometry, camera, ``poses`` (N, F, 4, 4) of the N samples (times (N,) in s) and
    the meshes ``parts`` (already thinned: :func:`thin`)."""
    poses = np.asarray(poses, dtype=float).reshape(-1, len(geo.frames), 4, 4)
    turn = np.eye(4)
    turn[:3, :3] = upright(geo.up)
    poses = turn @ poses  # the page's world has z up, against gravity
    packed = np.concatenate([poses[:, :, :3, :3].reshape(len(poses), -1, 9), poses[:, :, :3, 3]], axis=2)
    origins = poses[:, :, :3, 3].reshape(-1, 3)
    for part in parts:  # the camera frames the meshes too: their boxes' corners in every sample
        lo_, hi_ = part.vertices.min(axis=0), part.vertices.max(axis=0)
        corners = np.array([[a[0], b[1], c[2]] for a in (lo_, hi_) for b in (lo_, hi_) for c in (lo_, hi_)])
        at = poses[:, part.frame]
        origins = np.concatenate([origins, (corners @ at[:, :3, :3].transpose(0, 2, 1) + at[:, None, :3, 3]).reshape(-1, 3)])
    lo, hi = origins.min(axis=0), origins.max(axis=0)
    radius = max(0.5 * float(np.linalg.norm(hi - lo)), 0.5 * geo.size, 0.05)
    target = 0.5 * (lo + hi)
    return {
        "robot": geo.robot,
        "note": note,
        "frames": list(geo.frames),
        "segments": geo.segments.tolist(),
        "axes": [[int(f), [round(float(x), 6) for x in d]] for f, d in zip(geo.axes, geo.axis_dirs)],
        "bodies": [{"frame": int(f), "com": np.round(c, 6).tolist(), "rotation": np.round(R, 6).tolist(),
                    "edges": np.round(e, 6).tolist(), "radius": round(float(r), 6)}
                   for f, c, R, e, r in zip(geo.body_frames, geo.coms, geo.box_rotations, geo.box_sizes, geo.com_radii)],
        "axis_length": round(geo.axis_length, 6),
        "frame_length": round(geo.frame_length, 6),
        "grid": grid_step(geo.size),
        "floor": round(min(0.0, float(lo[2])), 4),  # z = 0, or under the lowest frame of a hanging arm
        "camera": {"target": np.round(target, 4).tolist(), "distance": round(1.4 * radius / math.sin(0.5 * FOV), 4),
                   "azimuth": AZIMUTH, "elevation": ELEVATION, "fov": FOV},
        "times": [] if times is None else np.round(np.asarray(times, dtype=float), 6).tolist(),
        "poses": [[round(float(x), 4) for x in sample.reshape(-1)] for sample in packed],
        "meshes": [_packed(p) for p in parts],
    }


def render_page(geo: Geometry, poses: np.ndarray, times: np.ndarray | None = None, note: str = "",
                parts: list[Part] | tuple[Part, ...] = ()) -> str:
    """The HTML page (text) of ``geo`` at ``poses`` (N, F, 4, 4); ``times`` (N,) make it a player; ``parts``
    the links' meshes (thinned to :data:`PAGE_TRIANGLES` here)."""
    data = json.dumps(page_data(geo, poses, times, note, thin(parts)), separators=(",", ":"))
    data = data.replace("</", "<\\/")  # "</script>" inside a name would end the script
    title = html.escape(f"{geo.robot}: derive view")
    return TEMPLATE.read_text(encoding="utf-8").replace("__TITLE__", title).replace("/*DATA*/null", data)
