"""derive view: the scene from models.yaml (numpy), the HTML page in a real headless browser, the live
viser server (start, answer, Ctrl-C) and the IK gizmo's solve."""

from __future__ import annotations

import json
import math
import os
import select
import shutil
import signal
import socket
import subprocess
import sys
import time
import urllib.request
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np
import pytest

import derive
from derive.cli import main
from derive.view.scene import Kinematics, equivalent_box, geometry, initial_q, place, upright
from derive.view.server import EXTRA

ARM = Path(__file__).resolve().parent / "data" / "rounded_arm_7dof.urdf"
WIDTH, HEIGHT = 800, 600
PANDA_LOWER = np.array([-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973])
PANDA_UPPER = np.array([2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973])


@pytest.fixture(scope="module")
def chromium():
    """Debian's chromium (installed by .ci/run); skipped without it, except in CI (CI=true), where its
    absence fails."""
    path = shutil.which("chromium") or shutil.which("chromium-browser")
    if path is None:
        if os.environ.get("CI"):
            pytest.fail("chromium not installed: .ci/run installs Debian's chromium")
        pytest.skip("no chromium: apt-get install chromium")
    return path


@pytest.fixture(scope="module")
def viser():
    try:
        import viser
    except ImportError:
        if os.environ.get("CI"):
            pytest.fail("viser not installed: the `viewer` extra should be installed by `make test`")
        pytest.skip("no viser: pip install 'derive-robotics[viewer]'")
    return viser


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


# --------------------------------------------------------------------------- the scene (numpy only)


def test_equivalent_box_has_the_links_mass_and_principal_moments():
    rng = np.random.default_rng(3)
    edges = np.array([0.3, 0.1, 0.05])
    m = 2.5
    moments = m / 12 * np.array([edges[1] ** 2 + edges[2] ** 2, edges[0] ** 2 + edges[2] ** 2, edges[0] ** 2 + edges[1] ** 2])
    Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    inertia = Q @ np.diag(moments) @ Q.T
    R, got = equivalent_box(m, inertia)
    assert np.isclose(np.linalg.det(R), 1.0, atol=1e-12)
    np.testing.assert_allclose(R @ np.diag(m / 12 * (got @ got - got ** 2)) @ R.T, inertia, atol=1e-14)
    np.testing.assert_allclose(sorted(got), sorted(edges), atol=1e-12)
    assert equivalent_box(0.0, inertia)[1].tolist() == [0.0, 0.0, 0.0]


def test_panda_scene_is_placed_by_the_generated_fk_all_as_by_the_reference():
    robot = derive.load_robot("panda")
    kin = Kinematics(robot)
    assert kin.source == "generated fk_all" and kin.ik_frames[0] == "tcp"
    geo = geometry(robot, kin)
    q = initial_q(robot)
    np.testing.assert_array_equal(q, np.clip(0.0, PANDA_LOWER, PANDA_UPPER))
    q = q + np.array([0.3, -0.4, 0.2, -1.2, 0.5, 1.1, -0.7])
    poses = kin.poses(q)
    reference = kin.reference.fk(q)
    assert geo.frames == robot.frame_names and len(geo.frames) == 13
    np.testing.assert_allclose(poses, [reference[n] for n in geo.frames], atol=1e-14)
    placed = place(geo, poses)
    # the skeleton: each of the 7 joints' parent -> child origins, then each of the 5 named frames off its link
    assert placed.segments.shape == (12, 2, 3) and placed.axes.shape == (7, 2, 3)
    np.testing.assert_allclose(placed.segments[6], [reference["panda_link6"][:3, 3], reference["panda_link7"][:3, 3]])
    np.testing.assert_allclose(placed.segments[7], [reference["panda_link7"][:3, 3], reference["tcp"][:3, 3]])
    np.testing.assert_allclose(np.linalg.norm(placed.axes[:, 1] - placed.axes[:, 0], axis=1), geo.axis_length, rtol=1e-14)
    # CoM spheres: the mass-weighted mean of the moving links' is the robot's CoM (the reference leaves out
    # the fixed root); radii of steel balls of the links' masses
    moving = geo.body_frames != 0
    mean = (geo.masses[moving, None] * placed.coms[moving]).sum(axis=0) / geo.masses[moving].sum()
    np.testing.assert_allclose(mean, kin.reference.com(q), atol=1e-14)
    np.testing.assert_allclose(4 / 3 * math.pi * geo.com_radii ** 3 * 7850, geo.masses, rtol=1e-12)


def test_up_is_against_gravity_and_the_page_turns_it_to_z():
    robot = derive.load_robot("planar_2r")  # a vertical x-y plane: gravity along -y
    geo = geometry(robot)
    assert geo.up == (0.0, 1.0, 0.0)
    for up in ([0.0, 1.0, 0.0], [0.0, 0.0, -1.0], [0.0, 0.0, 1.0], [0.6, 0.0, 0.8]):
        R = upright(up)
        np.testing.assert_allclose(R @ up, [0.0, 0.0, 1.0], atol=1e-15)
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-15)
        assert np.isclose(np.linalg.det(R), 1.0, atol=1e-15)


# --------------------------------------------------------------------------- the page, in a real browser


def panda_csv(path: Path) -> np.ndarray:
    """A 2 s trajectory CSV of the one schema (t, q_, qd_, qdd_, tau_), 101 samples; returns its q."""
    names = [f"panda_joint{i}" for i in range(1, 8)]
    t = np.linspace(0.0, 2.0, 101)
    q = 0.5 * (PANDA_LOWER + PANDA_UPPER) + 0.2 * (PANDA_UPPER - PANDA_LOWER) * np.sin(np.pi * t[:, None] + np.arange(7))
    qd, qdd = np.gradient(q, t, axis=0), np.zeros_like(q)
    header = ["t"] + [f"{k}_{n}" for k in ("q", "qd", "qdd", "tau") for n in names]
    np.savetxt(path, np.column_stack([t, q, qd, qdd, np.zeros_like(q)]), delimiter=",", header=",".join(header),
               comments="", fmt="%.9g")
    return q


def page_json(html: str) -> dict:
    start = html.index("const D = ") + len("const D = ")
    return json.loads(html[start:html.index(";\nconst LAYERS", start)].replace("<\\/", "</"))


def project(data: dict, points: np.ndarray) -> np.ndarray:
    """The page's camera (viewer.html's setupCamera and project) in Python: pixel (x, y) of world points."""
    c = data["camera"]
    target, ce = np.array(c["target"]), math.cos(c["elevation"])
    eye = target + c["distance"] * np.array([ce * math.cos(c["azimuth"]), ce * math.sin(c["azimuth"]), math.sin(c["elevation"])])
    fwd = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(fwd, [0, 0, 1])
    right /= np.linalg.norm(right)
    up = np.cross(right, fwd)
    focal = 0.5 * HEIGHT / math.tan(0.5 * c["fov"])
    v = points - eye
    z = v @ fwd
    return np.column_stack([0.5 * WIDTH + focal * (v @ right) / z, 0.5 * HEIGHT - focal * (v @ up) / z])


@pytest.fixture(scope="module")
def pages(tmp_path_factory, chromium):
    """The three pages of the issue, written by the CLI, and their screenshots (chromium, in parallel)."""
    tmp = tmp_path_factory.mktemp("view")
    q = panda_csv(tmp / "run.csv")
    assert main(["import-urdf", str(ARM), "--out", str(tmp / "arm.yaml")]) == 0
    runs = {"panda": ["view", "panda", "--html", str(tmp / "panda.html")],
            "urdf": ["--models", str(tmp / "arm.yaml"), "view", "rounded_arm", "--html", str(tmp / "urdf.html")],
            "csv": ["view", "panda", "--csv", str(tmp / "run.csv"), "--html", str(tmp / "csv.html")]}
    for argv in runs.values():
        assert main(argv) == 0

    def shoot(name):
        start = time.monotonic()
        done = subprocess.run([chromium, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                               "--host-resolver-rules=MAP * ~NOTFOUND",  # offline: nothing may be fetched
                               f"--screenshot={tmp / name}.png", f"--window-size={WIDTH},{HEIGHT}",
                               "--virtual-time-budget=2000", (tmp / f"{name}.html").as_uri()],
                              capture_output=True, text=True, timeout=120, cwd=tmp)
        assert (tmp / f"{name}.png").is_file(), done.stderr[-2000:]
        return time.monotonic() - start

    with ThreadPoolExecutor(3) as pool:
        seconds = dict(zip(runs, pool.map(shoot, runs)))
    return tmp, q, seconds


@pytest.mark.parametrize("name", ["panda", "urdf", "csv"])
def test_exported_page_shows_the_robot_in_headless_chromium(pages, name):
    """The skeleton is drawn where the robot projects (dark pixels along its projected segments), something
    is drawn at every projected CoM, and the sides are the white background."""
    from matplotlib.image import imread

    tmp, q, _ = pages
    html = (tmp / f"{name}.html").read_text()
    assert "http://" not in html.replace("http://www.w3.org", "") and "https://" not in html  # nothing to fetch
    data = page_json(html)
    image = imread(tmp / f"{name}.png")[:, :, :3]
    assert image.shape == (HEIGHT, WIDTH, 3)
    poses = np.array(data["poses"][0]).reshape(-1, 12)
    origins = poses[:, 9:]
    if name == "csv":
        assert len(data["poses"]) == 101 and data["times"][-1] == 2.0
        robot = derive.load_robot("panda")
        expected = Kinematics(robot).poses(q[0])[:, :3, 3]
        np.testing.assert_allclose(origins, expected, atol=1e-4)  # the page starts at the CSV's first sample
    # the robot's ink: the skeleton's dark grey, or a sphere, joint axis or frame triad in front of it (the
    # background is white, the grid light grey, a box face a light translucent orange)
    dark = image.min(axis=2) < 0.5
    hits = total = 0
    for a, b in data["segments"]:
        pa, pb = project(data, origins[[a, b]])
        if np.linalg.norm(pb - pa) < 8:
            continue
        for s in np.linspace(0.15, 0.85, 8):
            x, y = np.round(pa + s * (pb - pa)).astype(int)
            total += 1
            hits += bool(dark[max(y - 2, 0):y + 3, max(x - 2, 0):x + 3].any())
    assert total >= 40 and hits >= 0.75 * total, (hits, total)
    coms = []
    for body in data["bodies"]:
        P = poses[body["frame"]]
        coms.append(P[:9].reshape(3, 3) @ body["com"] + P[9:])
    for x, y in np.round(project(data, np.array(coms))).astype(int):
        assert image[y, x].min() < 0.75, (x, y, image[y, x])  # a sphere (or a box face in front of it), not background
    for y, x in [(HEIGHT // 2, 2), (HEIGHT // 2, WIDTH - 3)]:
        assert image[y, x].min() > 0.8  # background (or the faint grid), not a blank black page


def test_pages_screenshot_fast(pages):
    _, _, seconds = pages
    assert max(seconds.values()) < 60, seconds


# --------------------------------------------------------------------------- the live viewer


def test_view_without_the_viewer_extra_says_so_in_one_line(monkeypatch, capsys):
    monkeypatch.setitem(sys.modules, "viser", None)  # import viser raises ImportError
    assert main(["view", "panda"]) == 2
    assert capsys.readouterr().err == f"derive: error: {EXTRA}\n"
    assert EXTRA == "derive view needs the viewer extra: pip install 'derive-robotics[viewer]'"


def test_live_viewer_serves_and_ends_on_sigint(viser, tmp_path):
    port = free_port()
    proc = subprocess.Popen([sys.executable, "-m", "derive", "view", "panda", "--port", str(port)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    try:
        ready, _, _ = select.select([proc.stdout], [], [], 120)
        line = proc.stdout.readline() if ready else ""
        assert line == f"derive view panda: http://127.0.0.1:{port} (Ctrl-C ends it)\n", proc.stderr.read() if not line else line
        with urllib.request.urlopen(f"http://127.0.0.1:{port}/", timeout=30) as answer:
            assert answer.status == 200 and b"<html" in answer.read(4096).lower()
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=30) in (0, 130)
        err = proc.stderr.read()
        assert "Traceback" not in err and err.count("\n") <= 1, err
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def test_ik_gizmo_moves_the_robot_to_the_generated_ik_answer(viser):
    from derive.view.server import LiveView

    robot = derive.load_robot("panda")
    kin = Kinematics(robot)
    geo = geometry(robot, kin)
    server = viser.ViserServer(host="127.0.0.1", port=free_port(), verbose=False)
    try:
        view = LiveView(server, robot, kin, geo, initial_q(robot))
        goal = np.array([0.3, -0.4, 0.2, -1.2, 0.5, 1.1, -0.7])
        target = kin.poses(goal)[geo.frames.index("tcp")]
        view.target.position = target[:3, 3]
        view.target.wxyz = viser.transforms.SO3.from_matrix(target[:3, :3]).wxyz
        view.solve()
        reached = kin.poses(view.q)[geo.frames.index("tcp")]
        assert np.abs(reached[:3, 3] - target[:3, 3]).max() < 1e-5
        assert view.ik_status.content.startswith("IK tcp: solved")
        assert [view.sliders[k].value for k in range(7)] == view.q.tolist()
        np.testing.assert_allclose(view.skeleton.points, place(geo, kin.poses(view.q)).segments, atol=1e-6)
    finally:
        server.stop()


def test_live_player_plays_a_simulated_csv_in_real_time(viser, tmp_path):
    from derive.view.scene import read_trajectory
    from derive.view.server import LiveView

    robot = derive.load_robot("planar_2r")
    t = np.linspace(0.0, 2.0, 201)
    q = np.column_stack([-1.2 + 0.3 * np.sin(np.pi * t), 0.3 * np.cos(np.pi * t)])
    header = "t," + ",".join(f"{k}_{c}" for k in ("q", "qd", "qdd", "tau") for c in robot.velocity_names)
    np.savetxt(tmp_path / "run.csv", np.column_stack([t, q, np.zeros((201, 6))]), delimiter=",", header=header,
               comments="", fmt="%.12g")
    trajectory = read_trajectory(robot, tmp_path / "run.csv")
    kin = Kinematics(robot)
    server = viser.ViserServer(host="127.0.0.1", port=free_port(), verbose=False)
    try:
        view = LiveView(server, robot, kin, geometry(robot, kin), initial_q(robot), trajectory)
        start = time.monotonic()
        view.play.value = True
        time.sleep(0.5)
        view.play.value = False
        elapsed = time.monotonic() - start
        time.sleep(0.1)  # the player notices within a tick
        k = view.sample.value
        assert 0 < t[k] <= elapsed + 0.01  # real time: the sample of the wall clock, never ahead of it
        assert view.q.tolist() == trajectory.q[k].tolist()
    finally:
        server.stop()
