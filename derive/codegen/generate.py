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
- Runs into one output folder take turns: each holds an advisory lock (``flock``) on the folder
  that holds the output for its whole run, and reads MANIFEST.json only once it has it, so the
  second run merges onto what the first wrote. A temporary folder beside the output is removed
  only by a run that holds that lock (its owner is then gone, whatever its pid or PID namespace).
- Links in the output folder stay links (never followed); files derive does not manage are
  carried over as hard links where the file system allows (else copied), so they are kept whole.
- An output folder that cannot be renamed (a mount point: a Docker volume, a bind mount) is
  updated in place instead, robot folder by robot folder, each in one atomic exchange, with
  MANIFEST.json written last.
"""

from __future__ import annotations

import contextlib
import ctypes
import errno
import fcntl
import hashlib
import json
import os
import re
import shutil
import stat
import sys
import tempfile
import time
from importlib.metadata import version
from pathlib import Path
from typing import Callable, Iterable


from derive.codegen.backends.c import translation_unit_hash
from derive.codegen.catalogue import function_specs, selected, template_functions, wanted
from derive.codegen.checks import NEEDS_INVERSE_MASS, check_constants, check_mass_matrix, unmoved_reason
from derive.codegen.render import render_robot
from derive.errors import DeriveError
from derive.description.files import InputFileError, read_text
from derive.description.model import default_models_path
from derive.filesystem import forget, register, write_atomically
from derive.description.robot import CONTACT_NEEDS_INVERSE_MASS, Robot, model_data
from derive.resources import PACKAGE, TEMPLATES
from derive.symbolic.model import SXModel

TOOLS = ("sympy", "casadi", "numpy", "jinja2")


def default_output() -> Path:
    """Where generated code is written and looked for when no folder is given: ./generated."""
    return Path.cwd() / "generated"


def tool_versions() -> dict[str, str]:
    return {t: version(t) for t in TOOLS}


GENERATOR_SOURCES = ("errors.py", "resources.py", "filesystem.py", "description", "symbolic", "codegen")
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


ROBOT_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")
"""A robot's name, as the models file allows it: also its folder under the output."""


def manifest_problem(manifest) -> str | None:
    """Why ``manifest`` (MANIFEST.json, loaded) is not one derive wrote, or None."""
    if not isinstance(manifest, dict):
        return f"a JSON {type(manifest).__name__}, not an object"
    robots = manifest.get("robots")
    if not isinstance(robots, dict):
        return "its 'robots' is not an object"
    for name, entry in robots.items():
        if not ROBOT_NAME.match(name):
            return f"robot name {name!r} is not a robot's name"
        if not isinstance(entry, dict) or not all(isinstance(entry.get(k), str) for k in ("model_hash", "generator_hash")):
            return f"robots.{name} has no model_hash and generator_hash"
        files = entry.get("files")
        if not isinstance(files, dict) or not all(isinstance(v, str) for v in files.values()):
            return f"robots.{name}.files is not an object of sha256 strings"
        for rel in files:
            parts = rel.split("/")
            if not rel or rel.startswith("/") or any(part in ("", ".", "..") for part in parts):
                return f"robots.{name}.files names {rel!r}, not a path inside the robot's folder"
    return None


def _load_manifest(out: Path) -> tuple[dict, str | None]:
    """(MANIFEST.json of ``out``, why it cannot be used or None); ({}, None) where there is none."""
    path = out / "MANIFEST.json"
    if not os.path.lexists(path):
        return {}, None
    try:
        data = json.loads(read_text(path, "manifest"))
    except InputFileError as exc:
        return {}, str(exc)
    except ValueError as exc:
        return {}, f"{path}: not valid JSON ({exc})"
    problem = manifest_problem(data)
    return (data, None) if problem is None else ({}, f"{path}: not a derive manifest ({problem})")


def _read_manifest(out: Path) -> dict:
    """MANIFEST.json of ``out`` if it is one derive wrote, else {}."""
    return _load_manifest(out)[0]


def _regular(path: Path) -> bool:
    """A regular file, not a link to one: what derive writes in a robot's folder."""
    try:
        return stat.S_ISREG(os.lstat(path).st_mode)
    except OSError:
        return False


def _entries(robot_dir: Path) -> set[str]:
    """Paths under ``robot_dir`` of everything but folders (links and special files included), links not
    followed; not what Python's byte-code cache holds (``__pycache__``, written where a generated module is
    imported, rebuilt by Python from the sources: no part of the generated code nor the user's)."""
    found = set()
    for root, dirs, names in os.walk(robot_dir):
        base = Path(root)
        for d in list(dirs):
            if (base / d).is_symlink():
                names.append(d)
                dirs.remove(d)
            elif d == "__pycache__":
                dirs.remove(d)
        found |= {(base / n).relative_to(robot_dir).as_posix() for n in names}
    return found


def _intact(out: Path, name: str, entry: dict) -> bool:
    robot_dir = out / name
    if not robot_dir.is_dir() or robot_dir.is_symlink():
        return False
    for rel, digest in entry.get("files", {}).items():
        path = robot_dir / rel
        if not _regular(path) or _sha(path.read_bytes()) != digest:
            return False
    return _entries(robot_dir) == set(entry.get("files", {}))


FIRMWARE_RECORD = "firmware.json"
"""The firmware figures' file, beside the models file (see the module's docstring)."""


def firmware_record_path(models: str | Path | None = None) -> Path:
    """``firmware.json`` beside ``models``, or beside the default models file."""
    return Path(models if models else default_models_path()).with_name(FIRMWARE_RECORD)


def read_firmware_record(path: Path) -> dict:
    """The recorded figures, ``{"robots": {robot: entry}}``; empty when there is no such file.
    Read through the input files' guards: a FIFO, a device or an oversized file is refused."""
    if not os.path.lexists(path):
        return {"robots": {}}
    text = read_text(path, "firmware record")
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
    """{path under the robot's folder: bytes} of every regular file in it (links are not followed)."""
    robot_dir = Path(robot_dir)
    return {rel: (robot_dir / rel).read_bytes() for rel in sorted(_entries(robot_dir)) if _regular(robot_dir / rel)}


def record_firmware(out: Path, entries: dict[str, dict], record_path: Path, log: Callable[[str], None] = print) -> None:
    """Write measured figures: ``entries`` ({robot: entry}) replace those robots' entries of the record
    at ``record_path``, then the robots' manifest.json under ``out`` take them (and MANIFEST.json
    their new sha256), as ``derive generate`` would. The robots' folders must be as derive wrote them."""
    out = output_folder(Path(out))
    with output_lock(out, log):
        _record_firmware(out, entries, record_path, log)


def _record_firmware(out: Path, entries: dict[str, dict], record_path: Path, log: Callable[[str], None]) -> None:
    manifest = _read_manifest(out)
    for name in entries:
        entry = manifest.get("robots", {}).get(name)
        if entry is None or not _intact(out, name, entry):
            raise DeriveError(f"{out / name}: not as `derive generate` wrote it (see `derive generate --check`); "
                              "regenerate it before recording its firmware figures")
    record = read_firmware_record(record_path)
    record["robots"] = {**record["robots"], **entries}
    record["robots"] = {k: record["robots"][k] for k in sorted(record["robots"])}
    write_atomically(Path(record_path), json.dumps(record, indent=2, sort_keys=True) + "\n", "the firmware record")
    for name, entry in entries.items():
        files = robot_files(out / name)
        text = with_firmware(files, entry)
        write_atomically(out / name / "manifest.json", text, "the robot's manifest")
        manifest["robots"][name]["files"]["manifest.json"] = _sha(text)
        kept = json.loads(text).get("firmware", {}).get("functions", {})
        log(f"{out / name / 'manifest.json'}: firmware figures of {len(kept)} function(s)")
    write_atomically(out / "MANIFEST.json", json.dumps(manifest, indent=2, sort_keys=True) + "\n", "the manifest")


def left_out_entry(robot: Robot, unmoved: list[str]) -> dict | None:
    """manifest.json's ``left_out`` for a robot whose coordinates ``unmoved`` move no mass (None if none do):
    the functions of :data:`~derive.codegen.checks.NEEDS_INVERSE_MASS` its set would hold, and why."""
    if not unmoved:
        return None
    names = [q for q in NEEDS_INVERSE_MASS if q != "forward_dynamics_fext" or robot.wrench_frames]
    need = wanted(robot)  # the contact functions solve with M^-1 as well (catalogue.contact_specs)
    names += [f"{q}_{stance.name}" for stance in robot.stances for q in CONTACT_NEEDS_INVERSE_MASS if need(q) and (
        q != "contact_dynamics_baumgarte" or all(robot.contact(f).kind == "point" for f in stance.frames))]
    return {"functions": [f"{robot.name}_{q}" for q in names], "coordinates": list(unmoved),
            "reason": unmoved_reason(unmoved)}


def left_out_warning(robot: Robot, reason: str) -> str:
    """The one warning line of a robot generated without forward dynamics."""
    where = f"{robot.file}: robot '{robot.name}'" if robot.file else f"robot '{robot.name}'"
    return (f"derive: warning: {where}: {reason}: forward dynamics, the ODE and its Jacobians are not generated "
            "(--strict refuses the robot)")


def render(robot: Robot, mhash: str, log: Callable[[str], None], strict: bool = False,
           warn: Callable[[str], None] | None = None) -> dict[str, str]:
    """Derive and render one robot; prints stage times. A robot whose M(q) is singular because coordinates
    move no mass is refused with ``strict``, else generated without the functions that need M^-1, with
    one line to ``warn`` (default ``log``) and a ``left_out`` entry in its manifest.json."""
    t0 = time.perf_counter()
    model = SXModel(robot)
    unmoved = check_mass_matrix(model, strict=strict)
    left_out = left_out_entry(robot, unmoved)
    if left_out:
        (warn or log)(left_out_warning(robot, left_out["reason"]))
    specs = function_specs(model, forward=not unmoved)
    t1 = time.perf_counter()
    total_ops = [0]

    def count(spec, prog):
        check_constants(robot, spec, prog)
        total_ops[0] += prog.ops()["total"]

    templates = template_functions(model, forward=not unmoved)
    specs, templates = selected(robot, specs, templates)
    files = render_robot(robot, specs, mhash[:16], progress=count, templates=templates, left_out=left_out)
    t2 = time.perf_counter()
    log(f"  {robot.name}: derive {t1 - t0:.2f} s, cse+print+render {t2 - t1:.2f} s "
        f"({len(specs) + len(templates)} functions, {total_ops[0]} ops in the {len(specs)} expression functions)")
    return files


def generate(robots: dict[str, Robot], out: Path, only: Iterable[str] | None = None, use_cache: bool = True,
             log: Callable[[str], None] = print, prune: bool = False, firmware: Path | None = None,
             strict: bool = False, warn: Callable[[str], None] | None = None) -> dict:
    """Write the robots of ``robots`` (all, or the names in ``only``) into ``out``; returns the new MANIFEST.

    A robot with coordinates that move no mass or inertia (M(q) singular) is generated without forward
    dynamics, the ODE and its Jacobians, with one warning line to ``warn`` (default: stderr) and the
    functions left out named in its manifest.json (``left_out``); ``strict`` refuses it instead.
    Only those robots' folders are written or replaced: other robots already in ``out``
    (from another models file, say) and files derive does not manage stay as they are.
    With ``prune``, robots that ``out`` holds but ``robots`` does not are removed (and logged).
    ``firmware``: the firmware record whose figures go into the manifests (default: the one
    beside the default models file, :func:`firmware_record_path`).
    Another run into the same folder is waited for (a line is logged), then merged onto.
    """
    shown = Path(out)
    out = output_folder(shown)
    try:
        with output_lock(out, log):
            record = read_firmware_record(firmware or firmware_record_path())
            return _generate(robots, out, shown, only, use_cache, log, prune, record["robots"], strict,
                             warn or (lambda line: print(line, file=sys.stderr)))
    except OSError as exc:
        where = f" at {exc.filename}" if exc.filename and ".tmp-" not in os.fspath(exc.filename) else ""
        raise DeriveError(f"{shown}: cannot write the generated code ({exc.strerror or exc}{where}); "
                          "the output folder is left as it was") from None


def output_folder(out: Path) -> Path:
    """The real folder behind ``out`` (absolute): a symbolic link is written through (its target is
    replaced, the link stays). Refuses a file, or a folder that is not a derive output."""
    out = Path(os.path.abspath(out))
    if out.is_symlink():
        out = out.resolve()
    if out.parent == out:
        raise DeriveError(f"output {out}: the root of the file system cannot be an output folder")
    if out.exists() and not out.is_dir():
        raise DeriveError(f"output {out}: exists and is not a folder")
    if out.is_dir() and any(out.iterdir()) and not os.path.lexists(out / "MANIFEST.json"):
        raise DeriveError(f"output {out}: not empty and holds no MANIFEST.json, so it is not a derive output "
                          "folder; refusing to replace it (choose an empty or new folder)")
    return out


@contextlib.contextmanager
def output_lock(out: Path, log: Callable[[str], None] = print, shared: bool = False):
    """Hold the advisory lock of output folder ``out`` for the block: ``flock`` on the folder that holds
    it (where the run's temporary folder lives too), exclusive to write, ``shared`` to read. Works
    across processes, users and PID namespaces on one machine; the kernel releases it on every exit
    path, a kill included. Waits for the holder, after logging one line."""
    parent = out.parent
    if shared and not parent.is_dir():
        yield
        return
    parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(parent, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0) | getattr(os, "O_CLOEXEC", 0))
    try:
        mode = fcntl.LOCK_SH if shared else fcntl.LOCK_EX
        try:
            fcntl.flock(fd, mode | fcntl.LOCK_NB)
        except BlockingIOError:
            log(f"waiting for another derive run writing into {parent} to finish ...")
            fcntl.flock(fd, mode)
        except OSError as exc:
            if exc.errno not in (errno.ENOLCK, errno.EOPNOTSUPP, errno.EINVAL):
                raise
            log(f"warning: {parent}: its file system has no locks ({exc.strerror}); concurrent derive runs "
                "into it are not serialised")
        yield
    finally:
        os.close(fd)


def _makedirs(base: Path, rel: str) -> Path:
    """Create the folders of ``rel`` under the existing ``base`` without ever recreating ``base``:
    a run whose temporary folder was removed under it fails instead of writing a partial tree."""
    folder = base
    for part in Path(rel).parts:
        folder = folder / part
        try:
            folder.mkdir()
        except FileExistsError:
            if not folder.is_dir() or folder.is_symlink():
                raise
    return folder


def _put(path: Path, data: bytes) -> None:
    """Write a new file at ``path`` (a hard link there is replaced, never written through)."""
    path.unlink(missing_ok=True)
    with open(path, "xb") as f:
        f.write(data)


def _carry(src: Path, dst: Path) -> None:
    """Put ``src`` (a file, link or folder tree) at the new path ``dst`` as it is, links never followed:
    links recreated, regular files hard-linked (copied where the file system refuses), folders made
    with their modes, FIFOs recreated. A socket or device is refused."""
    stack = [(Path(src), Path(dst))]
    folders = []
    while stack:
        s, d = stack.pop()
        st = os.lstat(s)
        if stat.S_ISLNK(st.st_mode):
            os.symlink(os.readlink(s), d)
        elif stat.S_ISDIR(st.st_mode):
            os.mkdir(d)
            folders.append((s, d))
            stack.extend((s / n, d / n) for n in sorted(os.listdir(s), reverse=True))
        elif stat.S_ISREG(st.st_mode):
            try:
                os.link(s, d, follow_symlinks=False)
            except OSError:
                shutil.copy2(s, d, follow_symlinks=False)
        elif stat.S_ISFIFO(st.st_mode):
            os.mkfifo(d, stat.S_IMODE(st.st_mode))
        else:
            raise DeriveError(f"{s}: a socket or device file in the output folder cannot be carried over to the "
                              "new tree; move it out of the folder")
    for s, d in reversed(folders):
        shutil.copystat(s, d, follow_symlinks=False)


def _mount_point(path: Path) -> bool:
    """Whether ``path`` is a mount point (a volume, a bind mount): it cannot be renamed or exchanged."""
    if os.path.ismount(path):
        return True
    real = os.path.realpath(path)
    try:
        with open("/proc/self/mountinfo", encoding="utf-8", errors="replace") as f:
            lines = f.read().splitlines()
    except OSError:
        return False
    unescape = lambda text: re.sub(r"\\([0-7]{3})", lambda m: chr(int(m[1], 8)), text)  # noqa: E731
    return any(len(fields) > 4 and unescape(fields[4]) == real for fields in map(str.split, lines))


def _left_out(robot_dir: Path) -> dict | None:
    """The ``left_out`` entry of a generated robot's manifest.json, or None."""
    try:
        return json.loads((robot_dir / "manifest.json").read_bytes()).get("left_out")
    except (OSError, ValueError, AttributeError):
        return None


def _generate(robots, out: Path, shown: Path, only, use_cache, log, prune, figures: dict, strict: bool = False,
              warn: Callable[[str], None] = print) -> dict:
    _recover(out, log)
    names = sorted(robots) if only is None else sorted(only)
    ghash = generator_hash()
    old, problem = _load_manifest(out)
    if problem:
        log(f"warning: {problem}; the folders it would name are kept as files derive does not manage")
    old_robots = old.get("robots", {})
    pruned = sorted(k for k in old_robots if k not in robots) if prune else []
    kept = {k: v for k, v in old_robots.items() if k not in names and k not in pruned}
    new_robots = dict(kept)
    in_place = out.is_dir() and _mount_point(out)
    where = out if in_place else out.parent
    try:
        tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.tmp-{os.getpid()}-", dir=where))
    except OSError as exc:
        raise DeriveError(f"{shown}: cannot write the generated code: no temporary folder can be made in {where} "
                          f"({exc.strerror or exc}); the output folder is left as it was") from None
    register(tmp, True)
    made = None
    try:
        made = os.stat(tmp)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o777 & ~umask)  # mkdtemp makes it 0700; the output folder is an ordinary one
        start = time.perf_counter()
        if not in_place:
            # carry over, untouched, the robots not being regenerated and anything else a user keeps there
            skip = set(names) | set(pruned) | {"MANIFEST.json"}
            for entry in sorted(out.iterdir()) if out.is_dir() else ():
                if entry.name not in skip:
                    _carry(entry, tmp / entry.name)
        for k, name in enumerate(names, 1):
            robot = robots[name]
            mhash = model_hash(robot)
            prev = old_robots.get(name)
            left_out = _left_out(out / name) if use_cache and prev else None
            if (use_cache and prev and prev.get("model_hash") == mhash and prev.get("generator_hash") == ghash
                    and _intact(out, name, prev) and not (strict and left_out)):  # strict: refused as it derives
                if left_out:
                    warn(left_out_warning(robot, left_out.get("reason", "M(q) is singular")))
                _carry(out / name, tmp / name)
                new_robots[name] = prev
                text = with_firmware(robot_files(tmp / name), figures.get(name))
                if text != (tmp / name / "manifest.json").read_bytes():  # the record changed
                    _put(tmp / name / "manifest.json", text)
                    new_robots[name] = {**prev, "files": {**prev["files"], "manifest.json": _sha(text)}}
                    log(f"[{k}/{len(names)}] {name}: unchanged, kept; firmware figures updated")
                    continue
                log(f"[{k}/{len(names)}] {name}: unchanged, kept")
                continue
            log(f"[{k}/{len(names)}] {name}: deriving")
            files = {rel: text.encode() for rel, text in render(robot, mhash, log, strict, warn).items()}
            files["manifest.json"] = with_firmware(files, figures.get(name))
            (tmp / name).mkdir()
            for rel, data in files.items():
                _put(_makedirs(tmp / name, str(Path(rel).parent)) / Path(rel).name, data)
            new_robots[name] = {"model_hash": mhash, "generator_hash": ghash, "files": {rel: _sha(data) for rel, data in sorted(files.items())}}
        manifest = {"tools": tool_versions(),
                    "robots": {k: new_robots[k] for k in sorted(new_robots)}}
        _put(tmp / "MANIFEST.json", (json.dumps(manifest, indent=2, sort_keys=True) + "\n").encode())
        now = os.stat(tmp)
        if (now.st_dev, now.st_ino) != (made.st_dev, made.st_ino):
            raise FileNotFoundError(errno.ENOENT, "removed by another process during the run", str(tmp))
        if in_place:
            _replace_contents(tmp, out, names, pruned)
        else:
            try:
                _swap(tmp, out)
            except OSError as exc:
                if exc.errno not in (errno.EBUSY, errno.EXDEV):
                    raise
                _replace_contents(_moved_inside(tmp, out, names), out, names, pruned)  # a bind mount
        for name in pruned:
            log(f"pruned {shown / name}/ (robot not in the models file)")
        others = f"; {len(kept)} other robot(s) left as they were" if kept else ""
        log(f"generated {len(names)} robot(s) into {shown} in {time.perf_counter() - start:.1f} s{others}")
        return manifest
    except FileNotFoundError as exc:
        inside = [os.fspath(f) for f in (exc.filename, exc.filename2) if f is not None]
        # derive removes nothing in its own temporary folder while it runs: a path in it that is
        # missing was removed by another process (rm -rf empties the folder before removing it, so
        # the folder itself may still be there)
        if not any(tmp.name in f for f in inside) and _whole(tmp, made):
            raise
        raise DeriveError(f"{shown}: the temporary folder of this run ({tmp}) was removed by another process "
                          "during the run; nothing was written, the output folder is left as it was") from None
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
        forget(tmp)


def _whole(tmp: Path, made: os.stat_result | None) -> bool:
    """Whether the run's temporary folder is still the one it made (``made``: its stat then, None
    where it was gone before that), not removed, not made anew."""
    if made is None:
        return False
    try:
        now = os.stat(tmp)
    except FileNotFoundError:
        return False
    return (now.st_dev, now.st_ino) == (made.st_dev, made.st_ino)


def _moved_inside(tmp: Path, out: Path, names: list[str]) -> Path:
    """A copy, inside ``out``, of the new robots' folders and MANIFEST.json built in ``tmp`` beside it
    (for an output that turned out not to be renameable: a bind mount on the same file system)."""
    inner = Path(tempfile.mkdtemp(prefix=f".{out.name}.tmp-{os.getpid()}-", dir=out))
    register(inner, True)
    for name in names:
        shutil.copytree(tmp / name, inner / name, symlinks=True)
    shutil.copy2(tmp / "MANIFEST.json", inner / "MANIFEST.json")
    return inner


def _replace_contents(tmp: Path, out: Path, names: list[str], pruned: list[str]) -> None:
    """Update ``out`` in place from ``tmp`` (inside it): each robot's folder in one exchange (or two
    renames, the old one kept in ``tmp`` as ``.old-<robot>`` until the new one is in place, which
    :func:`_recover` puts back after a kill), pruned robots moved into ``tmp``, MANIFEST.json last.
    Files derive does not manage are not touched."""
    try:
        for name in names:
            new, target = tmp / name, out / name
            if not os.path.lexists(target):
                os.rename(new, target)
            elif not (target.is_dir() and not target.is_symlink() and _exchange(new, target)):
                os.rename(target, tmp / f".old-{name}")
                os.rename(new, target)
        for name in pruned:
            if os.path.lexists(out / name):
                os.rename(out / name, tmp / f".pruned-{name}")
        os.replace(tmp / "MANIFEST.json", out / "MANIFEST.json")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
        forget(tmp)


STALE = re.compile(r"^\.(?P<name>.+)\.(?:tmp|old)-\d+(?:-.*)?$")
"""A temporary folder (``.<output>.tmp-<pid>-<random>``) or backup (``.<output>.old-<pid>``) of a run."""


def _recover(out: Path, log: Callable[[str], None]) -> None:
    """Undo what a killed run left beside (or, for a mount point, inside) ``out``: restore ``out``
    from its backup if a kill fell between the two renames of a fallback swap, and remove the
    temporary folders. Called with the output's lock held, so no run that made them is alive
    (whatever its pid or PID namespace)."""
    if out.parent.is_dir():
        for entry in sorted(out.parent.iterdir()):
            m = STALE.match(entry.name)
            if not m or m["name"] != out.name or not entry.is_dir() or entry.is_symlink():
                continue
            if ".old-" in entry.name and not os.path.lexists(out):
                os.rename(entry, out)
                log(f"restored {out} from {entry.name}, left by an interrupted run")
                continue
            shutil.rmtree(entry, ignore_errors=True)
            log(f"removed {entry}, left by an interrupted run")
    if out.is_dir() and not out.is_symlink():
        for entry in sorted(out.iterdir()):
            m = STALE.match(entry.name)
            if not m or m["name"] != out.name or not entry.is_dir() or entry.is_symlink():
                continue
            for old in sorted(entry.glob(".old-*")):
                robot = out / old.name[len(".old-"):]
                if not os.path.lexists(robot):
                    os.rename(old, robot)
                    log(f"restored {robot} from {old}, left by an interrupted run")
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
    if not os.path.lexists(out):
        os.rename(tmp, out)
        return
    if _exchange(tmp, out):
        return  # tmp now holds the old tree; the caller removes it
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
    real = Path(os.path.abspath(out))
    real = real.resolve() if real.is_symlink() else real
    with output_lock(real, log=lambda line: print(line, file=sys.stderr), shared=True):
        return _check(robots, out, prune, record_path)


def _check(robots: dict[str, Robot], out: Path, prune: bool, record_path: Path) -> list[str]:
    figures = read_firmware_record(record_path)["robots"]
    manifest, problem = _load_manifest(out)
    if problem:
        return [f"{problem}; `derive generate` writes a new one"]
    if not manifest:
        return [f"{out}/MANIFEST.json (missing)"]
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
            if robot_dir.is_symlink():
                problems.append(f"{robot_dir} (a link, not the folder derive generated)")
                continue
            found = len(problems)
            for rel, digest in entry.get("files", {}).items():
                path = robot_dir / rel
                if not _regular(path):
                    problems.append(f"{path} (missing)" if not os.path.lexists(path) else f"{path} (not a regular file)")
                elif _sha(path.read_bytes()) != digest:
                    problems.append(f"{path} (edited by hand)")
            if robot_dir.is_dir() and not robot_dir.is_symlink():
                for rel in sorted(_entries(robot_dir) - set(entry.get("files", {}))):
                    problems.append(f"{robot_dir / rel} (not generated by derive)")
            if len(problems) == found:
                files = robot_files(robot_dir)
                if with_firmware(files, figures.get(name)) != files["manifest.json"]:
                    problems.append(f"{robot_dir / 'manifest.json'} (its firmware figures differ from {record_path})")
    return problems
