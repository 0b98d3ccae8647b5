"""One self-contained HTML page of a robot (``derive view ROBOT --html FILE``), for papers and docs.

The page holds the :class:`~derive.view.scene.Geometry` and the frame poses of every sample shown
(12 numbers per frame: R row-major, then the origin, rounded to 0.1 mm and 1e-4; turned so that
up, against gravity, is the page's +z) as JSON, and a
small canvas renderer inline (derive/view/viewer.html): perspective projection, painter's order,
no WebGL and nothing fetched, so it opens offline and in a headless browser at once. A trajectory
adds play, pause and a time slider that plays it in real time.
"""

from __future__ import annotations

import html
import json
import math
from pathlib import Path

import numpy as np

from derive.view.scene import Geometry, upright

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


def page_data(geo: Geometry, poses: np.ndarray, times: np.ndarray | None = None, note: str = "") -> dict:
    """The page's JSON: geometry, camera and ``poses`` (N, F, 4, 4) of the N samples (times (N,) in s)."""
    poses = np.asarray(poses, dtype=float).reshape(-1, len(geo.frames), 4, 4)
    turn = np.eye(4)
    turn[:3, :3] = upright(geo.up)
    poses = turn @ poses  # the page's world has z up, against gravity
    packed = np.concatenate([poses[:, :, :3, :3].reshape(len(poses), -1, 9), poses[:, :, :3, 3]], axis=2)
    origins = poses[:, :, :3, 3].reshape(-1, 3)
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
    }


def render_page(geo: Geometry, poses: np.ndarray, times: np.ndarray | None = None, note: str = "") -> str:
    """The HTML page (text) of ``geo`` at ``poses`` (N, F, 4, 4); ``times`` (N,) make it a player."""
    data = json.dumps(page_data(geo, poses, times, note), separators=(",", ":"))
    data = data.replace("</", "<\\/")  # "</script>" inside a name would end the script
    title = html.escape(f"{geo.robot}: derive view")
    return TEMPLATE.read_text(encoding="utf-8").replace("__TITLE__", title).replace("/*DATA*/null", data)
