"""The README's example runs as written, and the demo (the quick start's main job) works."""

import re
from pathlib import Path

import numpy as np

import qpcontact as qc
from qpcontact import cli

ROOT = Path(__file__).resolve().parents[1]


def test_readme_example_runs():
    block = re.findall(r"```python\n(.*?)```", (ROOT / "README.md").read_text(), re.S)[0]
    namespace: dict = {}
    exec(compile(block, "README.md", "exec"), namespace)
    result = namespace["result"]
    assert result.converged and len(result.contacts) == 1
    assert np.allclose(result.impulses[0, :3], [0.0, 0.5, 0.0], atol=1e-6)


def test_demo_prints_a_row_per_solver_and_formulation(tmp_path, capsys):
    out = tmp_path / "demo.md"
    assert cli.main(["demo", "--cells", "60", "--out", str(out)]) == 0
    text = out.read_text()
    rows = [line for line in text.splitlines() if line.startswith("| ") and not line.startswith("| solver")]
    expected = sum(len(qc.get_solver(solver).formulations) for solver in qc.available_solvers())
    assert len(rows) == expected
    assert all("| yes |" in row for row in rows if row.split("|")[1].strip() in ("linear", "mprgp", "osqp", "clarabel"))
    assert "colliding contacts" in capsys.readouterr().out


def test_cli_lists_commands_and_rejects_unknown_ones(capsys):
    assert cli.main([]) == 0
    assert "demo" in capsys.readouterr().out
    assert cli.main(["frobnicate"]) == 2
