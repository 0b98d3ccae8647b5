"""The package's structure: stages import one way, no cycles, no hidden or private imports.

The flow is description -> symbolic -> codegen -> files, with the numeric reference beside
symbolic (it shares only the description), and inspect, analysis, solvers on top, then
figures (plot), benchmarks (bench), the viewer (view) and the command line (cli). A module may import its own
package and the packages listed for it below, nothing else of derive.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "derive"
BASE = {"errors", "resources", "filesystem"}
ALLOWED = {
    "errors": set(),
    "resources": set(),
    "filesystem": {"errors"},
    "description": BASE,
    "symbolic": BASE | {"description"},
    "reference": BASE | {"description"},
    "codegen": BASE | {"description", "symbolic"},
    "inspect": BASE | {"description", "symbolic", "codegen"},
    "analysis": BASE | {"description", "symbolic"},
    "solvers": BASE | {"description", "symbolic", "codegen", "reference"},
    "runtime": BASE | {"description", "codegen"},
    "plot": BASE | {"description", "symbolic", "inspect", "analysis", "solvers"},
    "bench": BASE | {"description", "symbolic", "codegen", "reference", "inspect", "analysis", "solvers", "runtime"},
    "view": BASE | {"description", "codegen", "reference", "solvers", "runtime"},
    "cli": BASE | {"description", "symbolic", "codegen", "reference", "inspect", "analysis", "solvers", "plot", "bench",
                   "runtime", "view"},
    "__init__": BASE | {"description", "symbolic", "inspect", "runtime"},
    "__main__": {"cli"},
}
DEFERRED_OK = {"matplotlib", "scipy"}  # heavy optional dependencies, imported where used on purpose
# derive modules imported inside a function on purpose, by the module importing them: the package's
# names for type checkers only (derive/__init__.py loads them on first use), and generate's code
# generation after the models file is read (a bad file is refused before CasADi loads)
DEFERRED_DERIVE = {
    "derive.__init__": {"derive.description.model", "derive.description.robot", "derive.inspect.sympy_model",
                        "derive.runtime", "derive.symbolic.model"},
    "derive.cli.generate": {"derive.codegen.generate"},
}
GENERATION = ("description", "symbolic", "codegen", "errors", "resources", "filesystem")


def modules() -> dict[str, Path]:
    out = {}
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE.parent).with_suffix("")
        parts = list(rel.parts)
        if parts[-1] == "__init__" and len(parts) > 2:
            parts = parts[:-1]
        out[".".join(parts)] = path
    return out


def stage(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def imports(path: Path) -> list[tuple[str, list[str], bool]]:
    """(module, names, at module top?) of every import of derive in a file."""
    tree = ast.parse(path.read_text())
    top = set(map(id, tree.body))
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module:
            assert node.level == 0, f"{path}: relative import of {node.module}"
            out.append((node.module, [a.name for a in node.names], id(node) in top))
        elif isinstance(node, ast.Import):
            out += [(a.name, [], id(node) in top) for a in node.names]
    return out


def derive_imports(path: Path) -> list[tuple[str, list[str], bool]]:
    return [(m, names, top) for m, names, top in imports(path) if m == "derive" or m.startswith("derive.")]


def test_every_stage_is_listed():
    assert {stage(m) for m in modules()} <= set(ALLOWED)


@pytest.mark.parametrize("module", sorted(modules()))
def test_imports_run_one_way(module):
    """A module imports only its own stage and the stages below it."""
    own = stage(module)
    for target, names, _ in derive_imports(modules()[module]):
        targets = [target] if target != "derive" else [f"derive.{n}" for n in names]
        for t in targets:
            assert stage(t) == own or stage(t) in ALLOWED[own], f"{module} imports {t} (stage {stage(t)})"


@pytest.mark.parametrize("module", sorted(modules()))
def test_no_private_or_hidden_imports(module):
    """No underscore names taken from another module; derive and other imports at module top, except
    matplotlib and scipy, which stay deferred on purpose."""
    for target, names, top in imports(modules()[module]):
        if target.startswith("derive"):
            assert not [n for n in names if n.startswith("_")], f"{module} imports private {names} from {target}"
        if not top and target.split(".")[0] not in DEFERRED_OK:
            assert not target.startswith("derive") or target in DEFERRED_DERIVE.get(module, ()), \
                f"{module}: import of {target} inside a function"


def test_no_import_cycles():
    mods = modules()
    graph = {m: set() for m in mods}
    for m, path in mods.items():
        for target, names, _ in derive_imports(path):
            for t in ([target] if target != "derive" else [f"derive.{n}" for n in names]):
                if t in mods and t != m:
                    graph[m].add(t)
    # a package's __init__ re-exporting its modules is not a cycle of the stages: judge modules only
    state: dict[str, int] = {}

    def visit(m, trail):
        state[m] = 1
        for t in sorted(graph[m]):
            if state.get(t) == 1:
                raise AssertionError("import cycle: " + " -> ".join(trail[trail.index(t):] + [t]))
            if t not in state:
                visit(t, trail + [t])
        state[m] = 2

    for m in sorted(graph):
        if m not in state:
            visit(m, [m])


def test_generation_depends_only_on_its_stages():
    """What `derive generate` imports is what its hash covers (codegen.generate.GENERATOR_SOURCES)."""
    from derive.codegen.generate import GENERATOR_SOURCES

    covered = {s.removesuffix(".py") for s in GENERATOR_SOURCES}
    assert covered == set(GENERATION)
    for module, path in modules().items():
        if stage(module) in GENERATION:
            for target, names, _ in derive_imports(path):
                assert stage(target) in GENERATION, f"{module} imports {target}, which the generator hash does not cover"
