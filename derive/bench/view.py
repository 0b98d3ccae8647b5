"""Benchmark ``view_meshes``: ``derive view --html`` pages of robots with meshes, in headless chromium.

For the Panda and the UR5 of example-robot-data (imported with their ``<visual>`` DAE meshes into a
temporary models file; the meshes stay in the installed package), in one run:

- the page's size and the mesh triangles (the file's, and at most :data:`derive.view.page.PAGE_TRIANGLES`
  on the page), and the wall time of ``derive view ROBOT --html`` (reading the DAE files, thinning);
- the page's draw time in Debian's chromium (headless, no GPU): the median of 15 redraws, each after
  turning the camera a little, against the same page without meshes (``--no-meshes``) measured alike.

Both run through the command line (``python -m derive``) and chromium as subprocesses; nothing of
the meshes is kept.
"""

from __future__ import annotations

import base64
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from derive.description.urdf import example_robot_data_dir

PACKAGE = Path(__file__).resolve().parent.parent  # this derive, which the subprocesses run

ROBOTS = {
    "panda": (["example-robot-data:panda_description/urdf/panda.urdf", "--tip", "panda_hand_tcp", "--lock",
               "panda_finger_joint1,panda_finger_joint2"], ["0", "-0.6", "0", "-2.2", "0", "1.6", "0.8"]),
    "ur5": (["example-robot-data:ur_description/urdf/ur5_robot.urdf", "--tip", "tool0"],
            ["0", "-1.2", "1.4", "-1.8", "-1.5", "0"]),
}
"""Robot -> (import-urdf arguments, the --q shown)."""
REDRAWS = 15
HARNESS = """draw();
const times = [];
for (let i = 0; i < %d; i++) { const t0 = performance.now(); cam.az += 0.05; draw(); times.push(performance.now() - t0); }
times.sort((a, b) => a - b); document.body.dataset.median = times[times.length >> 1].toFixed(1);
</script>""" % REDRAWS


def _derive(*argv: str, cwd: Path) -> tuple[str, float]:
    start = time.perf_counter()
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(PACKAGE.parent), os.environ.get("PYTHONPATH", "")]))
    done = subprocess.run([sys.executable, "-m", "derive", *argv], cwd=cwd, capture_output=True, text=True, env=env)
    if done.returncode != 0:
        raise RuntimeError(f"derive {' '.join(argv)}: {done.stderr.strip()}")
    return done.stdout + done.stderr, time.perf_counter() - start


def _draw_ms(chromium: str, page: Path) -> float:
    """Median ms of a redraw of ``page`` in headless chromium (the page with a timing loop appended)."""
    timed = page.with_name(page.stem + "_timed.html")
    timed.write_text(page.read_text().replace("draw();\n</script>", HARNESS, 1))
    done = subprocess.run([chromium, "--headless", "--no-sandbox", "--disable-gpu", "--window-size=800,600",
                           "--virtual-time-budget=60000", "--dump-dom", timed.as_uri()],
                          capture_output=True, text=True, timeout=300)
    found = re.search(r'data-median="([0-9.]+)"', done.stdout)
    if not found:
        raise RuntimeError(f"chromium gave no draw time for {page.name}: {done.stderr[-500:]}")
    return float(found.group(1))


def _page_triangles(page: Path) -> int:
    """The triangles a page holds (its JSON's meshes)."""
    text = page.read_text()
    start = text.index("const D = ") + len("const D = ")
    data = json.loads(text[start:text.index(";\nconst LAYERS", start)].replace("<\\/", "</"))
    return sum(len(base64.b64decode(m["f"])) // (12 if m["wide"] else 6) for m in data["meshes"])


def view_meshes(args) -> str:
    chromium = shutil.which("chromium") or shutil.which("chromium-browser")
    out = ["## derive view --html with meshes (example-robot-data, headless chromium)", ""]
    if example_robot_data_dir() is None or chromium is None:
        return "\n".join(out + ["Skipped: needs example-robot-data (the pinocchio extra) and Debian's chromium."]) + "\n"
    out += ["Each robot imported with its `<visual>` DAE meshes; the page at the --q shown; draw time: the median of "
            f"{REDRAWS} redraws in headless chromium (no GPU, 800x600), against the same page without meshes.", "",
            "| robot | mesh triangles (file / page) | page KiB | `derive view --html` s | draw ms | without meshes: KiB, draw ms |",
            "|---|---|---|---|---|---|"]
    with tempfile.TemporaryDirectory(prefix="derive-bench-view-") as tmp:
        folder = Path(tmp)
        for robot, (source, q) in ROBOTS.items():
            models = folder / f"{robot}.yaml"
            _derive("import-urdf", *source, "--out", str(models), cwd=folder)
            page, plain = folder / f"{robot}.html", folder / f"{robot}_plain.html"
            said, seconds = _derive("--models", str(models), "view", robot, "--q", *q, "--html", str(page), cwd=folder)
            _derive("--models", str(models), "view", robot, "--q", *q, "--no-meshes", "--html", str(plain), cwd=folder)
            triangles = re.search(r"(\d+) mesh triangles", said)
            out.append(f"| {robot} | {int(triangles.group(1)) if triangles else 0} / {_page_triangles(page)} | "
                       f"{page.stat().st_size / 1024:.0f} | {seconds:.1f} | {_draw_ms(chromium, page):.1f} | "
                       f"{plain.stat().st_size / 1024:.0f}, {_draw_ms(chromium, plain):.1f} |")
    return "\n".join(out) + "\n"


def benchmarks() -> dict:
    return {"view_meshes": view_meshes}
