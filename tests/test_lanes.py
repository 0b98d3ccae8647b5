"""Lane mode: the generated C with DERIVE_REAL a vector (derive_lanes.h), as derive.compiled runs it.

A copy of planar_2r cut down to seven functions (lane-wise dynamics, the regressor's sign, rk4_step
calling ode_rhs, and ik_tcp, which branches and stays scalar) is built three times at -O0 (values,
not speed): with the host's lanes, with DERIVE_LANES=off (the scalar fallback), and on x86-64 with
sse2 lanes (the per-lane <math.h> path). Seeded batches of 11 states (two blocks of 4 and a tail of
3) agree with the scalar build to 1e-13 of each output's largest entry (libmvec), and bit for bit
where the lanes call <math.h>.
"""

from __future__ import annotations

import json
import platform
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from derive.errors import DeriveError
from derive.runtime import build, loader

ROOT = Path(__file__).resolve().parent.parent
GENERATED = ROOT / "generated"
KEEP = ("inverse_dynamics", "forward_dynamics", "regressor", "ode_rhs", "rk4_step", "fk_jacobian_tcp", "ik_tcp")
X86 = platform.machine().lower() in ("x86_64", "amd64")


@pytest.fixture(scope="module")
def small(tmp_path_factory) -> Path:
    """generated/ holding planar_2r with only the functions of KEEP (its manifest, sources, umbrella header)."""
    out = tmp_path_factory.mktemp("gen")
    src, dst = GENERATED / "planar_2r", out / "planar_2r"
    (dst / "c").mkdir(parents=True)
    manifest = json.loads((src / "manifest.json").read_text())
    names = {f"planar_2r_{k}" for k in KEEP}
    manifest["functions"] = [f for f in manifest["functions"] if f["name"] in names]
    (dst / "manifest.json").write_text(json.dumps(manifest))
    for path in (src / "c").iterdir():
        m = re.fullmatch(r"(planar_2r_\w+)\.[ch]", path.name)
        if path.suffix in (".c", ".h") and (m is None or m[1] in names):
            shutil.copy(path, dst / "c" / path.name)
    umbrella = dst / "c" / "planar_2r.h"
    lines = umbrella.read_text().splitlines(keepends=True)
    umbrella.write_text("".join(ln for ln in lines if not (ln.startswith('#include "planar_2r_')
                                                          and ln.split('"')[1][:-2] not in names)))
    return out


@pytest.fixture(scope="module")
def mods(small, tmp_path_factory):
    """{mode: derive.compiled module} built into one fresh cache at -O0."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("XDG_CACHE_HOME", str(tmp_path_factory.mktemp("xdg")))
        mp.setenv("CFLAGS", "-O0")
        mp.delenv("CC", raising=False)
        out = {}
        avx2 = ("avx2",) if "avx2" in build._cpu_flags() and build.host_lanes().isa != "avx2" else ()
        for mode in ("auto", "off") + (("sse2",) if X86 else ()) + avx2:
            mp.setenv("DERIVE_LANES", mode)
            out[mode] = loader.compiled("planar_2r", small)
        mp.delenv("DERIVE_LANES")
        # every whole block through the large-batch path (non-temporal stores), whatever the batch size
        mp.setenv("CFLAGS", "-O0 -DDERIVE_RT_STREAM_BYTES=0")
        out["stream"] = loader.compiled("planar_2r", small)
        mp.setattr(build, "STACK_VECTORS", 0)  # the vectors and the block's outputs on the heap (a large robot's)
        out["heap"] = loader.compiled("planar_2r", small)
        out["host"] = build.host_lanes()
        yield out


def values(result) -> list[np.ndarray]:
    return list(result) if isinstance(result, tuple) else [result]


def batch(name: str, n: int, seed: int):
    rng = np.random.default_rng(seed)
    sig = next(s for s in build.signatures(json.loads((GENERATED / "planar_2r" / "manifest.json").read_text()))
               if s.name == name)
    args = [rng.uniform(-2, 2, (n,) + a.shape) for a in sig.inputs]
    return args


LANE_WISE = ("inverse_dynamics", "forward_dynamics", "regressor", "ode_rhs", "rk4_step", "fk_jacobian_tcp")


def test_host_lanes_are_chosen_and_ik_stays_scalar(mods):
    host = mods["host"]
    auto, off = mods["auto"], mods["off"]
    if X86 or platform.machine().lower() in ("aarch64", "arm64"):
        assert host.count in (2, 4, 8)
    assert auto.LANES == host.count
    assert sorted(auto.LANE_FUNCTIONS) == (sorted(LANE_WISE) if host.count else [])
    assert off.LANES == 0 and off.LANE_FUNCTIONS == ()  # the scalar fallback: every state by the scalar C


@pytest.mark.parametrize("name", LANE_WISE)
def test_lanes_equal_scalar_to_1e13(mods, name):
    """11 states: two blocks of 4 lanes and a tail of 3 (padded with the last state); each state's
    results also equal its results alone (the one-state path runs the lanes too)."""
    args = batch(name, 11, seed=len(name))
    scalar = values(getattr(mods["off"], name)(*args))
    for mode in ("auto", "avx2"):  # avx2 as well where the host's own mode is wider
        if mode not in mods:
            continue
        lanes = values(getattr(mods[mode], name)(*args))
        for got, want in zip(lanes, scalar):
            flat_l, flat_s = got.reshape(11, -1), want.reshape(11, -1)
            scale = np.max(np.abs(flat_s), axis=1)
            assert np.all(scale > 0) and np.all(np.max(np.abs(flat_l - flat_s), axis=1) <= 1e-13 * scale), mode
    lanes = values(getattr(mods["auto"], name)(*args))
    for k in (0, 5, 8, 10):  # a first lane, a middle one, the tail's first and last
        for got, alone in zip(lanes, values(getattr(mods["auto"], name)(*[a[k] for a in args]))):
            np.testing.assert_array_equal(alone, got[k])


@pytest.mark.parametrize("name", LANE_WISE)
def test_large_batch_stores_equal_the_small_batch_ones(mods, name):
    """A batch whose outputs pass DERIVE_RT_STREAM_BYTES writes each block's outputs by whole cache
    lines (non-temporal stores) and the partial first and last lines by plain stores: the same
    numbers as the plain stores, bit for bit, in outputs at every offset from a cache line (37
    states: blocks starting at 8-byte offsets that cycle through the line, and a tail)."""
    assert mods["stream"].LANES == mods["heap"].LANES == mods["host"].count
    args = batch(name, 37, seed=3)
    big = [np.repeat(a, 4, axis=0)[:-3] for a in args]  # 145 states, in a fresh (differently aligned) output
    for given in (args, big):
        plain = values(getattr(mods["auto"], name)(*given))
        for mode in ("stream", "heap"):  # heap: the same path with its buffers on the heap
            for got, want in zip(values(getattr(mods[mode], name)(*given)), plain):
                np.testing.assert_array_equal(got, want)


@pytest.mark.skipif(not X86, reason="sse2 lanes are x86-64's")
@pytest.mark.parametrize("name", LANE_WISE)
def test_per_lane_maths_is_bit_for_bit_scalar(mods, name):
    """Without libmvec (sse2: 2 lanes, <math.h> per lane) the lanes compute exactly what the scalar C does."""
    assert mods["sse2"].LANES == 2
    args = batch(name, 5, seed=7)
    for got, want in zip(values(getattr(mods["sse2"], name)(*args)), values(getattr(mods["off"], name)(*args))):
        np.testing.assert_array_equal(got, want)


def test_ik_is_unchanged_by_lanes(mods):
    T = mods["off"].fk_jacobian_tcp(np.array([0.3, -0.4]))[0]
    for mode in ("auto", "off"):
        q, *_, status = mods[mode].ik_tcp(T, np.array([0.2, -0.2]))
        assert status == 0 and np.allclose(mods[mode].fk_jacobian_tcp(q)[0], T, atol=1e-9)


def test_bad_lane_mode_is_one_line(small, monkeypatch):
    monkeypatch.setenv("DERIVE_LANES", "avx9")
    with pytest.raises(DeriveError, match=r"^DERIVE_LANES=avx9: not a lane mode \(auto, off, avx512f, avx2, sse2, neon\)$"):
        loader.compiled("planar_2r", small)


def test_code_without_the_lane_header_builds_without_lanes(small):
    snap = build.read_generated("planar_2r", small / "planar_2r")
    sigs = build.signatures(snap.manifest)
    assert set(build.lane_sources("planar_2r", sigs, build.LANE_MODES["avx2"], snap)) == {
        f"planar_2r_{n}_lanes.c" for n in LANE_WISE}
    old = build.Snapshot(snap.robot, snap.folder, snap.manifest,
                         tuple(s for s in snap.sources if s[0] != "derive_lanes.h"), snap.sources_hash)
    assert build.lane_sources("planar_2r", sigs, build.LANE_MODES["avx2"], old) == {}


def test_manifest_says_which_functions_are_lane_wise():
    """Every function of every committed robot: "lanes" false exactly for ik and manipulability."""
    robots = sorted(json.loads((GENERATED / "MANIFEST.json").read_text())["robots"])
    for robot in robots:
        manifest = json.loads((GENERATED / robot / "manifest.json").read_text())
        assert {"file": "c/derive_lanes.h", "source": "templates/c/support/derive_lanes.h"} in manifest["support"]
        for f in manifest["functions"]:
            assert f["c"]["lanes"] is (f["quantity"] not in ("ik", "manipulability")), f["name"]


def test_a_lane_mode_the_cpu_lacks_is_one_line(monkeypatch):
    """Forcing AVX-512F (or AVX2) lanes on a CPU without them would end the process at the first
    batch (SIGILL): refused in one line instead."""
    cpu = build._cpu_flags()
    for isa in ("avx512f", "avx2"):
        monkeypatch.setenv("DERIVE_LANES", isa)
        if X86 and cpu and isa not in cpu:
            with pytest.raises(DeriveError, match=rf"^DERIVE_LANES={isa}: this CPU has no {isa} "):
                build.host_lanes()
        elif X86 and cpu:
            assert build.host_lanes() == build.LANE_MODES[isa]


EDGES = r"""
#include <stdio.h>
int main(void)
{
    const double inf = HUGE_VAL;
    double special[] = {0.0, -0.0, 1e-300, -1e-8, 1.5707963267948966, 3.141592653589793, 1e5, 100000.5, -1e6,
                        1e300, -1e300, 0.0, 0.0, 0.0, 0.0, 0.0};
    int k, j;
    special[11] = inf;
    special[12] = -inf;
    special[13] = inf - inf;
    for (j = 0; j < 16; j += DERIVE_LANES) {
        DERIVE_REAL a, s, c;
        for (k = 0; k < DERIVE_LANES; k++)
            a[k] = special[(j + k) % 16];
        s = DERIVE_SIN(a);
        c = DERIVE_COS(a);
        for (k = 0; k < DERIVE_LANES; k++)
            printf("%a %a %a %a %a\n", a[k], s[k], sin(a[k]), c[k], cos(a[k]));
    }
    return 0;
}
"""


@pytest.mark.skipif(not X86 or shutil.which("cc") is None, reason="the lanes' own sin and cos are x86-64's (AVX2, AVX-512F)")
@pytest.mark.parametrize("isa,lanes", [("avx2", 4), ("avx512f", 8)])
def test_lane_sin_and_cos_are_within_2_ulp_and_exact_at_the_edges(isa, lanes, tmp_path):
    """Double lanes with libmvec compute sin and cos by derive_lanes.h's inline kernel: within 2 ulp
    of <math.h> on [-4, 4] and [-1e5, 1e5] (1e6 arguments each); sin(-0) is -0; beyond 1e5,
    infinite or NaN arguments give <math.h>'s results (NaN for the infinities)."""
    import subprocess

    from derive.bench.lanes import ULP  # the benchmark's ulp program: 1e6 arguments per range

    def run(name: str, text: str) -> list[str]:
        (tmp_path / f"{name}.c").write_text(text)
        subprocess.run(["cc", "-std=c99", "-O2", "-Wall", "-Wextra", "-Werror", "-pedantic", f"-m{isa}",
                        f"-DDERIVE_LANES={lanes}", f"-I{GENERATED / 'planar_2r' / 'c'}", "-include", "derive_lanes.h",
                        str(tmp_path / f"{name}.c"), "-lm", "-o", str(tmp_path / name)], check=True)
        if isa not in build._cpu_flags():
            return []  # built clean; this CPU cannot run it
        return subprocess.run([str(tmp_path / name)], check=True, capture_output=True, text=True).stdout.splitlines()

    ulp, edges = run("ulp", ULP), run("edges", EDGES)
    if not ulp:
        return
    *worst, kernel = map(int, ulp[0].split())
    assert kernel == 1 and max(worst) <= 2, ulp[0]
    for line in edges:
        x, s, s_ref, c, c_ref = (float.fromhex(v) for v in line.split())
        if abs(x) > 1e5 or x != x:
            assert (s == s_ref or s != s and s_ref != s_ref) and (c == c_ref or c != c and c_ref != c_ref), line
        else:
            assert abs(s - s_ref) <= 2 * np.spacing(abs(s_ref)) and abs(c - c_ref) <= 2 * np.spacing(abs(c_ref)), line
        if s_ref == 0:
            assert np.signbit(s) == np.signbit(s_ref), line
