"""The documentation site's generated pages say what derive does: the models.yaml schema page lists
exactly the keys the parser accepts, the CLI page every command, the function pages every function of
the shipped manifests; and the snippet runner fails on a failing or unmarked block.

The site itself (`make docs`, mkdocs build --strict with every tutorial executed) is built by .ci/run.
"""

from __future__ import annotations

import ast
import copy
import importlib.util
import json
import re
from pathlib import Path

import pytest
import yaml

from derive.description.model import parse_models
from derive.description.robot import ModelError
from derive.description.schema import SECTIONS

ROOT = Path(__file__).resolve().parent.parent
_spec = importlib.util.spec_from_file_location("derive_docs_hooks", ROOT / "docs" / "_hooks" / "derive_docs.py")
hooks = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(hooks)

ARM = {"robots": {"arm": {
    "parameters": {"L": 0.3},
    "links": [{"name": "base"},
              {"name": "l1", "mass": {"param": "m1", "default": 1.0}, "inertia": {"ixx": 0.1, "iyy": 0.1, "izz": 0.1}},
              {"name": "l2", "mass": 0.5, "inertia": [0.01, 0.01, 0.01], "visual": [{"box": [0.1, 0.02, 0.02]}]}],
    "joints": [{"name": "j1", "type": "revolute", "parent": "base", "child": "l1", "axis": [0, 0, 1],
                "origin": {"xyz": [0, 0, 0.1]}, "limits": {"lower": -1, "upper": 1}, "actuator": {"viscous": 0.1}},
               {"name": "j2", "type": "revolute", "parent": "l1", "child": "l2", "mimic": {"joint": "j1"}}],
    "frames": [{"name": "tcp", "link": "l2", "xyz": ["L", 0, 0]}],
    "bundles": [{"name": "tick", "quantities": ["mass_matrix"]}],
    "generate": {"quantities": ["mass_matrix"]},
}}}
DH = {"robots": {"dh_arm": {"dh": {"convention": "standard", "rows": [
    {"joint": "q1", "type": "revolute", "a": 0.5, "link": "link1", "mass": 1.0, "inertia": [0.1, 0.1, 0.1]}]}}}}
# a closed chain: the shipped four-bar
LOOP = {"robots": {"fourbar": yaml.safe_load((ROOT / "models.yaml").read_text())["robots"]["fourbar"]}}

# a floating body with a leg and a foot contact
LEGGED = {"robots": {"legged": {
    "base": "floating",
    "links": [{"name": "body", "mass": 2.0, "inertia": [0.1, 0.1, 0.1]}, {"name": "leg", "mass": 0.5}],
    "joints": [{"name": "hip", "type": "revolute", "parent": "body", "child": "leg", "axis": [0, 1, 0]}],
    "frames": [{"name": "foot", "link": "leg", "xyz": [0, 0, -0.3]}],
    "contacts": [{"frame": "foot", "kind": "point"}],
}}}

# where each section's mapping sits in the models above
PLACES = {
    "file": (ARM, ()), "robot": (ARM, ("robots", "arm")), "link": (ARM, ("robots", "arm", "links", 1)),
    "inertia": (ARM, ("robots", "arm", "links", 1, "inertia")), "joint": (ARM, ("robots", "arm", "joints", 0)),
    "origin": (ARM, ("robots", "arm", "joints", 0, "origin")), "limits": (ARM, ("robots", "arm", "joints", 0, "limits")),
    "actuator": (ARM, ("robots", "arm", "joints", 0, "actuator")), "mimic": (ARM, ("robots", "arm", "joints", 1, "mimic")),
    "frame": (ARM, ("robots", "arm", "frames", 0)), "bundle": (ARM, ("robots", "arm", "bundles", 0)),
    "generate": (ARM, ("robots", "arm", "generate")), "parameter": (ARM, ("robots", "arm", "links", 1, "mass")),
    "loop": (LOOP, ("robots", "fourbar", "loops", 0)), "visual": (ARM, ("robots", "arm", "links", 2, "visual", 0)),
    "contact": (LEGGED, ("robots", "legged", "contacts", 0)),
    "dh": (DH, ("robots", "dh_arm", "dh")), "dh_row": (DH, ("robots", "dh_arm", "dh", "rows", 0)),
}


def test_the_two_test_models_are_valid():
    assert set(parse_models(yaml.safe_dump(ARM))) == {"arm"}
    assert set(parse_models(yaml.safe_dump(DH))) == {"dh_arm"}


@pytest.mark.parametrize("section", sorted(SECTIONS))
def test_parser_accepts_exactly_the_keys_of_its_table(section):
    """An unknown key in each mapping is refused, and the error lists the table's keys: the parser's
    allowed set is the documented one, section by section."""
    model, path = PLACES[section]
    data = copy.deepcopy(model)
    target = data
    for step in path:
        target = target[step]
    target["not_a_field"] = 1
    with pytest.raises(ModelError, match=re.escape(f"expected one of: {', '.join(sorted(SECTIONS[section].keys))})")):
        parse_models(yaml.safe_dump(data))


def test_every_place_of_the_parser_checks_keys_against_the_tables():
    """No key set is written inline: every check_keys call passes keys("<section>") of a known section."""
    sections_used = set()
    for name in ("model.py", "dh.py"):
        tree = ast.parse((ROOT / "derive" / "description" / name).read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.Call) and getattr(node.func, "attr", getattr(node.func, "id", "")) in (
                    "check_keys", "_check_keys"):
                allowed = node.args[-1]
                if isinstance(allowed, ast.Name) and allowed.id == "allowed":  # the method passing its argument on
                    continue
                assert isinstance(allowed, ast.Call) and getattr(allowed.func, "id", "") == "keys", (name, node.lineno)
                sections_used.add(allowed.args[0].value)
    assert sections_used == set(SECTIONS)


def test_schema_page_lists_every_key_the_validator_accepts():
    page = hooks.schema_markdown()
    parts = re.split(r"^## ", page, flags=re.M)
    listed = {p.split("\n", 1)[0]: set(re.findall(r"^\| `([a-z_0-9]+)` \|", p, re.M)) for p in parts[1:]}
    for name, section in SECTIONS.items():
        assert listed[name] == set(section.keys), name


def test_cli_page_lists_every_command_and_option():
    from derive.cli import build_parser
    import argparse

    page = hooks.cli_markdown()
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    for name, p in sub.choices.items():
        assert f"## derive {name}\n" in page, name
        for action in p._actions:
            if isinstance(action, argparse._HelpAction):
                continue
            for option in action.option_strings:
                assert f"`{option}`" in page, (name, option)


def test_function_pages_list_every_generated_function():
    pages = hooks.quantity_pages()
    for manifest in sorted((ROOT / "generated").glob("*/manifest.json")):
        for fn in json.loads(manifest.read_text())["functions"]:
            page = pages[f"code/functions/{fn['quantity']}.md"]
            assert f"## {fn['name']}\n" in page
            assert f"`{fn['name']}`" in pages["code/functions/index.md"] or fn["quantity"] in pages["code/functions/index.md"]


def test_snippets_run_in_order_and_a_failing_one_fails_the_build():
    ok = "```bash run show\necho 41 > n\n```\n\n```python run show\nprint(int(open('n').read()) + 1)\n```\n"
    shown, times = hooks.run_blocks(ok, "ok.md")
    assert "```text\n42\n```" in shown and "run" not in shown.replace("run show", "").split("```")[1]
    assert len(times) == 2
    with pytest.raises(hooks.PluginError, match=r"bad.md: a bash block failed \(exit 3\)"):
        hooks.run_blocks("```bash run\nexit 3\n```\n", "bad.md")
    with pytest.raises(hooks.PluginError, match="marked neither `run` nor `norun`"):
        hooks.run_blocks("```bash\nls\n```\n", "tutorial.md", required=True)
    assert hooks.run_blocks("```bash norun\nrm -rf /nothing\n```\n", "t.md", required=True)[0] == \
        "```bash\nrm -rf /nothing\n```\n"


def test_the_viewer_guide_embeds_the_pages_the_build_writes():
    """Every `derive view --html` page the build writes (EMBEDDED_VIEWS) is shown by an iframe of the guide,
    and every iframe of the docs shows one of them (a missing page would be a blank frame, not a warning)."""
    shown = {m for page in (ROOT / "docs").rglob("*.md")
             for m in re.findall(r'<iframe src="\.\./([^"]+)"', page.read_text())}
    assert shown == {Path(p).name for p in hooks.EMBEDDED_VIEWS} and shown
    assert all(p.startswith("guide/") for p in hooks.EMBEDDED_VIEWS)  # beside guide/viewer/, which ../ leaves
