"""Meshes in derive view: models.yaml ``visual:`` (schema, errors, not in the model hash), kept by
import-urdf (package:// resolved, merged links placed in their body, written relative to --out) and
import-mjcf (MuJoCo's mesh recentring undone), read (STL binary and ASCII, OBJ; primitives built),
thinned for the page, drawn by the exported page in headless chromium where they should be, and moved
with the joints in the live viewer (viser)."""

from __future__ import annotations

import os
import shutil
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from derive.cli import main
from derive.codegen.generate import model_hash
from derive.description.model import load_robot, parse_models
from derive.description.robot import ModelError
from derive.description.urdf import import_urdf
from derive.view.meshes import read_mesh, shape_mesh, simplify, visual_parts
from derive.view.page import thin
from derive.view.scene import Kinematics, geometry, initial_q

from test_view import HEIGHT, WIDTH, free_port, page_json, project

SLAB = np.array([0.3, 0.04, 0.3])  # the STL: a box of these edges about its centre, 12 triangles


def box_triangles(edges) -> np.ndarray:
    """(12, 3, 3) outward-wound triangles of a box of ``edges`` about the origin."""
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float) * np.asarray(edges) / 2
    faces = [[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
             [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]]
    return corners[faces]


def write_stl(path: Path, triangles: np.ndarray, ascii_: bool = False) -> None:
    if ascii_:
        lines = ["solid slab"]
        for t in triangles:
            lines += ["facet normal 0 0 0", "outer loop", *[f"vertex {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in t],
                      "endloop", "endfacet"]
        path.write_text("\n".join(lines + ["endsolid slab"]) + "\n")
        return
    records = np.zeros(len(triangles), dtype=[("n", "<f4", 3), ("v", "<f4", (3, 3)), ("attr", "<u2")])
    records["v"] = triangles
    path.write_bytes(b"derive test slab".ljust(80, b" ") + struct.pack("<I", len(triangles)) + records.tobytes())


LOOKS_URDF = """<?xml version="1.0"?>
<robot name="looks">
  <material name="blue"><color rgba="0 0 1 1"/></material>
  <link name="base">
    <inertial><mass value="2"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>
    <visual><origin xyz="0 0 0.05"/><geometry><box size="0.3 0.3 0.1"/></geometry>
      <material name="grey"><color rgba="0.5 0.5 0.5 1"/></material></visual>
  </link>
  <link name="arm">
    <inertial><origin xyz="0 0 0.2"/><mass value="1"/><inertia ixx="0.01" iyy="0.01" izz="0.002" ixy="0" ixz="0" iyz="0"/></inertial>
    <visual><origin xyz="0 0 0.2"/><geometry><mesh filename="package://looks_description/meshes/slab.stl"/></geometry>
      <material name="red"><color rgba="1 0 0 1"/></material></visual>
  </link>
  <link name="tool">
    <visual><origin xyz="0 0 0.05"/><geometry><cylinder radius="0.04" length="0.1"/></geometry><material name="blue"/></visual>
  </link>
  <joint name="j1" type="revolute"><parent link="base"/><child link="arm"/><origin xyz="0 0 0.1"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="10" velocity="2"/></joint>
  <joint name="fix" type="fixed"><parent link="arm"/><child link="tool"/><origin xyz="0 0 0.35" rpy="0 0 1.5"/></joint>
</robot>
"""


@pytest.fixture
def looks(tmp_path):
    """A ROS-like package (urdf/, meshes/ with a binary STL) and the robot imported into models/looks.yaml."""
    package = tmp_path / "looks_description"
    (package / "urdf").mkdir(parents=True)
    (package / "meshes").mkdir()
    write_stl(package / "meshes" / "slab.stl", box_triangles(SLAB))
    (package / "urdf" / "looks.urdf").write_text(LOOKS_URDF)
    models = tmp_path / "models" / "looks.yaml"
    models.parent.mkdir()
    assert main(["import-urdf", str(package / "urdf" / "looks.urdf"), "--out", str(models)]) == 0
    return models


@pytest.fixture(scope="module")
def trimesh():
    try:
        import trimesh
    except ImportError:
        if os.environ.get("CI"):
            pytest.fail("trimesh not installed: the `viewer` extra should be installed by `make test`")
        pytest.skip("no trimesh: pip install 'derive-robotics[viewer]'")
    return trimesh


# --------------------------------------------------------------------------- models.yaml


MODEL = """robots:
  bot:
    links:
      - {name: base}
      - name: l1
        mass: 1
        inertia: [0.1, 0.1, 0.1]
        visual: [VISUAL]
    joints:
      - {name: j1, type: revolute, parent: base, child: l1, axis: [0, 0, 1]}
"""


def test_visuals_parse_and_leave_the_model_hash_alone():
    plain = parse_models(MODEL.replace("\n        visual: [VISUAL]", ""))["bot"]
    dressed = parse_models(MODEL.replace("VISUAL", "{mesh: m.stl, xyz: [0, 0, 0.1], scale: [0.001, 0.001, 0.001]}, "
                                                   "{box: [0.1, 0.2, 0.3], rpy: [0, 0, 1], color: [1, 0, 0]}, "
                                                   "{cylinder: [0.1, 0.5]}, {sphere: 0.2}, {capsule: [0.1, 0.4]}"))["bot"]
    mesh, box, cylinder, sphere, capsule = dressed.links[1].visual
    assert (mesh.shape, mesh.mesh, mesh.origin.xyz, mesh.scale, mesh.color) == ("mesh", "m.stl", (0, 0, 0.1), (0.001,) * 3, None)
    assert (box.size, box.origin.rpy, box.color) == ((0.1, 0.2, 0.3), (0, 0, 1), (1.0, 0.0, 0.0, 1.0))
    assert (cylinder.size, sphere.size, capsule.size) == ((0.1, 0.5), (0.2,), (0.1, 0.4))
    assert model_hash(dressed) == model_hash(plain)  # the looks regenerate nothing
    assert dressed == plain


@pytest.mark.parametrize("visual, field, problem", [
    ("{box: [0.1, 0.2]}", "visual[0].box", "expected a list of 3 numbers, got [0.1, 0.2]"),
    ("{mesh: m.stl, box: [1, 1, 1]}", "visual[0]", "needs exactly one of mesh, box, cylinder, sphere, capsule, got mesh, box"),
    ("{xyz: [0, 0, 1]}", "visual[0]", "needs exactly one of mesh, box, cylinder, sphere, capsule, got none"),
    ("{sphere: -1}", "visual[0].sphere", "must be a positive radius, got -1"),
    ("{cylinder: [0.1, 0]}", "visual[0].cylinder[1]", "must be positive, got 0"),
    ("{mesh: m.stl, color: [1, 0, 2]}", "visual[0].color[2]", "must be from 0 to 1, got 2"),
    ("{mesh: m.stl, scale: [1, 0, 1]}", "visual[0].scale[1]", "must not be 0"),
    ("{mesh: m.stl, texture: t.png}", "visual[0].texture", "unknown field (expected one of: box, capsule, color, "
                                                             "cylinder, mesh, rpy, scale, sphere, xyz)"),
])
def test_bad_visuals_are_one_line_errors(tmp_path, capsys, visual, field, problem):
    path = tmp_path / "models.yaml"
    path.write_text(MODEL.replace("VISUAL", visual))
    with pytest.raises(ModelError):
        parse_models(path.read_text())
    assert main(["--models", str(path), "info"]) == 2
    assert capsys.readouterr().err == f"derive: error: {path}: robot 'bot': links[1].{field}: {problem}\n"


# --------------------------------------------------------------------------- import


def test_import_urdf_keeps_the_visuals_in_their_bodies(looks, tmp_path):
    robot = load_robot("looks", looks)
    base, arm = robot.links
    assert [(v.shape, v.size, v.origin.xyz, v.color) for v in base.visual] == [("box", (0.3, 0.3, 0.1), (0, 0, 0.05), (0.5, 0.5, 0.5, 1.0))]
    slab, tool = arm.visual
    # package://looks_description/... found as an ancestor of the URDF; written relative to the models file
    assert slab.mesh == "../looks_description/meshes/slab.stl" and slab.color == (1.0, 0.0, 0.0, 1.0)
    assert slab.origin.xyz == (0.0, 0.0, 0.2)
    # the fixed link 'tool' merged into 'arm': its cylinder at fix's origin composed with its own, the named colour
    assert tool.shape == "cylinder" and tool.size == (0.04, 0.1) and tool.color == (0.0, 0.0, 1.0, 1.0)
    np.testing.assert_allclose(tool.origin.xyz, [0.0, 0.0, 0.4], atol=1e-15)
    np.testing.assert_allclose(tool.origin.rpy, [0.0, 0.0, 1.5], atol=1e-15)
    # --no-visuals: none, and the command says so
    urdf = tmp_path / "looks_description" / "urdf" / "looks.urdf"
    plain = import_urdf(urdf, visuals=False)
    assert all("visual" not in link for link in plain["links"]) and plain["source"].endswith(" --no-visuals`")
    assert model_hash(load_robot("looks", looks)) == model_hash(parse_models(
        "robots:\n  looks: " + __import__("json").dumps(import_urdf(urdf)))["looks"])


def test_mesh_files_resolve_as_ros_does(tmp_path, monkeypatch):
    """package://NAME/...: --package-path first, then a folder NAME at or beside an ancestor of the URDF's
    folder, then ROS_PACKAGE_PATH; talos' package:///NAME/... too; relative paths from the URDF's folder."""
    from derive.description.urdf import mesh_file

    urdf_folder = tmp_path / "ws" / "src" / "arm_description" / "urdf"
    urdf_folder.mkdir(parents=True)
    for package in (tmp_path / "ws" / "src" / "arm_description", tmp_path / "ws" / "src" / "gripper",
                    tmp_path / "elsewhere" / "arm_description", tmp_path / "ros" / "tools"):
        (package / "meshes").mkdir(parents=True)
        (package / "meshes" / "m.stl").write_bytes(b"")
    (urdf_folder / "local.stl").write_bytes(b"")
    monkeypatch.setenv("ROS_PACKAGE_PATH", str(tmp_path / "ros"))
    missing = []
    found = {name: mesh_file(name, urdf_folder, {"arm_description": tmp_path / "elsewhere" / "arm_description"} if k == 0
                             else {}, missing.append)
             for k, name in enumerate(["package://arm_description/meshes/m.stl", "package:///arm_description/meshes/m.stl",
                                       "package://gripper/meshes/m.stl", "package://tools/meshes/m.stl", "local.stl",
                                       f"file://{urdf_folder / 'local.stl'}", "package://nowhere/m.stl"])}
    assert list(found.values()) == [
        (tmp_path / "elsewhere" / "arm_description" / "meshes" / "m.stl").as_posix(),
        (tmp_path / "ws" / "src" / "arm_description" / "meshes" / "m.stl").as_posix(),
        (tmp_path / "ws" / "src" / "gripper" / "meshes" / "m.stl").as_posix(),
        (tmp_path / "ros" / "tools" / "meshes" / "m.stl").as_posix(),
        (urdf_folder / "local.stl").as_posix(), (urdf_folder / "local.stl").as_posix(), "package://nowhere/m.stl"]
    assert missing == ["package://nowhere/m.stl: package 'nowhere' not found (--package-path nowhere=DIR)"]


def test_import_urdf_keeps_a_missing_mesh_with_one_warning(tmp_path, capsys):
    urdf = tmp_path / "arm.urdf"
    urdf.write_text(LOOKS_URDF.replace("package://looks_description/meshes/slab.stl", "meshes/gone.stl")
                    .replace("<mesh filename=\"meshes/gone.stl\"/>", "<mesh filename=\"meshes/gone.stl\"/>"))
    entry = import_urdf(urdf)
    err = capsys.readouterr().err
    assert err == (f"warning: {urdf}: visual: 1 mesh file not found, kept as written (derive view skips it): "
                   f"meshes/gone.stl: no such file ({tmp_path / 'meshes' / 'gone.stl'})\n")
    assert entry["links"][1]["visual"][0]["mesh"] == (tmp_path / "meshes" / "gone.stl").as_posix()


MJCF = """<mujoco model="tet">
  <compiler angle="radian" meshdir="meshes"/>
  <asset><mesh name="tet" file="tet.stl" scale="2 1 1"/><material name="green" rgba="0 1 0 1"/></asset>
  <worldbody>
    <body name="b" pos="0 0 1" euler="0.3 0 0">
      <joint name="j" type="hinge" axis="0 0 1"/>
      <geom type="mesh" mesh="tet" pos="0.05 0.1 0" euler="0 0.5 0.2" rgba="1 0 0 1"/>
      <geom type="capsule" size="0.02 0.1" pos="0 0 0.3" material="green"/>
      <geom type="box" size="0.1 0.2 0.3" group="3"/>
    </body>
  </worldbody>
</mujoco>
"""


def test_import_mjcf_places_meshes_where_mujoco_does(mujoco, trimesh, tmp_path):
    """MuJoCo's compiler moves a mesh to its inertial frame; the imported visual, read back from the STL,
    lands on MuJoCo's own compiled vertices (mj_forward's geom pose) to 1e-6 (float32 STL)."""
    (tmp_path / "meshes").mkdir()
    tet = np.array([[0.1, 0, 0], [0.3, 0, 0], [0.1, 0.2, 0], [0.1, 0, 0.4]])
    write_stl(tmp_path / "meshes" / "tet.stl", tet[[[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]])
    (tmp_path / "tet.xml").write_text(MJCF)
    models = tmp_path / "out" / "tet.yaml"
    models.parent.mkdir()
    assert main(["import-mjcf", str(tmp_path / "tet.xml"), "--out", str(models)]) == 0
    robot = load_robot("tet", models)
    mesh, capsule = robot.link("b").visual  # the group-3 (collision) box left out
    assert mesh.mesh == "../meshes/tet.stl" and mesh.scale == (2.0, 1.0, 1.0) and mesh.color == (1.0, 0.0, 0.0, 1.0)
    assert capsule.size == (0.02, 0.2) and capsule.color == (0.0, 1.0, 0.0, 1.0)
    m = mujoco.MjModel.from_xml_path(str(tmp_path / "tet.xml"))
    d = mujoco.MjData(m)
    d.qpos[:] = [0.7]
    mujoco.mj_forward(m, d)
    g = 0
    start, count = m.mesh_vertadr[0], m.mesh_vertnum[0]
    theirs = m.mesh_vert[start:start + count] @ d.geom_xmat[g].reshape(3, 3).T + d.geom_xpos[g]
    parts = visual_parts(robot, robot.frame_names, print)
    T = Kinematics(robot).poses(np.array([0.7]))[robot.frame_names.index("b")]
    ours = parts[0].vertices @ T[:3, :3].T + T[:3, 3]
    assert len(ours) == len(theirs) == 4
    for p in theirs:
        assert np.abs(ours - p).max(axis=1).min() < 1e-6


# --------------------------------------------------------------------------- reading and thinning


def test_stl_binary_ascii_and_obj_read_alike(trimesh, tmp_path):
    triangles = box_triangles(SLAB)
    write_stl(tmp_path / "b.stl", triangles)
    write_stl(tmp_path / "a.stl", triangles, ascii_=True)
    corners = np.unique(triangles.reshape(-1, 3), axis=0)
    index = {tuple(c): k for k, c in enumerate(corners)}
    (tmp_path / "c.obj").write_text("".join(f"v {float(x)!r} {float(y)!r} {float(z)!r}\n" for x, y, z in corners)
                                    + "".join("f " + " ".join(str(index[tuple(p)] + 1) for p in t) + "\n" for t in triangles))
    for name in ("b.stl", "a.stl", "c.obj"):
        (vertices, faces, colour), = read_mesh(tmp_path / name)
        assert len(faces) == 12
        np.testing.assert_allclose(np.sort(vertices[faces].reshape(-1, 3), axis=0),
                                   np.sort(triangles.reshape(-1, 3), axis=0), atol=1e-7)  # float32 in binary STL


DAE = """<?xml version="1.0" encoding="utf-8"?>
<COLLADA xmlns="http://www.collada.org/2005/11/COLLADASchema" version="1.4.1">
  <asset><unit name="millimeter" meter="0.001"/><up_axis>Z_UP</up_axis></asset>
  <library_effects>
    <effect id="green-fx"><profile_COMMON><technique sid="common"><lambert>
      <diffuse><color>0 0.8 0 1</color></diffuse></lambert></technique></profile_COMMON></effect>
  </library_effects>
  <library_materials><material id="green" name="green"><instance_effect url="#green-fx"/></material></library_materials>
  <library_geometries>
    <geometry id="tri-mesh"><mesh>
      <source id="tri-pos"><float_array id="tri-pos-array" count="9">0 0 0 100 0 0 0 200 0</float_array>
        <technique_common><accessor source="#tri-pos-array" count="3" stride="3">
          <param name="X" type="float"/><param name="Y" type="float"/><param name="Z" type="float"/></accessor></technique_common></source>
      <vertices id="tri-vtx"><input semantic="POSITION" source="#tri-pos"/></vertices>
      <triangles material="mat" count="1"><input semantic="VERTEX" source="#tri-vtx" offset="0"/><p>0 1 2</p></triangles>
    </mesh></geometry>
  </library_geometries>
  <library_visual_scenes>
    <visual_scene id="scene"><node id="n"><matrix>1 0 0 0.5 0 1 0 0 0 0 1 0 0 0 0 1</matrix>
      <instance_geometry url="#tri-mesh"><bind_material><technique_common>
        <instance_material symbol="mat" target="#green"/></technique_common></bind_material></instance_geometry></node></visual_scene>
  </library_visual_scenes>
  <scene><instance_visual_scene url="#scene"/></scene>
</COLLADA>
"""
"""One triangle in millimetres, moved 0.5 mm along x by its node, in a green material."""


def test_dae_reads_in_metres_with_its_colours(trimesh, tmp_path, monkeypatch):
    try:
        import collada  # noqa: F401
    except ImportError:
        if os.environ.get("CI"):
            pytest.fail("pycollada not installed: the `viewer` extra should be installed by `make test`")
        pytest.skip("no pycollada: pip install 'derive-robotics[viewer]'")
    (tmp_path / "tri.dae").write_text(DAE)
    (vertices, faces, colour), = read_mesh(tmp_path / "tri.dae")
    np.testing.assert_allclose(vertices, [[0.0005, 0, 0], [0.1005, 0, 0], [0.0005, 0.2, 0]], rtol=1e-12, atol=1e-15)
    assert faces.tolist() == [[0, 1, 2]] and colour == (0.0, 0.8, 0.0, 1.0)
    monkeypatch.setitem(sys.modules, "collada", None)  # a DAE without pycollada: the extra named
    robot = parse_models(MODEL.replace("VISUAL", f"{{mesh: {tmp_path / 'tri.dae'}}}"))["bot"]
    lines = []
    assert visual_parts(robot, robot.frame_names, lines.append) == []
    assert lines == ["warning: derive view bot: reading mesh files needs the viewer extra (trimesh, pycollada): "
                     "pip install 'derive-robotics[viewer]' (collada is missing); the meshes are left out"]


def test_primitives_are_the_shapes_they_name():
    from derive.description.robot import Visual

    v, f = shape_mesh(Visual("box", size=(0.1, 0.2, 0.3)))
    np.testing.assert_array_equal(np.ptp(v, axis=0), [0.1, 0.2, 0.3])
    assert len(f) == 12
    for shape, size in (("cylinder", (0.05, 0.4)), ("capsule", (0.05, 0.4)), ("sphere", (0.05,))):
        v, f = shape_mesh(Visual(shape, size=size))
        r = np.hypot(v[:, 0], v[:, 1])
        assert np.isclose(r.max(), 0.05, rtol=1e-12)
        half = {"cylinder": 0.2, "capsule": 0.25, "sphere": 0.05}[shape]
        np.testing.assert_allclose([v[:, 2].min(), v[:, 2].max()], [-half, half], rtol=1e-12)
        if shape != "cylinder":  # every vertex on the sphere (or the capsule's end spheres and its side)
            centre = np.clip(v[:, 2], -(half - 0.05), half - 0.05)
            np.testing.assert_allclose(np.hypot(r, v[:, 2] - centre), 0.05, rtol=1e-12)
        # a closed surface: every edge in exactly two triangles, and the volume positive (outward faces)
        edges = np.sort(np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]), axis=1)
        assert (np.unique(edges, axis=0, return_counts=True)[1] == 2).all()
        volume = np.einsum("ij,ij->i", v[f[:, 0]], np.cross(v[f[:, 1]], v[f[:, 2]])).sum() / 6
        assert 0 < volume < {"cylinder": np.pi * 0.05 ** 2 * 0.4, "capsule": np.pi * 0.05 ** 2 * (0.4 + 4 / 3 * 0.05),
                             "sphere": 4 / 3 * np.pi * 0.05 ** 3}[shape]


def dense_sphere(sub: int) -> tuple[np.ndarray, np.ndarray]:
    """A unit sphere of shape_mesh's, every triangle split into sub^2 (vertices pushed onto the sphere)."""
    from derive.description.robot import Visual

    v, f = shape_mesh(Visual("sphere", size=(1.0,)))
    verts, faces = [], []
    for a, b, c in v[f]:
        base = len(verts)
        grid = {}
        for i in range(sub + 1):
            for j in range(sub + 1 - i):
                grid[i, j] = len(verts) - base
                p = a + (b - a) * i / sub + (c - a) * j / sub
                verts.append(p / np.linalg.norm(p))
        for i in range(sub):
            for j in range(sub - i):
                faces.append([base + grid[i, j], base + grid[i + 1, j], base + grid[i, j + 1]])
                if j < sub - i - 1:
                    faces.append([base + grid[i + 1, j], base + grid[i + 1, j + 1], base + grid[i, j + 1]])
    return np.array(verts), np.array(faces)


def test_simplify_meets_the_budget():
    verts, faces = dense_sphere(6)
    assert len(faces) > 15000
    for limit in (4000, 500, 60):
        v2, f2 = simplify(verts, faces, limit)
        assert 0.3 * limit < len(f2) <= limit
        assert f2.max() < len(v2) and len(np.unique(f2)) == len(v2)  # no vertex left unused
        assert np.abs(np.linalg.norm(v2, axis=1) - 1).max() < 0.2  # still a unit sphere, roughly
    same = simplify(verts, faces, len(faces))
    assert same[0] is verts and same[1] is faces


def test_without_trimesh_the_meshes_go_with_one_warning(looks, monkeypatch):
    monkeypatch.setitem(sys.modules, "trimesh", None)
    robot = load_robot("looks", looks)
    lines = []
    parts = visual_parts(robot, robot.frame_names, lines.append)
    assert lines == ["warning: derive view looks: reading mesh files needs the viewer extra (trimesh, pycollada): pip install "
                     "'derive-robotics[viewer]'; the meshes are left out"]
    assert [p.name for p in parts] == ["base_0", "arm_1"]  # the box and the cylinder are drawn without it


def test_a_missing_mesh_file_is_one_warning(looks, trimesh):
    robot = load_robot("looks", looks)
    (looks.parent.parent / "looks_description" / "meshes" / "slab.stl").unlink()
    lines = []
    parts = visual_parts(robot, robot.frame_names, lines.append)
    assert lines == ["warning: derive view looks: 1 mesh file not found, left out: ../looks_description/meshes/slab.stl "
                     f"(relative to {looks.parent})"]
    assert len(parts) == 2


# --------------------------------------------------------------------------- the page, in a real browser


def test_page_draws_the_meshes_where_they_are(looks, trimesh, tmp_path):
    """The exported page of the imported robot at q = 1.2: the red STL slab's pixels where its turned
    centre projects and along its length, the blue cylinder's at the tool; the page's quantised vertices
    are the parts' to within half a quantisation step."""
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    if chromium is None:
        if os.environ.get("CI"):
            pytest.fail("chromium not installed: .ci/run installs Debian's chromium")
        pytest.skip("no chromium: apt-get install chromium")
    from matplotlib.image import imread

    page = tmp_path / "looks.html"
    assert main(["--models", str(looks), "view", "looks", "--q", "1.2", "--html", str(page)]) == 0
    done = subprocess.run([chromium, "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                           "--host-resolver-rules=MAP * ~NOTFOUND", f"--screenshot={tmp_path / 'looks.png'}",
                           f"--window-size={WIDTH},{HEIGHT}", "--virtual-time-budget=2000", page.as_uri()],
                          capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert (tmp_path / "looks.png").is_file(), done.stderr[-2000:]
    data = page_json(page.read_text())
    robot = load_robot("looks", looks)
    parts = visual_parts(robot, robot.frame_names, print)
    assert len(data["meshes"]) == len(parts) == 3
    import base64
    for packed, part in zip(data["meshes"], parts):
        q = np.frombuffer(base64.b64decode(packed["v"]), dtype="<u2").reshape(-1, 3)
        np.testing.assert_allclose(np.array(packed["lo"]) + q * np.array(packed["step"]), part.vertices,
                                   atol=0.5 * max(packed["step"]) * (1 + 1e-9))
        faces = np.frombuffer(base64.b64decode(packed["f"]), dtype="<u4" if packed["wide"] else "<u2").reshape(-1, 3)
        np.testing.assert_array_equal(faces, part.faces)
    image = imread(tmp_path / "looks.png")[:, :, :3]
    c, s = np.cos(1.2), np.sin(1.2)
    # the slab: arm frame z = 0.1 (joint) + 0.2 (visual); along its length (arm x) turned by q about z
    red = [np.array([c * x, s * x, 0.3 + dz]) for x in (-0.1, 0.0, 0.1) for dz in (-0.1, 0.0, 0.1)]
    for x, y in np.round(project(data, np.array(red))).astype(int):
        r, g, b = image[y, x]
        assert r > 0.3 and g < 0.1 and b < 0.1, (x, y, image[y, x])
    for x, y in np.round(project(data, np.array([[0.0, 0.0, 0.5]]))).astype(int):  # the tool's cylinder, z 0.45 .. 0.55
        r, g, b = image[y, x]
        assert b > 0.3 and r < 0.1 and g < 0.1, (x, y, image[y, x])
    for y, x in [(HEIGHT // 2, 2), (HEIGHT // 2, WIDTH - 3)]:
        assert image[y, x].min() > 0.8  # background at the sides


def test_view_html_thins_a_big_mesh_and_says_so(trimesh, tmp_path, capsys):
    verts, faces = dense_sphere(8)
    assert len(faces) > 30_000
    write_stl(tmp_path / "ball.stl", 0.1 * verts[faces])
    (tmp_path / "models.yaml").write_text(MODEL.replace("VISUAL", "{mesh: ball.stl}"))
    page = tmp_path / "bot.html"
    assert main(["--models", str(tmp_path / "models.yaml"), "view", "bot", "--html", str(page)]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"wrote {page} (") and out.endswith(f" KiB, {len(faces)} mesh triangles thinned to at most 30000)\n")
    import base64
    (packed,) = page_json(page.read_text())["meshes"]
    assert 15_000 < len(base64.b64decode(packed["f"])) // 6 <= 30_000
    assert main(["--models", str(tmp_path / "models.yaml"), "view", "bot", "--no-meshes", "--html", str(page)]) == 0
    assert page_json(page.read_text())["meshes"] == [] and "mesh" not in capsys.readouterr().out


def test_page_thins_to_its_budget():
    from derive.view.meshes import Part

    v, f = shape_mesh(__import__("derive.description.robot", fromlist=["Visual"]).Visual("sphere", size=(1.0,)))
    parts = [Part(0, v, f, (1, 1, 1, 1), "a"), Part(0, v + 3, f, (1, 1, 1, 1), "b")]
    assert thin(parts, 10_000) == parts
    thinned = thin(parts, 200)
    assert sum(len(p.faces) for p in thinned) <= 200 and all(len(p.faces) >= 30 for p in thinned)


# --------------------------------------------------------------------------- the live viewer


def test_live_meshes_move_with_the_joints_and_toggle(looks, trimesh):
    try:
        import viser
    except ImportError:
        if os.environ.get("CI"):
            pytest.fail("viser not installed: the `viewer` extra should be installed by `make test`")
        pytest.skip("no viser: pip install 'derive-robotics[viewer]'")
    from derive.view.server import LiveView

    robot = load_robot("looks", looks)
    kin = Kinematics(robot)
    geo = geometry(robot, kin)
    parts = visual_parts(robot, geo.frames, print)
    server = viser.ViserServer(host="127.0.0.1", port=free_port(), verbose=False)
    try:
        view = LiveView(server, robot, kin, geo, initial_q(robot), parts=parts)
        assert sorted(view.mesh_frames) == [geo.frames.index("base"), geo.frames.index("arm")]
        assert len(view.meshes) == 3 and not view.boxes[0].visible and view.skeleton.visible
        # the first camera looks at the centre of the frames from the page's direction, not from viser's far default
        origins = kin.poses(initial_q(robot))[:, :3, 3]
        np.testing.assert_allclose(server.initial_camera.look_at, 0.5 * (origins.min(axis=0) + origins.max(axis=0)),
                                   atol=1e-6)
        assert np.linalg.norm(np.asarray(server.initial_camera.position) - server.initial_camera.look_at) < 3 * geo.size
        view.sliders[0].value = 0.9
        view._slid(0)(None)
        arm = kin.poses(view.q)[geo.frames.index("arm")]
        handle = view.mesh_frames[geo.frames.index("arm")]
        np.testing.assert_allclose(handle.position, arm[:3, 3], atol=1e-12)
        np.testing.assert_allclose(viser.transforms.SO3(np.asarray(handle.wxyz)).as_matrix(), arm[:3, :3], atol=1e-12)
        view.layers["meshes"].value = False
        view._shown(list(view.mesh_frames.values()), view.layers["meshes"])(None)
        assert not any(h.visible for h in view.mesh_frames.values())
    finally:
        server.stop()
