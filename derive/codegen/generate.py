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
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import tempfile
import time
from importlib.metadata import version
from pathlib import Path
from typing import Callable, Iterable

from derive.codegen.catalogue import function_specs, template_functions
from derive.codegen.render import render_robot
from derive.errors import DeriveError
from derive.description.robot import Robot, model_data
from derive.resources import PACKAGE, TEMPLATES
from derive.symbolic.model import SXModel

TOOLS = ("sympy", "casadi", "numpy", "jinja2")


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


def render(robot: Robot, mhash: str, log: Callable[[str], None]) -> dict[str, str]:
    """Derive and render one robot; prints stage times."""
    t0 = time.perf_counter()
    model = SXModel(robot)
    specs = function_specs(model)
    t1 = time.perf_counter()
    total_ops = [0]

    def count(spec, prog):
        total_ops[0] += prog.ops()["total"]

    templates = template_functions(model)
    files = render_robot(robot, specs, mhash[:16], progress=count, templates=templates)
    t2 = time.perf_counter()
    log(f"  {robot.name}: derive {t1 - t0:.2f} s, cse+print+render {t2 - t1:.2f} s "
        f"({len(specs) + len(templates)} functions, {total_ops[0]} ops in the {len(specs)} expression functions)")
    return files


def generate(robots: dict[str, Robot], out: Path, only: Iterable[str] | None = None, use_cache: bool = True,
             log: Callable[[str], None] = print, prune: bool = False) -> dict:
    """Write the robots of ``robots`` (all, or the names in ``only``) into ``out``; returns the new MANIFEST.

    Only those robots' folders are written or replaced: other robots already in ``out``
    (from another models file, say) and files derive does not manage stay as they are.
    With ``prune``, robots that ``out`` holds but ``robots`` does not are removed (and logged).
    """
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise DeriveError(f"output {out}: exists and is not a folder")
    if out.is_dir() and any(out.iterdir()) and not (out / "MANIFEST.json").is_file():
        raise DeriveError(f"output {out}: not empty and holds no MANIFEST.json, so it is not a derive output "
                          "folder; refusing to replace it (choose an empty or new folder)")
    names = sorted(robots) if only is None else sorted(only)
    ghash = generator_hash()
    old = _read_manifest(out)
    old_robots = old.get("robots", {})
    pruned = sorted(k for k in old_robots if k not in robots) if prune else []
    kept = {k: v for k, v in old_robots.items() if k not in names and k not in pruned}
    new_robots = dict(kept)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.tmp-", dir=out.parent))
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
                log(f"[{k}/{len(names)}] {name}: unchanged, kept")
                continue
            log(f"[{k}/{len(names)}] {name}: deriving")
            files = render(robot, mhash, log)
            for rel, text in files.items():
                path = tmp / name / rel
                path.parent.mkdir(parents=True, exist_ok=True)
                path.write_text(text)
            new_robots[name] = {"model_hash": mhash, "generator_hash": ghash, "files": {rel: _sha(text) for rel, text in sorted(files.items())}}
        manifest = {"tools": tool_versions(),
                    "robots": {k: new_robots[k] for k in sorted(new_robots)}}
        (tmp / "MANIFEST.json").write_text(json.dumps(manifest, indent=2, sort_keys=True) + "\n")
        _swap(tmp, out)
        for name in pruned:
            log(f"pruned {out / name}/ (robot not in the models file)")
        others = f"; {len(kept)} other robot(s) left as they were" if kept else ""
        log(f"generated {len(names)} robot(s) into {out} in {time.perf_counter() - start:.1f} s{others}")
        return manifest
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def _swap(tmp: Path, out: Path) -> None:
    """Replace ``out`` by ``tmp`` with renames only (no half-written state is ever visible)."""
    backup = None
    if out.exists():
        backup = out.with_name(f".{out.name}.old-{os.getpid()}")
        os.rename(out, backup)
    os.rename(tmp, out)
    if backup:
        shutil.rmtree(backup, ignore_errors=True)


def check(robots: dict[str, Robot], out: Path, prune: bool = False) -> list[str]:
    """Stale or edited files of ``robots`` under ``out``: empty when they match the models and derive.

    Other robots in ``out`` are not judged, unless ``prune``: then each is a problem
    (``generate --prune`` would remove it).
    """
    out = Path(out)
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
    return problems
