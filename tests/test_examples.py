"""Every script in examples/ runs at its defaults (the size a user would try; each under ~20 s
here) and does what it says. Only the output folder is given (a temporary one)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

from qpcontact.timestep import PositionSettings

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"


def run_example(name: str, *argv: str) -> int:
    """The example's ``main(argv)``, in this process."""
    spec = importlib.util.spec_from_file_location(f"example_{name}", EXAMPLES / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.main(list(argv))


def test_every_example_is_tested():
    tested = {"own_loop", "channel", "biofilm_paraview", "compare_solvers", "model_hook", "foreign_state",
              "pressure_growth",
              "mpi_loop"}  # under mpiexec: tests/mpi/test_distributed.py
    assert {p.stem for p in EXAMPLES.glob("*.py")} == tested


def test_own_loop_clears_the_overlap(capsys):
    """The user's own loop with the position-level step (issue 35: it used the velocity step while
    the README recommends position_step): the start's overlap of 0.05 is cleared, and no step
    ends above the overlap tolerance."""
    assert run_example("own_loop") == 0
    lines = capsys.readouterr().out.splitlines()
    overlaps = [float(line.split("|")[1]) for line in lines if "|" in line and line.split("|")[0].strip().isdigit()]
    assert overlaps[0] == pytest.approx(0.05) and max(overlaps[1:]) <= PositionSettings().overlap_tolerance + 1e-12
    final = [line for line in lines if line.startswith("final largest overlap")]
    assert len(final) == 1 and float(final[0].split()[3]) <= PositionSettings().overlap_tolerance
    assert "qc.position_step(" in (EXAMPLES / "own_loop.py").read_text()


MISSING = """
import runpy, sys
sys.modules[sys.argv[1]] = None  # import of it raises ImportError, as where it is not installed
sys.argv = [sys.argv[2], *sys.argv[3:]]
runpy.run_path(sys.argv[0], run_name="__main__")
"""


@pytest.mark.parametrize(("example", "missing", "argv", "says"), [
    ("mpi_loop", "petsc4py", [], "scripts/install-mpi"),
    ("biofilm_paraview", "meshio", ["--out", "{tmp}"], "pip install 'qpcontact[vtk]'"),
])
def test_an_example_without_its_optional_part_says_what_to_install_in_one_line(tmp_path, example, missing, argv,
                                                                                says):
    """Issue 35: examples/mpi_loop.py without PETSc ended in a ModuleNotFoundError's traceback
    (exit 1); now one line naming what to install, exit status 2, as every command does."""
    import subprocess
    import sys

    done = subprocess.run([sys.executable, "-c", MISSING, missing, str(EXAMPLES / f"{example}.py"),
                           *(a.format(tmp=tmp_path / "out") for a in argv)], capture_output=True, text=True,
                          cwd=ROOT, timeout=300)
    assert done.returncode == 2, done.stderr
    assert len(done.stderr.strip().splitlines()) == 1 and says in done.stderr and "Traceback" not in done.stderr


def test_a_foreign_state_with_overlaps_of_0_15_is_cleared_without_spinning(capsys):
    assert run_example("foreign_state") == 0
    lines = capsys.readouterr().out.splitlines()
    start = float(lines[0].split("largest overlap ")[1].split()[0])
    rows = [line.split("|") for line in lines if "|" in line and line.split("|")[0].strip().isdigit()]
    overlaps = [float(row[1]) for row in rows]
    assert start > 0.14 and overlaps[-1] < 0.01  # the layer's rows overlap by 0.15 at the start
    assert all(b <= a + 1e-9 for a, b in zip([start, *overlaps], overlaps, strict=False))
    assert max(float(row[2]) for row in rows) <= 0.5  # tips turned by less than half a diameter a step: not spun


def test_a_cellmodeller_state_is_cleared_from_its_pickles(capsys):
    """``--state`` takes CellModeller's run folder (read by qc.read_cellmodeller), as the
    10⁴-cell states of benchmarks/cellmodeller/ are; before, a file outside the repository."""
    assert run_example("foreign_state", "--state", str(ROOT / "tests/data/cellmodeller/ex1_simpleGrowth_seed1"),
                       "--steps", "2") == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("64 cells, 2D, largest overlap 0.02")  # CellModeller leaves 0.02 diameters at 64 cells
    assert lines[-1] == "largest overlap never grew, no cell's tips turned 0.5 of a diameter in a step"


def test_a_colony_between_walls_stays_between_them(tmp_path, capsys):
    """At its default 60 cells: until issue 19 a step's Clarabel answer ended "AlmostSolved" with
    residuals inside what the tolerance promises, was refused for its status word, and the
    example stopped with a traceback (the test ran 12 cells)."""
    assert run_example("channel", "--out", str(tmp_path)) == 0
    assert (tmp_path / "channel.png").stat().st_size > 1000
    out = capsys.readouterr().out
    assert "walls at 2 µm" in out and int(out.split()[0]) >= 60


def test_a_3d_biofilm_is_exported_to_paraview(tmp_path, capsys):
    pytest.importorskip("meshio", reason="the example needs qpcontact[vtk]")
    from qpcontact.io.paraview import read_series

    assert run_example("biofilm_paraview", "--out", str(tmp_path)) == 0
    series = read_series(tmp_path / "colony.pvd")
    assert len(series) >= 3 and all(f.exists() for _, f in series)
    assert "open" in capsys.readouterr().out


def test_a_solver_comparison_on_your_own_scene(capsys):
    import qpcontact as qc

    assert run_example("compare_solvers") == 0
    out = capsys.readouterr().out
    assert all(f"\n{solver} " in out for solver in qc.available_solvers())


def test_the_model_hook_example_runs_as_a_script_and_as_a_model(tmp_path):
    assert run_example("model_hook", "--out", str(tmp_path / "script")) == 0
    import numpy as np

    from qpcontact.io.snapshots import load_snapshot

    # Issue 27: types by lineage (before, drawn per cell id: sisters differed half the time).
    colony = load_snapshot(sorted((tmp_path / "script" / "snapshots").glob("step_*.npz"))[-1]).colony
    assert set(colony.cell_types) == {0, 1}
    sisters = [np.flatnonzero(colony.parent_ids == parent) for parent in set(colony.parent_ids) - {-1}]
    pairs = [s for s in sisters if len(s) == 2]
    assert len(pairs) >= 10 and all(colony.cell_types[a] == colony.cell_types[b] for a, b in pairs)
    assert np.all((colony.cell_data["division_length"] >= 3.0) & (colony.cell_data["division_length"] <= 5.0))
    from qpcontact.cli import main

    assert main(["simulate", "--hook", str(EXAMPLES / "model_hook.py"), "--cells", "4", "--out", str(tmp_path / "cli"),
                 "--quiet"]) == 0


def test_the_pressure_growth_example_stalls_the_inside_and_runs_as_a_model(tmp_path, capsys):
    assert run_example("pressure_growth", "--cells", "40", "--stall-pressure", "5", "--out", str(tmp_path / "script")) == 0
    free, slowed = [line for line in capsys.readouterr().out.splitlines() if " cells at t = " in line]
    time = [float(line.split("t = ")[1].split()[0]) for line in (free, slowed)]
    largest = [float(line.split("(median) ")[1].split()[0]) for line in (free, slowed)]
    assert time[1] > time[0] and largest[1] < largest[0]  # slower to 40 cells, and less squeezed
    assert (tmp_path / "script" / "pressure.png").stat().st_size > 1000
    from qpcontact.cli import main

    assert main(["simulate", "--hook", str(EXAMPLES / "pressure_growth.py"), "--cells", "6", "--out",
                 str(tmp_path / "cli"), "--quiet"]) == 0
