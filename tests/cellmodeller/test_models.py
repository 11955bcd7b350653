"""CellModeller model scripts (tests/cellmodeller/models, written in CellModeller's style) on
qpcontact's physics: ``qpcontact cellmodeller`` and :func:`qpcontact.cellmodeller.run_model`."""

from __future__ import annotations

import importlib
import math
import pickle
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from qpcontact.cellmodeller import ModelRefused, load_model, run_model
from qpcontact.cli import main
from qpcontact.errors import InvalidArgumentError
from qpcontact.io.cellmodeller import load_pickle, read_cellmodeller

MODELS = Path(__file__).parent / "models"


def test_a_free_cell_grows_as_cellmodellers_does_per_step():
    """CellModeller grows a free cell by length·growthRate·dt each step: after n steps
    L (1 + r dt)^n, in the model's time unit (n dt)."""
    outcome = run_model(MODELS / "free.py", cells=2, steps=10)
    colony = outcome.run.colony
    assert colony.cells.n == 1 and outcome.run.steps == 10
    assert colony.cells.lengths[0] == pytest.approx(2.0 * 1.05**10, rel=1e-9)
    assert colony.time == pytest.approx(0.5)
    state = outcome.hook.states[int(colony.ids[0])]
    assert state.seenAge == 9  # update at step 10 saw nine steps of physics (cellAge counts them)


def test_growth_and_division_at_each_cells_target_volume(tmp_path):
    outcome = run_model(MODELS / "growth.py", cells=40, out=tmp_path / "run")
    colony, hook = outcome.run.colony, outcome.hook
    assert colony.cells.n >= 40 and not outcome.run.error
    target = colony.cell_data["targetVol"]
    # a cell flagged at volume > targetVol divides at the start of the next step: no cell is
    # longer than its target by more than one step's growth (5 %)
    assert np.all(colony.cells.lengths <= target * 1.0501)
    assert np.all((2.5 <= target) & (target <= 3.0))
    # daughters are born at length/2 − radius of a mother just past her target, and own no extra
    # length (CellModeller's)
    assert np.all(colony.owed == 0)
    assert colony.cells.lengths.min() >= 2.5 / 2 - 0.5 - 1e-9
    assert max(outcome.run.history["max_overlap"]) <= 0.01 + 1e-9
    assert hook.lineage and set(hook.lineage.values()) <= set(hook.lineage) | {1}
    assert np.all(colony.rates == pytest.approx(math.log1p(2.0 * 0.025) / 0.025))


def test_two_types_keep_their_types_colours_and_rates(tmp_path):
    outcome = run_model(MODELS / "two_types.py", cells=40, out=tmp_path / "run")
    colony = outcome.run.colony
    types = colony.cell_types
    assert set(types.tolist()) == {0, 1} and colony.cells.n >= 40
    x = colony.cells.centers[:, 0]
    assert np.all(x[types == 0] < 0) and np.all(x[types == 1] > 0)
    assert np.sum(types == 0) > np.sum(types == 1)  # type 0 grows twice as fast
    color = colony.cell_data["color"]
    assert color.shape == (colony.cells.n, 3)
    assert np.allclose(color[types == 1], [0.7, 0.4, 0.3])
    growth = colony.cell_data["growthRate"]
    assert np.all(growth[types == 0] == 2.0) and np.all(growth[types == 1] == 1.0)
    assert (tmp_path / "run" / "colony.png").stat().st_size > 0
    assert (tmp_path / "run" / "model.py").read_text() == (MODELS / "two_types.py").read_text()


def test_inherited_numbers_and_divide_callback(tmp_path):
    outcome = run_model(MODELS / "inherited.py", cells=24, out=tmp_path / "run")
    colony, hook = outcome.run.colony, outcome.hook
    data = colony.cell_data
    assert np.all(data["n_a"] + data["n_b"] == 6)
    assert data["n_a"].dtype.kind == "i"
    assert np.all(data["lineageMark"] == 7.25)  # copied to both daughters unchanged
    assert data["generation"].max() >= 3
    # generation is the number of divisions since the founder, along the lineage
    for cell_id, generation in zip(colony.ids.tolist(), data["generation"].tolist(), strict=True):
        depth, i = 0, cell_id
        while i in hook.lineage:
            i, depth = hook.lineage[i], depth + 1
        assert depth == generation
    # the neighbours CellModeller lists with compNeighbours=True
    assert data["touching"].max() >= 2
    assert "label" in hook.left_out  # a string: kept on the cells and in the pickles, not in snapshots
    assert all(s.label == "founder" for s in hook.states.values())


def test_planes_keep_the_colony_in_its_channel(tmp_path):
    outcome = run_model(MODELS / "channel.py", cells=40)
    cells = outcome.run.colony.cells
    reach = np.abs(cells.centers[:, 1]) + np.abs(cells.axes[:, 1]) * cells.lengths / 2 + cells.radii
    assert cells.n >= 40 and reach.max() <= 3.0 + 0.01
    assert np.ptp(cells.centers[:, 0]) > 4 * np.ptp(cells.centers[:, 1])


def test_a_channel_at_cellmodellers_default_gamma(tmp_path):
    """CellModeller's default gamma 10 (growth nearly as easy to compress as a cell to move) between
    walls: with the position step's aim at exactly 0, contacts resting on their constraints made
    the interior point stall at step 114; the default aim of 0.001 of a diameter runs."""
    model = tmp_path / "channel10.py"
    model.write_text((MODELS / "channel.py").read_text().replace(", gamma=100", ""))
    outcome = run_model(model, cells=40)
    assert not outcome.run.error and outcome.run.colony.cells.n >= 40


def test_3d_model_on_its_base_plane_inside_its_sphere(tmp_path):
    outcome = run_model(MODELS / "biofilm3d.py", cells=30, out=tmp_path / "run")
    assert (tmp_path / "run" / "colony.png").stat().st_size > 0  # from above and from the side, in the cells' colours
    assert outcome.settings.run.dimensions == 3
    cells = outcome.run.colony.cells
    ends = np.concatenate([cells.centers + cells.axes * cells.lengths[:, None] / 2,
                           cells.centers - cells.axes * cells.lengths[:, None] / 2])
    radii = np.concatenate([cells.radii, cells.radii])
    assert np.all(ends[:, 2] - radii >= -0.01)
    assert np.all(np.linalg.norm(ends, axis=1) + radii <= 6.0 * 1.01)
    assert any("256 planes" in note for note in outcome.notes)


def test_a_signalling_model_is_refused_in_one_line(tmp_path, capsys):
    out = tmp_path / "run"
    status = main(["cellmodeller", str(MODELS / "signalling.py"), "--out", str(out)])
    err = capsys.readouterr().err
    assert status == 2
    assert err.count("\n") == 1 and "signalling" in err and "GridDiffusion" in err
    assert not out.exists()


def test_unknown_option_and_broken_model_refused(tmp_path):
    bad = tmp_path / "bad.py"
    bad.write_text((MODELS / "growth.py").read_text().replace("gamma=10.0", "gamma=10.0, stiffness=3"))
    with pytest.raises(ModelRefused, match="unknown option stiffness"):
        load_model(bad)
    broken = tmp_path / "broken.py"
    broken.write_text("def setup(sim):\n    sim.init(\n")
    with pytest.raises(InvalidArgumentError, match="line 2: SyntaxError"):
        load_model(broken)
    raising = tmp_path / "raising.py"
    raising.write_text((MODELS / "growth.py").read_text().replace("sim.pickleSteps = 5", "sim.pickleSteps = 1 / 0"))
    with pytest.raises(InvalidArgumentError, match=r"setup\(sim\) raised line \d+: ZeroDivisionError"):
        load_model(raising)


def test_cellmodeller_names_are_served_only_while_the_model_runs():
    run_model(MODELS / "free.py", cells=2, steps=2)
    assert not any(name == "CellModeller" or name.startswith("CellModeller.") for name in sys.modules)
    with pytest.raises(ImportError):
        importlib.import_module("CellModeller.Regulation.ModuleRegulator")


ANALYSIS = """
import pickle, sys
data = pickle.load(open(sys.argv[1], "rb"))
for cid, cell in data["cellStates"].items():
    assert cid == cell.id
    print(cid, cell.pos[0], cell.pos[1], cell.dir[0], cell.length, cell.cellType, *cell.color)
print(len(data["lineage"]), data["stepNum"])
"""


def test_pickles_in_cellmodellers_layout_read_by_an_analysis_script_and_imported_back(tmp_path):
    outcome = run_model(MODELS / "two_types.py", cells=30, out=tmp_path / "run")
    pickles = sorted((tmp_path / "run" / "pickles").glob("step-*.pickle"))
    assert pickles[0].name == "step-00000.pickle" and pickles[1].name == "step-00010.pickle"
    last = pickles[-1]
    assert last.name == f"step-{outcome.run.steps - 1:05d}.pickle"
    script = tmp_path / "analysis.py"
    script.write_text(ANALYSIS)
    printed = subprocess.run([sys.executable, str(script), str(last)], capture_output=True, text=True, check=True,
                             cwd=tmp_path).stdout.splitlines()
    rows = np.array([line.split() for line in printed[:-1]], dtype=float)
    rows = rows[np.argsort(rows[:, 0])][:, 1:]
    colony = outcome.run.colony
    order = np.argsort(colony.ids)
    assert rows.shape == (colony.cells.n, 8)
    assert np.allclose(rows[:, :2], colony.cells.centers[order, :2])
    assert np.allclose(rows[:, 3], colony.cells.lengths[order])
    assert np.array_equal(rows[:, 4], colony.cell_types[order])
    state = read_cellmodeller(tmp_path / "run" / "pickles")
    assert state.cellmodeller_step == outcome.run.steps - 1 and state.dt == pytest.approx(0.025)
    assert np.allclose(np.sort(state.colony.cells.lengths), np.sort(colony.cells.lengths))
    assert "targetVol" in state.colony.cell_data
    with open(last, "rb") as fh:
        assert pickle.load(fh)["moduleName"] == "two_types"


def test_resume_continues_exactly(tmp_path):
    whole = run_model(MODELS / "inherited.py", cells=10_000, steps=60, out=tmp_path / "whole")
    run_model(MODELS / "inherited.py", cells=10_000, steps=33, out=tmp_path / "split")
    resumed = run_model(MODELS / "inherited.py", cells=10_000, steps=60, out=tmp_path / "split", resume=True)
    a, b = whole.run.colony, resumed.run.colony
    assert resumed.run.first_step == 33 and b.cells.n == a.cells.n >= 8
    assert np.array_equal(a.ids, b.ids)
    assert np.allclose(a.cells.centers, b.cells.centers, atol=1e-9)
    for name in ("n_a", "generation", "targetVol", "cellAge", "effGrowth"):
        assert np.allclose(a.cell_data[name], b.cell_data[name]), name
    assert resumed.hook.lineage == whole.hook.lineage


def test_command_line_run_and_max_cells(tmp_path, capsys):
    model = tmp_path / "capped.py"
    model.write_text((MODELS / "growth.py").read_text().replace("max_cells=100000", "max_cells=12"))
    status = main(["cellmodeller", str(model), "--cells", "50", "--out", str(tmp_path / "run"), "--quiet",
                   "--seed", "3"])
    captured = capsys.readouterr()
    assert status == 0
    assert "max_cells 12 stops the run" in captured.err
    assert "CLBacterium gamma" not in captured.err and "cells at step" in captured.out
    assert (tmp_path / "run" / "history.csv").exists()
    status = main(["cellmodeller", str(model), "--out", str(tmp_path / "run"), "--quiet"])
    assert status == 2 and "--overwrite" in capsys.readouterr().err


def test_a_cellmodeller_state_continued_with_its_own_model(tmp_path):
    """CellModeller's own pickle (tests/data/cellmodeller) continued with the model it holds."""
    pickle_path = Path(__file__).parents[1] / "data" / "cellmodeller" / "ex1_simpleGrowth_seed1" / "step-00221.pickle"
    state = read_cellmodeller(pickle_path)
    source = load_pickle(pickle_path)["moduleStr"]  # (plain pickle.load would need CellModeller's classes)
    model = tmp_path / "ex1_simpleGrowth.py"
    model.write_text(source)
    outcome = run_model(model, start=pickle_path, cells=80, out=tmp_path / "run")
    run, hook = outcome.run, outcome.hook
    assert run.first_step == 222 and run.colony.time == pytest.approx(0.025 * run.steps)
    assert run.colony.cells.n >= 80 and not run.error
    kept = set(state.colony.ids.tolist()) & set(run.colony.ids.tolist())
    assert kept  # cells that have not divided since keep their ids and their targetVol
    rows = {int(i): k for k, i in enumerate(state.colony.ids)}
    for k, i in enumerate(run.colony.ids.tolist()):
        if i in kept:
            assert run.colony.cell_data["targetVol"][k] == state.colony.cell_data["targetVol"][rows[i]]
    assert set(state.colony.parent_ids[state.colony.parent_ids >= 0].tolist()) <= set(hook.lineage.values())
    assert np.all(run.colony.cells.lengths <= run.colony.cell_data["targetVol"] * 1.0251)
    assert np.all(run.colony.cell_data["growthRate"] == 1.0)


def test_an_imported_state_is_drawn_with_its_source_overlap_and_time_unit(tmp_path, monkeypatch):
    from qpcontact.io.snapshots import load_snapshot
    from qpcontact.simulation import picture

    state = read_cellmodeller(Path(__file__).parents[1] / "data" / "cellmodeller" / "ex1_simpleGrowth_seed1")
    snapshot = load_snapshot(state.save(tmp_path / "state.npz"))
    titles = []
    monkeypatch.setattr(picture, "colony_picture", lambda path, colony, mechanics, settings, color, title:
                        titles.append(title) or path)
    picture.plot_snapshot(snapshot, tmp_path / "state.png")
    assert "CellModeller's time unit, its step 0.025" in titles[0] and "a CellModeller state (its step 221)" in titles[0]
    measured = float(snapshot.extra["cellmodeller.max_overlap"][0])
    assert 0.01 < measured < 0.2 and f"{measured:.3g} of a diameter as measured" in titles[0]
    assert "doubling times" not in titles[0]
