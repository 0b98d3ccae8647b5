"""How derive ends on SIGINT (Ctrl-C), SIGTERM and SIGHUP: at once, whatever library is running.

SIGINT, SIGTERM and SIGHUP end every command within a fraction of a second, whatever library is
running (CasADi and IPOPT, sympy, numpy, a compiler): the child processes are stopped, every
temporary file and folder is removed (those registered in :mod:`derive.filesystem` and whatever
else ``tempfile`` made during the command), one line goes to stderr and the exit status is
128 + the signal's number: 130, 143, 129 (see :func:`_end`). An ignored signal (a background
job's SIGINT, SIGHUP under nohup) stays ignored. :class:`EndOnSignals` sets this up for one
command and puts back what was there afterwards.
"""

from __future__ import annotations

import contextlib
import os
import select
import shutil
import signal
import sys
import threading
import time

from derive import filesystem

SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, name))
MESSAGES = {signal.SIGINT: b"derive: interrupted (SIGINT); stopped at once, temporary files removed\n",
            signal.SIGTERM: b"derive: terminated (SIGTERM); stopped at once, temporary files removed\n"}
if hasattr(signal, "SIGHUP"):
    MESSAGES[signal.SIGHUP] = b"derive: hung up (SIGHUP); stopped at once, temporary files removed\n"
GRACE = 0.25
"""Seconds the watchdog leaves the main thread to act on a signal before ending the process itself."""
CHILD_WAIT = 0.5
"""Seconds child processes get to exit on SIGTERM (gcc removes its temporary files) before SIGKILL."""
SPAWNING = frozenset({"subprocess.Popen", "os.system", "os.posix_spawn", "os.spawn", "os.fork", "os.forkpty",
                      "os.exec", "pty.spawn"})
"""Audit events of Python starting a process: refused to every other thread once the process is ending."""

_ENDING = threading.Lock()  # held by the thread that ends the process
_ENDER: list[int] = []      # that thread's ident, once it holds _ENDING
_AUDITING = [False]         # the audit hook is installed (once per process: it cannot be removed)
_WATCHING = [0]             # commands running (main() calls not yet returned) in this process
_MADE: list[tuple[str, bool]] = []  # (path, is a folder) of what tempfile made while a command runs


def _audit(event: str, args) -> None:
    """Audit hook. While a command runs, note every temporary file and folder that ``tempfile``
    makes in this process (``TemporaryDirectory``, ``mkstemp``, ``NamedTemporaryFile``...): the
    ones not registered in :mod:`derive.filesystem` (the benchmarks', a library's) would outlive
    ``os._exit`` too. And once :func:`_end` runs, no other thread starts a process (a pool of
    compile jobs would start the next compiler as each one is stopped, and it would outlive us)."""
    if event in ("tempfile.mkdtemp", "tempfile.mkstemp"):
        if _WATCHING[0]:
            _MADE.append((os.path.abspath(args[0]), event == "tempfile.mkdtemp"))
    elif _ENDER and event in SPAWNING and threading.get_ident() != _ENDER[0]:
        raise OSError(f"derive is ending on a signal: {event} refused")


def _stat(pid: int | str) -> tuple[int, bytes] | None:
    """(parent pid, state letter) of a process from /proc, None if it is gone or unreadable."""
    try:
        with open(f"/proc/{pid}/stat", "rb") as f:
            stat = f.read()
        fields = stat[stat.rindex(b")") + 2:].split()  # the command name may hold blanks and parentheses
        return int(fields[1]), fields[0]
    except (OSError, ValueError, IndexError):
        return None


def _process_table() -> dict[int, tuple[int, bytes]]:
    """{pid: (parent pid, state letter)} of every process in sight (Linux /proc, else ``ps``)."""
    table: dict[int, tuple[int, bytes]] = {}
    if os.path.isdir("/proc/self"):
        for name in os.listdir("/proc"):
            entry = _stat(name) if name.isdigit() else None
            if entry is not None:
                table[int(name)] = entry
        return table
    try:
        import subprocess  # noqa: PLC0415 (only where there is no /proc)

        out = subprocess.run(["ps", "-A", "-o", "pid=", "-o", "ppid=", "-o", "stat="], capture_output=True,
                             text=True, timeout=1).stdout
    except Exception:  # noqa: BLE001 (never fail on the way out)
        return table
    for line in out.splitlines():
        parts = line.split()
        if len(parts) >= 3 and parts[0].isdigit() and parts[1].isdigit():
            table[int(parts[0])] = (int(parts[1]), parts[2][:1].encode())
    return table


def _descendants(table: dict[int, tuple[int, bytes]]) -> list[int]:
    """This process's live descendants in a process table, parents before their children."""
    children: dict[int, list[int]] = {}
    for pid, (ppid, state) in table.items():
        if state != b"Z":
            children.setdefault(ppid, []).append(pid)
    found, frontier = [], [os.getpid()]
    while frontier:
        frontier = [c for p in frontier for c in children.get(p, ())]
        found += frontier
    return found


def _alive(pid: int) -> bool:
    """Whether ``pid`` still runs (a zombie does not; one that is our child is reaped)."""
    with contextlib.suppress(OSError):
        os.waitpid(pid, os.WNOHANG)
    if os.path.isdir("/proc/self"):
        entry = _stat(pid)
        return entry is not None and entry[1] != b"Z"
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True
    return True


def _stop_children() -> None:
    """End every descendant process (the compilers of derive.compiled, pdflatex, a compiler
    wrapper and what it runs): freeze the whole tree (SIGSTOP, the table read again until no new
    process appears), send SIGTERM to all, let them go on (SIGCONT), SIGKILL what still runs
    after CHILD_WAIT s.

    A terminal's Ctrl-C reaches them already (one process group), but a SIGTERM sent to derive
    alone does not: they would run on, writing into folders about to be removed. Freezing first
    matters: a process that sees its child die before its own signal arrives reacts (a shell
    script runs its next command, a compiler driver starts the assembler on a temporary file in
    TMPDIR); frozen, each wakes up with SIGTERM pending and only its signal handler runs (gcc's
    removes its temporary files)."""
    deadline = time.monotonic() + CHILD_WAIT
    frozen: list[int] = []
    for _ in range(100):
        new = [pid for pid in _descendants(_process_table()) if pid not in frozen]
        if not new:
            break
        for pid in new:
            with contextlib.suppress(OSError):
                os.kill(pid, signal.SIGSTOP)
        frozen += new
    for sig in (signal.SIGTERM, signal.SIGCONT):
        for pid in frozen:
            with contextlib.suppress(OSError):
                os.kill(pid, sig)
    running = frozen
    while running and time.monotonic() < deadline:
        time.sleep(0.005)
        running = [pid for pid in running if _alive(pid)]
    for pid in running:  # it ignores SIGTERM
        with contextlib.suppress(OSError):
            os.kill(pid, signal.SIGKILL)
    deadline = time.monotonic() + 0.2
    while running and time.monotonic() < deadline:
        time.sleep(0.005)
        running = [pid for pid in running if _alive(pid)]


def _remove_temporaries() -> None:
    """Every registered temporary, then whatever else tempfile made during the command and is still
    there (a temporary file renamed into place is not: its name is gone)."""
    filesystem.remove_temporaries_now()
    for path, folder in list(_MADE):
        if folder and os.path.isdir(path) and not os.path.islink(path):
            shutil.rmtree(path, ignore_errors=True)
        elif not folder and os.path.lexists(path):
            with contextlib.suppress(OSError):
                os.unlink(path)


def _end(signum: int) -> None:
    """End the process for ``signum``: stop the child processes, remove every temporary file and
    folder (:func:`_remove_temporaries`), write one line on stderr, exit 128 + signum. Whichever of the main thread and
    the watchdog comes first does it; the main thread then never returns to the interrupted code."""
    main = threading.current_thread() is threading.main_thread()
    if main:  # a second signal during the clean-up ends the process at once
        for s in SIGNALS:
            if signal.getsignal(s) is _handler:
                signal.signal(s, signal.SIG_DFL)
    if not _ENDING.acquire(blocking=False):
        while main:  # the watchdog is ending the process: go no further
            time.sleep(1)
        return
    _ENDER.append(threading.get_ident())
    try:
        for step in (_stop_children, _remove_temporaries):
            try:
                step()
            except Exception:  # noqa: BLE001 (on the way out: do the other steps all the same)
                pass
        os.write(2, MESSAGES.get(signum, b"derive: ended by signal %d\n" % signum))
    finally:
        os._exit(128 + signum)


def _handler(signum, frame) -> None:
    _end(signum)


class _Watchdog:
    """A thread that ends the process GRACE s after one of SIGNALS unless the main thread did.

    It sleeps in select() on the read end of a pipe whose write end is the signal wakeup fd,
    which CPython's C-level handler writes at once, whatever the main thread is doing."""

    def __init__(self) -> None:
        self.read, self.write = os.pipe()
        for fd in (self.read, self.write):
            os.set_blocking(fd, False)
        self.previous = signal.set_wakeup_fd(self.write, warn_on_full_buffer=False)
        self.stop = threading.Event()
        self.thread = threading.Thread(target=self._watch, name="derive-signal-watchdog", daemon=True)
        self.thread.start()

    def _watch(self) -> None:
        while not self.stop.is_set():
            select.select([self.read], [], [])
            try:
                data = os.read(self.read, 512)
            except BlockingIOError:
                continue
            for signum in data:
                if signum in SIGNALS and not self.stop.is_set():
                    time.sleep(GRACE)
                    _end(signum)
                    return

    def close(self) -> None:
        signal.set_wakeup_fd(self.previous)
        self.stop.set()
        with contextlib.suppress(OSError):
            os.write(self.write, b"\0")  # wakes the thread up
        self.thread.join(timeout=GRACE + 5)
        os.close(self.read)
        os.close(self.write)


_PRCTL: list = []  # libc's prctl, loaded once


def _subreaper(on: bool) -> bool | None:
    """Linux: make this process (or no longer) the reaper of its orphaned descendants; returns the
    previous setting, None where there is none. A terminal's Ctrl-C reaches the whole process
    group: a compiler driver dies of it, and a child of its that ignores SIGINT (any background
    job of a shell script does) would leave our tree and run on; with this it stays in our tree,
    where :func:`_stop_children` finds it."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        import ctypes  # noqa: PLC0415 (Linux only)

        if not _PRCTL:
            _PRCTL.append(ctypes.CDLL(None, use_errno=True).prctl)
        prctl = _PRCTL[0]
        previous = ctypes.c_int(0)
        if prctl(37, ctypes.byref(previous), 0, 0, 0) != 0 or prctl(36, int(on), 0, 0, 0) != 0:
            return None  # 37, 36: PR_GET_CHILD_SUBREAPER, PR_SET_CHILD_SUBREAPER
        return bool(previous.value)
    except (OSError, AttributeError):
        return None


class EndOnSignals:
    """While a command runs (in the main thread): SIGNALS go to :func:`_end`, watched by a
    :class:`_Watchdog`, this process is a subreaper and :func:`_audit` notes what tempfile makes;
    :meth:`close` puts back what was there
    (main() runs many times in one process in tests). An ignored signal stays ignored: a
    background job of a shell script ignores SIGINT, a command under nohup SIGHUP."""

    def __init__(self) -> None:
        self.previous: dict[int, object] = {}
        self.watchdog: _Watchdog | None = None
        self.reaper: bool | None = None
        self.watching = False
        if threading.current_thread() is not threading.main_thread():
            return
        if not _AUDITING[0]:
            sys.addaudithook(_audit)
            _AUDITING[0] = True
        _WATCHING[0] += 1
        self.watching = True
        for s in SIGNALS:
            if signal.getsignal(s) != signal.SIG_IGN:
                self.previous[s] = signal.signal(s, _handler)
        try:
            self.watchdog = _Watchdog()
        except (OSError, ValueError):  # no pipe left, or no wakeup fd here: the handler alone
            self.watchdog = None
        self.reaper = _subreaper(True)

    def close(self) -> None:
        if self.watchdog is not None:
            self.watchdog.close()  # first, so that no signal it sees is one for the previous handlers
        for s, handler in self.previous.items():
            signal.signal(s, handler if handler is not None else signal.SIG_DFL)
        if self.reaper is False:
            _subreaper(False)
        if self.watching:
            _WATCHING[0] -= 1
            if not _WATCHING[0]:
                _MADE.clear()
