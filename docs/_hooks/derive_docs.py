"""MkDocs hooks of derive's documentation site (mkdocs.yml: ``hooks:``).

What the site shows of derive is rendered from derive itself at build time, so it cannot drift:
- ``reference/schema.md``: every field of models.yaml, from the parser's own tables
  (:data:`derive.description.schema.SECTIONS`, the joint-type registry, the quantity lists);
- ``reference/cli.md``: every command and option, from the argparse parser (``derive.cli.build_parser``);
- ``code/functions/<quantity>.md``: one page per generated quantity, from the shipped
  ``generated/<robot>/manifest.json`` files and the C headers (signature, shapes, conventions,
  operation counts, Cortex-M figures).

And every fenced block marked ``run`` (```` ```bash run ```` or ```` ```python run ````) is executed when
the page is built, in a fresh temporary folder per page (the blocks of one page share it, in order),
with this Python's ``derive`` first on PATH; a failing block, or a page whose blocks take longer than
:data:`PAGE_SECONDS`, fails the build. ```` ```bash run show ```` also prints the block's output below it.
A page whose front matter says ``execute: true`` (a tutorial) must mark every shell or Python block
``run`` or ``norun`` (the latter for what cannot run in a build, such as installing a wheel).
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import re
import subprocess
import sys
import tempfile
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

from mkdocs.exceptions import PluginError
from mkdocs.structure.files import File
from mkdocs.utils.meta import get_data

ROOT = Path(__file__).resolve().parents[2]
PAGE_SECONDS = 60.0
"""The most CPU time an executed page (a tutorial) may take, all its blocks together (user + system
time of the processes they start: on a machine shared with other work the wall time says little)."""
BLOCK_SECONDS = 120.0
"""A block still running after this long is stopped (and fails the build)."""

log = logging.getLogger("mkdocs.plugins.derive_docs")

FENCE = re.compile(r"^(?P<indent>[ ]*)```(?P<lang>[A-Za-z0-9_+-]*)(?P<opts>[^\n`]*)\n(?P<body>.*?)^(?P=indent)```[ ]*$",
                   re.M | re.S)
SHELLS = {"bash", "sh", "shell", "console"}
RUNNABLE = SHELLS | {"python", "py"}


# --------------------------------------------------------------------------- generated pages

def _derive():
    sys.path.insert(0, str(ROOT)) if str(ROOT) not in sys.path else None
    import derive  # noqa: F401  (the checkout's derive, or the installed one)
    return derive


def schema_markdown() -> str:
    """The models.yaml reference: one table per mapping of :data:`derive.description.schema.SECTIONS`."""
    _derive()
    from derive.description.joints import COORDINATE_SUFFIXES, JOINT_TYPES
    from derive.description.robot import BASES, BUNDLE_FRAME_QUANTITIES, BUNDLE_QUANTITIES, FUNCTION_QUANTITIES
    from derive.description.schema import SECTIONS

    out = ["# models.yaml reference", "",
           "Generated from the tables the parser checks keys against (`derive.description.schema.SECTIONS`): "
           "a key not listed here is refused with one line naming the robot and the field. "
           "A guide with examples is [Writing a model](../guide/models.md).", ""]
    for s in SECTIONS.values():
        out += [f"## {s.name}", "", f"`{s.where}`: {s.doc}", "", "| key | meaning |", "|---|---|"]
        out += [f"| `{k}` | {v.replace('|', '&#124;')} |" for k, v in s.fields.items()]
        out.append("")
    out += ["## Allowed values", "", "| field | values |", "|---|---|",
            f"| `base` | {', '.join(f'`{b}`' for b in BASES)} |",
            "| `joints[i].type` | " + ", ".join(f"`{t}` ({d} DOF)" for t, d in JOINT_TYPES.items()) + " |",
            "| coordinates of multi-DOF joints | " + "; ".join(
                f"{t}: " + ", ".join(f"`<joint>_{x}`" for x in xs) for t, xs in COORDINATE_SUFFIXES.items()) + " |",
            "| `bundles[i].quantities` | " + ", ".join(f"`{q}`" for q in BUNDLE_QUANTITIES) + ", and "
            + ", ".join(f"`{q}_<frame>`" for q in BUNDLE_FRAME_QUANTITIES) + " |",
            "| `generate.quantities` | " + ", ".join(f"`{q}`" for q in FUNCTION_QUANTITIES) + " |", ""]
    return "\n".join(out)


def _option_row(action: argparse.Action) -> str:
    if action.option_strings:
        name = ", ".join(f"`{o}`" for o in action.option_strings)
        if action.nargs != 0:
            metavar = action.metavar or (action.dest.upper() if not action.choices else
                                         "{" + ",".join(map(str, action.choices)) + "}")
            metavar = " ".join(metavar) if isinstance(metavar, tuple) else metavar
            more = " ..." if action.nargs in ("+", "*") else ""
            name += f" `{metavar}{more}`"
    else:
        name = f"`{action.metavar or action.dest}`"
    text = (action.help or "").replace("%(default)s", str(action.default)).replace("%%", "%")
    text = " ".join(text.split()).replace("|", "&#124;")
    if action.default not in (None, False, argparse.SUPPRESS) and "default" not in text and action.option_strings:
        text += f" (default: `{action.default}`)"
    return f"| {name} | {text} |"


def _parser_section(prog: str, parser: argparse.ArgumentParser, summary: str, level: int, out: list[str]) -> None:
    out += [f"{'#' * level} {prog}", ""]
    if summary:
        out += [summary[0].upper() + summary[1:] + ".", ""]
    os.environ["COLUMNS"] = "100"
    out += ["```text", parser.format_usage().strip(), "```", ""]
    if parser.description and parser.description != summary:
        out += [" ".join(parser.description.split()), ""]
    rows, subs = [], []
    for action in parser._actions:
        if isinstance(action, argparse._HelpAction) or action.help == argparse.SUPPRESS:
            continue
        if isinstance(action, argparse._SubParsersAction):
            helps = {a.dest: a.help or "" for a in action._choices_actions}
            subs += [(name, p, helps.get(name, "")) for name, p in action.choices.items()]
            continue
        rows.append(_option_row(action))
    if rows:
        out += ["| argument | meaning |", "|---|---|", *rows, ""]
    if parser.epilog:
        out += ["```text", parser.epilog.strip(), "```", ""]
    for name, sub, helptext in subs:
        _parser_section(f"{prog} {name}", sub, helptext, level + 1, out)


def cli_markdown() -> str:
    """Every command of ``derive`` with its usage and options, from the argparse parser itself."""
    _derive()
    from derive.cli import build_parser

    parser = build_parser()
    out = ["# Command-line reference", "",
           "Generated from `derive`'s argparse parser when the site is built (`derive COMMAND --help` prints "
           "the same). Conventions shared by every command are in [The command line](../guide/cli.md).", ""]
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            out += ["| command | what it does |", "|---|---|"]
            out += [f"| [`{a.dest}`](#derive-{a.dest}) | {a.help} |" for a in action._choices_actions]
            out.append("")
    _parser_section("derive", parser, "", 2, out)
    return "\n".join(out)


# ---- generated functions, from the manifests

def _manifests() -> dict[str, dict]:
    out = {}
    for path in sorted((ROOT / "generated").glob("*/manifest.json")):
        out[path.parent.name] = json.loads(path.read_text())
    return out


def _prototype(robot: str, fn: dict) -> str:
    header = ROOT / "generated" / robot / fn["c"]["header"]
    m = re.search(r"^DERIVE_FN [^\n]*\b" + re.escape(fn["name"]) + r"\([^)]*\);", header.read_text(), re.M)
    return " ".join(m.group(0).split()) if m else ""


def _shape(shape) -> str:
    return " x ".join(map(str, shape)) if shape else "scalar"


def quantity_pages() -> dict[str, str]:
    """``code/functions/<quantity>.md`` for every quantity of the shipped robots' manifests, and the index."""
    manifests = _manifests()
    by_quantity: dict[str, list[tuple[str, dict]]] = {}
    for robot, m in manifests.items():
        for fn in m["functions"]:
            by_quantity.setdefault(fn["quantity"], []).append((robot, fn))
    conventions: dict[str, str] = {}
    for m in manifests.values():
        conventions.update(m.get("conventions", {}))
    pages: dict[str, str] = {}
    index = ["# Generated functions", "",
             "One page per quantity, rendered from the shipped robots' `generated/<robot>/manifest.json` and C "
             "headers when the site is built. Layout, calling conventions and build files: "
             "[Generated code](../index.md).", "", "| quantity | functions | robots |", "|---|---|---|"]
    for quantity in sorted(by_quantity):
        entries = by_quantity[quantity]
        robots = sorted({r for r, _ in entries})
        index.append(f"| [`{quantity}`]({quantity}.md) | {len(entries)} | {', '.join(robots)} |")
        page = [f"# {quantity}", ""]
        conv = conventions.get(quantity) or conventions.get(quantity.split("_")[0])
        if conv:
            page += [f"Convention (manifest `conventions.{quantity if quantity in conventions else quantity.split('_')[0]}`):"
                     f" {conv}.", ""]
        if "matrices" in conventions:
            page += [f"Matrices are stored {conventions['matrices']}; a vector is an n x 1 output.", ""]
        for robot, fn in entries:
            m = manifests[robot]
            page += [f"## {fn['name']}", "", f"Robot `{robot}` (nq = {m['nq']}, nv = {m['nv']})"
                     + (f", frame `{fn['frame']}`" if fn.get("frame") else "")
                     + (f", algorithm: {fn['algorithm']}" if fn.get("algorithm") else "") + ".", ""]
            proto = _prototype(robot, fn)
            if proto:
                page += ["```c", proto, "```", ""]
            py = fn.get("python")
            if py:
                rets = ", ".join(f"{r['name']} {_shape(r.get('shape'))}" for r in py["returns"])
                page += [f"Python: `{py['function']}` in `{py['module']}` returns {rets}."
                         + (f" JAX: `{fn['jax']['function']}` in `{fn['jax']['module']}`." if fn.get("jax") else
                            " JAX: not provided."), ""]
            page += ["| argument | direction | shape | C length |", "|---|---|---|---|"]
            lengths = {a["name"]: a["length"] for a in fn["c"].get("reads", []) + fn["c"].get("writes", [])}
            page += [f"| `{a['name']}` | in | {_shape(a['shape'])} | {lengths.get(a['name'], '')} |" for a in fn["inputs"]]
            page += [f"| `{a['name']}` | out | {_shape(a['shape'])} | {lengths.get(a['name'], '')} |" for a in fn["outputs"]]
            page.append("")
            ops = fn.get("ops")
            if ops:
                page += ["Operations after CSE: " + ", ".join(f"{k} {v}" for k, v in ops.items()) + ".", ""]
            if fn.get("calls"):
                page += ["Calls: " + ", ".join(f"`{c}`" for c in fn["calls"]) + " (compile them too).", ""]
            fw = m.get("firmware", {}).get("functions", {}).get(fn["name"])
            if fw:
                page += ["Cortex-M, arm-none-eabi-gcc, bytes: text -O2 / stack -O2 / stack -O0:", "",
                         "| target | double | float |", "|---|---|---|"]
                for target in ("cortex-m4f", "cortex-m7"):
                    if target in fw:
                        cells = [" / ".join(str(fw[target][p][k]) for k in ("text_O2", "stack_O2", "stack_O0"))
                                 for p in ("double", "float")]
                        page.append(f"| {target} | {cells[0]} | {cells[1]} |")
                page.append("")
        pages[f"code/functions/{quantity}.md"] = "\n".join(page)
    pages["code/functions/index.md"] = "\n".join(index + [""])
    return pages


def generated_pages() -> dict[str, str]:
    """Every page this hook renders: path under docs/ -> Markdown."""
    return {"reference/schema.md": schema_markdown(), "reference/cli.md": cli_markdown(), **quantity_pages()}


def on_config(config):
    """Lists the per-quantity pages under Generated code > Functions (their names come from the manifests)."""
    quantities = sorted({fn["quantity"] for m in _manifests().values() for fn in m["functions"]})
    for section in config["nav"]:
        if isinstance(section, dict) and "Generated code" in section:
            for entry in section["Generated code"]:
                if isinstance(entry, dict) and entry.get("Functions") == "code/functions/index.md":
                    entry["Functions"] = ["code/functions/index.md"] + [f"code/functions/{q}.md" for q in quantities]
    return config


EMBEDDED_VIEWS = {"guide/panda_view.html": ["panda", "--q", "0", "-0.6", "0", "-2.2", "0", "1.6", "0.8"]}
"""Pages of `derive view ROBOT ... --html` the site embeds (docs/guide/viewer.md), written at build time."""


def viewer_exports() -> dict[str, str]:
    """{site path: the self-contained HTML page `derive view` writes} for :data:`EMBEDDED_VIEWS`."""
    out = {}
    with tempfile.TemporaryDirectory(prefix="derive-docs-view-") as tmp:
        for path, argv in EMBEDDED_VIEWS.items():
            page = Path(tmp) / Path(path).name
            done = subprocess.run([sys.executable, "-m", "derive", "view", *argv, "--html", str(page)], cwd=tmp,
                                  env=_environment(Path(tmp), sys.executable), capture_output=True, text=True)
            if done.returncode != 0:
                raise PluginError(f"derive view {' '.join(argv)} --html: exit {done.returncode}: {done.stderr.strip()}")
            out[path] = page.read_text()
    return out


def on_files(files, config):
    for path, text in generated_pages().items():
        files.append(File.generated(config, path, content=text))
    for path, text in viewer_exports().items():
        files.append(File.generated(config, path, content=text))
    _start_executing(files)
    return files


# --------------------------------------------------------------------------- executed snippets

def _environment(workdir: Path, python: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if not k.startswith("DERIVE_") and k != "PYTHONPATH"}
    env["PATH"] = os.pathsep.join([str(Path(python).parent), env.get("PATH", "")])
    env["MPLBACKEND"] = "Agg"
    env["PYTHONDONTWRITEBYTECODE"] = "1"
    env["HOME"] = str(workdir / "home")  # derive.compiled's cache and anything else stays in the folder
    return env


def run_blocks(markdown: str, name: str, required: bool = False,
               python: str | None = None) -> tuple[str, list[tuple[str, float]]]:
    """Execute the page's ``run`` blocks in order in one temporary folder, with ``python`` (default:
    the one building the site) for Python blocks and its folder's ``derive`` first on PATH (so
    tests/test_installed.py runs the Getting started page on the installed wheel); return the
    Markdown as it is shown (markers removed, outputs inserted) and the time per block. Raises
    PluginError on a failing block, an unmarked block on a ``required`` page, or a page over
    :data:`PAGE_SECONDS`."""
    python = python or sys.executable
    times: list[tuple[str, float]] = []
    with tempfile.TemporaryDirectory(prefix="derive-docs-") as tmp:
        workdir = Path(tmp)
        (workdir / "home").mkdir()
        env = _environment(workdir, python)

        def replace(match: re.Match) -> str:
            lang, opts = match["lang"], match["opts"].split()
            indent, body = match["indent"], match["body"]
            if lang not in RUNNABLE:
                return match.group(0)
            if "run" not in opts:
                if required and "norun" not in opts:
                    raise PluginError(f"{name}: a {lang} block is marked neither `run` nor `norun` (a tutorial runs "
                                      f"every block):\n{body}")
                return f"{indent}```{lang}\n{body}{indent}```"
            code = "\n".join(line[len(indent):] for line in body.splitlines())
            command = (["bash", "-euo", "pipefail", "-c", code] if lang in SHELLS else [python, "-c", code])
            usage = workdir / "cpu-seconds"
            try:  # through _TIMED, which reports the CPU time of the block's processes (pages run in parallel)
                done = subprocess.run([sys.executable, "-c", _TIMED, str(usage), *command], cwd=workdir, env=env,
                                      capture_output=True, text=True, timeout=BLOCK_SECONDS, stdin=subprocess.DEVNULL)
            except subprocess.TimeoutExpired:
                raise PluginError(f"{name}: a {lang} block ran past {BLOCK_SECONDS:.0f} s:\n{code}") from None
            seconds = float(usage.read_text()) if usage.exists() else 0.0
            usage.unlink(missing_ok=True)
            times.append((code.splitlines()[0] if code.strip() else "", seconds))
            if done.returncode != 0:
                raise PluginError(f"{name}: a {lang} block failed (exit {done.returncode}):\n{code}\n--- output:\n"
                                  f"{(done.stdout + done.stderr)[-3000:]}")
            shown = f"{indent}```{lang}\n{body}{indent}```"
            if "show" in opts and done.stdout.strip():
                output = "\n".join(indent + line for line in done.stdout.rstrip().splitlines())
                shown += f"\n\n{indent}```text\n{output}\n{indent}```"
            return shown

        markdown = FENCE.sub(replace, markdown)
    total = sum(t for _, t in times)
    if total > PAGE_SECONDS:
        raise PluginError(f"{name}: its executed blocks took {total:.1f} s of CPU time, more than the "
                          f"{PAGE_SECONDS:.0f} s a tutorial may take")
    return markdown, times


_TIMED = """import resource, subprocess, sys
code = subprocess.call(sys.argv[2:])
usage = resource.getrusage(resource.RUSAGE_CHILDREN)
open(sys.argv[1], "w").write(repr(usage.ru_utime + usage.ru_stime))
sys.exit(code)
"""
"""Runs a command and writes the CPU time (user + system) of it and its descendants to a file."""

_RUNS: dict[str, Future] = {}


def _start_executing(files) -> None:
    """Executes the blocks of every page that has some, pages in parallel (each in its own folder)."""
    _RUNS.clear()
    pool = ThreadPoolExecutor(max_workers=max(1, min(4, os.cpu_count() or 1)))
    for file in files.documentation_pages():
        if file.generated_by:
            continue
        markdown, meta = get_data(file.content_string)
        if re.search(r"^[ ]*```[A-Za-z0-9_+-]+[^\n`]*\brun\b", markdown, re.M) or meta.get("execute"):
            _RUNS[file.src_uri] = pool.submit(run_blocks, markdown, file.src_uri, bool(meta.get("execute")))
    pool.shutdown(wait=False)


def on_page_markdown(markdown, page, config, files):
    required = bool(page.meta.get("execute"))
    if "```" not in markdown:
        return markdown
    run = _RUNS.pop(page.file.src_uri, None)
    markdown, times = run.result() if run is not None else run_blocks(markdown, page.file.src_uri, required)
    if times:
        log.info("%s: %d block(s) executed in %.1f s of CPU time", page.file.src_uri, len(times),
                 sum(t for _, t in times))
    return markdown

