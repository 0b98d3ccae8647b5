"""`derive identify` and `derive excite` on the inputs that used to hurt (issue 24, items 3, 7, 9, 13, 16, 23).

- The measurement CSV: duplicate, missing, unnamed or non-numeric columns, values that are not
  finite or not numbers, ragged lines, text that is not UTF-8, too few rows after the edge trim,
  values that overflow: each one line naming the file, the line and the column. Excel's
  byte-order mark, CRLF line ends and a quoted header are read.
- The CSV is streamed: the result equals the in-memory estimator (the issue's reference: OLS,
  sigma per joint, weighted least squares on the stacked regressor, filtfilt over the whole file)
  to rounding, whatever the block and window sizes; peak memory does not grow with the file;
  long work shows progress; absurd sizes are refused in one line.
- Input guards: a FIFO or /dev/zero as the CSV is refused at once; outputs are written
  atomically (a failure leaves the old file byte-identical and names it, no temporary left).
- excite's numeric options are checked; a nearly degenerate model is refused naming the robot,
  the parameters, the joint and a way forward.
"""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
import yaml

from derive.bench.identification import perturbed
from derive.cli import main
from derive.description.model import load_models, parse_models
from derive.solvers import identify as ident
from derive.solvers.identify import (Measurements, identify, identify_file, open_measurements, regressor_along,
                                     scan_measurements, torques_along)
from derive.symbolic.base_parameters import base_parameters
from derive.symbolic.dynamics import NewtonEuler
from derive.symbolic.regressor import Regressor
from derive.symbolic.symbols import make_symbols

ROOT = Path(__file__).resolve().parents[1]
DT = 0.002


def motion(nv: int, samples: int, seed: int = 1):
    """A sum of sines per coordinate, sampled every DT: (t, q, qd, qdd)."""
    rng = np.random.default_rng(seed)
    t = np.arange(samples) * DT
    q, qd, qdd = (np.zeros((samples, nv)) for _ in range(3))
    for j in range(nv):
        for h in range(1, 4):
            a, ph, w = rng.uniform(0.2, 0.6) / h, rng.uniform(0, 6), 2 * np.pi * h / 4.0 * rng.uniform(0.7, 1.3)
            q[:, j] += a * np.sin(w * t + ph)
            qd[:, j] += a * w * np.cos(w * t + ph)
            qdd[:, j] -= a * w * w * np.sin(w * t + ph)
    return t, q, qd, qdd


def csv_text(names, t, q, qd, qdd, tau, rates: bool = True) -> str:
    blocks = [("q", q)] + ([("qd", qd), ("qdd", qdd)] if rates else []) + [("tau", tau)]
    header = ",".join(["t"] + [f"{k}_{c}" for k, _ in blocks for c in names])
    rows = np.column_stack([t] + [b for _, b in blocks])
    return header + "\n" + "\n".join(",".join(repr(float(x)) for x in row) for row in rows) + "\n"


class CartPole:
    """The shipped cart-pole, its regressor and base parameters, and data from a perturbed copy."""

    def __init__(self):
        self.nominal = load_models()["cartpole"]
        self.true = perturbed(self.nominal, armature=0.05, viscous=0.3, coulomb=0.8)
        self.reg = Regressor(NewtonEuler(self.nominal, make_symbols(self.nominal)))
        self.bp = base_parameters(self.nominal, regressor=self.reg)
        self.pi0 = np.asarray(self.reg.values(), dtype=float)
        self.Y = regressor_along(self.reg, self.nominal)
        true_reg = Regressor(NewtonEuler(self.true, make_symbols(self.true)))
        self.pib_true = self.bp.K @ np.asarray(true_reg.values())
        self.names = [c.name for c in self.nominal.coordinates]
        self.t, self.q, self.qd, self.qdd = motion(2, 400)
        self.tau = torques_along(self.true, self.q, self.qd, self.qdd)
        self.text = csv_text(self.names, self.t, self.q, self.qd, self.qdd, self.tau)

    def lines(self) -> list[str]:
        return self.text.splitlines()


@pytest.fixture(scope="module")
def cp():
    return CartPole()


@pytest.fixture(scope="module")
def models(tmp_path_factory) -> Path:
    """A models file of the shipped cart-pole alone (reading it is 6 times faster than all shipped robots)."""
    shipped = yaml.safe_load((ROOT / "models.yaml").read_text())
    path = tmp_path_factory.mktemp("models") / "cartpole.yaml"
    path.write_text(yaml.safe_dump({"robots": {"cartpole": shipped["robots"]["cartpole"]}}, sort_keys=False))
    return path


@pytest.fixture(autouse=True)
def derived_once(cp, monkeypatch):
    """The cart-pole's regressor and base parameters derived once for the module (they depend on the model only)."""
    import derive.cli.identify as command

    derive = command.regressor_of
    monkeypatch.setattr(command, "regressor_of",
                        lambda robot: (cp.reg, cp.bp) if robot.name == "cartpole" else derive(robot))


def run(argv, capsys, models: Path | None = None) -> tuple[int, str, list[str]]:
    capsys.readouterr()
    status = main((["--models", str(models)] if models and "--models" not in argv else []) + argv)
    captured = capsys.readouterr()
    return status, captured.out, captured.err.strip().splitlines()


def one_line(err: list[str], *fragments: str) -> str:
    assert len(err) == 1 and err[0].startswith("derive: error: "), err
    for fragment in fragments:
        assert fragment in err[0], (fragment, err[0])
    return err[0]


def identified(out: str) -> dict[str, float]:
    """The identified values of the report: {base parameter: value}."""
    rows = [line.split() for line in out.splitlines() if line.startswith("  ") and len(line.split()) == 5]
    return {r[0]: float(r[1]) for r in rows if r[0] != "base"}


# --------------------------------------------------------------------------- item 7: columns and values


def test_duplicate_column_is_refused_not_the_last_one_taken(cp, tmp_path, capsys, models):
    """The issue's case: a second tau_s (here twice the first) used to win silently (MR_cart 2.21 for 1.1)."""
    lines = cp.lines()
    k = lines[0].split(",").index("tau_s")
    text = "\n".join([lines[0] + ",tau_s"] + [r + "," + repr(2 * float(r.split(",")[k])) for r in lines[1:]]) + "\n"
    data = tmp_path / "dup.csv"
    data.write_text(text)
    status, _, err = run(["identify", "cartpole", str(data), "--out", str(tmp_path / "o.yaml")], capsys, models)
    assert status == 2
    one_line(err, str(data), "line 1", "column tau_s appears twice in the header (columns 8 and 10)")
    assert sorted(os.listdir(tmp_path)) == ["dup.csv"]


def _edit(lines: list[str], line: int, column: int, value: str) -> list[str]:
    """``lines`` with the value at (file line ``line``, 0-based ``column``) replaced."""
    out = list(lines)
    fields = out[line - 1].split(",")
    fields[column] = value
    out[line - 1] = ",".join(fields)
    return out


# (id, edit of the CSV lines, fragments of the error)
# columns: t q_s q_theta qd_s qd_theta qdd_s qdd_theta tau_s tau_theta
VALUE_CASES = [
    ("not-a-number", lambda L: _edit(L, 7, 3, "abc"), ["line 7, column qd_s: 'abc' is not a number"]),
    ("nan", lambda L: _edit(L, 9, 4, "nan"), ["line 9, column qd_theta: nan is not a finite number"]),
    ("inf", lambda L: _edit(L, 9, 4, "-inf"), ["line 9, column qd_theta: -inf is not a finite number"]),
    ("overflowing-literal", lambda L: _edit(L, 12, 1, "1e999"), ["line 12, column q_s: 1e999 is not a finite number"]),
    ("empty-field", lambda L: _edit(L, 5, 2, ""), ["line 5, column q_theta: no value"]),
    ("python-underscores", lambda L: _edit(L, 5, 1, "1_0"), ["line 5, column q_s: '1_0' is not a number"]),
    ("non-ascii-digits", lambda L: _edit(L, 5, 1, "\u0661"), ["line 5, column q_s: '\u0661' is not a number"]),
    ("hex", lambda L: _edit(L, 5, 1, "0x10"), ["line 5, column q_s: '0x10' is not a number"]),
    ("short-line", lambda L: L[:10] + [",".join(L[10].split(",")[:-1])] + L[11:],
     ["line 11: 8 values, but the header has 9 columns"]),
    ("long-line", lambda L: L[:10] + [L[10] + ",1"] + L[11:], ["line 11: 10 values, but the header has 9 columns"]),
    ("late-bad-value", lambda L: _edit(L, 400, 8, "x"), ["line 400, column tau_theta: 'x' is not a number"]),
    ("missing-column", lambda L: [",".join(x.split(",")[:-1]) for x in L],
     ["missing column tau_theta (header: t, q_<c>, [qd_<c>, qdd_<c>,] tau_<c> for c in s, theta)"]),
    ("missing-t", lambda L: [",".join(x.split(",")[1:]) for x in L], ["missing column t (time, s)"]),
    ("unnamed-column", lambda L: [L[0] + ","] + [x + ",1" for x in L[1:]],
     ["line 1: column 10 of the header has no name"]),
    ("semicolons", lambda L: [x.replace(",", ";") for x in L],
     ["line 1: the columns must be separated by commas (this header has semicolons)"]),
    ("header-only", lambda L: L[:1], ["needs a header line and samples"]),
    ("empty", lambda L: [], ["needs a header line and samples"]),
    ("blank-lines-only", lambda L: ["", "  ", ""], ["needs a header line and samples"]),
]


@pytest.mark.parametrize("edit, fragments", [c[1:] for c in VALUE_CASES], ids=[c[0] for c in VALUE_CASES])
def test_bad_columns_and_values_are_one_line_naming_line_and_column(edit, fragments, cp, tmp_path, capsys, models):
    data = tmp_path / "bad.csv"
    data.write_text("\n".join(edit(cp.lines())) + "\n")
    status, out, err = run(["identify", "cartpole", str(data), "--out", str(tmp_path / "o.yaml")], capsys, models)
    assert status == 2 and out == ""
    one_line(err, f"identify: {data}: ", *fragments)
    assert sorted(os.listdir(tmp_path)) == ["bad.csv"]


def test_text_that_is_not_utf8_names_the_line(cp, tmp_path, capsys, models):
    data = tmp_path / "latin1.csv"
    data.write_bytes(("\n".join(cp.lines()[:6]) + "\n").encode() + b"0.1,\xe9\n")
    status, _, err = run(["identify", "cartpole", str(data), "--out", str(tmp_path / "o.yaml")], capsys, models)
    assert status == 2
    one_line(err, str(data), "line 7: not UTF-8 text")


# --------------------------------------------------------------------------- item 16


def test_bom_crlf_and_a_quoted_header_are_read_like_the_plain_file(cp, tmp_path, capsys, models):
    """Excel writes a UTF-8 byte-order mark (and CRLF, and may quote names): "missing column t" no more."""
    lines = cp.lines()
    excel = "\r\n".join([",".join(f'"{h}"' for h in lines[0].split(","))] + lines[1:]) + "\r\n"
    (tmp_path / "plain.csv").write_text(cp.text)
    (tmp_path / "excel.csv").write_bytes(b"\xef\xbb\xbf" + excel.encode())
    values = {}
    for name in ("plain", "excel"):
        status, out, err = run(["identify", "cartpole", str(tmp_path / f"{name}.csv"), "--out",
                                str(tmp_path / f"{name}.yaml")], capsys, models)
        assert status == 0 and err == [], err
        values[name] = identified(out)
    assert values["excel"] == values["plain"]
    got = np.array([values["excel"][n] for n in cp.bp.names])
    assert np.abs(got - cp.pib_true).max() <= 1e-5 * np.abs(cp.pib_true).max()  # the report's 6 digits
    assert sorted(os.listdir(tmp_path)) == ["excel.csv", "excel.yaml", "plain.csv", "plain.yaml"]


def q_only(cp, rows: int) -> str:
    lines = csv_text(cp.names, cp.t[:rows], cp.q[:rows], None, None, cp.tau[:rows], rates=False)
    return lines


def test_too_few_rows_after_the_edge_trim_is_one_line_with_the_count_needed(cp, tmp_path, capsys, models):
    """20 rows of q only: the trim of 10 samples at either end used to leave none (a CasADi assertion)."""
    data = tmp_path / "q20.csv"
    data.write_text(q_only(cp, 20))
    status, _, err = run(["identify", "cartpole", str(data), "--out", str(tmp_path / "o.yaml")], capsys, models)
    assert status == 2
    line = one_line(err, str(data), "too few rows after trimming 10 edge samples at either end", "20 rows leave 0 "
                    "samples, 8 base parameters need at least 5: need at least 25 rows")
    assert "qd_<c> and qdd_<c>" in line
    data.write_text(q_only(cp, 25))  # the count is exact: 25 rows pass this check
    status, _, err = run(["identify", "cartpole", str(data), "--out", str(tmp_path / "o.yaml")], capsys, models)
    assert len(err) != 1 or "too few rows" not in err[0], err
    data.write_text(q_only(cp, 12))  # fewer than the filter needs at all
    status, _, err = run(["identify", "cartpole", str(data), "--out", str(tmp_path / "o.yaml")], capsys, models)
    assert status == 2
    one_line(err, "12 samples; qd and qdd are missing and cannot be derived from q: need at least 17 samples")
    assert sorted(os.listdir(tmp_path)) == ["q20.csv"]


@pytest.mark.parametrize("edit, fragment", [
    (lambda t: np.concatenate([t[:40], t[39:-1]]), "line 42, column t: the times t must increase from one sample"),
    (lambda t: t + 1e-4 * (np.arange(len(t)) > 200),
     "the samples are not evenly spaced in t (steps 0.002 to 0.0021 s)"),
], ids=["repeated-time", "uneven-steps"])
def test_rates_need_evenly_increasing_times_to_be_derived(edit, fragment, cp, tmp_path, capsys, models):
    data = tmp_path / "q.csv"
    data.write_text(csv_text(cp.names, edit(cp.t), cp.q, None, None, cp.tau, rates=False))
    status, _, err = run(["identify", "cartpole", str(data), "--out", str(tmp_path / "o.yaml")], capsys, models)
    assert status == 2
    one_line(err, str(data), fragment)


def scaled(cp, columns: list[int], factor: float) -> str:
    lines = cp.lines()
    return "\n".join([lines[0]] + [",".join(repr(float(x) * factor) if k in columns else x
                                            for k, x in enumerate(r.split(","))) for r in lines[1:]]) + "\n"


@pytest.mark.parametrize("columns, factor, fragments", [
    (list(range(9)), 1e300, ["line 2: the regressor overflows (is not finite) at this sample"]),
    ([1, 2, 3, 4, 5, 6], 1e200, ["line 2: the regressor overflows"]),
    ([7, 8], 1e300, ["the least-squares problem overflows", "at line 2; check the units of the data"]),
    (list(range(9)), 1e150, ["the data does not excite every base parameter (condition number"]),
    ([7, 8], 1e100, ["do not make a valid model", "larger than", "rerun with --physical"]),
], ids=["all-1e300", "q-1e200", "tau-1e300", "all-1e150", "tau-1e100"])
def test_huge_values_are_one_line_not_an_svd_failure(columns, factor, fragments, cp, tmp_path, capsys, models):
    """Values x1e300 used to end in "SVD did not converge" (exit 3)."""
    data = tmp_path / "huge.csv"
    data.write_text(scaled(cp, columns, factor))
    status, _, err = run(["identify", "cartpole", str(data), "--out", str(tmp_path / "o.yaml")], capsys, models)
    assert status == 2
    one_line(err, str(data), *fragments)
    assert sorted(os.listdir(tmp_path)) == ["huge.csv"]


# --------------------------------------------------------------------------- item 9: streaming


def reference_identify(cp, t, q, qd, qdd, tau) -> tuple[np.ndarray, np.ndarray, float]:
    """The estimator as it was before streaming (in memory): OLS, sigma per joint, weighted least squares
    on the stacked base regressor. Returns (pi_b, std, condition)."""
    full = cp.Y(q, qd, qdd).reshape(-1, cp.bp.K.shape[1])
    tau = tau.reshape(-1)
    Yb = full[:, list(cp.bp.columns)]
    r = Yb.shape[1]
    res = (tau - Yb @ np.linalg.lstsq(Yb, tau, rcond=None)[0]).reshape(-1, 2)
    sigma = np.sqrt(np.sum(res ** 2, axis=0) / max(res.shape[0] - r / 2, 1.0))
    sigma = np.where(sigma > 1e-12 * max(1.0, float(np.abs(tau).max())), sigma, 1.0)
    w = np.tile(1.0 / sigma, res.shape[0])
    W, tw = Yb * w[:, None], tau * w
    sv = np.linalg.svd(W, compute_uv=False)
    pib = np.linalg.lstsq(W, tw, rcond=None)[0]
    s2 = float((tw - W @ pib) @ (tw - W @ pib)) / (len(tw) - r)
    return pib, np.sqrt(np.diag(s2 * np.linalg.inv(W.T @ W))), float(sv[0] / sv[-1])


@pytest.fixture(scope="module")
def long_motion(cp):
    """3000 samples with 1 % torque noise (so that sigma and the std devs mean something)."""
    t, q, qd, qdd = motion(2, 3000, seed=5)
    tau = torques_along(cp.true, q, qd, qdd)
    tau = tau + np.random.default_rng(2).normal(size=tau.shape) * 0.01 * np.sqrt(np.mean(tau ** 2, axis=0))
    return t, q, qd, qdd, tau


@pytest.mark.parametrize("rates", [True, False], ids=["q-qd-qdd", "q-only"])
def test_streamed_identification_equals_the_in_memory_estimator(rates, cp, long_motion, tmp_path, monkeypatch):
    """Small blocks and filter windows (many of each) give the in-memory result to rounding."""
    from scipy.signal import butter, filtfilt

    t, q, qd, qdd, tau = long_motion
    data = tmp_path / "long.csv"
    data.write_text(csv_text(cp.names, t, q, qd, qdd, tau, rates=rates))
    if not rates:  # the reference: the whole file filtered at once, then the edge trim
        b, a = butter(ident.FILTER_ORDER, 2 * ident.FILTER_CUTOFF)
        h = float(np.mean(np.diff(t)))
        qd = np.gradient(filtfilt(b, a, q, axis=0), h, axis=0)
        qdd = np.gradient(qd, h, axis=0)
        trim = max(10, len(t) // 50)
        t, q, qd, qdd, tau = (x[trim:-trim] for x in (t, q, qd, qdd, tau))
    pib, std, cond = reference_identify(cp, t, q, qd, qdd, tau)
    monkeypatch.setattr(ident, "READ_BYTES", 4096)  # ~ 40 samples a block
    monkeypatch.setattr(ident, "WINDOW_ROWS", 500)  # 6 filter windows
    monkeypatch.setattr(ident, "QR_ROWS", 64)
    mf = open_measurements(data, cp.names)
    if mf.derives:
        scan_measurements(mf)
    got = identify_file(cp.Y, cp.bp, cp.pi0, mf, bodies=len(cp.reg.bodies))
    assert got.samples == len(t)
    assert np.abs(got.base_values - pib).max() <= 1e-11 * np.abs(pib).max()
    assert np.abs(got.std - std).max() <= 1e-8 * np.abs(std).max()
    assert got.condition == pytest.approx(cond, rel=1e-9)
    # and in memory, through the same stack, the same numbers
    direct = identify(cp.Y, cp.bp, cp.pi0, Measurements(t, q, qd, qdd, tau), bodies=len(cp.reg.bodies))
    assert np.abs(direct.base_values - got.base_values).max() <= 1e-11 * np.abs(pib).max()


def test_progress_is_shown_on_long_work(cp, long_motion, tmp_path, monkeypatch, capsys, models):
    t, q, qd, qdd, tau = long_motion
    data = tmp_path / "long.csv"
    data.write_text(csv_text(cp.names, t, q, qd, qdd, tau, rates=False))
    monkeypatch.setattr(ident, "PROGRESS_SECONDS", 0.0)
    monkeypatch.setattr(ident, "READ_BYTES", 32768)
    status, _, err = run(["identify", "cartpole", str(data), "--out", str(tmp_path / "o.yaml")], capsys, models)
    assert status == 0, err
    checking = [x for x in err if x.startswith(f"identify: {data}: pass 1 of 2, checking: ")]
    fitting = [x for x in err if x.startswith(f"identify: {data}: pass 2 of 2, fitting: ")]
    assert len(checking) >= 3 and len(fitting) >= 3 and len(checking) + len(fitting) == len(err), err
    assert fitting[-1].endswith(f"fitting: {len(t):,} samples read (100 % of the file)"), fitting[-1]


def test_absurd_sizes_are_refused_in_one_line(cp, tmp_path, monkeypatch, capsys, models):
    out = tmp_path / "o.yaml"
    sparse = tmp_path / "sparse.csv"  # 40 GiB that take no disk: refused before a byte is read
    with open(sparse, "wb") as f:
        f.write(cp.lines()[0].encode() + b"\n")
        f.truncate(40 * 2**30)
    status, _, err = run(["identify", "cartpole", str(sparse), "--out", str(out)], capsys, models)
    assert status == 2
    one_line(err, str(sparse), "the data is 40 GiB, more than the 32 GiB identify reads: split it or resample it")
    sparse.unlink()
    long_line = tmp_path / "line.csv"
    long_line.write_text(cp.lines()[0] + "\n" + "1" * (2**20 + 10) + "\n")
    status, _, err = run(["identify", "cartpole", str(long_line), "--out", str(out)], capsys, models)
    assert status == 2
    one_line(err, str(long_line), "line 2 is longer than 1 MiB")
    rows = tmp_path / "rows.csv"
    rows.write_text(cp.text)
    monkeypatch.setattr(ident, "MAX_CSV_ROWS", 100)
    status, _, err = run(["identify", "cartpole", str(rows), "--out", str(out)], capsys, models)
    assert status == 2
    one_line(err, str(rows), "more than 100 samples: split the file or resample it")
    assert sorted(os.listdir(tmp_path)) == ["line.csv", "rows.csv"]


MEMORY_PROBE = textwrap.dedent("""
    import resource, sys
    from derive.cli import main
    from derive.solvers import identify
    identify.READ_BYTES, identify.WINDOW_ROWS = 2**17, 4096  # blocks and windows the small files fill
    def peak():
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    folder, models = sys.argv[1:]
    def identify_(name):
        argv = ["--models", models, "identify", "cartpole", f"{folder}/{name}.csv", "--out", f"{folder}/{name}.yaml"]
        assert main(argv) == 0
    identify_("small_q")  # everything imported, derived and mapped once
    before = peak()
    identify_("large_q")
    print(before, peak())
""")


def test_peak_memory_does_not_grow_with_the_csv(cp, tmp_path, models):
    """60 000 samples of q and tau (6 MB; qd and qdd filtered and differentiated, the longest path) after
    6000: the peak grows by less than 2 bytes per byte of CSV (a few MB of the allocator's, whatever the
    length; it used to grow by 46 bytes per byte, 21 with qd and qdd given), measured in a fresh process."""
    t, q, qd, qdd = motion(2, 60_000, seed=3)
    tau = torques_along(cp.true, q, qd, qdd)
    header = ",".join(["t"] + [f"{b}_{c}" for b in ("q", "tau") for c in cp.names])
    for name, rows in (("small_q", 6000), ("large_q", None)):
        np.savetxt(tmp_path / f"{name}.csv", np.column_stack([t, q, tau])[:rows], delimiter=",", header=header,
                   comments="", fmt="%.17g")
    size = (tmp_path / "large_q.csv").stat().st_size
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    probe = subprocess.run([sys.executable, "-c", MEMORY_PROBE, str(tmp_path), str(models)], capture_output=True,
                           text=True, env=env, cwd=tmp_path, timeout=300)
    assert probe.returncode == 0, probe.stderr
    before, after = (int(x) for x in probe.stdout.split()[-2:])
    assert size > 5 * 10**6
    assert after - before < 2 * size, (before, after, size)


# --------------------------------------------------------------------------- item 3: input guards, atomic output


class Alarm:
    """Fail (instead of hanging the suite) if the block takes longer than ``seconds``."""

    def __init__(self, seconds: int):
        self.seconds = seconds

    def __enter__(self):
        def fire(signum, frame):
            raise TimeoutError("hung")
        self.previous = signal.signal(signal.SIGALRM, fire)
        signal.alarm(self.seconds)

    def __exit__(self, *exc):
        signal.alarm(0)
        signal.signal(signal.SIGALRM, self.previous)


def test_a_fifo_or_dev_zero_as_the_csv_is_refused_at_once(tmp_path, capsys, models):
    fifo = tmp_path / "data.csv"
    os.mkfifo(fifo)
    for path in (fifo, Path("/dev/zero"), tmp_path):
        with Alarm(20):
            status, _, err = run(["identify", "cartpole", str(path), "--out", str(tmp_path / "o.yaml")], capsys, models)
        assert status == 2
        one_line(err, f"identify: {path}: cannot read the data: not a regular file")
    status, _, err = run(["identify", "cartpole", str(tmp_path / "nosuch.csv"), "--out", str(tmp_path / "o.yaml")],
                         capsys, models)
    assert status == 2
    one_line(err, f"identify: {tmp_path / 'nosuch.csv'}: no such file")
    assert sorted(os.listdir(tmp_path)) == ["data.csv"]


def _disk_full(monkeypatch):
    import derive.filesystem

    def fsync(fd):
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(derive.filesystem.os, "fsync", fsync)


def test_identify_output_is_atomic_and_a_failure_names_it(cp, tmp_path, monkeypatch, capsys, models):
    data = tmp_path / "data.csv"
    data.write_text(cp.text)
    out = tmp_path / "models" / "cp.yaml"
    status, stdout, err = run(["identify", "cartpole", str(data), "--out", str(out), "--name", "cp_id"], capsys, models)
    assert status == 0 and err == [] and f"wrote {out} (robot 'cp_id')" in stdout
    written = out.read_bytes()
    robot = parse_models(written.decode(), str(out))["cp_id"]
    pib = cp.bp.K @ np.asarray(Regressor(NewtonEuler(robot, make_symbols(robot))).values())
    assert np.abs(pib - cp.pib_true).max() <= 1e-6 * np.abs(cp.pib_true).max()
    _disk_full(monkeypatch)
    status, _, err = run(["identify", "cartpole", str(data), "--out", str(out), "--name", "cp_id", "--physical"],
                         capsys, models)
    assert status == 2
    one_line(err, f"{out}: cannot write models file (No space left on device); it is left as it was")
    assert out.read_bytes() == written
    assert sorted(os.listdir(out.parent)) == ["cp.yaml"]  # no temporary left beside it


@pytest.mark.parametrize("case", ["out-is-data", "out-is-models", "out-is-folder", "out-below-a-file", "bad-name",
                                  "empty-out", "empty-data"])
def test_identify_refuses_outputs_that_would_lose_data(case, cp, tmp_path, capsys):
    data = tmp_path / "data.csv"
    data.write_text(cp.text)
    models = tmp_path / "models.yaml"
    models.write_bytes((ROOT / "models.yaml").read_bytes())
    argv, fragments = {
        "out-is-data": (["--out", str(data)], [f"--out {data} is the data file"]),
        "out-is-models": (["--out", str(models)], [f"--out {models} is the models file {models} that holds cartpole",
                                                   "other robots would be lost"]),
        "out-is-folder": (["--out", str(tmp_path)], [f"identify: {tmp_path}: is a folder"]),
        "out-below-a-file": (["--out", str(data / "x.yaml")], [f"{data} is not a folder"]),
        "bad-name": (["--out", str(tmp_path / "o.yaml"), "--name", "my robot"], ["'my robot' is not a C identifier"]),
        "empty-out": (["--out", ""], ["argument --out: empty path"]),
        "empty-data": ([], ["argument DATA.csv: empty path"]),
    }[case]
    target = "" if case == "empty-data" else str(data)
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    status, _, err = run(["--models", str(models), "identify", "cartpole", target, *argv], capsys)
    assert status == 2
    one_line(err, *fragments)
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before


# --------------------------------------------------------------------------- excite: options and outputs


@pytest.mark.parametrize("argv, fragment", [
    (["--seed", "-1"], "--seed must be 0 to 2^63 - 1, got -1"),
    (["--seed", str(2**64)], f"--seed must be 0 to 2^63 - 1, got {2**64}"),
    (["--iterations", "0"], "--iterations must be 1 to 100,000, got 0"),
    (["--iterations", "-3"], "--iterations must be 1 to 100,000, got -3"),
    (["--iterations", "1000000000"], "--iterations must be 1 to 100,000, got 1000000000"),
    (["--period", "nan"], "--period must be 0.01 to 3600 s, got nan"),
    (["--period", "inf"], "--period must be 0.01 to 3600 s, got inf"),
    (["--period", "-1"], "--period must be 0.01 to 3600 s, got -1"),
    (["--period", "1e300"], "--period must be 0.01 to 3600 s, got 1e+300"),
    (["--harmonics", "0"], "--harmonics must be 1 to 20, got 0"),
    (["--samples", "100000"], "--samples must be 10 to 2000, got 100000"),
    (["--samples", "1e9"], "argument --samples: invalid int value: '1e9'"),
    (["--out", ""], "argument --out: empty path"),
], ids=lambda x: " ".join(x) if isinstance(x, list) else None)
def test_excite_options_out_of_range_are_one_line(argv, fragment, tmp_path, capsys):
    status, out, err = run(["excite", "pendulum", "--out", str(tmp_path / "exc"), *argv], capsys)
    assert status == 2 and out == ""
    one_line(err, "excite", fragment)
    assert os.listdir(tmp_path) == []


def test_excite_writes_both_files_atomically(tmp_path, monkeypatch, capsys):
    out = tmp_path / "exc"
    argv = ["excite", "pendulum", "--samples", "10", "--harmonics", "1", "--iterations", "3", "--out", str(out)]
    status, stdout, err = run(argv, capsys)
    assert status in (0, 1), err
    assert f"wrote {out / 'excitation.csv'} and {out / 'excitation.png'}" in stdout
    csv, png = (out / "excitation.csv").read_bytes(), (out / "excitation.png").read_bytes()
    assert csv.startswith(b"t,q_phi,qd_phi,qdd_phi,tau_phi\n") and len(csv.splitlines()) == 11
    assert png.startswith(b"\x89PNG\r\n\x1a\n")
    _disk_full(monkeypatch)
    status, _, err = run(argv + ["--seed", "3"], capsys)
    assert status == 2
    # the work's progress lines, then the one error line
    assert err[0] == "deriving the base regressor of pendulum ..."
    assert err[1].startswith("excite pendulum: 1 coordinates")
    one_line(err[2:], f"{out / 'excitation.csv'}: cannot write excitation CSV (No space left on device); it is left "
             "as it was")
    assert (out / "excitation.csv").read_bytes() == csv and (out / "excitation.png").read_bytes() == png
    assert sorted(os.listdir(out)) == ["excitation.csv", "excitation.png"]
    status, _, err = run(argv[:-2] + ["--out", str(out / "excitation.png")], capsys)
    assert status == 2
    one_line(err, f"--out {out / 'excitation.png'} is a file; it names the folder")
    assert sorted(os.listdir(out)) == ["excitation.csv", "excitation.png"]


# --------------------------------------------------------------------------- item 23: nearly degenerate models


def degenerate_models(tilt: float) -> str:
    """Three revolute joints; the second's axis tilted ``tilt`` rad from the first's (z)."""
    links = [{"name": "base"}] + [{"name": f"l{i}", "mass": 1.0, "com": [0.1, 0.05, 0.02],
                                   "inertia": [0.01, 0.02, 0.03]} for i in (1, 2, 3)]
    joints = [
        {"name": "j1", "type": "revolute", "parent": "base", "child": "l1", "axis": [0, 0, 1]},
        {"name": "j2", "type": "revolute", "parent": "l1", "child": "l2", "axis": [0, math.sin(tilt), math.cos(tilt)],
         "origin": {"xyz": [0.3, 0, 0]}},
        {"name": "j3", "type": "revolute", "parent": "l2", "child": "l3", "axis": [0, 0, 1],
         "origin": {"xyz": [0.2, 0, 0]}},
    ]
    return yaml.safe_dump({"robots": {"deg": {"links": links, "joints": joints}}})


@pytest.mark.parametrize("tilt", [1e-9, 1e-5])
def test_nearly_degenerate_model_keeps_the_exact_rank_and_names_the_near_dependencies(tilt, tmp_path, capsys):
    """The rank tolerance (1e-4 of the regressor's scale): a tilt of 1e-9 or 1e-5 rad adds no base parameter;
    the columns it makes nearly, not exactly, dependent are named in one warning line."""
    models = tmp_path / "deg.yaml"
    models.write_text(degenerate_models(0.0))  # exactly parallel
    status, exact, err = run(["--models", str(models), "base-parameters", "deg"], capsys)
    assert status == 0 and err == [] and exact.startswith("deg: 15 base parameters of ")
    models.write_text(degenerate_models(tilt))
    status, out, err = run(["--models", str(models), "base-parameters", "deg"], capsys)
    assert status == 0 and out.startswith("deg: 15 base parameters of ") and len(err) == 1
    for fragment in ("warning: robot 'deg': near-dependencies", "rank tolerance 0.0001", "Ixz_l3", "Iyz_l2",
                     "nearly, not exactly, degenerate geometry"):
        assert fragment in err[0], (fragment, err[0])
