"""derive.compiled under races and bad input; the generated Python's input checks.

- A build during which `derive generate` replaces the code compiles the bytes it hashed (a
  compiler that waits for a file lets the test swap the folder mid-build): the cached library is
  the hashed code, a second build of the same hash waits for the first and reuses it, and a
  library whose own record disagrees with the module is rebuilt or refused, never called.
- Temporary build folders are judged by the lock of the live builder, not by a pid: a build
  waiting in another process (or another PID namespace, `unshare`) keeps its folder while another
  build cleans up; a name holding a 20-digit pid blocks nobody.
- A misaligned, big-endian or strided float64 array reaches the C as an aligned native copy.
- None for a one-element input, complex numbers, text and IK's T of shape (2, 8) are TypeErrors
  or ValueErrors naming the function and the argument, the same in the generated Python and in
  derive.compiled; IK's q0 and w still take None.

The robots are pendulum (nv 1) and planar_2r (nv 2), generated here, each renamed "robo" and cut
to a few functions, so that one robot's code can change its nv under a running build and each
build compiles a handful of files.
"""

from __future__ import annotations

import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import time
import warnings
from pathlib import Path

import numpy as np
import pytest

import derive
from derive.codegen.generate import generate
from derive.errors import DeriveError
from derive.runtime import build, loader
from util import load_module, robots

ROOT = Path(__file__).resolve().parent.parent
SMALL = ("mass_matrix", "gravity")
FULL = ("mass_matrix", "gravity", "fk_tcp", "ik_tcp", "rk4_step")
TIMEOUT = 240

RUN = """
import json, sys
import numpy as np
import derive
from derive.runtime import build
m = derive.compiled("robo", sys.argv[1])
q = np.linspace(0.3, -0.2, m.NV)
print(json.dumps({"library": str(m.LIBRARY), "nv": m.NV, "builds": build.BUILDS,
                  "M": m.mass_matrix(q).tolist(), "g": m.gravity(q).tolist()}))
"""


@pytest.fixture(scope="module")
def fresh(tmp_path_factory) -> Path:
    """pendulum and planar_2r as derive generates them now (Python from the current templates)."""
    out = tmp_path_factory.mktemp("fresh") / "generated"
    generate({k: v for k, v in robots().items() if k in ("pendulum", "planar_2r")}, out, use_cache=False,
             log=lambda s: None)
    return out


def python_module(fresh: Path, robot: str):
    return load_module(fresh / robot / "python" / f"{robot}.py", f"reliability_{robot}")


def version(fresh: Path, src: str, folder: Path, keep=SMALL) -> Path:
    """generated/<src>/ as robot 'robo' in folder/robo/: the manifest's functions ``keep`` (Python
    names) and those they call, their C sources, every header. Returns folder."""
    manifest = json.loads((fresh / src / "manifest.json").read_text())
    by_c = {f["name"]: f for f in manifest["functions"]}
    todo = [f["name"] for f in manifest["functions"] if f["python"]["function"] in keep]
    kept: set[str] = set()
    while todo:
        name = todo.pop()
        if name not in kept:
            kept.add(name)
            todo += by_c[name]["calls"]
    manifest["functions"] = [f for f in manifest["functions"] if f["name"] in kept]

    def rename(text: str) -> str:
        return text.replace(src, "robo").replace(src.upper(), "ROBO")

    dst = folder / "robo"
    (dst / "c").mkdir(parents=True)
    (dst / "manifest.json").write_text(rename(json.dumps(manifest, indent=1)))
    for path in sorted((fresh / src / "c").iterdir()):
        if path.suffix == ".h" or (path.suffix == ".c" and path.stem in kept):
            (dst / "c" / rename(path.name)).write_text(rename(path.read_text()))
    return folder


def swap(fresh: Path, folder: Path, src: str) -> None:
    """Replace folder/robo by the version of ``src`` as `derive generate` does: built beside, then renamed in."""
    new = version(fresh, src, folder.parent / f"{folder.name}.new")
    os.rename(folder / "robo", folder / ".robo.old")
    os.rename(new / "robo", folder / "robo")
    shutil.rmtree(folder / ".robo.old")
    new.rmdir()


def reference(fresh: Path, src: str) -> dict:
    py = python_module(fresh, src)
    q = np.linspace(0.3, -0.2, py.NV)
    return {"nv": py.NV, "M": py.mass_matrix(q), "g": py.gravity(q)}


def same_values(result: dict, ref: dict) -> None:
    """The compiled results equal the generated Python's to 1e-12 relative (as tests/test_compiled.py)."""
    assert result["nv"] == ref["nv"]
    for key in ("M", "g"):
        got, want = np.asarray(result[key]), ref[key]
        assert got.shape == want.shape, key
        assert np.all(np.abs(got - want) <= 1e-12 * max(1.0, float(np.abs(want).max()))), (key, got, want)


def waiting_compiler(folder: Path) -> tuple[str, Path]:
    """A compiler script that, but for --version, logs its parent's pid, touches ``started`` and
    waits for ``go`` in ``folder`` before it runs the real compiler."""
    real = shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")
    if real is None:
        pytest.skip("no C compiler on PATH")
    folder.mkdir(parents=True, exist_ok=True)
    script = folder / "cc-waits"
    d = shlex.quote(str(folder))
    script.write_text(f"""#!/bin/sh
case "$1" in --version) exec {shlex.quote(real)} "$@";; esac
echo "$PPID" >> {d}/calls
: > {d}/started
while [ ! -e {d}/go ]; do sleep 0.02; done
exec {shlex.quote(real)} "$@"
""")
    script.chmod(0o755)
    return str(script), folder


def start(generated: Path, cache: Path, cc: str | None, prefix: tuple[str, ...] = ()) -> subprocess.Popen:
    env = {k: v for k, v in os.environ.items() if k not in ("CC", "CFLAGS")}
    env["XDG_CACHE_HOME"] = str(cache)
    if cc:
        env["CC"] = cc
    return subprocess.Popen([*prefix, sys.executable, "-c", RUN, str(generated)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, cwd=ROOT, env=env)


def finish(proc: subprocess.Popen) -> dict:
    out, err = proc.communicate(timeout=TIMEOUT)
    assert proc.returncode == 0, err
    return json.loads(out.strip().splitlines()[-1])


def wait_for(condition, proc: subprocess.Popen | None = None, what: str = "") -> None:
    deadline = time.monotonic() + TIMEOUT
    while not condition():
        if proc is not None and proc.poll() is not None:
            pytest.fail(f"the process ended before {what}: {proc.communicate()}")
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.02)


def blocked_on_a_lock(pid: int) -> bool:
    """Whether process ``pid`` waits for a flock (a line '-> FLOCK ... <pid> ...' in /proc/locks)."""
    text = Path("/proc/locks").read_text()
    return any(re.search(rf"->\s+FLOCK\s+\S+\s+WRITE\s+{pid}\s", line) for line in text.splitlines())


def leftovers(root: Path) -> list[str]:
    return sorted(p.name for p in root.iterdir() if p.name.startswith(".")) if root.is_dir() else []


@pytest.fixture
def cache(tmp_path, monkeypatch) -> Path:
    """This test's build cache; no CC or CFLAGS from the caller's environment."""
    xdg = tmp_path / "xdg"
    monkeypatch.setenv("XDG_CACHE_HOME", str(xdg))
    monkeypatch.delenv("CC", raising=False)
    monkeypatch.delenv("CFLAGS", raising=False)
    return xdg


# ---- item 4: the build compiles the bytes it hashed; the library's record is checked ----

def test_generate_during_a_build_cannot_change_what_is_compiled(fresh, tmp_path, cache):
    """Build A while the folder is replaced by B (another nv) mid-build: the library cached under
    A's hash is A's code; a second build of A waits for the first and reuses it; B builds anew."""
    cc, waits = waiting_compiler(tmp_path / "cc")
    moving, steady = version(fresh, "pendulum", tmp_path / "moving"), version(fresh, "pendulum", tmp_path / "steady")
    first = start(moving, cache, cc)
    wait_for(lambda: (waits / "started").exists(), first, "the first compile")
    swap(fresh, moving, "planar_2r")  # nv 1 -> 2 while the first build compiles
    second = start(steady, cache, cc)
    wait_for(lambda: blocked_on_a_lock(second.pid), second, "the second build to wait for the first's lock")
    (waits / "go").touch()
    one, two = finish(first), finish(second)
    same_values(one, reference(fresh, "pendulum"))
    assert one["builds"] == 1 and two["builds"] == 0 and two["library"] == one["library"]
    assert two["M"] == one["M"] and two["g"] == one["g"]
    assert set((waits / "calls").read_text().split()) == {str(first.pid)}  # the second never compiled
    # the cached library is the code hashed: its record names exactly the sources read before the swap
    snap = build.read_generated("robo", steady / "robo")
    expected = build.record("robo", snap.manifest, build.signatures(snap.manifest), snap.sources_hash)
    assert build.file_record(Path(one["library"])) == expected
    # the new code (nv 2) is another library, built from its own bytes
    builds = build.BUILDS
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("CC", cc)  # the same compiler (now without waiting): only the code differs
        m = derive.compiled("robo", moving)
    q = np.linspace(0.3, -0.2, 2)
    same_values({"nv": m.NV, "M": m.mass_matrix(q), "g": m.gravity(q)}, reference(fresh, "planar_2r"))
    assert build.BUILDS == builds + 1 and str(m.LIBRARY) != one["library"]
    assert leftovers(cache / "derive" / "compiled") == []


def test_a_library_that_is_not_its_code_is_rebuilt_or_refused(fresh, tmp_path, cache):
    a = version(fresh, "pendulum", tmp_path / "a")
    b = version(fresh, "planar_2r", tmp_path / "b")
    lib_a, lib_b = derive.compiled("robo", a).LIBRARY, derive.compiled("robo", b).LIBRARY
    snap = build.read_generated("robo", a / "robo")
    sigs = build.signatures(snap.manifest)
    # the loader checks the library's own record before any call: B's library for A's module is refused
    with pytest.raises(DeriveError) as err:
        loader._module("robo", snap.manifest, sigs, lib_b)
    message = str(err.value)
    assert "\n" not in message and message.startswith(f"robot 'robo': {lib_b} is not this module's code: ")
    assert "nv 2 in the library, 1 in the manifest" in message
    # what the old build stored after a generate mid-build: B's library under A's hash -> rebuilt, correct
    shutil.copyfile(lib_b, lib_a.parent / "swap.tmp")
    os.replace(lib_a.parent / "swap.tmp", lib_a)  # a new inode: the library loaded here stays mapped
    result = finish(start(a, cache, None))
    same_values(result, reference(fresh, "pendulum"))
    assert result["builds"] == 1 and result["library"] == str(lib_a)
    expected = build.record("robo", snap.manifest, sigs, snap.sources_hash)
    assert build.file_record(lib_a) == expected
    # a library cut short (a power cut after the rename) is rebuilt too
    (lib_a.parent / "cut.tmp").write_bytes(lib_a.read_bytes()[:4096])
    os.replace(lib_a.parent / "cut.tmp", lib_a)
    builds = build.BUILDS
    assert build.library("robo", snap, sigs) == lib_a and build.BUILDS == builds + 1
    assert build.file_record(lib_a) == expected
    assert leftovers(cache / "derive" / "compiled") == []


def test_the_code_is_read_as_one_version(fresh, tmp_path, cache, monkeypatch):
    """A generate between reading the manifest and the sources: read again, all of the new version.
    Code that stays mixed, or a manifest of the wrong shape, is a one-line error."""
    gen = version(fresh, "pendulum", tmp_path / "gen")
    real, reads = build._read_sources, []

    def swapping(cdir):
        if not reads:
            swap(fresh, gen, "planar_2r")
        reads.append(cdir)
        return real(cdir)

    monkeypatch.setattr(build, "_read_sources", swapping)
    m = derive.compiled("robo", gen)
    monkeypatch.setattr(build, "_read_sources", real)
    assert len(reads) == 2 and m.NV == 2
    q = np.linspace(0.3, -0.2, 2)
    same_values({"nv": m.NV, "M": m.mass_matrix(q), "g": m.gravity(q)}, reference(fresh, "planar_2r"))
    mixed = version(fresh, "pendulum", tmp_path / "mixed")
    shutil.rmtree(mixed / "robo" / "c")
    shutil.copytree(gen / "robo" / "c", mixed / "robo" / "c")  # B's code under A's manifest
    with pytest.raises(DeriveError) as err:
        derive.compiled("robo", mixed)
    message = str(err.value)
    assert "\n" not in message and message.startswith("robot 'robo': ") and "robo.h is the code of robot 'robo' model" in message
    assert "run `derive generate`" in message
    broken = json.loads((gen / "robo" / "manifest.json").read_text())  # B's, as the code now is
    broken["functions"] = [{"name": 1}]
    for text, words in (("[]", "is not a JSON object"), (json.dumps(broken), "manifest: malformed function entry"),
                        ("{", "cannot read")):
        (mixed / "robo" / "manifest.json").write_text(text)
        with pytest.raises(DeriveError, match=re.escape(words)) as err:
            derive.compiled("robo", mixed)
        assert "\n" not in str(err.value)


def test_odd_names_and_files_are_one_line_errors(fresh, tmp_path, cache):
    """A robot name that is no identifier, and a source that is a FIFO or a link to /dev/zero
    (read through the input-file guards: no hang, no endless read)."""
    for name in ("../robo", "", "robo b", None):
        with pytest.raises(DeriveError, match="is not a robot name") as err:
            derive.compiled(name, tmp_path)
        assert "\n" not in str(err.value)
    gen = version(fresh, "pendulum", tmp_path / "gen")
    fifo, zero = gen / "robo" / "c" / "robo_extra.c", gen / "robo" / "c" / "robo_zero.h"
    os.mkfifo(fifo)
    with pytest.raises(DeriveError) as err:
        derive.compiled("robo", gen)
    assert str(err.value) == f"robot 'robo': {fifo}: cannot read generated C source: not a regular file"
    fifo.unlink()
    zero.symlink_to("/dev/zero")
    with pytest.raises(DeriveError) as err:
        derive.compiled("robo", gen)
    assert str(err.value) == f"robot 'robo': {zero}: cannot read generated C source: not a regular file"
    assert leftovers(cache / "derive" / "compiled") == []


# ---- item 17: temporary folders judged by the builder's lock, never by a pid ----

@pytest.mark.parametrize("where", ["process", "pid-namespace"])
def test_a_live_build_keeps_its_folder_whatever_its_pid(fresh, tmp_path, cache, where):
    prefix: tuple[str, ...] = ()
    if where == "pid-namespace":
        prefix = ("unshare", "--pid", "--fork", "--kill-child")
        if not shutil.which("unshare") or subprocess.run([*prefix, "true"], capture_output=True).returncode != 0:
            pytest.skip("cannot make a PID namespace here (unshare --pid needs root or user namespaces)")
    cc, waits = waiting_compiler(tmp_path / "cc")
    a, b = version(fresh, "pendulum", tmp_path / "a"), version(fresh, "planar_2r", tmp_path / "b")
    builder = start(a, cache, cc, prefix)
    wait_for(lambda: (waits / "started").exists(), builder, "the build to compile")
    root = cache / "derive" / "compiled"
    live = [p for p in root.iterdir() if re.fullmatch(r"\.[0-9a-f]{64}\.tmp-.*", p.name)]
    assert len(live) == 1
    huge = root / ".0123456789abcdef.tmp-99999999999999999999-a"  # as named before the locks: a 20-digit pid
    old = root / ".0123456789abcdef.tmp-99999999999999999999-b"
    dead = root / f".{'d' * 64}.tmp-x"  # nobody holds d...d's lock
    lock = root / f".{'e' * 64}.lock"   # a lock file a killed build left
    for folder in (huge, old, dead):
        folder.mkdir()
        (folder / "half.o").write_bytes(b"\0" * 100)
    lock.touch()
    os.utime(old, (time.time() - 2 * 86400, time.time() - 2 * 86400))
    m = derive.compiled("robo", b)  # another build: it cleans up the cache first
    assert m.NV == 2
    assert live[0].is_dir() and huge.is_dir()
    assert not old.exists() and not dead.exists() and not lock.exists()
    (waits / "go").touch()
    result = finish(builder)
    same_values(result, reference(fresh, "pendulum"))
    assert result["builds"] == 1 and Path(result["library"]).parent.parent == root
    assert leftovers(root) == [huge.name]


# ---- items 21 and 22: what reaches the C, and inputs that are not numbers of the right shape ----

@pytest.fixture(scope="module")
def modules(fresh, tmp_path_factory):
    """pendulum's FULL functions as the generated Python and as derive.compiled ("robo"), and the
    snapshot of planar_2r's, compiled (for loading it again)."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("XDG_CACHE_HOME", str(tmp_path_factory.mktemp("xdg")))
        mp.delenv("CC", raising=False)
        mp.delenv("CFLAGS", raising=False)
        pendulum = derive.compiled("robo", version(fresh, "pendulum", tmp_path_factory.mktemp("p"), FULL))
        planar = build.read_generated("robo", version(fresh, "planar_2r", tmp_path_factory.mktemp("r"), FULL) / "robo")
        sigs = build.signatures(planar.manifest)
        yield python_module(fresh, "pendulum"), pendulum, (planar, sigs, build.library("robo", planar, sigs))


def test_misaligned_and_big_endian_arrays_reach_the_c_aligned(modules, monkeypatch):
    """Every array the general path hands the C is native float64, C-contiguous and aligned (a copy
    where the input is not), and the results are those of the aligned input."""
    snap, sigs, lib = modules[2]
    seen = []
    general = loader._general

    def spy(s, batch, pointer):
        def recorded(x):
            seen.append((x.dtype == np.float64 and x.dtype.isnative, x.flags.c_contiguous, x.flags.aligned,
                         x.ctypes.data % 8 == 0))
            return pointer(x)
        return general(s, batch, recorded)

    monkeypatch.setattr(loader, "_general", spy)
    mod = loader._module("robo", snap.manifest, sigs, lib)
    assert mod.FAST_PATH
    q = np.array([0.3, -0.2])
    want_m, want_g = mod.mass_matrix(q), mod.gravity(q)
    assert seen == []  # an aligned float64 array takes the one-state fast path
    buf = bytearray(8 * 6 + 1)
    misaligned = np.frombuffer(buf, offset=1, count=2)
    misaligned[:] = q
    big_misaligned = np.frombuffer(bytearray(17), dtype=">f8", offset=1)
    big_misaligned[:] = q
    cases = {"misaligned": misaligned, "big-endian": q.astype(">f8"), "big-endian misaligned": big_misaligned,
             "strided": np.repeat(q, 2)[::2]}
    assert not misaligned.flags.aligned and not big_misaligned.flags.aligned
    for name, x in cases.items():
        seen.clear()
        np.testing.assert_array_equal(mod.mass_matrix(x), want_m, err_msg=name)
        np.testing.assert_array_equal(mod.gravity(x), want_g, err_msg=name)
        assert len(seen) == 6 and all(all(flags) for flags in seen), (name, seen)  # q, p, M; q, p, g
    batch = np.frombuffer(buf, offset=1, count=6).reshape(3, 2)
    batch[:] = q
    seen.clear()
    out = mod.mass_matrix(batch)
    assert out.shape == (3, 2, 2) and all(np.array_equal(o, want_m) for o in out)
    assert len(seen) == 3 and all(all(flags) for flags in seen)  # q, p, M


# (call, exception, words in the message): the same for the generated Python and derive.compiled
BAD = [
    (lambda m, T: m.mass_matrix(None), TypeError, "mass_matrix: q must be real numbers (bool, int or float), got None"),
    (lambda m, T: m.mass_matrix([None]), TypeError, "mass_matrix: q must be real numbers"),
    (lambda m, T: m.gravity(np.array([0.3 + 1j])), TypeError, "gravity: q must be real numbers (bool, int or float), got complex"),
    (lambda m, T: m.gravity(0.3 + 0j), TypeError, "gravity: q must be real numbers"),
    (lambda m, T: m.mass_matrix("0.3"), TypeError, "mass_matrix: q must be real numbers (bool, int or float), got text"),
    (lambda m, T: m.mass_matrix(np.array(["0.3"])), TypeError, "got text"),
    (lambda m, T: m.mass_matrix(object()), TypeError, "mass_matrix: q must be real numbers"),
    (lambda m, T: m.mass_matrix([[0.3], [0.1, 0.2]]), ValueError, "mass_matrix: q is not an array of numbers"),
    (lambda m, T: m.mass_matrix(0.3, None), TypeError, "mass_matrix: p must be real numbers (bool, int or float), got None"),
    (lambda m, T: m.rk4_step([0.1, 0.2], [0.1], None), TypeError, "rk4_step: dt must be real numbers"),
    (lambda m, T: m.rk4_step([0.1, 0.2], None, 0.01), TypeError, "rk4_step: u must be real numbers"),
    (lambda m, T: m.rk4_step([0.1, 0.2, 0.3], [0.1], 0.01), ValueError, "rk4_step: x must have"),
    (lambda m, T: m.ik_tcp(T.reshape(2, 8)), ValueError, "ik_tcp: T must have shape (..., 4, 4)"),
    (lambda m, T: m.ik_tcp(T.reshape(8, 2)), ValueError, "ik_tcp: T must have shape (..., 4, 4)"),
    (lambda m, T: m.ik_tcp(T.reshape(1, 16)), ValueError, "ik_tcp: T must have shape (..., 4, 4)"),
    (lambda m, T: m.ik_tcp(T[:3]), ValueError, "ik_tcp: T must have shape (..., 4, 4)"),
    (lambda m, T: m.ik_tcp(None), TypeError, "ik_tcp: T must be real numbers (bool, int or float), got None"),
    (lambda m, T: m.ik_tcp(T + 0j), TypeError, "ik_tcp: T must be real numbers"),
    (lambda m, T: m.ik_tcp(T, [None]), TypeError, "ik_tcp: q0 must be real numbers"),
    (lambda m, T: m.ik_tcp(T, None, np.ones(6) * 1j), TypeError, "ik_tcp: w must be real numbers"),
    (lambda m, T: m.ik_tcp(T, np.zeros(2)), ValueError, "ik_tcp: q0 must have"),
    (lambda m, T: m.ik_tcp(T, None, np.ones(5)), ValueError, "ik_tcp: w must have"),
]


@pytest.mark.parametrize("which", ["python", "compiled"])
def test_inputs_that_are_not_real_numbers_of_the_shape_are_errors(modules, which):
    py, compiled, _ = modules
    m = py if which == "python" else compiled
    T = py.fk_tcp(0.4)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no ComplexWarning either: an error, not a dropped imaginary part
        for k, (call, error, words) in enumerate(BAD):
            with pytest.raises(error) as err:
                call(m, T)
            assert words in str(err.value) and "\n" not in str(err.value), (k, str(err.value))
        # what stays accepted: None for IK's q0 and w, a flat T, numbers of any real dtype, big-endian
        q, residual, status = m.ik_tcp(T, None, None)
        assert status == 0 and np.abs(np.asarray(m.fk_tcp(q)) - T).max() < 1e-4
        np.testing.assert_array_equal(m.ik_tcp(T.ravel())[0], q)
        np.testing.assert_array_equal(m.ik_tcp(T, q0=None, w=np.ones(6))[0], m.ik_tcp(T, w=[1, 1, 1, 1, 1, 1])[0])
        want = m.mass_matrix(1.0)
        for x in (True, 1, np.int64(1), np.float32(1.0), np.array([1.0], dtype=">f8"), [1]):
            np.testing.assert_array_equal(m.mass_matrix(x), want)
        assert m.mass_matrix(np.zeros((3, 1))).shape == (3, 1)


def test_python_and_compiled_agree_on_each_error(modules):
    """The same exception type and message for every bad input in both modules."""
    py, compiled, _ = modules
    T = py.fk_tcp(0.4)
    for call, error, _ in BAD:
        errors = []
        for m in (py, compiled):
            with pytest.raises(error) as err:
                call(m, T)
            errors.append(str(err.value))
        if "must be real numbers" in errors[0] or "is not an array" in errors[0]:
            assert errors[0] == errors[1]
