"""`derive generate`: models.yaml -> generated/, deterministic and all-or-nothing.

- Only the robots asked for are written; other robots in the folder stay (``prune`` removes
  those no longer in the models file). The new tree is built in a temporary folder beside the
  target, which then replaces the target in one rename: a failure part-way leaves the folder
  as it was.
- Unchanged robots are not rederived: generated/MANIFEST.json records, per robot,
  a content hash of the model and of the generator (description, symbolic, codegen, templates
  and pinned tool versions) and the sha256 of every file; if both match and the
  files are intact, they are carried over.
- ``check`` compares those hashes and files without writing anything.
- Firmware figures (text and stack of each C function cross-compiled for microcontrollers, see
  ``derive firmware-check``) are measured, not derived: ``derive firmware-check --record`` keeps
  them in ``firmware.json`` beside the models file, each against the sha256 of the function's
  translation unit. Generation copies a robot's figures into its manifest.json (``firmware``) for
  the functions whose translation unit still has that hash, and leaves out the others, so a
  figure never outlives its source and a fresh generation reproduces the same files.
"""

from __future__ import annotations

import ctypes
import errno
import hashlib
import json
import math
import os
import re
import shutil
import tempfile
import time
from importlib.metadata import version
from pathlib import Path
from typing import Callable, Iterable

import casadi as ca
import numpy as np

from derive.codegen.backends.c import translation_unit_hash
from derive.codegen.catalogue import function_specs, template_functions
from derive.codegen.render import render_robot
from derive.errors import DeriveError
from derive.description.model import default_models_path
from derive.description.robot import Robot, model_data
from derive.resources import PACKAGE, TEMPLATES
from derive.symbolic.model import SXModel

TOOLS = ("sympy", "casadi", "numpy", "jinja2")


ACTIVE_TEMPORARIES: set[Path] = set()
"""Temporary folders of generations under way in this process: a SIGTERM handler removes them
(see :func:`remove_temporaries`) even where the signal cannot unwind the Python stack."""


def remove_temporaries() -> None:
    """Remove the temporary folders of generations under way (for signal handlers)."""
    for path in list(ACTIVE_TEMPORARIES):
        shutil.rmtree(path, ignore_errors=True)
        ACTIVE_TEMPORARIES.discard(path)


def default_output() -> Path:
    """Where generated code is written and looked for when no folder is given: ./generated."""
    return Path.cwd() / "generated"


def tool_versions() -> dict[str, str]:
    return {t: version(t) for t in TOOLS}


GENERATOR_SOURCES = ("errors.py", "resources.py", "description", "symbolic", "codegen")
"""What generated/ depends on, under derive/: the description, the symbolic derivation and code
generation (with every backend), plus the templates. The solvers, analysis, inspection and the
command line are left out: editing them does not make generated/ stale."""


def generator_hash() -> str:
    """sha256 over the generator's sources and templates (line endings normalised) and the tool versions."""
    h = hashlib.sha256()
    files = []
    for rel in GENERATOR_SOURCES:
        path = PACKAGE / rel
        files += [path] if path.is_file() else [p for p in path.rglob("*")]
    labelled = [(f"derive/{p.relative_to(PACKAGE).as_posix()}", p) for p in files]
    labelled += [(f"templates/{p.relative_to(TEMPLATES).as_posix()}", p) for p in TEMPLATES.rglob("*")]
    for label, path in sorted(labelled):
        if path.is_file() and path.suffix in (".py", ".jinja", ".c", ".h") and "__pycache__" not in path.parts:
            h.update(label.encode())
            h.update(path.read_bytes().replace(b"\r\n", b"\n"))
    h.update(json.dumps(tool_versions(), sort_keys=True).encode())
    return h.hexdigest()


def model_hash(robot: Robot) -> str:
    """sha256 of the validated model (not of its YAML text: comments do not count)."""
    return hashlib.sha256(json.dumps(model_data(robot), sort_keys=True).encode()).hexdigest()


def _sha(text: str | bytes) -> str:
    return hashlib.sha256(text.encode() if isinstance(text, str) else text).hexdigest()


def _read_manifest(out: Path) -> dict:
    try:
        return json.loads((out / "MANIFEST.json").read_text())
    except (OSError, ValueError):
        return {}


def _intact(out: Path, name: str, entry: dict) -> bool:
    for rel, digest in entry.get("files", {}).items():
        path = out / name / rel
        if not path.is_file() or _sha(path.read_bytes()) != digest:
            return False
    robot_dir = out / name
    present = {p.relative_to(robot_dir).as_posix() for p in robot_dir.rglob("*") if p.is_file()} if robot_dir.is_dir() else set()
    return present == set(entry.get("files", {}))


FIRMWARE_RECORD = "firmware.json"
"""The firmware figures' file, beside the models file (see the module's docstring)."""


def firmware_record_path(models: str | Path | None = None) -> Path:
    """``firmware.json`` beside ``models``, or beside the default models file."""
    return Path(models if models else default_models_path()).with_name(FIRMWARE_RECORD)


def read_firmware_record(path: Path) -> dict:
    """The recorded figures, ``{"robots": {robot: entry}}``; empty when there is no such file."""
    try:
        text = Path(path).read_text()
    except FileNotFoundError:
        return {"robots": {}}
    try:
        record = json.loads(text)
    except ValueError as exc:
        raise DeriveError(f"{path}: not valid JSON ({exc}); it is written by `derive firmware-check --record`") from None
    robots = record.get("robots") if isinstance(record, dict) else None
    if not isinstance(robots, dict) or not all(
            isinstance(e, dict) and isinstance(e.get("functions"), dict) for e in robots.values()):
        raise DeriveError(f"{path}: not a firmware record (expected {{\"robots\": {{robot: {{..., \"functions\": "
                          "{...}}}}); it is written by `derive firmware-check --record`")
    return record


def source_hashes(files: dict[str, bytes]) -> dict[str, str]:
    """{C function: sha256 of its translation unit} of one robot's files ({path under generated/<robot>/:
    bytes}, manifest.json among them); the key of its firmware figures."""
    manifest = json.loads(files["manifest.json"])
    return {fn["name"]: translation_unit_hash(files, fn["c"]["source"], manifest["model_hash"])
            for fn in manifest["functions"] if fn.get("c")}


def firmware_section(files: dict[str, bytes], entry: dict | None) -> dict | None:
    """A robot's recorded figures (its entry of firmware.json) cut down to the functions whose
    translation unit is unchanged; None when none is."""
    if not entry:
        return None
    hashes = source_hashes(files)
    functions = {name: figures for name, figures in entry["functions"].items()
                 if isinstance(figures, dict) and hashes.get(name) == figures.get("source_sha256")}
    if not functions:
        return None
    # keys sorted at every level, as firmware.json holds them: the same text from a record read or in memory
    return json.loads(json.dumps({**entry, "functions": functions}, sort_keys=True))


def with_firmware(files: dict[str, bytes], entry: dict | None) -> bytes:
    """The robot's manifest.json with its ``firmware`` section as the record says (or without one)."""
    manifest = json.loads(files["manifest.json"])
    manifest.pop("firmware", None)
    section = firmware_section(files, entry)
    if section:
        manifest["firmware"] = section
    return (json.dumps(manifest, indent=2) + "\n").encode()


def robot_files(robot_dir: Path) -> dict[str, bytes]:
    """{path under the robot's folder: bytes} of every file in it."""
    return {p.relative_to(robot_dir).as_posix(): p.read_bytes() for p in sorted(Path(robot_dir).rglob("*")) if p.is_file()}


def record_firmware(out: Path, entries: dict[str, dict], record_path: Path, log: Callable[[str], None] = print) -> None:
    """Write measured figures: ``entries`` ({robot: entry}) replace those robots' entries of the record
    at ``record_path``, then the robots' manifest.json under ``out`` take them (and MANIFEST.json
    their new sha256), as ``derive generate`` would. The robots' folders must be as derive wrote them."""
    out = Path(out)
    manifest = _read_manifest(out)
    for name in entries:
        entry = manifest.get("robots", {}).get(name)
        if entry is None or not _intact(out, name, entry):
            raise DeriveError(f"{out / name}: not as `derive generate` wrote it (see `derive generate --check`); "
                              "regenerate it before recording its firmware figures")
    record = read_firmware_record(record_path)
    record["robots"] = {**record["robots"], **entries}
    record["robots"] = {k: record["robots"][k] for k in sorted(record["robots"])}
    _write_atomically(Path(record_path), (json.dumps(record, indent=2, sort_keys=True) + "\n").encode())
    for name, entry in entries.items():
        files = robot_files(out / name)
        text = with_firmware(files, entry)
        _write_atomically(out / name / "manifest.json", text)
        manifest["robots"][name]["files"]["manifest.json"] = _sha(text)
        kept = json.loads(text).get("firmware", {}).get("functions", {})
        log(f"{out / name / 'manifest.json'}: firmware figures of {len(kept)} function(s)")
    _write_atomically(out / "MANIFEST.json", (json.dumps(manifest, indent=2, sort_keys=True) + "\n").encode())


def _write_atomically(path: Path, data: bytes) -> None:
    tmp = path.with_name(f".{path.name}.tmp-{os.getpid()}")
    try:
        tmp.write_bytes(data)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def check_mass_matrix(model: SXModel, samples: int = 3) -> None:
    """Refuse a robot whose M(q) is singular at every q, where forward dynamics and the ODE do not
    exist (their code would divide by zero): a coordinate that moves no mass or inertia."""
    robot = model.robot
    s = model.sym
    f = ca.Function("M", [s.q, s.p], [model.newton_euler.mass_matrix])
    lo, hi = robot.joint_box()
    rng = np.random.default_rng(0)
    p = np.array([par.default for par in robot.parameters], dtype=float)
    Ms = []
    for _ in range(samples):
        q = rng.uniform(lo, hi)
        if robot.floating:  # a unit quaternion
            q[3:7] = rng.normal(size=4)
            q[3:7] /= np.linalg.norm(q[3:7])
        Ms.append(np.array(f(q, p)))
    diag = np.min([np.diag(M) for M in Ms], axis=0)
    scale = max(float(np.max(np.abs(diag), initial=0.0)), 1e-300)
    for c, d in zip(robot.coordinates, diag):
        if not np.isfinite(d):
            raise DeriveError(f"robot '{robot.name}': joints ({c.joint}): M(q) is not finite at the default "
                              "parameters (overflowing masses, inertias or lengths?)")
        if d <= 1e-12 * scale:
            raise DeriveError(f"robot '{robot.name}': joints ({c.joint}): coordinate '{c.name}' moves no mass or "
                              "inertia, so M(q) is singular and forward dynamics do not exist; give the links it "
                              "moves a mass (links[i].mass) or inertia about its axis")
    if all(np.isfinite(M).all() for M in Ms):
        eig = [np.linalg.eigh(M) for M in Ms]
        if all(w[0] <= 1e-12 * max(w[-1], 1e-300) for w, _ in eig):
            v = eig[0][1]
            names = robot.velocity_names
            moving = [names[int(k)] for k in np.argsort(-np.abs(v[:, 0]))[:3] if abs(v[int(k), 0]) > 1e-6]
            raise DeriveError(f"robot '{robot.name}': M(q) is singular at every q tried: the coordinates "
                              f"{', '.join(moving)} move the same way (e.g. a joint about the same axis through the "
                              "same point as a massless floating base's turn), so forward dynamics do not exist")


def check_constants(robot: Robot, spec, prog) -> None:
    """Refuse code with a non-finite constant (it would print DERIVE_LIT(inf) in C, a bare inf in Python)."""
    for ins in prog.body:
        for a in ins.args:
            if a[0] == "c" and not math.isfinite(a[1]):
                raise DeriveError(f"robot '{robot.name}': {spec.name}: a constant of the derived expression is "
                                  f"{a[1]} (overflowing or degenerate numbers in the model)")
    for _, _, a in prog.results:
        if a[0] == "c" and not math.isfinite(a[1]):
            raise DeriveError(f"robot '{robot.name}': {spec.name}: an output is the constant {a[1]} "
                              "(overflowing or degenerate numbers in the model)")


def render(robot: Robot, mhash: str, log: Callable[[str], None]) -> dict[str, str]:
    """Derive and render one robot; prints stage times."""
    t0 = time.perf_counter()
    model = SXModel(robot)
    check_mass_matrix(model)
    specs = function_specs(model)
    t1 = time.perf_counter()
    total_ops = [0]

    def count(spec, prog):
        check_constants(robot, spec, prog)
        total_ops[0] += prog.ops()["total"]

    templates = template_functions(model)
    files = render_robot(robot, specs, mhash[:16], progress=count, templates=templates)
    t2 = time.perf_counter()
    log(f"  {robot.name}: derive {t1 - t0:.2f} s, cse+print+render {t2 - t1:.2f} s "
        f"({len(specs) + len(templates)} functions, {total_ops[0]} ops in the {len(specs)} expression functions)")
    return files


def generate(robots: dict[str, Robot], out: Path, only: Iterable[str] | None = None, use_cache: bool = True,
             log: Callable[[str], None] = print, prune: bool = False, firmware: Path | None = None) -> dict:
    """Write the robots of ``robots`` (all, or the names in ``only``) into ``out``; returns the new MANIFEST.

    Only those robots' folders are written or replaced: other robots already in ``out``
    (from another models file, say) and files derive does not manage stay as they are.
    With ``prune``, robots that ``out`` holds but ``robots`` does not are removed (and logged).
    ``firmware``: the firmware record whose figures go into the manifests (default: the one
    beside the default models file, :func:`firmware_record_path`).
    """
    shown = Path(out)
    out = output_folder(shown)
    record = read_firmware_record(firmware or firmware_record_path())
    try:
        return _generate(robots, out, shown, only, use_cache, log, prune, record["robots"])
    except OSError as exc:
        raise DeriveError(f"{exc.filename or out}: cannot write the generated code ({exc.strerror or exc})") from None


def output_folder(out: Path) -> Path:
    """The real folder behind ``out``: a symbolic link is written through (its target is replaced,
    the link stays). Refuses a file, or a folder that is not a derive output."""
    out = Path(out)
    if out.is_symlink():
        out = out.resolve()
    if out.exists() and not out.is_dir():
        raise DeriveError(f"output {out}: exists and is not a folder")
    if out.is_dir() and any(out.iterdir()) and not (out / "MANIFEST.json").is_file():
        raise DeriveError(f"output {out}: not empty and holds no MANIFEST.json, so it is not a derive output "
                          "folder; refusing to replace it (choose an empty or new folder)")
    return out


def _generate(robots, out: Path, shown: Path, only, use_cache, log, prune, figures: dict) -> dict:
    _recover(out, log)
    names = sorted(robots) if only is None else sorted(only)
    ghash = generator_hash()
    old = _read_manifest(out)
    old_robots = old.get("robots", {})
    pruned = sorted(k for k in old_robots if k not in robots) if prune else []
    kept = {k: v for k, v in old_robots.items() if k not in names and k not in pruned}
    new_robots = dict(kept)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.tmp-{os.getpid()}-", dir=out.parent))
    ACTIVE_TEMPORARIES.add(tmp)
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o777 & ~umask)  # mkdtemp makes it 0700; the output folder is an ordinary one
    try:
        start = time.perf_counter()
        # carry over the robots not being regenerated, untouched
        for name in kept:
            if (out / name).is_dir():
                shutil.copytree(out / name, tmp / name)
        # and anything else a user keeps in the folder that derive does not manage
        managed = set(old_robots) | set(names) | {"MANIFEST.json"}
        for entry in sorted(out.iterdir()) if out.is_dir() else ():
            if entry.name not in managed:
                (shutil.copytree if entry.is_dir() else shutil.copy2)(entry, tmp / entry.name)
        for k, name in enumerate(names, 1):
            robot = robots[name]
            mhash = model_hash(robot)
            prev = old_robots.get(name)
            if (use_cache and prev and prev.get("model_hash") == mhash and prev.get("generator_hash") == ghash
                    and _intact(out, name, prev)):
                shutil.copytree(out / name, tmp / name)
                new_robots[name] = prev
                text = with_firmware(robot_files(tmp / name), figures.get(name))
                if text != (tmp / name / "manifest.json").read_bytes():  # the record changed
                    (tmp / name / "manifest.json").write_bytes(text)
                    new_robots[name] = {**prev, "files": {**prev["files"], "manifest.json": _sha(text)}}
                    log(f"[{k}/{len(names)}] {name}: unchanged, kept; firmware figures updated")
                    continue
                log(f"[{k}/{len(names)}] {name}: unchanged, kept")
                continue
            log(f"[{k}/{len(names)}] {name}: deriving")
            files = {rel: text.encode() for rel, text in render(robot, mhash, log).items()}
            files["manifest.json"] = with_firmware(files, figures.get(name))
            for rel, data in files.items():
                path = tmp / name / rel
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_bytes(data)
            new_robots[name] = {"model_hash": mhash, "generator_hash": ghash, "files": {rel: _sha(data) for rel, data in sorted(files.items())}}
        manifest = {"tools": tool_versions(),
                    "robots": {k: new_robots[k] for k in sorted(new_robots)}}
        (tmp / "MANIFEST.json").write_text(json.dumps(manifest, indent=2, sort_keys=True) + "\n")
        _swap(tmp, out)
        for name in pruned:
            log(f"pruned {shown / name}/ (robot not in the models file)")
        others = f"; {len(kept)} other robot(s) left as they were" if kept else ""
        log(f"generated {len(names)} robot(s) into {shown} in {time.perf_counter() - start:.1f} s{others}")
        return manifest
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    finally:
        ACTIVE_TEMPORARIES.discard(tmp)


STALE = re.compile(r"^\.(?P<name>.+)\.(?:tmp|old)-(?P<pid>\d+)(?:-.*)?$")


def process_alive(pid: int) -> bool:
    """Whether process ``pid`` exists (a temporary folder named after it may still be in use)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:  # exists, but another user's
        return True
    return True


def _recover(out: Path, log: Callable[[str], None]) -> None:
    """Undo what a killed run left beside ``out``: restore ``out`` from its backup if a kill fell
    between the two renames of the fallback swap, and remove temporary folders of dead runs."""
    if not out.parent.is_dir():
        return
    for entry in sorted(out.parent.iterdir()):
        m = STALE.match(entry.name)
        if not m or m["name"] != out.name or not entry.is_dir() or process_alive(int(m["pid"])):
            continue
        if ".old-" in entry.name and not out.exists():
            os.rename(entry, out)
            log(f"restored {out} from {entry.name}, left by an interrupted run")
            continue
        shutil.rmtree(entry, ignore_errors=True)
        log(f"removed {entry}, left by an interrupted run")


def _exchange(a: Path, b: Path) -> bool:
    """Swap two existing folders in one atomic step (Linux renameat2 RENAME_EXCHANGE); False where
    the system has no such call."""
    fn = getattr(ctypes.CDLL(None, use_errno=True), "renameat2", None)
    if fn is None:
        return False
    at_fdcwd, rename_exchange = -100, 2
    if fn(at_fdcwd, os.fsencode(str(a)), at_fdcwd, os.fsencode(str(b)), rename_exchange) == 0:
        return True
    err = ctypes.get_errno()
    if err in (errno.ENOSYS, errno.EINVAL, errno.EOPNOTSUPP):
        return False
    raise OSError(err, os.strerror(err), str(b))


def _swap(tmp: Path, out: Path) -> None:
    """Replace ``out`` by ``tmp`` so that one of them is in place at every instant: an atomic
    exchange where the system has one; else two renames, with :func:`_recover` restoring the
    backup on the next run if a kill falls between them."""
    if not out.exists():
        os.rename(tmp, out)
        return
    if _exchange(tmp, out):
        shutil.rmtree(tmp, ignore_errors=True)  # tmp now holds the old tree
        return
    backup = out.with_name(f".{out.name}.old-{os.getpid()}")
    os.rename(out, backup)
    os.rename(tmp, out)
    shutil.rmtree(backup, ignore_errors=True)


def check(robots: dict[str, Robot], out: Path, prune: bool = False, firmware: Path | None = None) -> list[str]:
    """Stale or edited files of ``robots`` under ``out``: empty when they match the models, derive and
    the firmware record (``firmware``, default :func:`firmware_record_path`).

    Other robots in ``out`` are not judged, unless ``prune``: then each is a problem
    (``generate --prune`` would remove it).
    """
    out = Path(out)
    record_path = firmware or firmware_record_path()
    figures = read_firmware_record(record_path)["robots"]
    manifest = _read_manifest(out)
    if not manifest:
        return [f"{out}/MANIFEST.json (missing or unreadable)"]
    problems = []
    ghash = generator_hash()
    entries = manifest.get("robots", {})
    for name in sorted(set(robots) | (set(entries) if prune else set())):
        entry = entries.get(name)
        if name not in robots:
            problems.append(f"{out}/{name}/ (robot not in the models file; --prune removes it)")
        elif entry is None:
            problems.append(f"{out}/{name}/ (not generated)")
        elif entry.get("model_hash") != model_hash(robots[name]):
            problems.append(f"{out}/{name}/ (model changed in the models file)")
        elif entry.get("generator_hash") != ghash:
            problems.append(f"{out}/{name}/ (derive, its templates or tool versions changed since generation)")
        else:
            robot_dir = out / name
            found = len(problems)
            for rel, digest in entry.get("files", {}).items():
                path = robot_dir / rel
                if not path.is_file():
                    problems.append(f"{path} (missing)")
                elif _sha(path.read_bytes()) != digest:
                    problems.append(f"{path} (edited by hand)")
            if robot_dir.is_dir():
                for path in sorted(robot_dir.rglob("*")):
                    if path.is_file() and path.relative_to(robot_dir).as_posix() not in entry.get("files", {}):
                        problems.append(f"{path} (not generated by derive)")
            if len(problems) == found:
                files = robot_files(robot_dir)
                if with_firmware(files, figures.get(name)) != files["manifest.json"]:
                    problems.append(f"{robot_dir / 'manifest.json'} (its firmware figures differ from {record_path})")
    return problems
