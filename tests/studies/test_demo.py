"""The demo (the quick start's main job): a row per installed solver and formulation."""

from __future__ import annotations

import qpcontact as qc
from qpcontact import cli
from qpcontact.studies import demo


def test_demo_prints_a_row_per_solver_and_formulation(tmp_path, capsys):
    assert cli.main(["demo", "--cells", "60", "--out", str(tmp_path)]) == 0
    text = (tmp_path / "demo.md").read_text()
    rows = [line for line in text.splitlines() if line.startswith("| ") and not line.startswith("| solver")]
    expected = [(solver, formulation) for solver in qc.available_solvers()
                for formulation in qc.get_solver(solver).formulations]
    assert [tuple(cell.strip() for cell in row.split("|")[1:3]) for row in rows] == expected
    bundled = [row for row in rows if qc.get_solver(row.split("|")[1].strip()).bundled]
    assert {row.split("|")[1].strip() for row in bundled} == {"linear", "mprgp", "ipm", "osqp", "clarabel"}
    assert all("| yes |" in row for row in bundled)
    printed = capsys.readouterr().out
    assert "colliding contacts" in printed and f"wrote:\n  {tmp_path / 'demo.md'}" in printed


def test_demo_in_3d(tmp_path):
    assert cli.main(["demo", "--cells", "40", "--dimensions", "3", "--out", str(tmp_path)]) == 0
    assert (tmp_path / "demo.md").read_text().startswith("3D colony, 40 cells")


def test_the_demo_is_the_command_of_its_module():
    assert cli.COMMANDS["demo"][0] == demo.__name__
