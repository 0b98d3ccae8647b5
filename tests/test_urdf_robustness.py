"""Bad or odd URDF input never hurts the importer (issue 12).

One test per class of what a new user hits with real URDFs:
- joints that form a cycle (detached from the root, through a self-joint, or with no
  root at all) end in a one-line ModelError naming the file and the cycle, at once;
- exporter-default ``<limit lower="0" upper="0" effort="0" velocity="0"/>`` is read as
  no limits, with one warning line on stderr naming the file and the joint;
- ``<mimic>`` on a fixed joint is ignored (as Pinocchio does); on a moving joint it is
  still refused, with a ``--lock`` suggestion that works as given;
- inertia rounding noise (-2e-22 kg m^2 on a link whose inertia is zero) is accepted,
  clamped below 1e-12 of the robot's largest inertia; a clearly negative moment or a
  clear triangle violation is still refused;
- double_pendulum, talos_left_arm, anymal and go1 of example-robot-data import as chains
  (``--chain``) without hand edits and match Pinocchio (FK of every frame, mass matrix) to
  1e-12 relative (whole trees: tests/test_urdf_trees.py).
"""

from __future__ import annotations

import re
import threading
import time

import numpy as np
import pytest

from derive.description.model import parse_robot
from derive.description.robot import ModelError
from derive.description.urdf import example_robot_data_dir, import_urdf, import_urdf_named, parse_lock
from derive.reference import NumericRobot
from test_urdf import PinSide, erd_path, random_q, rel, write

PIN_TOL = 1e-12


def link(name: str, mass: float | None = 1.0, inertia: str = 'ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"',
         com: str = "0 0 0.1") -> str:
    if mass is None:
        return f'  <link name="{name}"/>\n'
    return (f'  <link name="{name}"><inertial><origin xyz="{com}"/><mass value="{mass}"/>'
            f'<inertia {inertia}/></inertial></link>\n')


def joint(name: str, parent: str, child: str, jtype: str = "revolute", extra: str = "",
          limit: str = '<limit lower="-2" upper="2" effort="10" velocity="1"/>') -> str:
    limit = limit if jtype != "fixed" else ""
    return (f'  <joint name="{name}" type="{jtype}"><parent link="{parent}"/><child link="{child}"/>'
            f'<origin xyz="0 0 0.3" rpy="0.1 0.2 0.3"/><axis xyz="0 0 1"/>{limit}{extra}</joint>\n')


def robot(*parts: str, name: str = "odd") -> str:
    return f'<?xml version="1.0"?>\n<robot name="{name}">\n{"".join(parts)}</robot>\n'


ARM = (link("world", None), link("l1"), link("l2"), link("tool", None),
       joint("j1", "world", "l1"), joint("j2", "l1", "l2"), joint("tool_mount", "l2", "tool", "fixed"))


def one_line(match: str, *args, **kwargs) -> ModelError:
    with pytest.raises(ModelError, match=match) as info:
        import_urdf(*args, **kwargs)
    assert "\n" not in str(info.value)
    return info.value


# --------------------------------------------------------------------------- 1. cycles


def import_within(seconds: float, *args, **kwargs):
    """import_urdf in a daemon thread: (result or exception, elapsed); fails if it has not ended by then."""
    out: dict = {}

    def run():
        try:
            out["value"] = import_urdf(*args, **kwargs)
        except Exception as exc:  # handed to the test
            out["value"] = exc

    start = time.perf_counter()
    worker = threading.Thread(target=run, daemon=True)
    worker.start()
    worker.join(seconds)
    assert not worker.is_alive(), f"import_urdf still running after {seconds} s"
    return out["value"], time.perf_counter() - start


@pytest.mark.parametrize("case", ["detached, tip on it", "detached, tip elsewhere", "self-joint", "no root"])
def test_cycle_is_one_line_error_at_once(tmp_path, case):
    loop = (link("a"), link("b"), link("c"), joint("ab", "a", "b"), joint("bc", "b", "c", "fixed"), joint("ca", "c", "a"))
    if case == "self-joint":
        parts, tip, members = ARM + (link("s"), joint("ss", "s", "s")), "tool", ["'ss'"]
    elif case == "no root":
        parts, tip, members = loop, "b", ["'ab'", "'bc'", "'ca'"]
    else:
        parts, tip = ARM + loop, ("b" if case == "detached, tip on it" else "tool")
        members = ["'ab'", "'bc'", "'ca'"]
    path = write(tmp_path, robot(*parts))
    err, elapsed = import_within(5.0, path, tip)
    assert elapsed < 1.0, elapsed
    assert isinstance(err, ModelError), err
    text = str(err)
    assert "\n" not in text
    assert text.startswith(f"{path}: robot 'odd': joints: the joints "), text
    assert "form a cycle through the links" in text and "a URDF must be a tree" in text
    for name in members:
        assert name in text, (name, text)
    if case.startswith("detached"):
        assert "detached from the root link 'world'" in text
        assert "'a'" in text and "'b'" in text and "'c'" in text  # the links of the cycle
    if case == "no root":
        assert "so no link is the root" in text


def test_deep_branch_is_no_recursion(tmp_path):
    """A 3000-link branch off the tip path: a one-line error (no RecursionError), whose lock imports."""
    n = 3000
    parts = [link("world", None), link("l0"), joint("j0", "world", "l0"), link("b0"), joint("jb", "world", "b0")]
    parts += [link(f"b{i}", 0.001) for i in range(1, n)]
    parts += [joint(f"f{i}", f"b{i - 1}", f"b{i}", "fixed") for i in range(1, n)]
    path = write(tmp_path, robot(*parts))
    # CPU seconds, not wall: no quadratic walk of the branch (it took minutes), whatever else the machine runs
    start = time.process_time()
    err = one_line(r"^.*/robot\.urdf: robot 'odd': joints\[jb\]: moves a branch with mass \(3.999 kg\) that does not lead to the tip "
                   r"'l0'; lock it \(--lock jb\)", path, chain="l0")
    assert time.process_time() - start < 5.0, err
    entry = import_urdf(path, lock="jb", chain="l0")
    assert [j["name"] for j in entry["joints"]] == ["j0"]
    assert entry["links"][0]["mass"] == pytest.approx(1.0 + 0.001 * (n - 1), rel=1e-12)  # the branch, merged into the root
    start = time.process_time()
    entry = import_urdf(path)  # the whole tree: the branch moves, as one body of 2999 merged links
    assert time.process_time() - start < 5.0
    assert [j["name"] for j in entry["joints"]] == ["j0", "jb"]
    entry = import_urdf(path, "l0", "jb")
    assert [j["name"] for j in entry["joints"]] == ["j0"]
    assert entry["links"][0]["mass"] == pytest.approx(1.0 + 0.001 * (n - 1), rel=1e-12)  # the branch, merged into the root


# --------------------------------------------------------------------------- 2. exporter-default limits


def test_exporter_default_limits_are_absent_with_a_warning(tmp_path, capsys):
    zeros = '<limit lower="0" upper="0" effort="0" velocity="0"/>'
    parts = (link("world", None), link("l1"), link("l2"), link("l3"),
             joint("j1", "world", "l1", limit=zeros),
             joint("j2", "l1", "l2", "continuous", limit='<limit effort="0" velocity="0"/>'),
             joint("j3", "l2", "l3", limit='<limit lower="-1" upper="1.5" effort="0" velocity="2"/>'))
    path = write(tmp_path, robot(*parts))
    entry = import_urdf(path, "l3")
    joints = {j["name"]: j for j in entry["joints"]}
    assert "limits" not in joints["j1"] and "limits" not in joints["j2"]
    assert joints["j3"]["limits"] == {"lower": -1.0, "upper": 1.5, "velocity": 2.0}  # only the zero effort goes
    parse_robot("odd", entry)
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 3, lines
    for name, line in zip(("j1", "j2", "j3"), lines):
        assert line.startswith(f"warning: {path}: joints[{name}].limit: "), line
        assert "exporter's placeholder" in line
    assert "imported without limits" in lines[0] and "imported without effort limit" in lines[2]
    # real but wrong numbers are still refused by the model's validation
    path = write(tmp_path, robot(*ARM).replace('velocity="1"', 'velocity="-1"', 1))
    one_line(r"^.*/robot\.urdf: robot 'odd': joints\[0\].limits.velocity: must be positive, got -1.0", path, "tool")
    # real limits are copied exactly, and give no warning
    entry = import_urdf(write(tmp_path, robot(*ARM)), "tool")
    assert entry["joints"][0]["limits"] == {"lower": -2.0, "upper": 2.0, "velocity": 1.0, "effort": 10.0}
    assert capsys.readouterr().err == ""


# --------------------------------------------------------------------------- 3. mimic


def test_mimic_on_a_fixed_joint_is_ignored(tmp_path, capsys):
    mimic = '<mimic joint="j2" multiplier="-1.0" offset="0.0"/>'
    parts = ARM + (link("finger"), joint("finger_joint", "l2", "finger", "fixed", extra=mimic))
    entry = import_urdf(write(tmp_path, robot(*parts)), "tool")
    assert [j["name"] for j in entry["joints"]] == ["j1", "j2"]
    assert entry["links"][-1]["mass"] == 2.0  # the finger is merged into l2
    assert "finger" in {f["name"] for f in entry["frames"]}
    # on a moving joint it becomes a mimic joint; with the joint it follows locked, it must be locked too
    # (one line, with a lock suggestion that works: values within limits)
    mimic = '<mimic joint="j2" multiplier="-2.0" offset="0.3"/>'
    parts = ARM + (link("finger"), joint("finger_joint", "l2", "finger", extra=mimic,
                                         limit='<limit lower="0.1" upper="0.5" effort="1" velocity="1"/>'))
    path = write(tmp_path, robot(*parts))
    finger = import_urdf(path, "tool")["joints"][-1]
    assert finger["name"] == "finger_joint" and finger["mimic"] == {"joint": "j2", "multiplier": -2.0, "offset": 0.3}
    err = one_line(r"^.*/robot\.urdf: robot 'odd': joints\[finger_joint\]\.mimic: mimics 'j2', a locked joint: lock it "
                   r"\(--lock j2,finger_joint=0.1\)", path, "tool", "j2")
    lock = re.search(r"--lock (\S+)\)", str(err)).group(1)
    tip_off_branch = import_urdf(path, "l1", lock)  # the suggested command imports
    assert [j["name"] for j in tip_off_branch["joints"]] == ["j1"]
    assert import_urdf(path, lock=lock, chain="l1")["joints"] == tip_off_branch["joints"]


def test_talos_left_arm_mimic_fixed_joints(capsys):
    """The talos gripper's six fixed joints with <mimic> no longer block the import; the only thing said
    is the list of its two rounded angles (written to 11 and 16 digits: 4.7e-12 and 2.1e-13 off)."""
    name, entry = import_urdf_named("example-robot-data:talos_data/robots/talos_left_arm.urdf", "gripper_left_motor_double_link")
    assert name == "talos" and len(entry["joints"]) == 7
    assert capsys.readouterr().err == (
        "warning: example-robot-data:talos_data/robots/talos_left_arm.urdf: angles: 2 constant angles are within 0.0001 "
        "rad of a multiple of pi/2 without being one (kept as written; --snap-angles 0.0001 makes them exact): "
        "frames[wrist_left_ft_link].rpy[2] = -4.71238898038 (-3 pi/2 + 4.7e-12), "
        "frames[gripper_left_fingertip_3_link].rpy[2] = -3.1415926535895866 (-pi + 2.1e-13)\n")


# --------------------------------------------------------------------------- 4. inertia noise


NOISE = 'ixx="-2e-22" ixy="1e-22" ixz="0" iyy="1e-22" iyz="-1e-22" izz="0"'


def test_inertia_noise_is_accepted_and_real_errors_are_not(tmp_path):
    # a link whose inertia is rounding noise (about -2e-22 kg m^2): nothing of its own to be relative to
    parts = (link("world", None), link("l1"), link("l2", inertia=NOISE), link("tool", None),
             joint("j1", "world", "l1"), joint("j2", "l1", "l2"), joint("tool_mount", "l2", "tool", "fixed"))
    path = write(tmp_path, robot(*parts))
    entry = import_urdf(path, "tool")
    inertia = entry["links"][2]["inertia"]
    assert all(abs(v) <= 1e-21 for v in inertia.values()), inertia  # clamped by less than 1e-12 of 0.03
    m = np.array([[inertia["ixx"], inertia["ixy"], inertia["ixz"]], [inertia["ixy"], inertia["iyy"], inertia["iyz"]],
                  [inertia["ixz"], inertia["iyz"], inertia["izz"]]])
    assert np.linalg.eigvalsh(m)[0] >= 0
    parse_robot("odd", entry)
    # anymal's and go1's base: 1e-6 kg, every entry 1e-6 (principal moments -2e-22, 9e-23, 3e-6),
    # merged with the real base body behind a fixed joint
    base = 'ixx="1e-6" ixy="1e-6" ixz="1e-6" iyy="1e-6" iyz="1e-6" izz="1e-6"'
    parts = (link("base", 1e-6, base), link("trunk", 5.0, 'ixx="0.02" ixy="0" ixz="0" iyy="0.06" iyz="0" izz="0.07"'),
             link("l1"), link("l2"), joint("base_to_trunk", "base", "trunk", "fixed"),
             joint("j1", "trunk", "l1"), joint("j2", "l1", "l2"))
    entry = import_urdf(write(tmp_path, robot(*parts)), "l2")
    assert entry["links"][0]["mass"] == 5.0 + 1e-6
    # noise on a link with a real inertia is left exactly as written
    ok = 'ixx="0.01" ixy="-2e-22" ixz="0" iyy="0.01" iyz="0" izz="0"'
    entry = import_urdf(write(tmp_path, robot(*ARM).replace(ARM[2], link("l2", inertia=ok))), "tool")
    assert entry["links"][2]["inertia"] == {"ixx": 0.01, "ixy": -2e-22, "ixz": 0.0, "iyy": 0.01, "iyz": 0.0, "izz": 0.0}

    # real errors stay refused
    bad = {
        "negative": ('ixx="-0.001" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"', "not positive semi-definite"),
        "triangle": ('ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.01"', "breaks the triangle inequality"),
        "tiny but clear": ('ixx="1e-6" ixy="1e-6" ixz="1e-6" iyy="1e-6" iyz="1e-6" izz="1e-6"', "breaks the triangle"),
    }
    for inertia, why in bad.values():
        path = write(tmp_path, robot(*ARM).replace(ARM[2], link("l2", inertia=inertia)))
        one_line(rf"^.*/robot\.urdf: robot 'odd': links\[2\] \(l2\)\.inertia: {why}", path, "tool")
    # a massless link with a real inertia, merged into another: named as written in the URDF
    parts = ARM + (link("cam", 0.0, 'ixx="0.001" ixy="0" ixz="0" iyy="0.001" iyz="0" izz="0.001"'),
                   joint("cam_mount", "l2", "cam", "fixed"))
    one_line(r"^.*/robot\.urdf: robot 'odd': links\[cam\]\.inertia \(merged into 'l2'\): a massless link must have zero inertia",
             write(tmp_path, robot(*parts)), "tool")
    # ... while one with noise is a massless link
    parts = ARM + (link("cam", 0.0, NOISE), joint("cam_mount", "l2", "cam", "fixed"))
    assert import_urdf(write(tmp_path, robot(*parts)), "tool")["links"][2]["mass"] == 1.0


# --------------------------------------------------------------------------- 5. example-robot-data vs Pinocchio


ERD = "example-robot-data:"
# (URDF, tip, lock or None): None where the import needs no lock; "suggested" takes the lock the
# error message proposes, which must then import as given.
ROBOTS = {
    "double_pendulum": (ERD + "double_pendulum_description/urdf/double_pendulum.urdf", "link2", None),
    "talos_left_arm": (ERD + "talos_data/robots/talos_left_arm.urdf", "gripper_left_motor_double_link", None),
    "talos_left_arm_locked": (ERD + "talos_data/robots/talos_left_arm.urdf", "gripper_left_fingertip_3_link", "suggested"),
    "anymal": (ERD + "anymal_b_simple_description/robots/anymal.urdf", "LF_FOOT", "suggested"),
    "go1": (ERD + "go1_description/urdf/go1.urdf", "FL_foot", "suggested"),
}


@pytest.mark.parametrize("key", ROBOTS)
def test_example_robot_data_against_pinocchio(key, capsys):
    import pinocchio as pin  # a hard requirement here: this test must not be skipped

    assert example_robot_data_dir() is not None, "example-robot-data is not installed"
    path, tip, lock = ROBOTS[key]
    if lock == "suggested":  # the chain to the tip: the other legs must be locked
        with pytest.raises(ModelError, match="--lock ") as info:
            import_urdf_named(path, chain=tip)
        lock = re.search(r"--lock (\S+)\)", str(info.value)).group(1)
    start = time.perf_counter()
    name, entry = import_urdf_named(path, lock=lock, chain=tip)
    elapsed = time.perf_counter() - start
    robot = parse_robot(name, entry)
    locks = {n: v for n, (v, _) in parse_lock(lock).items()}
    side = PinSide(pin, erd_path(path), robot, locks, tip)
    nr = NumericRobot(robot)
    rng = np.random.default_rng(12)
    worst_fk = worst_m = 0.0
    for _ in range(5):
        q = random_q(robot, rng)
        fk = nr.fk(q)
        for frame in robot.frame_names:
            worst_fk = max(worst_fk, rel(fk[frame], side.pose(q, frame)))
        worst_m = max(worst_m, rel(nr.crba(q), side.crba(q)))
    with capsys.disabled():
        print(f"\n{key}: nv {robot.nv}, {len(robot.frame_names)} frames, import {elapsed * 1e3:.0f} ms, "
              f"worst relative error vs Pinocchio: FK {worst_fk:.1e}, M {worst_m:.1e}")
    assert worst_fk < PIN_TOL and worst_m < PIN_TOL, (worst_fk, worst_m)
    assert elapsed < 5.0
    moving = sum(link.mass for link in robot.links if link.name != robot.root)
    assert moving == pytest.approx(sum(i.mass for i in side.model.inertias[1:]), rel=1e-14)
