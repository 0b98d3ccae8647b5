"""Writing files and folders so that nothing is lost: atomic replacement, temporaries that go away.

- :func:`write_atomically` replaces a file so that, at every instant and whatever happens (a full
  disk, a kill, a power cut after the call returned), the path holds either the old bytes or the
  new ones: a temporary file beside it, written, fsync'ed, renamed over it, the folder fsync'ed.
  On failure the old file is byte-identical and the error names the path.
- Every temporary file or folder that derive makes is registered here (:func:`temporary_directory`,
  :func:`register`) so that a signal handler that must end the process at once (see
  :mod:`derive.cli`) can still remove them all (:func:`remove_temporaries`): ``os._exit`` skips
  ``finally`` blocks and ``TemporaryDirectory`` clean-up.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import stat
import tempfile
import threading
from pathlib import Path
from typing import Iterable, Iterator

from derive.errors import DeriveError

_LOCK = threading.Lock()
TEMPORARIES: dict[str, bool] = {}
"""Temporary paths of this process still in use: {path: is a folder}."""


def register(path: str | Path, folder: bool) -> None:
    """Remember a temporary path so that :func:`remove_temporaries` removes it."""
    with _LOCK:
        TEMPORARIES[os.fspath(path)] = folder


def forget(path: str | Path) -> None:
    """The temporary path is gone or kept on purpose: no longer remove it."""
    with _LOCK:
        TEMPORARIES.pop(os.fspath(path), None)


def remove_temporaries() -> None:
    """Remove every registered temporary path (for signal handlers; never raises)."""
    with _LOCK:
        items = list(TEMPORARIES.items())
        TEMPORARIES.clear()
    for path, folder in items:
        try:
            if folder:
                shutil.rmtree(path, ignore_errors=True)
            else:
                os.unlink(path)
        except OSError:
            pass


def remove_temporaries_now(wait: float = 0.2) -> None:
    """:func:`remove_temporaries` for a process that ends at once (the signal handler of
    :mod:`derive.cli`): never blocks on the registry's lock for more than ``wait`` seconds, since
    the thread a signal interrupted may hold it (a Python signal handler runs between two
    bytecodes of the main thread, possibly inside :func:`register`). Never raises."""
    held = _LOCK.acquire(timeout=wait)
    try:
        items: list[tuple[str, bool]] = []
        for _ in range(100):  # without the lock, another thread may change the dict as it is read
            try:
                items = list(TEMPORARIES.items())
                break
            except RuntimeError:
                continue
        TEMPORARIES.clear()
    finally:
        if held:
            _LOCK.release()
    for path, folder in items:
        for _ in range(3):  # a thread still writing into the folder can make one pass miss a file
            if folder:
                shutil.rmtree(path, ignore_errors=True)
            else:
                with contextlib.suppress(OSError):
                    os.unlink(path)
            if not os.path.lexists(path):
                break


@contextlib.contextmanager
def temporary_directory(prefix: str = "derive-", dir: str | Path | None = None) -> Iterator[Path]:
    """``tempfile.TemporaryDirectory`` whose folder is removed on every exit path, signals included."""
    path = Path(tempfile.mkdtemp(prefix=prefix, dir=dir))
    register(path, True)
    try:
        yield path
    finally:
        shutil.rmtree(path, ignore_errors=True)
        forget(path)


def _fsync_folder(folder: Path) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0))
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass  # some file systems cannot fsync a folder; the rename is still atomic
    finally:
        os.close(fd)


def write_atomically(path: str | Path, data: str | bytes, what: str = "file") -> Path:
    """Replace ``path`` (``what`` names it in errors) by ``data`` all at once; returns ``path``.

    A symbolic link is written through (its target is replaced, the link stays). An existing
    file keeps its permission bits; a new one gets 0666 less the umask, as ``open`` would.
    Raises a DeriveError naming ``path`` on any failure, with the old file left byte-identical.
    """
    return write_chunks_atomically(path, [data], what)


def write_chunks_atomically(path: str | Path, chunks: Iterable[str | bytes], what: str = "file",
                            make_folder: bool = False) -> Path:
    """:func:`write_atomically` of the concatenated ``chunks`` (text as UTF-8), written as they come so
    that a long output is never held whole in memory; ``make_folder`` creates the folder first."""
    path = Path(path)
    if str(path) in ("", "."):
        raise DeriveError(f"{what}: empty path")
    real = Path(os.path.realpath(path)) if path.is_symlink() else path
    tmp = None
    try:
        if make_folder:
            real.parent.mkdir(parents=True, exist_ok=True)
        if real.is_dir():
            raise IsADirectoryError(21, "is a folder", str(path))
        try:
            mode = stat.S_IMODE(os.stat(real).st_mode)
        except FileNotFoundError:
            umask = os.umask(0)
            os.umask(umask)
            mode = 0o666 & ~umask
        fd, tmp = tempfile.mkstemp(prefix=f".{real.name}.", suffix=".tmp", dir=real.parent)
        register(tmp, False)
        with os.fdopen(fd, "wb") as f:
            for chunk in chunks:
                f.write(chunk.encode() if isinstance(chunk, str) else chunk)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, mode)
        os.replace(tmp, real)
        forget(tmp)
        tmp = None
        _fsync_folder(real.parent)
    except OSError as exc:
        reason = exc.strerror or str(exc)
        raise DeriveError(f"{path}: cannot write {what} ({reason}); it is left as it was") from None
    finally:
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)
            forget(tmp)
    return path