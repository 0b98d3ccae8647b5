"""Dynamic parameter identification from measured motion: ``derive identify ROBOT DATA.csv``.

tau = Y(q, qd, qdd) pi is linear in the standard parameters pi (10 per body and the actuators'
armature, viscous and Coulomb friction, :mod:`derive.symbolic.regressor`); only the base
parameters pi_b = K pi (Gautier's numerical QR, :mod:`derive.symbolic.base_parameters`) are
identifiable: tau = Y_b pi_b with Y_b the base columns of Y.

- Data: a CSV with a header, columns ``t, q_<coordinate>..., [qd_<coordinate>..., qdd_...,]
  tau_<coordinate>...`` (simulate's, trajopt's and excite's CSV; a UTF-8 byte-order mark, as Excel writes,
  is accepted). Missing qd and qdd are obtained from q by a zero-phase low-pass filter (a
  4th-order Butterworth run forwards and backwards) and central differences; the report says so.
- The CSV is streamed, never held: it is read in blocks of rows and each block's regressor is
  folded into, per joint j, the R factor of [Y_b,j | tau_j] (the rows of joint j stacked over the
  samples, QR-updated block by block) and, for ``physical``, the Gram matrix of [Y_j | tau_j].
  Memory is bounded whatever the file's length. Where qd and qdd are derived, a first pass
  counts the samples and checks the times, and the filter runs over overlapping windows
  (FILTER_OVERLAP samples either side, far beyond the filter's memory), equal to one pass over
  the whole file to rounding.
- Weighted least squares (Gautier): an ordinary least-squares pass gives each joint's residual
  standard deviation sigma_j; its rows are then divided by sigma_j and solved again. The
  standard deviation of each base parameter is sqrt(diag(sigma^2 (W^T W)^-1)) of the weighted
  problem; the report gives it, relative in %, the condition number of W and the residual per joint.
  The R factors give all of it exactly: ||Y_b,j x - tau_j|| = ||R_j [x; -1]||, and W^T W =
  sum_j R_j^T R_j / sigma_j^2.
- ``physical=True``: the standard parameters are fitted instead, each body's 10 through the
  Cholesky factor L of its pseudo-inertia J = L L^T (J >= 0: positive mass, positive
  semi-definite inertia, the triangle inequality), the actuators' bounded below by 0, with IPOPT
  (CasADi), starting from the model's values and pulled towards them by 1e-6 of the fit
  (the directions the data does not see stay at the model's values).
- Without ``physical``, the standard parameters written back are the physically consistent ones
  closest to the model's values that reproduce the identified base parameters exactly (K pi = pi_b,
  IPOPT as above), or where none does, the model's values moved the least (in the 2-norm):
  pi = pi0 + K^+ (pi_b - K pi0), which may not load as a model (the report says so).
"""

from __future__ import annotations

import math
import os
import re
import stat
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterable, Iterator

import casadi as ca
import numpy as np

from derive.description.robot import Robot
from derive.errors import DeriveError
from derive.symbolic.base_parameters import BaseParameters, dependencies_text, near_dependencies
from derive.symbolic.closed_regressor import ClosedRegressor
from derive.symbolic.closure import ReducedChain
from derive.symbolic.dynamics import NewtonEuler
from derive.symbolic.regressor import Regressor
from derive.symbolic.symbols import make_symbols

FILTER_ORDER = 4
FILTER_CUTOFF = 0.1  # of the sampling frequency (Nyquist = 0.5)
FILTER_OVERLAP = 400  # samples either side of a filter window: the filter's poles (|p| < 0.8) forget in 400
# samples to 0.8^400 = 1e-39, so windows agree with one pass over the whole file to rounding
MAX_CSV_BYTES = 32 * 2**30  # a CSV larger than this is refused: split it or resample
MAX_CSV_ROWS = 100_000_000  # samples; 10 million take minutes
MAX_LINE_BYTES = 2**20  # one line of the CSV
READ_BYTES = 2**21  # read at a time
WINDOW_ROWS = 65536  # samples filtered at a time (plus the overlap)
REGRESSOR_BYTES = 2**21  # bytes of Y evaluated and folded in at a time (2 MiB)
QR_ROWS = 1024  # rows per QR update: small enough for LAPACK to stay on one thread (threads cost more here)
PROGRESS_SECONDS = 5.0  # a progress line at most this often
NUMBER = re.compile(r"\s*[+-]?(?:\d+\.?\d*(?:[eE][+-]?\d+)?|\.\d+(?:[eE][+-]?\d+)?|nan|inf|infinity)\s*",
                    re.IGNORECASE | re.ASCII)


@dataclass
class Measurements:
    """Samples of one robot's motion: arrays (N, nv); ``derived`` says how qd and qdd were obtained;
    ``lines`` (N) are the samples' line numbers in the CSV they come from (for errors), if any."""

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    tau: np.ndarray
    derived: str = ""
    lines: np.ndarray | None = None


# --------------------------------------------------------------------------- the CSV, streamed


class Progress:
    """A line through ``log`` at most every PROGRESS_SECONDS (none for work that ends sooner)."""

    def __init__(self, log: Callable[[str], None] | None):
        self.log = log
        self.last = time.monotonic()

    def __call__(self, message: Callable[[], str]) -> None:
        now = time.monotonic()
        if self.log is not None and now - self.last >= PROGRESS_SECONDS:
            self.last = now
            self.log(message())


@dataclass
class MeasurementFile:
    """A measurement CSV whose header has been read and checked: which column holds what.

    ``rows`` and the time statistics are known after :func:`scan_measurements` (the first pass,
    needed only where qd and qdd are derived from q)."""

    path: Path
    what: str
    columns: list[str]
    t: int
    q: list[int]
    tau: list[int]
    qd: list[int] | None
    qdd: list[int] | None
    identity: tuple = ()  # (device, inode, size, mtime) when opened: the second pass must read the same file
    rows: int | None = None
    h: float = 0.0  # mean time step
    trim: int = 0  # samples dropped at either end (the filter's and the differences' edge effects)

    @property
    def derives(self) -> bool:
        """Whether qd or qdd come from q (filtered and differentiated)."""
        return self.qd is None or self.qdd is None

    def error(self, problem: str, line: int | None = None, column: int | None = None) -> DeriveError:
        where = f" line {line}" if line is not None else ""
        where += (", " if where else " ") + f"column {self.columns[column]}" if column is not None else ""
        return DeriveError(f"{self.what}: {self.path}:{where}{':' if where else ''} {problem}")

    def note(self) -> str:
        """What the report says about derived rates."""
        return (f"qd and qdd derived from q: zero-phase Butterworth low-pass (order {FILTER_ORDER}, cut-off "
                f"{FILTER_CUTOFF / self.h:.4g} Hz) and central differences at {1 / self.h:.4g} Hz; the first and "
                f"last {self.trim} samples dropped (edge effects)")


def _size(n: int) -> str:
    """A size for messages: ``32 GiB``, ``1 MiB``, ``512 bytes``."""
    for unit, scale in (("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if n >= scale:
            return f"{n / scale:.3g} {unit}"
    return f"{n} bytes"


def _stat_identity(st: os.stat_result) -> tuple:
    return st.st_dev, st.st_ino, st.st_size, st.st_mtime_ns


class _Reader:
    """The lines of a CSV after its header, in blocks, with the input-file guards: a regular file
    only (a FIFO or /dev/zero is refused before it is opened), at most MAX_CSV_BYTES read (the file
    may grow while read), lines of at most MAX_LINE_BYTES, UTF-8."""

    def __init__(self, path: Path, what: str):
        self.path, self.what = path, what
        if str(path) in ("", "."):
            raise DeriveError(f"{what}: empty path for the data")
        try:
            st = os.stat(path)
        except FileNotFoundError:
            raise DeriveError(f"{what}: {path}: no such file") from None
        except OSError as exc:
            raise DeriveError(f"{what}: {path}: cannot read the data ({exc.strerror or exc})") from None
        if not stat.S_ISREG(st.st_mode):  # before opening: a FIFO would block open()
            raise DeriveError(f"{what}: {path}: cannot read the data: not a regular file")
        if st.st_size > MAX_CSV_BYTES:
            raise DeriveError(f"{what}: {path}: the data is {_size(st.st_size)}, more than the {_size(MAX_CSV_BYTES)} "
                              f"{what} reads: split it or resample it")
        try:
            self.file = open(path, "rb")
            st = os.fstat(self.file.fileno())
        except OSError as exc:
            raise DeriveError(f"{what}: {path}: cannot read the data ({exc.strerror or exc})") from None
        if not stat.S_ISREG(st.st_mode):
            self.file.close()
            raise DeriveError(f"{what}: {path}: cannot read the data: not a regular file")
        self.identity = _stat_identity(st)
        self.size = max(st.st_size, 1)
        self.read = 0  # bytes
        self.line = 0  # the number of the last line handed out

    def close(self) -> None:
        self.file.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def _chunk(self) -> bytes:
        try:
            data = self.file.read(READ_BYTES)
        except OSError as exc:
            raise DeriveError(f"{self.what}: {self.path}: cannot read the data ({exc.strerror or exc})") from None
        self.read += len(data)
        if self.read > MAX_CSV_BYTES:
            raise DeriveError(f"{self.what}: {self.path}: more than {_size(MAX_CSV_BYTES)} read (the file grows "
                              "while it is read?): split it or resample it")
        return data

    def _decode(self, data: bytes, first_line: int) -> str:
        try:
            return data.decode("utf-8")
        except UnicodeDecodeError as exc:
            line = first_line + data.count(b"\n", 0, exc.start)
            raise DeriveError(f"{self.what}: {self.path}: line {line}: not UTF-8 text (a CSV of numbers)") from None

    def header(self) -> tuple[int, str]:
        """(line number, text) of the first line that is not blank; a byte-order mark is dropped."""
        while True:
            raw = self.file.readline(MAX_LINE_BYTES + 1)
            self.read += len(raw)
            if not raw:
                raise DeriveError(f"{self.what}: {self.path}: needs a header line and samples")
            self.line += 1
            if len(raw) > MAX_LINE_BYTES and not raw.endswith(b"\n"):
                raise DeriveError(f"{self.what}: {self.path}: line {self.line} is longer than "
                                  f"{_size(MAX_LINE_BYTES)}")
            if self.line == 1 and raw.startswith(b"\xef\xbb\xbf"):  # Excel's UTF-8 byte-order mark
                raw = raw[3:]
            text = self._decode(raw, self.line)
            if text.strip():
                return self.line, text.rstrip("\r\n")

    def blocks(self) -> Iterator[tuple[int, list[str]]]:
        """(number of the first line, lines) after the header, about READ_BYTES at a time."""
        rest = b""
        while True:
            data = self._chunk()
            if not data:
                if rest:
                    first = self.line + 1
                    self.line += 1
                    yield first, [self._decode(rest, first)]
                return
            data = rest + data
            cut = data.rfind(b"\n")
            if cut < 0:
                rest = data
                if len(rest) > MAX_LINE_BYTES:
                    raise DeriveError(f"{self.what}: {self.path}: line {self.line + 1} is longer than "
                                      f"{_size(MAX_LINE_BYTES)}")
                continue
            rest = data[cut + 1:]
            if len(rest) > MAX_LINE_BYTES:
                line = self.line + data.count(b"\n") + 1
                raise DeriveError(f"{self.what}: {self.path}: line {line} is longer than {_size(MAX_LINE_BYTES)}")
            first = self.line + 1
            lines = self._decode(data[:cut], first).replace("\r\n", "\n").split("\n")
            if cut > MAX_LINE_BYTES and max(map(len, lines)) > MAX_LINE_BYTES:
                line = first + next(k for k, x in enumerate(lines) if len(x) > MAX_LINE_BYTES)
                raise DeriveError(f"{self.what}: {self.path}: line {line} is longer than {_size(MAX_LINE_BYTES)}")
            self.line += len(lines)
            yield first, lines


def open_measurements(path: str | Path, coordinates: list[str], what: str = "identify") -> MeasurementFile:
    """Read and check the header of a measurement CSV (t, q_<c>..., [qd_<c>..., qdd_<c>...,] tau_<c>...).

    One-line DeriveError naming the file and the column: a duplicate, missing or unnamed column."""
    path = Path(path)
    with _Reader(path, what) as reader:
        line, text = reader.header()
        identity = reader.identity
        first = next(((k, block) for k, block in reader.blocks() if any(x.strip() for x in block)), None)
    if first is None:
        raise DeriveError(f"{what}: {path}: needs a header line and samples")
    names = [h.strip() for h in text.split(",")]
    names = [h[1:-1].strip() if len(h) >= 2 and h[0] == h[-1] == '"' else h for h in names]
    if len(names) == 1 and (";" in names[0] or "\t" in names[0]):
        raise DeriveError(f"{what}: {path}: line {line}: the columns must be separated by commas (this header has "
                          f"{'semicolons' if ';' in names[0] else 'tabs'})")
    seen: dict[str, int] = {}
    for k, name in enumerate(names):
        if not name:
            raise DeriveError(f"{what}: {path}: line {line}: column {k + 1} of the header has no name")
        if name in seen:
            raise DeriveError(f"{what}: {path}: line {line}: column {name} appears twice in the header (columns "
                              f"{seen[name] + 1} and {k + 1}): which one holds the data?")
        seen[name] = k
    _parse(MeasurementFile(path, what, names, 0, [], [], None, None), *first)  # the first samples' values

    def block(prefix: str, required: bool) -> list[int] | None:
        wanted = [f"{prefix}_{c}" for c in coordinates]
        missing = [n for n in wanted if n not in seen]
        if missing and (required or len(missing) < len(wanted)):
            raise DeriveError(f"{what}: {path}: missing column{'s' * (len(missing) > 1)} {', '.join(missing[:4])}"
                              f"{' ...' if len(missing) > 4 else ''} (header: t, q_<c>, [qd_<c>, qdd_<c>,] tau_<c> "
                              f"for c in {', '.join(coordinates)})")
        return None if missing else [seen[n] for n in wanted]

    if "t" not in seen:
        raise DeriveError(f"{what}: {path}: missing column t (time, s)")
    q, tau = block("q", True), block("tau", True)
    qd, qdd = block("qd", False), block("qdd", False)
    return MeasurementFile(path, what, names, seen["t"], q, tau, qd, qdd, identity)


def _diagnose(mf: MeasurementFile, first: int, lines: list[str]) -> DeriveError:
    """The first problem in ``lines`` (numbered from ``first``) that made them unreadable as numbers."""
    n = len(mf.columns)
    for k, line in enumerate(lines):
        if not line.strip():
            continue
        fields = line.split(",")
        if len(fields) != n:
            return mf.error(f"{len(fields)} values, but the header has {n} columns", first + k)
        for c, x in enumerate(fields):
            if not NUMBER.fullmatch(x):
                shown = x.strip()
                shown = shown[:40] + "..." if len(shown) > 40 else shown
                return mf.error(f"'{shown}' is not a number (the samples must be comma-separated numbers)" if shown
                                else "no value (the samples must be comma-separated numbers)", first + k, c)
            if not math.isfinite(float(x)):
                return mf.error(f"{x.strip()} is not a finite number", first + k, c)
    return mf.error(f"lines {first} to {first + len(lines) - 1} cannot be read as comma-separated numbers")


def _parse(mf: MeasurementFile, first: int, lines: list[str]) -> tuple[np.ndarray, np.ndarray]:
    """(values (rows, columns), line numbers (rows)) of the lines that are not blank; one-line errors."""
    keep = [k for k, line in enumerate(lines) if line and not line.isspace()]
    if not keep:
        return np.zeros((0, len(mf.columns))), np.zeros(0, dtype=np.int64)
    try:
        values = np.loadtxt(lines if len(keep) == len(lines) else [lines[k] for k in keep], delimiter=",",
                            comments=None, dtype=float, ndmin=2)
    except ValueError:
        raise _diagnose(mf, first, lines) from None
    if values.shape != (len(keep), len(mf.columns)) or not np.isfinite(values).all():
        raise _diagnose(mf, first, lines)
    return values, first + np.asarray(keep, dtype=np.int64)


def _rows(mf: MeasurementFile, progress: Progress, stage: str) -> Iterator[tuple[np.ndarray, np.ndarray]]:
    """Every sample of the file, in blocks: (values, line numbers)."""
    count = 0
    with _Reader(mf.path, mf.what) as reader:
        if reader.identity != mf.identity:
            raise DeriveError(f"{mf.what}: {mf.path}: the file changed while it was read: read it again when it "
                              "is complete")
        reader.header()
        for first, lines in reader.blocks():
            values, numbers = _parse(mf, first, lines)
            count += len(values)
            if count > MAX_CSV_ROWS:
                raise DeriveError(f"{mf.what}: {mf.path}: more than {MAX_CSV_ROWS:,} samples: split the file or "
                                  "resample it")
            progress(lambda: f"{mf.what}: {mf.path}: {stage}: {count:,} samples read "
                             f"({100 * reader.read / reader.size:.0f} % of the file)")
            if len(values):
                yield values, numbers


def scan_measurements(mf: MeasurementFile, log: Callable[[str], None] | None = None) -> MeasurementFile:
    """The first pass where qd and qdd are derived: count the samples, check that the times increase
    evenly, and set ``rows``, ``h`` and ``trim``. Every value is checked on the way."""
    progress = Progress(log)
    rows, t_last, dt_min, dt_max, dt_sum = 0, None, math.inf, -math.inf, 0.0
    bad_line = None
    for values, lines in _rows(mf, progress, "pass 1 of 2, checking"):
        t = values[:, mf.t]
        if t_last is not None:
            t = np.concatenate([[t_last], t])
            lines = np.concatenate([[0], lines])
        dt = np.diff(t)
        if len(dt):
            if bad_line is None and not (dt > 0).all():
                bad_line = int(lines[1 + int(np.argmax(~(dt > 0)))])
            dt_min, dt_max = min(dt_min, float(dt.min())), max(dt_max, float(dt.max()))
            dt_sum += float(np.sum(dt))
        t_last = float(t[-1])
        rows += len(values)
    need = 3 * (FILTER_ORDER + 1) + 2
    if rows < need:
        raise mf.error(f"{rows} samples; qd and qdd are missing and cannot be derived from q: need at least {need} "
                       "samples (or give qd_<c> and qdd_<c> columns)")
    if bad_line is not None:
        raise mf.error("the times t must increase from one sample to the next to derive the missing qd and qdd "
                       "from q", bad_line, mf.t)
    h = dt_sum / (rows - 1)
    if dt_max - dt_min > 1e-6 * h:
        raise mf.error(f"qd and qdd are missing and the samples are not evenly spaced in t (steps {dt_min:.6g} to "
                       f"{dt_max:.6g} s): resample, or give qd_<c> and qdd_<c>")
    mf.rows, mf.h, mf.trim = rows, h, max(10, rows // 50)  # the filter's and the differences' edge effects
    return mf


def least_rows(samples: int) -> int:
    """The fewest CSV rows that leave ``samples`` samples after the edge trim (where qd and qdd are derived)."""
    rows = max(samples + 20, 3 * (FILTER_ORDER + 1) + 2)
    while rows - 2 * max(10, rows // 50) < samples:
        rows += 1
    return rows


def check_sample_count(mf: MeasurementFile, parameters: int, nv: int) -> None:
    """Refuse, before the fit, a derived-rates file whose edge trim leaves too few samples for
    ``parameters`` base parameters (nv equations per sample)."""
    if mf.rows is None or not mf.derives:
        return
    need = parameters // nv + 1
    left = mf.rows - 2 * mf.trim
    if left < need:
        raise mf.error(f"too few rows after trimming {mf.trim} edge samples at either end (qd and qdd are derived from "
                       f"q): {mf.rows} rows leave {max(left, 0)} samples, {parameters} base parameters need at least "
                       f"{need}: need at least {least_rows(need)} rows (or give qd_<c> and qdd_<c> columns)")


def measurement_blocks(mf: MeasurementFile, log: Callable[[str], None] | None = None) -> Iterator[Measurements]:
    """The file's samples in blocks, as :class:`Measurements`; qd and qdd derived where missing (after
    :func:`scan_measurements`), the edge samples dropped."""
    progress = Progress(log)
    if not mf.derives:
        for values, lines in _rows(mf, progress, "fitting"):
            yield Measurements(values[:, mf.t], values[:, mf.q], values[:, mf.qd], values[:, mf.qdd],
                               values[:, mf.tau], lines=lines)
        return
    if mf.rows is None:
        scan_measurements(mf, log)
    from scipy.signal import butter, filtfilt  # deferred: scipy is only needed here

    b, a = butter(FILTER_ORDER, 2 * FILTER_CUTOFF)
    N, pad, trim = mf.rows, FILTER_OVERLAP, mf.trim
    buffer, lines_buffer = np.zeros((0, len(mf.columns))), np.zeros(0, dtype=np.int64)
    start = done = 0  # the global indices of buffer[0] and of the next sample to hand out

    def window(end: int, upto: int) -> Measurements | None:
        """The samples done..end, filtered over buffer up to ``upto`` (pad beyond end where the file goes on)."""
        w = buffer[: upto - start]
        qf = filtfilt(b, a, w[:, mf.q], axis=0)
        qd = np.gradient(qf, mf.h, axis=0)
        qdd = np.gradient(qd, mf.h, axis=0)
        lo, hi = max(done, trim), min(end, N - trim)
        if lo >= hi:
            return None
        k = slice(lo - start, hi - start)
        v = w[k]
        return Measurements(v[:, mf.t], v[:, mf.q], v[:, mf.qd] if mf.qd is not None else qd[k],
                            v[:, mf.qdd] if mf.qdd is not None else qdd[k], v[:, mf.tau], lines=lines_buffer[k])

    count = 0
    for values, lines in _rows(mf, progress, "pass 2 of 2, fitting"):
        count += len(values)
        if count > N:
            break
        buffer = np.concatenate([buffer, values])
        lines_buffer = np.concatenate([lines_buffer, lines])
        while done + WINDOW_ROWS < N and start + len(buffer) >= done + WINDOW_ROWS + pad:
            end = done + WINDOW_ROWS
            out = window(end, end + pad)
            if out is not None:
                yield out
            done = end
            cut = max(done - pad, 0) - start  # keep pad samples before the next window's first
            buffer, lines_buffer, start = buffer[cut:], lines_buffer[cut:], start + cut
    if count != N:
        raise DeriveError(f"{mf.what}: {mf.path}: the file changed while it was read ({N} samples, then "
                          f"{'more' if count > N else count}): read it again when it is complete")
    if done < N:
        out = window(N, N)
        if out is not None:
            yield out


def read_measurements(path: str | Path, coordinates: list[str], what: str = "identify") -> Measurements:
    """All samples of a CSV (header t, q_<c>..., [qd_<c>..., qdd_<c>...,] tau_<c>...) in memory; one-line
    DeriveError on any problem. :func:`identify_file` streams instead."""
    mf = open_measurements(path, coordinates, what)
    if mf.derives:
        scan_measurements(mf)
        check_sample_count(mf, 0, 1)
    blocks = list(measurement_blocks(mf))
    if not blocks:
        raise mf.error("needs a header line and samples")
    cat = [np.concatenate([getattr(m, k) for m in blocks]) for k in ("t", "q", "qd", "qdd", "tau", "lines")]
    return Measurements(*cat[:5], mf.note() if mf.derives else "", cat[5])


def differentiate(t: np.ndarray, q: np.ndarray, path: Path | str = "", what: str = "identify") -> tuple[np.ndarray, np.ndarray, str]:
    """qd and qdd from q (in memory): zero-phase Butterworth low-pass (forwards and backwards), then central
    differences."""
    from scipy.signal import butter, filtfilt  # deferred: scipy is only needed here

    dt = np.diff(t)
    if len(t) < 3 * (FILTER_ORDER + 1) + 2 or not (dt > 0).all():
        raise DeriveError(f"{what}: {path}: qd and qdd are missing and cannot be derived: need at least "
                          f"{3 * (FILTER_ORDER + 1) + 2} samples at increasing times")
    if np.ptp(dt) > 1e-6 * np.mean(dt):
        raise DeriveError(f"{what}: {path}: qd and qdd are missing and the samples are not evenly spaced in t "
                          "(resample, or give qd_<c> and qdd_<c>)")
    h = float(np.mean(dt))
    b, a = butter(FILTER_ORDER, 2 * FILTER_CUTOFF)
    qf = filtfilt(b, a, q, axis=0)
    qd = np.gradient(qf, h, axis=0)
    qdd = np.gradient(qd, h, axis=0)
    note = (f"qd and qdd derived from q: zero-phase Butterworth low-pass (order {FILTER_ORDER}, cut-off "
            f"{FILTER_CUTOFF / h:.4g} Hz) and central differences at {1 / h:.4g} Hz")
    return qd, qdd, note


@dataclass
class Identification:
    """The identified base parameters and their statistics, and standard parameters reproducing them."""

    base_names: list[str]
    base_values: np.ndarray  # pi_b
    base_prior: np.ndarray  # K pi0: the model's values
    std: np.ndarray  # standard deviation of each pi_b
    condition: float  # of the weighted, stacked base regressor
    sigma: np.ndarray  # residual standard deviation per joint (the weights' inverse)
    residual_rms: np.ndarray  # per joint, of tau - Y_b pi_b
    tau_rms: np.ndarray  # per joint, of tau
    standard: np.ndarray  # pi (all standard parameters) with K pi = pi_b
    physical: bool
    samples: int
    derived: str = ""
    notes: list[str] = field(default_factory=list)

    def report(self, joints: list[str]) -> str:
        lines = [f"{self.samples} samples, {len(self.base_names)} base parameters; condition number of the weighted "
                 f"regressor {self.condition:.4g}" + ("; physically consistent fit (pseudo-inertia LMI)" if self.physical
                                                      else "")]
        if self.derived:
            lines.append(self.derived)
        width = max(len(n) for n in self.base_names)
        lines.append(f"  {'base parameter':<{width}}  {'identified':>14}  {'std dev':>11}  {'rel. %':>8}  {'model':>14}")
        for n, v, s, v0 in zip(self.base_names, self.base_values, self.std, self.base_prior):
            rel = 100 * s / abs(v) if v != 0 else math.inf
            lines.append(f"  {n:<{width}}  {v:>14.6g}  {s:>11.3g}  {rel:>8.3g}  {v0:>14.6g}")
        lines.append("torque residual per joint (rms; rms of the torque; relative):")
        for j, r, tr in zip(joints, self.residual_rms, self.tau_rms):
            lines.append(f"  {j}: {r:.4g} ({tr:.4g}; {r / tr if tr else math.inf:.3g})")
        lines.extend(self.notes)
        return "\n".join(lines)



def regressor_along(reg: Regressor, robot: Robot) -> Callable:
    """Y(q, qd, qdd) for (N, nv) arrays -> (N, nv, n): the symbolic regressor at the model's parameter
    values p (pi carries the inertial ones), mapped over the samples by CasADi.

    The map runs over at most REGRESSOR_BYTES // 8 values at a time (a CasADi map's memory grows
    with its length), the last piece padded to a power of two, so a few maps serve any N.
    """
    s = reg.sym
    Ysx = reg.matrix
    if s.p.numel():
        Ysx = ca.substitute(Ysx, s.p, ca.DM([robot.parameter_defaults[n] for n in s.parameter_names]))
    f = ca.Function("Y", [s.q, s.qd, s.qdd], [ca.densify(Ysx)])
    return function_along(f, robot.nv, Ysx.shape[1])


def closed_regressor_along(regressor: ClosedRegressor, reduced: ReducedChain, robot: Robot) -> Callable:
    """Y_y(y, yd, ydd) for (N, ny) arrays -> (N, ny, n): a closed chain's regressor in its independent
    coordinates (:mod:`derive.symbolic.closed_regressor`) at the model's parameter values, mapped as
    :func:`regressor_along`."""
    f = regressor.function(reduced)
    p = regressor.reg.parameter_vector()
    y, yd, ydd = (ca.SX.sym(k, f.size1_in(i)) for i, k in enumerate(("y", "yd", "ydd")))
    g = ca.Function("Y_y", [y, yd, ydd], [f(y, yd, ydd, p)])
    return function_along(g, len(robot.independent), f.size2_out(0))


def function_along(f: ca.Function, nv: int, n: int) -> Callable:
    """(q, qd, qdd) for (N, nv) arrays -> (N, nv, n) of a casadi Function (q, qd, qdd) -> (nv x n), mapped
    over the samples (see :func:`regressor_along`)."""
    chunk = 1 << max(4, (REGRESSOR_BYTES // 8 // (nv * n)).bit_length() - 1)  # a power of two
    maps: dict[int, tuple] = {}

    def mapped(q, qd, qdd):  # Y at m <= chunk samples: (nv, m, n)
        m = q.shape[0]
        size = min(chunk, 1 << max(m - 1, 0).bit_length())
        if size not in maps:
            # CasADi's buffer interface: inputs and output are numpy memory (a DM's conversion to numpy
            # costs ten times the evaluation); column-major (nv, size) is row-major (size, nv)
            args = [np.zeros(size * nv) for _ in range(3)]
            out = np.zeros(size * n * nv)
            buffer, run = f.map(size).buffer()
            for k, a in enumerate(args):
                buffer.set_arg(k, memoryview(a))
            buffer.set_res(0, memoryview(out))
            maps[size] = (buffer, run, args, out)
        _, run, args, out = maps[size]
        for a, x in zip(args, (q, qd, qdd)):
            a[: m * nv] = x.reshape(-1)
            a[m * nv:] = 0.0
        run()
        return out.reshape(size * n, nv).T.reshape(nv, size, n)[:, :m]

    def Y(q, qd, qdd):
        q, qd, qdd = (np.asarray(x, dtype=float).reshape(-1, nv) for x in (q, qd, qdd))
        out = np.empty((q.shape[0], nv, n))
        for k in range(0, q.shape[0], chunk):
            s_ = slice(k, k + chunk)
            out[s_] = mapped(q[s_], qd[s_], qdd[s_]).transpose(1, 0, 2)
        return out
    return Y


def torques_along(robot: Robot, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray) -> np.ndarray:
    """The robot's inverse dynamics at (N, nv) samples (N, nv): data for round trips and benchmarks."""
    s = make_symbols(robot)
    f = ca.Function("id", [s.q, s.qd, s.qdd], [NewtonEuler(robot, s).inverse_dynamics()]).map(q.shape[0])
    return np.array(f(q.T, qd.T, qdd.T)).T


class RegressionStack:
    """The least-squares problem tau = Y_b pi_b over any number of samples, in bounded memory.

    Per joint j: R_j, the R factor of [Y_b,j | tau_j] (r + 1 square; the rows of joint j at every
    sample so far, QR-updated block by block), so ||Y_b,j x - tau_j|| = ||R_j [x; -1]||; with
    ``full`` also G_j = [Y_j | tau_j]^T [Y_j | tau_j] of the full regressor (n + 1 square) for the
    physically consistent fit. ``source`` names the data in errors.
    """

    def __init__(self, base: BaseParameters, nv: int, full: bool = False, source: str = "", what: str = "identify"):
        self.columns = list(base.columns)
        r, n = len(self.columns), base.K.shape[1]
        self.nv, self.source, self.what = nv, source, what
        self.R = np.zeros((nv, r + 1, r + 1))
        self.G = np.zeros((nv, n + 1, n + 1)) if full else None
        self.samples = 0
        self.tau_squares = np.zeros(nv)
        self.tau_max = 0.0

    def _where(self) -> str:
        return f"{self.what}: {self.source}: " if self.source else f"{self.what}: "

    def add(self, Y: np.ndarray, tau: np.ndarray, lines: np.ndarray | None = None) -> None:
        """Fold in samples: Y (c, nv, n) the full regressor, tau (c, nv); ``lines`` their CSV line numbers."""
        if not len(tau):
            return
        finite = np.isfinite(Y).all(axis=(1, 2))
        if not finite.all():
            k = int(np.argmin(finite))
            at = f"line {int(lines[k])}" if lines is not None else f"sample {self.samples + k}"
            raise DeriveError(f"{self._where()}{at}: the regressor overflows (is not finite) at this sample: its "
                              "values are too large (check the units of q, qd and qdd)")
        Yj = Y.transpose(1, 0, 2)  # (nv, c, n): joint j's rows
        tj = np.ascontiguousarray(tau.T)[:, :, None]
        M = np.concatenate([Yj[:, :, self.columns], tj], axis=2)
        R, G = self.R.copy(), self.G
        with np.errstate(over="ignore", invalid="ignore"):  # overflow is checked below, in one line
            for j in range(self.nv):  # one joint at a time: numpy's stacked QR forms every Q in full
                for k in range(0, len(tau), QR_ROWS):
                    R[j] = np.linalg.qr(np.concatenate([R[j], M[j, k:k + QR_ROWS]]), mode="r")
            if G is not None:
                A = np.concatenate([Yj, tj], axis=2)
                G = G + A.transpose(0, 2, 1) @ A
            squares = self.tau_squares + np.sum(tau ** 2, axis=0)
        if not (np.isfinite(R).all() and np.isfinite(squares).all() and (G is None or np.isfinite(G).all())):
            size = np.maximum(np.abs(Y).max(axis=(1, 2)), np.abs(tau).max(axis=1))
            k = int(np.argmax(size))
            at = f"line {int(lines[k])}" if lines is not None else f"sample {self.samples + k}"
            raise DeriveError(f"{self._where()}the least-squares problem overflows: the values are too large (tau or "
                              f"the regressor reaches {float(size[k]):.3g} at {at}; check the units of the data)")
        self.R, self.G, self.tau_squares = R, G, squares
        self.samples += len(tau)
        self.tau_max = max(self.tau_max, float(np.abs(tau).max()))

    def residual_squares(self, pib: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
        """Per joint, ||Y_b,j pib - tau_j||^2 (divided by weights_j^2 where given)."""
        x = np.append(pib, -1.0)
        out = np.sum((self.R @ x) ** 2, axis=1)
        return out if weights is None else out / weights ** 2

    def factor(self, sigma: np.ndarray | None = None) -> np.ndarray:
        """The R factor (r + 1 square) of every joint's rows stacked, each divided by sigma_j where given."""
        R = self.R if sigma is None else self.R / sigma[:, None, None]
        return np.linalg.qr(R.reshape(-1, R.shape[2]), mode="r")


def identify(Y: Callable, base: BaseParameters, pi0: np.ndarray, data: Measurements,
             physical: bool = False, bodies: int = 0, closed: bool = False) -> Identification:
    """Weighted least squares of tau = Y_b pi_b on the base parameters pi_b = K pi (see the module docstring).

    ``Y(q, qd, qdd)`` is the full regressor, (N, nv, n) for (N, nv) samples (:func:`regressor_along`);
    ``base`` gives K (r x n), the base columns and names; ``pi0`` the model's standard parameters;
    ``bodies`` is the number of 10-parameter blocks at the front of pi (the rest are the actuators'
    armature, viscous, Coulomb: kept >= 0 by ``physical``). A closed chain (``closed``): ``Y`` is its Y_y
    (:func:`closed_regressor_along`), ``base`` its own base parameters and the samples are (y, yd, ydd, tau_y).
    """
    return identify_samples(Y, base, pi0, [data], physical, bodies, derived=data.derived, closed=closed)


def identify_file(Y: Callable, base: BaseParameters, pi0: np.ndarray, mf: MeasurementFile, physical: bool = False,
                  bodies: int = 0, log: Callable[[str], None] | None = None, closed: bool = False) -> Identification:
    """:func:`identify` on the samples of a measurement CSV (:func:`open_measurements`), streamed."""
    check_sample_count(mf, base.rank, len(mf.tau))
    return identify_samples(Y, base, pi0, measurement_blocks(mf, log), physical, bodies,
                            derived=mf.note() if mf.derives else "", source=str(mf.path), what=mf.what, closed=closed)


def identify_samples(Y: Callable, base: BaseParameters, pi0: np.ndarray, blocks: Iterable[Measurements],
                     physical: bool = False, bodies: int = 0, derived: str = "", source: str = "",
                     what: str = "identify", closed: bool = False) -> Identification:
    """:func:`identify` on samples that come in blocks (any number; memory does not grow with them).
    ``closed``: Y is a closed chain's Y_y, whose samples are (y, yd, ydd): a sample where it is not finite
    does not assemble."""
    where = f"{what}: {source}: " if source else f"{what}: "
    stack = None
    for data in blocks:
        nv = data.tau.shape[1]
        if stack is None:
            stack = RegressionStack(base, nv, full=physical, source=source, what=what)
        step = max(1, REGRESSOR_BYTES // 8 // (nv * base.K.shape[1]))
        for k in range(0, len(data.t), step):
            s = slice(k, k + step)
            Ys = np.asarray(Y(data.q[s], data.qd[s], data.qdd[s]), dtype=float)
            bad = ~np.isfinite(Ys).all(axis=(1, 2)) & np.isfinite(data.q[s]).all(axis=1)
            if closed and bad.any():  # finite coordinates, no assembly: name the sample
                k = int(np.argmax(bad))
                at = f"line {int(data.lines[s][k])}" if data.lines is not None else f"sample {stack.samples + k}"
                raise DeriveError(f"{where}{at}: the loops do not close at y = "
                                  f"{np.array2string(data.q[s][k], precision=6, separator=', ')} (no assembly of the "
                                  "mechanism there): the data is not of this closed chain, or its columns are not y")
            stack.add(Ys, data.tau[s], None if data.lines is None else data.lines[s])
    if stack is None or stack.samples == 0:
        raise DeriveError(f"{where}no samples")
    return _solve(stack, base, pi0, physical, bodies, derived, where)


def _solve(stack: RegressionStack, base: BaseParameters, pi0: np.ndarray, physical: bool, bodies: int, derived: str,
           where: str) -> Identification:
    try:
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            return _solve_stack(stack, base, pi0, physical, bodies, derived, where)
    except np.linalg.LinAlgError as exc:  # e.g. values so large that an SVD does not converge
        raise DeriveError(f"{where}the least squares fail ({exc}): the values are too large or too small (check "
                          "the units of the data)") from None


def _solve_stack(stack: RegressionStack, base: BaseParameters, pi0: np.ndarray, physical: bool, bodies: int,
                 derived: str, where: str) -> Identification:
    K = base.K
    N, nv = stack.samples, stack.nv
    r = len(base.columns)
    if N * nv <= r:
        raise DeriveError(f"{where}{N} samples give {N * nv} equations for {r} base parameters: need at least "
                          f"{r // nv + 1} samples; record more")
    R = stack.factor()
    if not np.isfinite(R).all():
        raise DeriveError(f"{where}the least-squares problem overflows: the values are too large (check the units of "
                          "the data)")
    pib_ols = np.linalg.lstsq(R[:r, :r], R[:r, r], rcond=None)[0]
    dof = max(N - r / nv, 1.0)
    sigma = np.sqrt(stack.residual_squares(pib_ols) / dof)
    sigma = np.where(sigma > 1e-12 * max(1.0, stack.tau_max), sigma, 1.0)  # noise-free joints
    Rw = stack.factor(sigma)  # of W: every joint's rows divided by its sigma
    if not np.isfinite(Rw).all():
        raise DeriveError(f"{where}the weighted least-squares problem overflows: the values are too large or too "
                          "small (check the units of the data)")
    sv = np.linalg.svd(Rw[:r, :r], compute_uv=False)
    condition = float(sv[0] / sv[-1]) if sv[-1] > 0 else math.inf
    if not np.isfinite(condition) or condition > 1e12:
        raise DeriveError(f"{where}the data does not excite every base parameter (condition number "
                          f"{condition:.3g}); record a richer motion (`derive excite`)")
    pib = np.linalg.lstsq(Rw[:r, :r], Rw[:r, r], rcond=None)[0]
    s2 = float(np.sum(stack.residual_squares(pib, sigma))) / max(N * nv - r, 1)
    Rinv = np.linalg.inv(Rw[:r, :r])
    std = np.sqrt(np.maximum(s2 * np.sum(Rinv ** 2, axis=1), 0.0))  # diag(s2 (W^T W)^-1), (W^T W)^-1 = R^-1 R^-T
    notes = [dependencies_text(near_dependencies(Rw[:r, :r], base.names))]  # R has W's singular values, columns' norms
    if physical:
        Gw = np.sum(stack.G / (sigma ** 2)[:, None, None], axis=0)  # [W | tw]^T [W | tw] of the full regressor
        n = K.shape[1]
        standard = physical_fit((Gw[:n, :n], Gw[:n, n], float(Gw[n, n])), pi0, bodies)
        if standard is None or not np.isfinite(standard).all():
            raise DeriveError(f"{where}the physically consistent fit failed (IPOPT found no solution): check the "
                              "data's units, or identify without --physical")
        pib = K @ standard
        notes.append("base parameters of the physically consistent standard parameters (K pi)")
    else:
        standard = physical_fit(None, pi0, bodies, K, pib)
        if standard is not None:
            gap = float(np.abs(K @ standard - pib).max() / max(1.0, np.abs(pib).max()))
            notes.append(f"written: the physically consistent standard parameters closest to the model's with "
                         f"K pi = pi_b (to {gap:.1e} relative)")
        else:
            standard = pi0 + np.linalg.pinv(K) @ (pib - K @ pi0)
            notes.append("no physically consistent standard parameters give these base parameters: the written ones "
                         "are the model's moved the least (use --physical for a consistent fit)")
    resid = np.sqrt(stack.residual_squares(pib) / N)
    if not (np.isfinite(pib).all() and np.isfinite(std).all() and np.isfinite(resid).all()):
        raise DeriveError(f"{where}the fit overflows: the values are too large (check the units of the data)")
    return Identification(list(base.names), pib, K @ pi0, std, condition, sigma, resid,
                          np.sqrt(stack.tau_squares / N), standard, physical, N, derived, notes)


def pseudo_inertia_params(L) -> list:
    """Standard parameters [m, hx, hy, hz, Ixx, Ixy, Iyy, Ixz, Iyz, Izz] of the pseudo-inertia J = L L^T,
    J = [[S, h], [h^T, m]] with S = 1/2 tr(I) 1 - I (I about the body origin): I = tr(S) 1 - S."""
    J = L @ L.T
    S, h, m = J[0:3, 0:3], J[0:3, 3], J[3, 3]
    trace = S[0, 0] + S[1, 1] + S[2, 2]
    I = trace * ca.SX.eye(3) - S
    return [m, h[0], h[1], h[2], I[0, 0], I[0, 1], I[1, 1], I[0, 2], I[1, 2], I[2, 2]]


def pseudo_inertia(p: np.ndarray) -> np.ndarray:
    """J of standard parameters p (10): S = 1/2 tr(I) 1 - I."""
    m, h = p[0], np.asarray(p[1:4])
    I = np.array([[p[4], p[5], p[7]], [p[5], p[6], p[8]], [p[7], p[8], p[9]]])
    J = np.zeros((4, 4))
    J[0:3, 0:3] = 0.5 * np.trace(I) * np.eye(3) - I
    J[0:3, 3] = J[3, 0:3] = h
    J[3, 3] = m
    return J



def physical_fit(normal: tuple[np.ndarray, np.ndarray, float] | None, pi0: np.ndarray, bodies: int,
                 K: np.ndarray | None = None, pib: np.ndarray | None = None) -> np.ndarray | None:
    """Physically consistent standard parameters (see the module docstring): the weighted least squares of
    the data, given by its normal equations ``normal`` = (W^T W, W^T tw, tw^T tw) of the full weighted
    regressor W, or (``normal`` None) the ones closest to ``pi0`` with K pi = ``pib`` exactly. None where
    IPOPT finds none.
    """

    n = len(pi0)
    x, params, x0 = [], [], []
    lower = [(i, j) for j in range(4) for i in range(j, 4)]  # the 10 entries of a lower-triangular 4x4
    for b in range(bodies):
        entries = ca.SX.sym(f"L{b}", len(lower))
        Lt = ca.SX(4, 4)
        for k, (i, j) in enumerate(lower):
            Lt[i, j] = entries[k]
        x.append(entries)
        params += pseudo_inertia_params(Lt)
        J0 = pseudo_inertia(pi0[10 * b:10 * b + 10])
        w_, v_ = np.linalg.eigh(J0)
        L0 = np.linalg.cholesky(v_ @ np.diag(np.maximum(w_, 1e-9 * max(1.0, w_.max()))) @ v_.T)
        x0 += [L0[i, j] for i, j in lower]
    rest = ca.SX.sym("a", n - 10 * bodies)  # the actuators' parameters themselves, bounded below by 0
    x.append(rest)
    params += [rest[k] for k in range(n - 10 * bodies)]
    x0 += list(np.maximum(pi0[10 * bodies:], 0.0))
    X = ca.vertcat(*x)
    lbx = [-math.inf] * (10 * bodies) + [0.0] * (n - 10 * bodies)
    pi = ca.vertcat(*params)
    prior = ca.sumsqr(pi - ca.DM(pi0)) / max(float(np.dot(pi0, pi0)), 1e-12)
    problem, bounds = {"x": X}, {}
    if normal is not None:
        WtW, Wtw, twtw = normal
        A, b = ca.DM(WtW), ca.DM(Wtw)
        fit = ca.dot(pi, A @ pi) - 2 * ca.dot(b, pi) + twtw
        problem["f"] = fit / (twtw or 1.0) + 1e-9 * prior
    else:
        problem["f"], problem["g"] = prior, ca.DM(K) @ pi - ca.DM(pib)
        bounds = {"lbg": 0.0, "ubg": 0.0}
    solver = ca.nlpsol("physical", "ipopt", problem,
                       {"ipopt.print_level": 0, "ipopt.sb": "yes", "print_time": False, "ipopt.tol": 1e-14,
                        "ipopt.max_iter": 3000})
    try:
        sol = solver(x0=ca.DM(x0), lbx=ca.DM(lbx), **bounds)
    except RuntimeError:  # an evaluation that is not finite: no solution
        return None
    out = np.array(ca.Function("pi", [X], [pi])(sol["x"])).ravel()
    if not np.isfinite(out).all():
        return None
    out[10 * bodies:] = np.maximum(out[10 * bodies:], 0.0)  # IPOPT honours bounds to its tolerance only
    if normal is None and np.abs(K @ out - pib).max() > 1e-6 * max(1.0, np.abs(pib).max()):
        return None  # no physically consistent standard parameters reproduce pib
    return out


def identified_entry(raw: dict, robot, names: list[str], pi: np.ndarray, source: str) -> dict:
    """The models.yaml entry ``raw`` of ``robot`` with its mass properties and actuators replaced by ``pi``.

    Each body's 10 parameters (about the body origin, body frame) go to the body's link as mass, centre
    of mass and inertia about the centre of mass; links merged into it through fixed joints become
    massless, and so does a body whose identified mass is 0 (the Delta's carriages: the physically
    consistent fit leaves them the 1e-9 inertia of its start, which no body without mass can have). Actuator parameters replace the joints' armature (gear ratio 1, no motor inertia),
    viscous and Coulomb friction. ``names`` are the regressor's parameter names (``m_<link>``, ...,
    ``Ia_<coordinate>``, ``fv_<coordinate>``, ``fc_<coordinate>``).
    """
    import copy

    if "links" not in raw or "joints" not in raw:
        raise DeriveError(f"identify: robot '{robot.name}' is a DH table; identification writes link and joint "
                          "entries: write it with links and joints first")
    entry = copy.deepcopy(raw)
    value = dict(zip(names, (float(v) for v in pi)))
    links = {link["name"]: link for link in entry["links"]}
    fixed_below: dict[str, list[str]] = {}
    body_of = {robot.root: robot.root}
    for j in robot.joints:
        body_of[j.child] = body_of[j.parent] if j.type == "fixed" else j.child
    for link, body in body_of.items():
        fixed_below.setdefault(body, []).append(link)
    for body, members in fixed_below.items():
        if f"m_{body}" not in value:
            continue
        m = value[f"m_{body}"]
        h = np.array([value[f"{k}_{body}"] for k in ("mx", "my", "mz")])
        I = np.array([[value[f"Ixx_{body}"], value[f"Ixy_{body}"], value[f"Ixz_{body}"]],
                      [value[f"Ixy_{body}"], value[f"Iyy_{body}"], value[f"Iyz_{body}"]],
                      [value[f"Ixz_{body}"], value[f"Iyz_{body}"], value[f"Izz_{body}"]]])
        c = h / m if m > 0 else np.zeros(3)
        Ic = I - m * (float(c @ c) * np.eye(3) - np.outer(c, c))
        for link in members:
            fields = links[link]
            for key in ("mass", "com", "inertia", "inertia_rpy"):
                fields.pop(key, None)
            if link == body and m > 0:  # m = 0: a massless body (an inertia without mass is none; a fit's rest)
                fields.update({"mass": m, "com": [float(x) for x in c],
                               "inertia": {"ixx": Ic[0, 0], "ixy": Ic[0, 1], "ixz": Ic[0, 2], "iyy": Ic[1, 1],
                                           "iyz": Ic[1, 2], "izz": Ic[2, 2]}})
    for joint in entry["joints"]:
        coords = [c.name for c in robot.joint_coordinates if c.joint == joint["name"]]
        acts = [{"armature": value.get(f"Ia_{c}", 0.0), "viscous": value.get(f"fv_{c}", 0.0),
                 "coulomb": value.get(f"fc_{c}", 0.0)} for c in coords]
        acts = [{k: v for k, v in a.items() if v != 0.0} for a in acts]
        joint.pop("actuator", None)
        if any(acts):
            joint["actuator"] = acts[0] if len(acts) == 1 else acts
    entry["description"] = f"{robot.name} with identified dynamic parameters"
    entry["source"] = source
    return entry
