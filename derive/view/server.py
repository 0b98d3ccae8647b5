"""The live viewer (``derive view ROBOT``): the scene of :mod:`derive.view.scene` in viser, in the browser.

Joint sliders within the limits move the robot (poses from the generated ``fk_all`` or the numpy
reference); a trajectory CSV adds play, pause and a time slider; where the robot's generated Python
has ``ik_<frame>``, a transform gizmo at that frame is the IK target, solved by the generated IK from
the current q at each move (status and residual shown). The links' meshes (:mod:`derive.view.meshes`)
hang under one scene node per link, which :meth:`LiveView.show` moves with the rest; check boxes
show and hide each layer (meshes, skeleton and axes, frames, CoM spheres, inertia boxes). viser is the ``viewer`` extra, imported here
only: the rest of derive, and ``derive view --html``, run without it.
"""

from __future__ import annotations

import contextlib
import io
import math
import threading
import time
from typing import Callable

import numpy as np

from derive.description.robot import Robot
from derive.errors import DeriveError
from derive.view.meshes import Part
from derive.view.page import AZIMUTH, ELEVATION, FOV
from derive.view.scene import Geometry, Kinematics, Trajectory, place, upright

EXTRA = "derive view needs the viewer extra: pip install 'derive-robotics[viewer]'"
SKELETON, AXIS, COM, BOX = (58, 63, 71), (192, 38, 211), (40, 110, 210), (235, 140, 60)


def import_viser():
    """The viser module, or the one-line DeriveError that names the extra to install."""
    try:
        import viser  # noqa: PLC0415 (the optional viewer extra)
    except ImportError:
        raise DeriveError(EXTRA) from None
    return viser


def _wxyz(viser, R: np.ndarray) -> np.ndarray:
    return viser.transforms.SO3.from_matrix(R).wxyz


class LiveView:
    """The viser scene and GUI of one robot; :meth:`show` moves it to a configuration q (nq)."""

    def __init__(self, server, robot: Robot, kin: Kinematics, geo: Geometry, q0: np.ndarray,
                 trajectory: Trajectory | None = None, ik_frame: str | None = None, parts: list[Part] | tuple = ()):
        self.viser = import_viser()
        self.server, self.robot, self.kin, self.geo = server, robot, kin, geo
        self.q = np.array(q0, dtype=float)
        self.lock = threading.RLock()
        scene, gui = server.scene, server.gui
        placed = place(geo, kin.poses(self.q))
        scene.set_up_direction(geo.up)  # against gravity: a planar arm in x-y stands upright
        self._aim(placed.frames[:, :3, 3])
        scene.add_grid("/ground", width=4 * geo.size, height=4 * geo.size, cell_size=geo.size / 10,
                       wxyz=_wxyz(self.viser, upright(geo.up).T))  # the plane normal to up
        self.boxes = [scene.add_box(f"/inertia_boxes/{geo.frames[f]}", color=BOX, dimensions=tuple(np.maximum(e, 1e-4)),
                                    opacity=0.3, cast_shadow=False, receive_shadow=False)
                      for f, e in zip(geo.body_frames, geo.box_sizes)]
        self.coms = [scene.add_icosphere(f"/coms/{geo.frames[f]}", radius=float(r), color=COM)
                     for f, r in zip(geo.body_frames, geo.com_radii)]
        self.frames = [scene.add_frame(f"/frames/{name}", axes_length=geo.frame_length, axes_radius=geo.frame_length / 20,
                                       origin_radius=geo.frame_length / 10) for name in geo.frames]
        self.skeleton = scene.add_line_segments("/skeleton", points=placed.segments.astype(np.float32), colors=SKELETON,
                                                thickness=5.0, thickness_units="screen")
        self.axes = scene.add_line_segments("/joint_axes", points=placed.axes.astype(np.float32), colors=AXIS,
                                            thickness=3.0, thickness_units="screen")
        # the meshes: one node per link that has any, moved by show(); the parts hang under it, in its coordinates
        self.mesh_frames = {f: scene.add_frame(f"/meshes/{geo.frames[f]}", show_axes=False)
                            for f in sorted({p.frame for p in parts})}
        self.meshes = [scene.add_mesh_simple(f"/meshes/{geo.frames[p.frame]}/{p.name}",
                                             vertices=p.vertices.astype(np.float32), faces=p.faces.astype(np.uint32),
                                             color=tuple(int(round(255 * c)) for c in p.color[:3]),
                                             opacity=float(p.color[3]) if p.color[3] < 1 else None, side="double")
                       for p in parts]
        self.status = gui.add_markdown(f"**{robot.name}**: poses from the {kin.source}")
        self.layers = {}
        plain = not parts  # with meshes, the model's own primitives start hidden
        with gui.add_folder("layers"):
            for key, label, handles, on in (
                    ("meshes", "meshes", list(self.mesh_frames.values()), True),
                    ("skeleton", "skeleton and joint axes", [self.skeleton, self.axes], True),
                    ("frames", "frames", self.frames, plain), ("coms", "CoM spheres", self.coms, plain),
                    ("boxes", "inertia boxes", self.boxes, plain)):
                if key == "meshes" and not parts:
                    continue
                box = gui.add_checkbox(label, initial_value=on)
                box.on_update(self._shown(handles, box))
                for handle in handles:
                    handle.visible = on
                self.layers[key] = box
        lower, upper = robot.joint_box()
        first = 7 if robot.floating else 0
        self.sliders = {}
        with gui.add_folder("joints"):
            for k, c in enumerate(robot.coordinates[first:], start=first):
                slider = gui.add_slider(c.name, min=float(lower[k]), max=float(upper[k]), step=1e-3,
                                        initial_value=float(self.q[k]))
                slider.on_update(self._slid(k))
                self.sliders[k] = slider
        self.target = None
        frames = kin.ik_frames
        if frames:
            self.ik_frame = ik_frame if ik_frame in frames else ("tcp" if "tcp" in frames else frames[0])
            T = placed.frames[geo.frames.index(self.ik_frame)]
            self.target = scene.add_transform_controls("/ik_target", scale=0.25 * geo.size, position=T[:3, 3],
                                                       wxyz=_wxyz(self.viser, T[:3, :3]))
            self.target.on_update(lambda _: self.solve())
            self.ik_status = gui.add_markdown(f"IK target: drag the gizmo ({self.ik_frame}, generated ik_{self.ik_frame})")
        if trajectory is not None:
            self._player(trajectory)
        self.show(self.q)

    def _aim(self, origins: np.ndarray) -> None:
        """The first camera as the page's (:mod:`derive.view.page`): at the centre of the frames, from the
        front right and a little above, far enough for the robot to fill the view (viser's default stands
        metres away, where a 1 m arm is a speck)."""
        lo, hi = origins.min(axis=0), origins.max(axis=0)
        radius = max(0.5 * float(np.linalg.norm(hi - lo)), 0.5 * self.geo.size, 0.05)
        target = 0.5 * (lo + hi)
        ce = math.cos(ELEVATION)
        away = upright(self.geo.up).T @ np.array([ce * math.cos(AZIMUTH), ce * math.sin(AZIMUTH), math.sin(ELEVATION)])
        camera = self.server.initial_camera
        camera.look_at = tuple(float(x) for x in target)
        camera.position = tuple(float(x) for x in target + 1.4 * radius / math.sin(0.5 * FOV) * away)
        camera.up = tuple(float(x) for x in self.geo.up)
        camera.fov = FOV

    @staticmethod
    def _shown(handles: list, box) -> Callable:
        def toggled(_event) -> None:
            for handle in handles:
                handle.visible = bool(box.value)
        return toggled

    def _slid(self, k: int) -> Callable:
        def moved(_event) -> None:
            with self.lock:
                if self.q[k] != self.sliders[k].value:
                    q = self.q.copy()
                    q[k] = float(self.sliders[k].value)
                    self.show(q)
        return moved

    def show(self, q: np.ndarray) -> None:
        """Move every primitive to configuration q (and the sliders with it)."""
        with self.lock:
            self.q = np.array(q, dtype=float)
            placed = place(self.geo, self.kin.poses(self.q))
            self.skeleton.points = placed.segments.astype(np.float32)
            self.axes.points = placed.axes.astype(np.float32)
            for handle, T in zip(self.frames, placed.frames):
                handle.position, handle.wxyz = T[:3, 3], _wxyz(self.viser, T[:3, :3])
            for handle, c, R in zip(self.boxes, placed.box_centres, placed.box_rotations):
                handle.position, handle.wxyz = c, _wxyz(self.viser, R)
            for handle, c in zip(self.coms, placed.coms):
                handle.position = c
            for f, handle in self.mesh_frames.items():
                T = placed.frames[f]
                handle.position, handle.wxyz = T[:3, 3], _wxyz(self.viser, T[:3, :3])
            for k, slider in self.sliders.items():
                if slider.value != self.q[k]:
                    slider.value = float(self.q[k])

    def solve(self) -> None:
        """The generated IK towards the gizmo's pose, from the current q; the robot moves to its answer."""
        T = np.eye(4)
        T[:3, :3] = self.viser.transforms.SO3(np.asarray(self.target.wxyz)).as_matrix()
        T[:3, 3] = self.target.position
        q, residual, status = self.kin.ik(self.ik_frame, T, self.q)
        if status != 2:
            self.show(q)
        word = {0: "solved", 1: "not reached (closest q shown)", 2: "not a rigid transform"}[status]
        self.ik_status.content = f"IK {self.ik_frame}: {word}; residual {residual[0]:.2g} m, {residual[1]:.2g} rad"

    def _player(self, trajectory: Trajectory) -> None:
        gui = self.server.gui
        t = trajectory.t
        with gui.add_folder("trajectory"):
            play = gui.add_checkbox("play", initial_value=False)
            slider = gui.add_slider("sample", min=0, max=len(t) - 1, step=1, initial_value=0)
            clock = gui.add_markdown(f"t = {t[0]:.3f} s of {t[0]:.3f} .. {t[-1]:.3f} s")
        self.play, self.sample = play, slider

        def at(k: int) -> None:
            clock.content = f"t = {t[k]:.3f} s of {t[0]:.3f} .. {t[-1]:.3f} s"
            self.show(trajectory.q[k])

        slider.on_update(lambda _: at(int(slider.value)))

        def loop() -> None:  # real time: the sample of the wall clock since play was pressed
            while True:
                time.sleep(1 / 30)
                if not play.value:
                    continue
                start, k0 = time.monotonic(), int(slider.value)
                k0 = 0 if k0 >= len(t) - 1 else k0
                while play.value and k0 < len(t):
                    k = int(np.searchsorted(t, t[k0] + time.monotonic() - start, side="right")) - 1
                    if k >= len(t) - 1:
                        slider.value = len(t) - 1
                        play.value = False
                        break
                    if k != slider.value:
                        slider.value = k
                        at(k)
                    time.sleep(1 / 60)

        threading.Thread(target=loop, daemon=True, name="derive-view-player").start()


def serve(robot: Robot, kin: Kinematics, geo: Geometry, q0: np.ndarray, trajectory: Trajectory | None,
          host: str, port: int, ik_frame: str | None, announce: Callable[[str], None],
          parts: list[Part] | tuple = ()) -> None:
    """Serve the live viewer at http://host:port until the process ends (Ctrl-C)."""
    viser = import_viser()
    try:
        with contextlib.redirect_stdout(io.StringIO()):  # viser's own banner: announce() says where, in one line
            server = viser.ViserServer(host=host, port=port, verbose=False)
    except OSError as exc:
        raise DeriveError(f"view {robot.name}: cannot serve on {host}:{port} ({exc.strerror or exc}): "
                          "choose another --port") from None
    LiveView(server, robot, kin, geo, q0, trajectory, ik_frame, parts)
    announce(f"derive view {robot.name}: http://{host}:{server.get_port()} (Ctrl-C ends it)")
    while True:
        time.sleep(3600)
