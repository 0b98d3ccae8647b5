"""The output folder loses nothing: concurrent runs, other PID namespaces, links, odd manifests,
mount points, full and read-only disks (issue "Nothing lost, nothing hangs").

Each case runs for real: two processes at once, ``unshare`` for a PID or mount namespace, a tiny
tmpfs for a full disk. The namespace cases are skipped, with the reason, where the machine cannot
make namespaces (not root and no user namespaces).
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import socket
import stat
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from derive.cli import main

ROOT = Path(__file__).resolve().parent.parent

ARM = """\
robots:
  {name}:
    links:
      - {{name: base}}
      - {{name: l1, mass: {mass}, com: [0.1, 0, 0], inertia: [0.01, 0.01, 0.01]}}
      - {{name: l2, mass: 0.5, com: [0.1, 0, 0], inertia: [0.01, 0.01, 0.01]}}
    joints:
      - {{name: q1, type: revolute, parent: base, child: l1, axis: [0, 0, 1]}}
      - {{name: q2, type: revolute, parent: l1, child: l2, axis: [0, 1, 0], origin: {{xyz: [0.2, 0, 0]}}}}
    frames:
      - {{name: tcp, link: l2, xyz: [0.1, 0, 0]}}
"""


def arm(name: str = "arm", mass: str = "1.0") -> str:
    return ARM.format(name=name, mass=mass)


def chain(name: str, n: int) -> str:
    """A spatial chain of ``n`` links: several seconds of derivation, time to act during a run."""
    links = ["      - {name: l0}"] + [f"      - {{name: l{i}, mass: 1.0, com: [0.1, 0, 0], inertia: [0.01, 0.02, 0.03]}}"
                                      for i in range(1, n + 1)]
    axes = ["[0, 0, 1]", "[0, 1, 0]", "[1, 0, 0]"]
    joints = [f"      - {{name: j{i}, type: revolute, parent: l{i - 1}, child: l{i}, axis: {axes[i % 3]}, "
              "origin: {xyz: [0.2, 0.05, 0.1]}}" for i in range(1, n + 1)]
    return (f"robots:\n  {name}:\n    links:\n" + "\n".join(links) + "\n    joints:\n" + "\n".join(joints)
            + f"\n    frames:\n      - {{name: tcp, link: l{n}}}\n")


def tree(folder: Path) -> dict[str, str]:
    """{path: sha256 of a file | 'link -> target' | 'fifo' | 'dir'} of everything under ``folder``, links not followed."""
    out = {}
    for root, dirs, files in os.walk(folder):
        for name in dirs + files:
            path = Path(root) / name
            rel = path.relative_to(folder).as_posix()
            st = os.lstat(path)
            if stat.S_ISLNK(st.st_mode):
                out[rel] = f"link -> {os.readlink(path)}"
            elif stat.S_ISDIR(st.st_mode):
                out[rel] = "dir"
            elif stat.S_ISFIFO(st.st_mode):
                out[rel] = "fifo"
            elif stat.S_ISSOCK(st.st_mode):
                out[rel] = "socket"
            else:
                out[rel] = hashlib.sha256(path.read_bytes()).hexdigest()
        dirs[:] = [d for d in dirs if not (Path(root) / d).is_symlink()]
    return out


def derive(*argv: str, cwd: Path, timeout: float = 120, prefix: tuple[str, ...] = ()) -> subprocess.CompletedProcess:
    return subprocess.run([*prefix, sys.executable, "-m", "derive", *argv], cwd=cwd, capture_output=True, text=True,
                          timeout=timeout)


def start(*argv: str, cwd: Path, prefix: tuple[str, ...] = ()) -> subprocess.Popen:
    return subprocess.Popen([*prefix, sys.executable, "-m", "derive", *argv], cwd=cwd, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def wait_for_temporary(parent: Path, name: str = "generated", timeout: float = 60) -> Path:
    """The temporary folder of a run into ``parent/name`` once it exists (the run holds the lock then)."""
    deadline = time.time() + timeout
    while time.time() < deadline:
        found = [p for p in parent.iterdir() if p.name.startswith(f".{name}.tmp-")]
        if found:
            return found[0]
        time.sleep(0.01)
    raise AssertionError("the run never started")


def one_error_line(stderr: str) -> str:
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("derive: error: ") and "Traceback" not in stderr, stderr
    return lines[0]


def manifest_robots(out: Path) -> list[str]:
    return sorted(json.loads((out / "MANIFEST.json").read_text())["robots"])


def assert_intact(out: Path) -> None:
    """Every robot MANIFEST.json lists is on disk with exactly the files and bytes it records."""
    for name, entry in json.loads((out / "MANIFEST.json").read_text())["robots"].items():
        files = {p.relative_to(out / name).as_posix() for p in (out / name).rglob("*") if p.is_file()}
        assert files == set(entry["files"]), name
        for rel, digest in entry["files"].items():
            assert hashlib.sha256((out / name / rel).read_bytes()).hexdigest() == digest, f"{name}/{rel}"


def can_unshare(*flags: str) -> str | None:
    """None if ``unshare FLAGS true`` works here, else the reason it does not."""
    try:
        r = subprocess.run(["unshare", *flags, "true"], capture_output=True, text=True, timeout=20)
    except (OSError, subprocess.SubprocessError) as exc:
        return f"no unshare ({exc})"
    return None if r.returncode == 0 else f"unshare {' '.join(flags)} is not permitted here: {r.stderr.strip()}"


# ---- 1. concurrent runs into one folder take turns, and the second merges onto the first ----

def test_two_concurrent_generations_into_one_folder_keep_both_and_every_update(tmp_path):
    (tmp_path / "one.yaml").write_text(chain("chain6", 6) + arm("arm", "2.0").split("robots:\n", 1)[1])
    (tmp_path / "two.yaml").write_text(arm("other"))
    (tmp_path / "old.yaml").write_text(arm("arm", "1.0"))
    out = tmp_path / "generated"
    assert derive("--models", "old.yaml", "generate", "--out", str(out), cwd=tmp_path).returncode == 0
    old_arm = (out / "arm" / "python" / "arm.py").read_text()

    first = start("--models", "one.yaml", "generate", "--out", str(out), cwd=tmp_path)  # updates arm, adds chain6
    wait_for_temporary(tmp_path)
    second = derive("--models", "two.yaml", "generate", "--out", str(out), cwd=tmp_path)
    first_out, first_err = first.communicate(timeout=120)
    assert first.returncode == 0, first_err
    assert second.returncode == 0, second.stderr
    assert "waiting for another derive run" in second.stdout
    assert manifest_robots(out) == ["arm", "chain6", "other"]
    assert (out / "arm" / "python" / "arm.py").read_text() != old_arm  # the first run's update survived
    assert_intact(out)


# ---- 2. a live run in another PID namespace keeps its temporary folder ----

def test_a_run_in_another_pid_namespace_is_waited_for_not_deleted(tmp_path):
    reason = can_unshare("--pid", "--fork")
    if reason:
        pytest.skip(reason)
    (tmp_path / "one.yaml").write_text(chain("chain6", 6))
    (tmp_path / "two.yaml").write_text(arm("other"))
    out = tmp_path / "generated"
    container = start("--models", "one.yaml", "generate", "--out", str(out), cwd=tmp_path,
                      prefix=("unshare", "--pid", "--fork"))
    live = wait_for_temporary(tmp_path)
    pid = int(live.name.split("-")[1])
    assert pid < 10, live.name  # a pid of the new namespace, which the host may not know or may give to another
    host = derive("--models", "two.yaml", "generate", "--out", str(out), cwd=tmp_path)
    _, err = container.communicate(timeout=120)
    assert container.returncode == 0, err
    assert host.returncode == 0, host.stderr
    assert "waiting for another derive run" in host.stdout and "left by an interrupted run" not in host.stdout
    assert manifest_robots(out) == ["chain6", "other"]
    assert_intact(out)


def test_a_temporary_folder_removed_under_a_run_aborts_it(tmp_path):
    (tmp_path / "old.yaml").write_text(arm("arm"))
    (tmp_path / "one.yaml").write_text(chain("chain6", 6))
    out = tmp_path / "generated"
    assert derive("--models", "old.yaml", "generate", "--out", str(out), cwd=tmp_path).returncode == 0
    before = tree(out)
    run = start("--models", "one.yaml", "generate", "--out", str(out), cwd=tmp_path)
    live = wait_for_temporary(tmp_path)
    while live.exists():  # what a run that judged it dead would do (retried: the run may be writing into it)
        subprocess.run(["rm", "-rf", str(live)], capture_output=True)
    _, err = run.communicate(timeout=120)
    assert run.returncode == 2
    line = one_error_line(err)
    assert "was removed by another process" in line and str(live) in line
    assert tree(out) == before
    assert not any(p.name.startswith(".generated.") for p in tmp_path.iterdir())


# ---- 5. links in the output folder stay links ----

def test_links_and_fifos_in_the_output_folder_are_kept_as_they_are_never_followed(tmp_path):
    (tmp_path / "m.yaml").write_text(arm())
    out = tmp_path / "generated"
    assert main(["--models", str(tmp_path / "m.yaml"), "generate", "--out", str(out)]) == 0
    secret = tmp_path / "home" / ".ssh"
    secret.mkdir(parents=True)
    (secret / "id_ed25519").write_text("private key")
    (out / "keys").symlink_to(secret, target_is_directory=True)
    (out / "zero").symlink_to("/dev/zero")
    (out / "loop").symlink_to("loop")
    (out / "dangling").symlink_to(tmp_path / "nowhere")
    (out / "notes").mkdir()
    (out / "notes" / "todo.txt").write_text("mine")
    (out / "notes" / "up").symlink_to("..", target_is_directory=True)
    os.mkfifo(out / "pipe")
    before = {k: v for k, v in tree(out).items() if not k.startswith(("arm", "MANIFEST"))}
    assert main(["--models", str(tmp_path / "m.yaml"), "generate", "--out", str(out), "--no-cache"]) == 0
    after = {k: v for k, v in tree(out).items() if not k.startswith(("arm", "MANIFEST"))}
    assert after == before
    assert (out / "keys").is_symlink() and os.readlink(out / "keys") == str(secret)
    assert tree(secret) == {"id_ed25519": hashlib.sha256(b"private key").hexdigest()}
    # a link inside a robot's folder is not derive's file: --check names it, generate replaces the folder
    (out / "arm" / "c" / "extra.h").symlink_to("/dev/zero")
    r = subprocess.run([sys.executable, "-m", "derive", "--models", str(tmp_path / "m.yaml"), "generate", "--check",
                        "--out", str(out)], capture_output=True, text=True, timeout=60)
    assert r.returncode == 1 and "extra.h (not generated by derive)" in r.stderr


def test_a_socket_in_the_output_folder_is_refused_in_one_line(tmp_path, capsys):
    (tmp_path / "m.yaml").write_text(arm())
    out = tmp_path / "generated"
    assert main(["--models", str(tmp_path / "m.yaml"), "generate", "--out", str(out)]) == 0
    capsys.readouterr()
    before = tree(out)
    path = out / "s"
    sock = socket.socket(socket.AF_UNIX)
    try:
        sock.bind(str(path))
        assert main(["--models", str(tmp_path / "m.yaml"), "generate", "--out", str(out), "--no-cache"]) == 2
    finally:
        sock.close()
    line = one_error_line(capsys.readouterr().err)
    assert str(path) in line and "socket or device" in line
    assert {k: v for k, v in tree(out).items() if k != "s"} == before
    assert not any(p.name.startswith(".generated.") for p in tmp_path.iterdir())


# ---- 8. firmware.json goes through the input guards ----

@pytest.mark.parametrize("kind", ["fifo", "dev-zero", "folder", "not-json", "wrong-shape"])
def test_a_bad_firmware_record_is_one_line_at_once(tmp_path, kind):
    (tmp_path / "models.yaml").write_text(arm())
    record = tmp_path / "firmware.json"
    if kind == "fifo":
        os.mkfifo(record)
    elif kind == "dev-zero":
        record.symlink_to("/dev/zero")
    elif kind == "folder":
        record.mkdir()
    elif kind == "not-json":
        record.write_text("{")
    else:
        record.write_text('{"robots": []}')
    t0 = time.perf_counter()
    r = derive("generate", cwd=tmp_path, timeout=60)
    assert time.perf_counter() - t0 < 30
    assert r.returncode == 2
    line = one_error_line(r.stderr)
    assert str(record) in line or "firmware.json" in line
    expected = {"fifo": "not a regular file", "dev-zero": "not a regular file", "folder": "not a regular file",
                "not-json": "not valid JSON", "wrong-shape": "not a firmware record"}[kind]
    assert expected in line
    assert not (tmp_path / "generated").exists()


# ---- 12. a MANIFEST.json of the wrong shape ----

@pytest.fixture(scope="module")
def arm_generated(tmp_path_factory) -> Path:
    """arm() generated once for the module's cases, each of which copies it."""
    base = tmp_path_factory.mktemp("arm")
    (base / "m.yaml").write_text(arm())
    assert main(["--models", str(base / "m.yaml"), "generate", "--out", str(base / "generated")]) == 0
    return base / "generated"


@pytest.mark.parametrize("text", ["[]", '{"robots": null}', '{"robots": {"arm": 5}}', "{", '"x"',
                                  '{"robots": {"../escape": {"model_hash": "a", "generator_hash": "b", "files": {}}}}',
                                  '{"robots": {"arm": {"model_hash": "a", "generator_hash": "b", "files": {"../../x": "0"}}}}',
                                  "fifo"])
def test_a_manifest_of_the_wrong_shape_is_a_warning_for_generate_and_a_problem_for_check(tmp_path, capsys, text,
                                                                                       arm_generated):
    models = str(tmp_path / "m.yaml")
    (tmp_path / "m.yaml").write_text(arm())
    out = tmp_path / "generated"
    shutil.copytree(arm_generated, out)  # what `generate` writes for m.yaml: its models file's name is not recorded
    (out / "mine.txt").write_text("keep me")
    (out / "MANIFEST.json").unlink()
    if text == "fifo":
        os.mkfifo(out / "MANIFEST.json")
    else:
        (out / "MANIFEST.json").write_text(text)
    capsys.readouterr()
    assert main(["--models", models, "generate", "--check", "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert "MANIFEST.json" in err and "Traceback" not in err
    assert main(["--models", models, "generate", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "warning:" in printed and "MANIFEST.json" in printed
    assert manifest_robots(out) == ["arm"] and (out / "mine.txt").read_text() == "keep me"
    assert not (tmp_path / "escape").exists() and not (tmp_path.parent / "x").exists()
    assert main(["--models", models, "generate", "--check", "--out", str(out)]) == 0


# ---- 17. a stale temporary folder with an absurd pid ----

def test_stale_temporary_folders_with_any_pid_are_removed_by_the_next_run(tmp_path):
    (tmp_path / "m.yaml").write_text(arm())
    out = tmp_path / "generated"
    for name in (".generated.tmp-99999999999999999999-abc", ".generated.tmp-1-x", ".generated.old-99999999999999999999"):
        (tmp_path / name).mkdir()
        (tmp_path / name / "junk").write_text("x")
    r = derive("--models", "m.yaml", "generate", "--out", str(out), cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    # the .old- backup of a dead run is put back where no output exists, then regenerated into
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".generated.")) == []
    assert manifest_robots(out) == ["arm"] and "left by an interrupted run" in r.stdout


# ---- 18. an output folder that is a mount point; a read-only one ----

MOUNTED = textwrap.dedent("""\
    set -e
    mount -t tmpfs -o size=8m tmpfs "$OUT"
    {python} -m derive --models one.yaml generate --out "$OUT"
    echo mine > "$OUT/mine.txt"
    {python} -m derive --models two.yaml generate --out "$OUT"
    {python} -m derive --models two.yaml generate --out "$OUT" --check
    ls -a "$OUT" > listing.txt
    cat "$OUT/mine.txt" > mine.txt
    cat "$OUT/MANIFEST.json" > manifest.json
    """)


def test_an_output_folder_that_is_a_mount_point_is_updated_in_place(tmp_path):
    reason = can_unshare("--mount", "--map-root-user") if os.getuid() else can_unshare("--mount")
    if reason:
        pytest.skip(reason)
    (tmp_path / "one.yaml").write_text(arm("arm", "1.0"))
    (tmp_path / "two.yaml").write_text(arm("arm", "2.0") + arm("other").split("robots:\n", 1)[1])
    out = tmp_path / "generated"
    out.mkdir()
    script = MOUNTED.format(python=sys.executable)
    flags = ["--mount"] if os.getuid() == 0 else ["--mount", "--map-root-user"]
    r = subprocess.run(["unshare", *flags, "sh", "-c", script], cwd=tmp_path, env={**os.environ, "OUT": str(out)},
                       capture_output=True, text=True, timeout=180)
    assert r.returncode == 0, r.stdout + r.stderr
    listing = (tmp_path / "listing.txt").read_text().split()
    assert sorted(listing) == sorted([".", "..", "MANIFEST.json", "arm", "mine.txt", "other"])  # no temporary left
    assert (tmp_path / "mine.txt").read_text() == "mine\n"
    assert sorted(json.loads((tmp_path / "manifest.json").read_text())["robots"]) == ["arm", "other"]


READ_ONLY = textwrap.dedent("""\
    mount -t tmpfs -o size=8m tmpfs "$HERE/ro"
    mkdir "$HERE/ro/generated"
    cp -r "$HERE/generated/." "$HERE/ro/generated/"
    mount -o remount,ro "$HERE/ro"
    {python} -m derive --models m.yaml generate --out "$HERE/ro/generated" --no-cache 2> err.txt
    echo $? > status.txt
    """)


def test_a_read_only_output_names_the_output_and_the_cause(tmp_path):
    reason = can_unshare("--mount", "--map-root-user") if os.getuid() else can_unshare("--mount")
    if reason:
        pytest.skip(reason)
    (tmp_path / "m.yaml").write_text(arm())
    (tmp_path / "ro").mkdir()
    assert derive("--models", "m.yaml", "generate", "--out", str(tmp_path / "generated"), cwd=tmp_path).returncode == 0
    flags = ["--mount"] if os.getuid() == 0 else ["--mount", "--map-root-user"]
    r = subprocess.run(["unshare", *flags, "sh", "-c", READ_ONLY.format(python=sys.executable)], cwd=tmp_path,
                       env={**os.environ, "HERE": str(tmp_path)}, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr
    assert (tmp_path / "status.txt").read_text().strip() == "2"
    line = one_error_line((tmp_path / "err.txt").read_text())
    assert f"{tmp_path}/ro/generated" in line and "Read-only file system" in line and ".tmp-" not in line


# ---- 3. a full disk never truncates a file the user owns ----

FULL_DISK = textwrap.dedent("""\
    set -e
    mount -t tmpfs -o size=64k tmpfs "$HERE/disk"
    cp models.yaml "$HERE/disk/models.yaml"
    head -c 100000 /dev/zero > "$HERE/disk/filler" 2>/dev/null || true
    cd "$HERE/disk"
    set +e
    {python} -m derive init --out models.yaml --force 2> "$HERE/err.txt"
    echo $? > "$HERE/status.txt"
    cp models.yaml "$HERE/after.yaml"
    ls -a > "$HERE/listing.txt"
    """)


def test_init_on_a_full_disk_leaves_the_models_file_byte_identical(tmp_path):
    reason = can_unshare("--mount", "--map-root-user") if os.getuid() else can_unshare("--mount")
    if reason:
        pytest.skip(reason)
    (tmp_path / "models.yaml").write_text(arm())
    (tmp_path / "disk").mkdir()
    flags = ["--mount"] if os.getuid() == 0 else ["--mount", "--map-root-user"]
    r = subprocess.run(["unshare", *flags, "sh", "-c", FULL_DISK.format(python=sys.executable)], cwd=tmp_path,
                       env={**os.environ, "HERE": str(tmp_path)}, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr
    assert (tmp_path / "status.txt").read_text().strip() == "2"
    line = one_error_line((tmp_path / "err.txt").read_text())
    assert "models.yaml" in line and "No space left on device" in line and "left as it was" in line
    assert (tmp_path / "after.yaml").read_text() == arm()
    assert sorted((tmp_path / "listing.txt").read_text().split()) == [".", "..", "filler", "models.yaml"]


# ---- 24, 25: init into a folder; empty paths ----

def test_init_out_a_folder_is_refused_and_leaves_nothing(tmp_path, capsys):
    folder = tmp_path / "DIR"
    folder.mkdir()
    assert main(["init", "--out", str(folder), "--force"]) == 2
    line = one_error_line(capsys.readouterr().err)
    assert str(folder) in line and "is a folder" in line
    assert list(folder.iterdir()) == []


@pytest.mark.parametrize("argv", [["generate", "--out", ""], ["init", "--out", ""], ["generate", "--out", "  "],
                                  ["firmware-check", "--out", ""], ["bench", "--out", ""]])
def test_an_empty_path_is_refused_not_read_as_not_given(tmp_path, monkeypatch, capsys, argv):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "models.yaml").write_text(arm())
    assert main(argv) == 2
    line = one_error_line(capsys.readouterr().err)
    assert "--out" in line and "empty path" in line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["models.yaml"]


def test_write_atomically_keeps_mode_and_link_and_leaves_no_temporary(tmp_path):
    from derive.errors import DeriveError
    from derive.filesystem import TEMPORARIES, write_atomically

    target = tmp_path / "real.yaml"
    target.write_text("old")
    os.chmod(target, 0o640)
    link = tmp_path / "link.yaml"
    link.symlink_to(target)
    write_atomically(link, "new")
    assert link.is_symlink() and target.read_text() == "new" and stat.S_IMODE(os.stat(target).st_mode) == 0o640
    with pytest.raises(DeriveError, match="cannot write the models file .*left as it was"):
        write_atomically(tmp_path / "missing" / "m.yaml", "x", "the models file")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["link.yaml", "real.yaml"] and not TEMPORARIES
