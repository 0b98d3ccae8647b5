"""SIGINT and SIGTERM end every command at once (issue 24, items 10 and 11).

Each test runs a derive command in its own process, waits for it to reach a phase (a progress
line of derive's own, or a marker that a probe prints when a function of that phase is called),
waits a seeded random moment longer, sends the signal and measures how long the process takes
to exit. Asserted every time: exit status 128 + signum within LATENCY seconds of the signal; on
stderr, besides the command's own progress lines, exactly one line, the last, and no traceback;
the temporary folder (TMPDIR, fresh per test) empty; the working folder and the output folders
byte-identical to before; no child process left running.

Where the signal lands: between bytecodes (sympy, numpy, the wait for a compiler), in IPOPT
(whose iteration callback runs the Python handler), or deep in C++ CasADi code that never looks
at signals (there only the watchdog thread of :mod:`derive.cli.signals` can end the process).

The processes: importing casadi, sympy, numpy and matplotlib costs seconds of CPU per
interpreter, so the commands run in children forked from one server that imported derive once
(:data:`RUNNER`; ``derive.cli.main(argv)`` in a fresh process, the signal handling all its own),
and one IK case in a fresh interpreter of its own.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest

from derive.cli.signals import GRACE, MESSAGES

ROOT = Path(__file__).resolve().parent.parent
LATENCY = 2.0
"""Seconds from the signal to the exit, at most (measured: 0.03 to 0.2 s; 0.3 s where the watchdog acts)."""
LINUX = sys.platform.startswith("linux")
READY_TIMEOUT = 120.0  # a loaded 2-core machine imports casadi, sympy and numpy slowly

RUNNER = r'''
import importlib, json, os, signal, sys, tempfile, traceback


def probe(target, when):
    """Print @@ready on stdout when target (module:attr.path) is first called ("before";
    "instead:FILE" runs FILE then) or first returns ("after")."""
    module, _, path = target.partition(":")
    owner = importlib.import_module(module)
    *parents, name = path.split(".")
    for parent in parents:
        owner = getattr(owner, parent)
    original = getattr(owner, name)
    calls = []

    def probed(*args, **kwargs):
        calls.append(1)
        if when != "after" and len(calls) == 1:
            os.write(1, b"@@ready\n")
            if when.startswith("instead:"):
                exec(open(when[len("instead:"):]).read(), {})
        result = original(*args, **kwargs)
        if when == "after" and len(calls) == 1:
            os.write(1, b"@@ready\n")
        return result

    setattr(owner, name, probed)


def child(job):
    """In a forked child: the job's folder, environment, stdio and probe, then derive's main."""
    code = 99
    try:
        if job["group"]:
            os.setsid()
        os.chdir(job["cwd"])
        os.environ.clear()
        os.environ.update(job["env"])
        tempfile.tempdir = None  # computed again from TMPDIR
        for fd, name, mode in ((0, os.devnull, os.O_RDONLY), (1, job["stdout"], os.O_WRONLY | os.O_CREAT),
                               (2, job["stderr"], os.O_WRONLY | os.O_CREAT)):
            os.dup2(os.open(name, mode, 0o600), fd)
        for number in job["ignore"]:  # as a shell does for a background job, nohup for SIGHUP
            signal.signal(number, signal.SIG_IGN)
        if job["probe"]:
            probe(*job["probe"])
        from derive.cli import main
        code = main(job["argv"])
        sys.stdout.flush()
        sys.stderr.flush()
    except BaseException:
        traceback.print_exc()
    os._exit(code)


if sys.argv[1] == "serve":  # one job (JSON) a line on stdin; its pid, then its exit status, on stdout
    import derive.cli
    derive.cli.build_parser()  # imports every command module
    print(json.dumps({"ready": True}), flush=True)
    for line in sys.stdin:
        job = json.loads(line)
        pid = os.fork()
        if pid == 0:
            child(job)
        print(json.dumps({"pid": pid}), flush=True)
        print(json.dumps({"status": os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1])}), flush=True)
else:  # python -c RUNNER TARGET WHEN ARGV...: a fresh interpreter
    probe(sys.argv[1], sys.argv[2])
    from derive.cli import main
    sys.exit(main(sys.argv[3:]))
'''
"""The server (``python -c RUNNER serve``) forking one child per command, and the one-shot form."""


@dataclass
class Outcome:
    returncode: int
    latency: float  # seconds from the signal to the exit
    stdout: list[str]
    stderr: list[str]


def snapshot(folder: Path) -> dict[str, bytes | None]:
    """{relative path: bytes (None for a folder, the target for a link)} of everything under ``folder``."""
    out: dict[str, bytes | None] = {}
    for path in sorted(folder.rglob("*")):
        rel = path.relative_to(folder).as_posix()
        if path.is_symlink():
            out[rel] = os.readlink(path).encode()
        else:
            out[rel] = None if path.is_dir() else path.read_bytes()
    return out


def alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            return f.read().rsplit(b")", 1)[1].split()[0] != b"Z"
    except FileNotFoundError:
        return False
    except OSError:
        try:
            os.kill(pid, 0)
        except ProcessLookupError:
            return False
        return True


def lines(path: Path) -> list[str]:
    return path.read_text(errors="replace").splitlines() if path.exists() else []


class Server:
    """``python -c RUNNER serve``: derive imported once, one forked child per command."""

    def __init__(self):
        env = {**os.environ, "PYTHONUNBUFFERED": "1",
               "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
        self.proc = subprocess.Popen([sys.executable, "-c", RUNNER, "serve"], env=env, text=True,
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE)
        self.replies: list[dict] = []
        self.arrived = threading.Condition()
        threading.Thread(target=self._read, daemon=True).start()
        assert self.reply("ready", READY_TIMEOUT)["ready"]

    def _read(self):
        for line in self.proc.stdout:
            with self.arrived:
                self.replies.append(json.loads(line))
                self.arrived.notify_all()

    def reply(self, key: str, timeout: float) -> dict:
        with self.arrived:
            arrived = self.arrived.wait_for(lambda: any(key in r for r in self.replies), timeout)
            assert arrived, f"no {key} from the server"
            return self.replies.pop(next(i for i, r in enumerate(self.replies) if key in r))

    def start(self, job: dict) -> int:
        self.proc.stdin.write(json.dumps(job) + "\n")
        self.proc.stdin.flush()
        return self.reply("pid", 60)["pid"]

    def close(self):
        self.proc.stdin.close()
        self.proc.wait(timeout=60)


@pytest.fixture(scope="module")
def server():
    s = Server()
    yield s
    s.close()


class Scene:
    """The folders of one test: work/ (the working folder), tmp/ (TMPDIR) and files/ (where a test
    puts output folders and files) are checked; tools/ (what the test itself writes) is not."""

    def __init__(self, tmp_path: Path, server: Server):
        self.server = server
        self.work, self.tmp, self.files, self.tools = (tmp_path / n for n in ("work", "tmp", "files", "tools"))
        for folder in (self.work, self.tmp, self.files, self.tools):
            folder.mkdir()
        self.env = {**os.environ, "PYTHONUNBUFFERED": "1", "TMPDIR": str(self.tmp), "TMP": str(self.tmp),
                    "TEMP": str(self.tmp), "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
        self.env.pop("DERIVE_DEBUG", None)

    def state(self) -> tuple[dict, dict]:
        return snapshot(self.work), snapshot(self.files)

    def signalled(self, argv: list[str], sig: int, ready, delay: float, *, probe: tuple[str, str] | None = None,
                  group: bool = False, reference: str = "start", fresh: bool = False,
                  ignored: int | None = None) -> Outcome:
        """Run derive ``argv`` (``fresh``: in a new interpreter, ``python -m derive`` where there is no
        probe; else in a child forked from the server); once ``ready`` (a text in a line of stdout
        or stderr, or a callable that says so) and ``delay`` s more, send ``sig`` (to the process
        group with ``group``, as a terminal's Ctrl-C does), wait for the exit and check the
        promise. The folders must be as they were at the ``reference``: the "start", or the
        moment the phase was "ready". ``ignored``: a signal the process starts with ignored, sent
        first: it must run on."""
        before = self.state()
        out, err = self.tools / "stdout", self.tools / "stderr"
        if fresh:
            cmd = [sys.executable, "-c", RUNNER, *probe, *argv] if probe else [sys.executable, "-m", "derive", *argv]
            with open(out, "wb") as o, open(err, "wb") as e:
                proc = subprocess.Popen(cmd, cwd=self.work, env=self.env, stdin=subprocess.DEVNULL, stdout=o, stderr=e,
                                        start_new_session=group)
            pid, status = proc.pid, lambda timeout: proc.wait(timeout)
        else:
            pid = self.server.start({"argv": argv, "cwd": str(self.work), "env": self.env, "group": group,
                                     "stdout": str(out), "stderr": str(err), "probe": probe,
                                     "ignore": [] if ignored is None else [int(ignored)]})
            status = lambda timeout: self.server.reply("status", timeout)["status"]  # noqa: E731
        try:
            deadline = time.monotonic() + READY_TIMEOUT
            while not (ready() if callable(ready) else any(ready in line for line in lines(out) + lines(err))):
                assert alive(pid), "derive ended before the signal:\n" + "\n".join(lines(out) + lines(err))
                assert time.monotonic() < deadline, "derive never reached the phase to signal:\n" + "\n".join(
                    lines(out) + lines(err))
                time.sleep(0.005)
            if reference == "ready":
                before = self.state()
            time.sleep(delay)
            if ignored is not None:
                os.kill(pid, ignored)
                time.sleep(0.5)
                assert alive(pid), f"an ignored signal {ignored} ended derive:\n" + "\n".join(lines(err))
            assert alive(pid), "derive ended before the signal:\n" + "\n".join(lines(out) + lines(err))
            os.killpg(pid, sig) if group else os.kill(pid, sig)
            sent = time.monotonic()
            returncode = status(60)
            latency = time.monotonic() - sent
        except BaseException:
            with contextlib.suppress(OSError):
                (os.killpg if group else os.kill)(pid, signal.SIGKILL)
            status(60)  # the server's reply about this child is not left for the next test
            raise
        r = Outcome(returncode, latency, lines(out), lines(err))
        print(f"{' '.join(argv)}: signal {sig}, exit {r.returncode} after {latency:.3f} s")
        stderr = "\n".join(r.stderr)
        assert r.returncode == 128 + sig, stderr
        assert latency < LATENCY, f"{latency:.2f} s from the signal to the exit"
        assert "Traceback" not in stderr and "KeyboardInterrupt" not in stderr, stderr
        own = [line for line in r.stderr if not own_progress(line)]
        assert own == [MESSAGES[sig].decode().rstrip("\n")], stderr
        assert r.stderr[-1] == own[0]
        assert list(self.tmp.iterdir()) == [], "left in TMPDIR"
        assert self.state() == before, "the folders are not as they were"
        return r


def own_progress(line: str) -> bool:
    """A line a command writes on stderr on its way (progress, notes), not the signal's."""
    return (line.startswith(("note: ", "deriving ", "wrote ", "derive: compiling ")) or (" %" in line and ": " in line))


def moment(seed: int, low: float, high: float) -> float:
    """A seeded moment within [low, high) seconds after the phase began."""
    return float(np.random.default_rng(seed).uniform(low, high))


BOTH = [pytest.param(signal.SIGINT, id="SIGINT"), pytest.param(signal.SIGTERM, id="SIGTERM")]


@pytest.fixture
def scene(tmp_path, server) -> Scene:
    return Scene(tmp_path, server)


@pytest.mark.skipif(not LINUX, reason="reads /proc/self/fd and prctl's subreaper setting (Linux)")
def test_main_puts_back_what_it_changed(capsys):
    """In one process, main() runs again and again (the tests do): after each, the signal
    handlers, the wakeup fd, the subreaper setting, the threads and the open fds are as before."""
    import ctypes

    from derive.cli import main

    def state():
        fd = signal.set_wakeup_fd(-1)
        signal.set_wakeup_fd(fd)
        reaper = ctypes.c_int(-1)
        ctypes.CDLL(None).prctl(37, ctypes.byref(reaper), 0, 0, 0)  # PR_GET_CHILD_SUBREAPER
        return ([signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)], fd, reaper.value,
                threading.active_count(), sorted(os.listdir("/proc/self/fd")))

    before = state()
    for _ in range(3):
        assert main(["info", "pendulum"]) == 0
    assert main(["info", "no-such-robot"]) == 2
    assert state() == before
    assert "pendulum: nq = 1" in capsys.readouterr().out


# ---- CasADi / IPOPT ----

@pytest.mark.parametrize("sig, fresh", [(signal.SIGINT, True), (signal.SIGTERM, False)],
                         ids=["SIGINT-fresh-interpreter", "SIGTERM"])
def test_ik_ends_at_once_inside_ipopt(scene, sig, fresh):
    """An unreachable target with method opti: IPOPT solves and restarts for 60 s unless stopped.
    Before, a SIGINT there became a failed solve and the restarts went on (exit 0 or 1)."""
    r = scene.signalled(["ik", "planar_2r", "--xyz", "5", "0", "0", "--method", "opti", "--timeout", "60"], sig,
                        "@@ready", moment(sig, 0.05, 0.5), probe=("derive.solvers.ik:IkProblem.opti", "after"),
                        fresh=fresh)
    assert r.stdout == ["@@ready"]  # no result printed


@pytest.mark.parametrize("ignored", [signal.SIGINT, signal.SIGHUP], ids=["SIGINT-in-a-background-job", "nohup"])
def test_an_ignored_signal_stays_ignored(scene, ignored):
    """A shell starts a background job with SIGINT ignored, nohup a command with SIGHUP ignored:
    derive must not take them over (the run goes on), and SIGTERM still ends it."""
    scene.signalled(["ik", "planar_2r", "--xyz", "5", "0", "0", "--method", "opti", "--timeout", "60"],
                    signal.SIGTERM, "@@ready", 0.1, probe=("derive.solvers.ik:IkProblem.opti", "after"),
                    ignored=ignored)


def test_sighup_ends_at_once(scene):
    """The terminal closed: the same as SIGTERM, exit 129. The Panda: its derivation (1.4 s on a
    quiet machine) outlasts the moment; rrprr's (0.3 s) could end before it."""
    scene.signalled(["eom", "panda"], signal.SIGHUP, "@@ready", moment(8, 0.0, 0.5),
                    probe=("derive.inspect.sympy_model:SymbolicModel.__init__", "before"))


def test_trajopt_ends_at_once_inside_ipopt(scene):
    """The pendulum's swing-up with 1 N m takes hundreds of IPOPT iterations (seconds); IPOPT's
    iteration callback reports progress (the probe marks its first call). An earlier run's
    output stays as it was."""
    out = scene.files / "out"
    out.mkdir()
    (out / "trajectory.csv").write_text("an earlier run's\n")
    r = scene.signalled(["trajopt", "pendulum", "--swing-up", "--torque-limit", "1", "--out", str(out)],
                        signal.SIGTERM, "@@ready", moment(1, 0.0, 0.3),
                        probe=("derive.cli.analysis:Progress.__call__", "before"))
    assert r.stdout == ["pendulum: hermite-simpson, N = 100: solving", "@@ready"]


def test_trajopt_ends_at_once_while_casadi_builds(scene):
    """Right after "solving", opti.solve() expands the NLP to SX and builds its derivatives in C++."""
    r = scene.signalled(["trajopt", "cartpole", "--swing-up", "--out", str(scene.files / "out")], signal.SIGINT,
                        "solving", moment(2, 0.0, 0.3))
    assert r.stdout == ["cartpole: hermite-simpson, N = 100: solving"]


LONG_CASADI_CALL = """
import casadi as ca
x = ca.SX.sym("x")
ca.Function("f", [x], [ca.sin(x) + 0.5]).fold(10**9)(0.1)  # minutes of C++ that never looks at signals
"""


@pytest.mark.parametrize("sig", BOTH)
def test_a_long_casadi_call_is_cut_short_by_the_watchdog(scene, sig):
    """Inside one C++ call that never returns to Python (a fold of 1e9 steps: minutes), the Python
    handler cannot run; the watchdog thread (woken through the signal wakeup fd; CasADi releases
    the GIL) ends the process GRACE s later."""
    call = scene.tools / "long_call.py"
    call.write_text(LONG_CASADI_CALL)
    r = scene.signalled(["ik", "planar_2r", "--xyz", "0.5", "0.5", "0", "--method", "opti"], sig, "@@ready",
                        moment(sig + 10, 0.05, 0.3), probe=("derive.solvers.ik:IkProblem.opti", f"instead:{call}"))
    assert r.latency >= GRACE * 0.9  # the watchdog's doing: the handler itself never got to run
    assert r.stdout == ["@@ready"]


LIBRARY_TEMPORARIES = """
import os, tempfile, time
folder = tempfile.TemporaryDirectory(prefix="a-library-")
with open(os.path.join(folder.name, "data"), "wb") as f:
    f.write(bytes(100_000))
named = tempfile.NamedTemporaryFile(delete=False)
fd, path = tempfile.mkstemp()
os.write(1, b"@@made\\n")
time.sleep(60)
"""


@pytest.mark.parametrize("sig", BOTH)
def test_temporaries_that_derive_did_not_register_are_removed_too(scene, sig):
    """What tempfile makes for code that does not register it in derive.filesystem (a library,
    the benchmarks' TemporaryDirectory): os._exit skips its clean-up, the handler does not."""
    code = scene.tools / "library.py"
    code.write_text(LIBRARY_TEMPORARIES)
    scene.signalled(["info", "pendulum"], sig, "@@made", moment(sig + 50, 0.0, 0.1),
                    probe=("derive.cli.models:robots_of", f"instead:{code}"))


# ---- derivation: generate (CasADi SX + sympy CSE), eom and latex (sympy) ----

@pytest.fixture(scope="module")
def generated_pendulum(tmp_path_factory) -> Path:
    """An output folder holding the pendulum, as `derive generate` writes it."""
    from derive.cli import main

    out = tmp_path_factory.mktemp("signals") / "generated"
    assert main(["--models", str(ROOT / "models.yaml"), "generate", "--robot", "pendulum", "--out", str(out)]) == 0
    return out


@pytest.mark.parametrize("sig", BOTH)
def test_generate_ends_at_once_while_deriving(scene, sig, generated_pendulum):
    """The output folder (the pendulum, from an earlier run) stays as it was, nothing is left beside it."""
    out = scene.files / "generated"
    shutil.copytree(generated_pendulum, out, symlinks=True)
    r = scene.signalled(["--models", str(ROOT / "models.yaml"), "generate", "--robot", "rrprr", "--out", str(out)], sig,
                        "rrprr: deriving", moment(sig + 20, 0.0, 0.4))
    assert r.stdout[-1] == "[1/1] rrprr: deriving"


def test_eom_ends_at_once_inside_sympy(scene):
    r = scene.signalled(["eom", "rrprr"], signal.SIGINT, "@@ready", moment(3, 0.0, 0.5),
                        probe=("derive.inspect.sympy_model:SymbolicModel.__init__", "before"))
    assert r.stdout == ["@@ready"]


def test_latex_ends_at_once_inside_sympy(scene):
    """Nothing written: neither the .tex nor the .png."""
    r = scene.signalled(["latex", "rrprr", "--out", str(scene.files / "doc.tex"), "--png", str(scene.files / "eq.png")],
                        signal.SIGTERM, "deriving rrprr", moment(4, 0.0, 0.5))
    assert r.stdout == []


# ---- numpy: workspace ----

def test_workspace_ends_at_once_while_sampling(scene):
    """Ten million samples take minutes (FK of chunks of states, numpy)."""
    r = scene.signalled(["workspace", "ur5", "--samples", "1e7", "--png", str(scene.files / "ws.png")], signal.SIGINT,
                        "@@ready", moment(5, 0.2, 0.6), probe=("derive.cli.analysis:workspace", "before"))
    assert r.stdout == ["@@ready"]


# ---- simulate: its scratch generation in TMPDIR ----

@pytest.mark.parametrize("sig, phase", [(signal.SIGTERM, "simulating"), (signal.SIGINT, "note: ")],
                         ids=["SIGTERM-integrating", "SIGINT-generating"])
def test_simulate_ends_at_once_and_removes_its_scratch_generation(scene, sig, phase):
    """No ./generated: simulate generates the robot into a temporary folder (megabytes), then
    integrates; signalled in either phase, the folder goes (before, SIGTERM left 4.7 MB in /tmp)."""
    argv = ["simulate", "planar_2r", "--q0", "0.1", "0.2", "--t", "5e3", "--out", str(scene.files / "sim")]
    r = scene.signalled(argv, sig, phase, moment(sig + 30, 0.0, 0.3))
    assert "wrote" not in "\n".join(r.stdout)


# ---- child processes: the compiler of derive.compiled, pdflatex ----

SLOW_TOOL = """#!/bin/sh
case "$1" in --version) {then};; esac
echo $$ >> "{pids}"
{wait}
{then}
"""
WAIT = """sleep 60 &
echo $! >> "{pids}"
wait"""


def slow_tool(scene: Scene, name: str, then: str, waiting: bool = True) -> tuple[Path, Path]:
    """tools/<name>: a shell script that records its pid (and its sleep's, when ``waiting``: it
    sleeps 60 s), then runs ``then`` (at once for ``--version``)."""
    pids = scene.tools / f"{name}.pids"
    tool = scene.tools / name
    tool.write_text(SLOW_TOOL.format(pids=pids, then=then, wait=WAIT.format(pids=pids) if waiting else ""))
    tool.chmod(0o755)
    return tool, pids


def recorded(pids: Path) -> list[int]:
    return [int(p) for p in pids.read_text().split()] if pids.exists() else []


def cc1_of(parents: list[int]) -> list[int]:
    """The live cc1 processes (gcc's compiler proper) whose parent is one of ``parents``."""
    found = []
    for name in os.listdir("/proc"):
        try:
            stat = (Path("/proc") / name / "stat").read_bytes()
        except (OSError, ValueError):
            continue
        comm, rest = stat.split(b" (", 1)[1].rsplit(b") ", 1)
        if comm == b"cc1" and int(rest.split()[1]) in parents and rest[:1] != b"Z":
            found.append(int(name))
    return found


@pytest.mark.parametrize("sig, group", [(signal.SIGTERM, False), (signal.SIGINT, True)],
                         ids=["SIGTERM-to-derive-alone", "SIGINT-to-the-process-group"])
def test_a_command_compiling_for_derive_compiled_ends_at_once(scene, sig, group, generated_pendulum):
    """A command (here `info`, made to call ``derive.compiled("pendulum")`` first) building through
    $CC, a compiler that waits: every compiler is stopped (a SIGTERM to derive alone reaches none
    of them, the pool of compile jobs would start the next ones), nothing stays in the build
    cache or TMPDIR."""
    cc, pids = slow_tool(scene, "cc", 'exec cc "$@"')
    cache = scene.tools / "cache"
    scene.env.update(CC=str(cc), XDG_CACHE_HOME=str(cache))
    build = scene.tools / "build.py"
    build.write_text(f"import derive\nderive.compiled('pendulum', generated={str(generated_pendulum)!r})\n")
    r = scene.signalled(["info", "pendulum"], sig, lambda: len(recorded(pids)) >= 2, moment(sig + 40, 0.0, 0.3),
                        group=group, probe=("derive.cli.models:robots_of", f"instead:{build}"))
    assert r.stdout == ["@@ready"]
    started = recorded(pids)
    assert len(started) >= 2 and [pid for pid in started if alive(pid)] == []
    builds = cache / "derive" / "compiled"
    assert not builds.exists() or [p.name for p in builds.iterdir()] == []


def test_compiling_ends_at_once_inside_cc1(scene):
    """The Panda's generated C (large files) built through derive.compiled with $CC = gcc, caught
    in cc1 (gcc's compiler proper, which writes its assembly to a temporary file in TMPDIR): the
    compilers are stopped, gcc removes its files, the build cache keeps nothing."""
    if shutil.which("gcc") is None or not LINUX:
        pytest.skip("no gcc (its cc1 is what this case catches at work) or no /proc to find it in")
    cc, pids = slow_tool(scene, "cc", 'exec gcc "$@"', waiting=False)
    cache = scene.tools / "cache"
    scene.env.update(CC=str(cc), XDG_CACHE_HOME=str(cache))
    build = scene.tools / "build.py"
    build.write_text(f"import derive\nderive.compiled('panda', generated={str(ROOT / 'generated')!r})\n")
    caught: list[int] = []

    def compiling() -> bool:
        caught.extend(cc1_of(recorded(pids)))
        return bool(caught)

    r = scene.signalled(["info", "pendulum"], signal.SIGTERM, compiling, moment(7, 0.0, 0.05),
                        probe=("derive.cli.models:robots_of", f"instead:{build}"))
    assert r.stdout == ["@@ready"]
    started = recorded(pids) + caught
    assert len(started) >= 2 and [pid for pid in started if alive(pid)] == []
    builds = cache / "derive" / "compiled"
    assert not builds.exists() or [p.name for p in builds.iterdir()] == []


def test_pdflatex_is_stopped(scene):
    """`latex --pdf` runs pdflatex (here one that waits) on the .tex it wrote: it is stopped too,
    and the folder is as it was when pdflatex started (the new .tex, whole)."""
    tool, pids = slow_tool(scene, "pdflatex", "exit 0")
    scene.env["PATH"] = f"{tool.parent}{os.pathsep}{scene.env['PATH']}"
    tex = scene.files / "doc.tex"
    tex.write_text("an earlier run's\n")
    scene.signalled(["latex", "pendulum", "--out", str(tex), "--pdf"], signal.SIGTERM,
                    lambda: len(recorded(pids)) >= 2, moment(6, 0.0, 0.2), reference="ready")
    assert tex.read_text().endswith("\\end{document}\n")  # the new one, whole
    assert [pid for pid in recorded(pids) if alive(pid)] == []
