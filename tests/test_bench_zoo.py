"""`derive bench zoo`'s table on two tiny URDFs: a fixed-base row with the whole set, a floating
row above a cut-off (ID/M/FD only), and a refusal grouped with its reason."""

from __future__ import annotations

from derive.bench.zoo import QUANTITIES, cases, run_cases, section
from test_urdf import write

LINK = ('<link name="{n}"><inertial><origin xyz="0 0 -0.5"/><mass value="1"/>'
        '<inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>')
TWO_LINK = f"""<robot name="two-link">
  {LINK.format(n="base")}{LINK.format(n="a")}{LINK.format(n="b")}
  <joint name="j1" type="revolute"><parent link="base"/><child link="a"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="5" velocity="1"/></joint>
  <joint name="j2" type="revolute"><parent link="a"/><child link="b"/><origin xyz="0 0 -1"/><axis xyz="0 1 0"/>
    <limit lower="-2" upper="2" effort="5" velocity="1"/></joint>
</robot>"""
BRICK = f'<robot name="brick">{LINK.format(n="a")}</robot>'


def test_zoo_table(tmp_path, capsys):
    two, brick = str(write(tmp_path, TWO_LINK, "two.urdf")), str(write(tmp_path, BRICK, "brick.urdf"))
    todo = cases([two, brick], floating=[two])
    assert todo == [(two, False), (two, True), (brick, False)]
    lines = []
    rows = run_cases(todo, max_nv=4, log=lines.append)
    assert len(lines) == 3 and all(line.startswith("[zoo] ") for line in lines)
    fixed, floating, refused = rows
    assert (fixed.nq, fixed.nv, fixed.whole, floating.nq, floating.nv, floating.whole) == (2, 2, True, 9, 8, False)
    assert fixed.functions > floating.functions == 3
    assert all(r.ops[q] > 0 for r in (fixed, floating) for q in QUANTITIES)
    assert "no moving joint" in refused.refused
    text = section(rows, ["nosuch.urdf"], 1.0, quick=False, max_nv=4)
    assert text.startswith("## example-robot-data: whole trees\n")
    table = [line for line in text.splitlines() if line.startswith(f"| {two} ")]
    assert len(table) == 2 and "| fixed | 2 | 2 |" in table[0] and "| floating | 9 | 8 |" in table[1]
    assert "ID/M/FD only: " in table[1] and "functions)" in table[0]
    assert f"- no moving joint (a single rigid body; it imports with --floating) (1 URDF): {brick} (fixed): " in text
    assert "2 URDFs that Pinocchio loads (3 imports, fixed and floating): 1 import" in text
    assert "Not measured: 1 URDF(s)" in text
