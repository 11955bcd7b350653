"""CellModeller's pickles in (issue 27): a state CellModeller wrote (tests/data/cellmodeller/,
README there) becomes a snapshot with the cells, lineage, types and per-cell data CellModeller
recorded, that ``qpcontact simulate --start`` continues; and a pickle that asks for anything
but a CellModeller state is refused without running it."""

from __future__ import annotations

import os
import pickle
import sys
import types
from pathlib import Path

import numpy as np
import pytest

import qpcontact as qc
from qpcontact.cli import main
from qpcontact.errors import InvalidArgumentError, InvalidSnapshotError, RefusedPickleError
from qpcontact.io import Snapshot, load_snapshot
from qpcontact.io.cellmodeller import CellState, load_pickle, read_cellmodeller

DATA = Path(__file__).resolve().parents[1] / "data" / "cellmodeller"
RUN = DATA / "ex1_simpleGrowth_seed1"


def recorded() -> dict[str, np.ndarray]:
    """CellModeller's own arrays at the run's last pickle, saved from its memory by the harness
    (not from the pickle), ordered by cell id."""
    with np.load(DATA / "cellmodeller_64.npz") as data:
        return {name: data[name] for name in data.files}


def plain_states(path: Path) -> dict:
    """The pickle read by Python's own unpickler, CellModeller's CellState mapped to a class of
    this test (our own committed file: safe), for values read independently of the reader."""

    class Record:
        pass

    class Plain(pickle.Unpickler):
        def find_class(self, module, name):
            return Record if (module, name) == ("CellModeller.CellState", "CellState") else super().find_class(module, name)

    with open(path, "rb") as fh:
        return Plain(fh).load()


def by_id(colony: qc.Colony) -> np.ndarray:
    return np.argsort(colony.ids)


def test_a_run_folder_gives_its_last_step_with_what_cellmodeller_recorded():
    state = read_cellmodeller(RUN)
    expected = recorded()
    colony = state.colony
    assert state.path == RUN / "step-00221.pickle" and state.cellmodeller_step == 221 and state.model == "ex1_simpleGrowth"
    assert isinstance(state, Snapshot) and state.step == int(expected["step"]) == 222  # written after step 221 (from 0)
    assert colony.cells.n == 64 and colony.time == pytest.approx(float(expected["time"])) and state.dt == pytest.approx(0.025)
    order = by_id(colony)
    np.testing.assert_array_equal(colony.ids[order], expected["ids"])
    np.testing.assert_array_equal(colony.parent_ids[order], expected["parent_ids"])
    np.testing.assert_array_equal(colony.cell_types[order], expected["cell_types"])
    # float32 in CellModeller: positions to its precision, axes renormalized
    np.testing.assert_allclose(colony.cells.centers[order], expected["centers"], atol=1e-5)
    np.testing.assert_allclose(colony.cells.axes[order], expected["axes"], atol=1e-6)
    np.testing.assert_array_equal(colony.cells.lengths[order], expected["lengths"])  # between the cap centres, both
    np.testing.assert_array_equal(colony.cells.radii[order], expected["radii"])
    np.testing.assert_allclose(colony.rates[order] * colony.cells.lengths[order], expected["growth_rates"], rtol=1e-6)
    assert colony.next_id == expected["ids"].max() + 1 and np.all(colony.owed == 0)
    np.testing.assert_allclose(colony.cells.masses, qc.colony.volumes(colony.cells))
    # the model's CLBacterium(gamma=100.): growth drag 100 against CellModeller's drag of motion muA·(l + 2ρ)
    ratio = 100.0 / (np.median(colony.cells.lengths) + 1.0)
    np.testing.assert_allclose(colony.cells.growth_inertia, ratio * colony.cells.masses)
    target = float(np.median(colony.cell_data["targetVol"]))
    assert state.settings == {"run": {"dimensions": 2}, "model": {"rate_noise": 0.0, "radius": 0.5, "rate": 1.0,
                                                                  "growth_inertia_ratio": pytest.approx(ratio),
                                                                  "division_length": target}}
    assert any("not at each cell's targetVol" in note and "qpcontact cellmodeller MODEL.py --start" in note
               for note in state.notes)
    assert any("CellModeller's own unit" in note for note in state.notes)


def test_the_models_own_per_cell_state_is_kept_and_what_is_not_is_named():
    state = read_cellmodeller(RUN)
    plain = plain_states(RUN / "step-00221.pickle")["cellStates"]
    data = state.colony.cell_data
    for i, cell_id in enumerate(state.colony.ids):
        cell = plain[int(cell_id)]
        assert data["targetVol"][i] == cell.targetVol and data["cellAge"][i] == cell.cellAge
        np.testing.assert_array_equal(data["color"][i], cell.color)
    assert set(data) == {"targetVol", "cellAge", "color", "effGrowth", "strainRate", "cellAdh"}
    assert np.all((data["targetVol"] >= 3.5) & (data["targetVol"] <= 4.0))  # ex1: 3.5 + U(0, 0.5)
    assert {"ends", "volume", "neighbours", "divideFlag"} <= set(state.left_out)


def test_a_step_of_a_run_folder_is_chosen_by_its_number():
    state = read_cellmodeller(RUN, step=200)
    assert state.colony.cells.n == 35 and state.step == 201 and state.colony.time == pytest.approx(201 * 0.025)
    assert read_cellmodeller(RUN / "step-00200.pickle").colony.cells.n == 35
    with pytest.raises(InvalidArgumentError, match=r"no pickle of step 7 \(it has 200, 221\)"):
        read_cellmodeller(RUN, step=7)
    with pytest.raises(InvalidArgumentError, match="only in a run folder"):
        read_cellmodeller(RUN / "step-00200.pickle", step=200)
    with pytest.raises(InvalidArgumentError, match="no CellModeller pickles"):
        read_cellmodeller(DATA)


def test_the_import_command_writes_a_snapshot_that_simulate_continues(tmp_path, capsys):
    snapshot = tmp_path / "ex1.npz"
    assert main(["import-cellmodeller", str(RUN), "--out", str(snapshot)]) == 0
    out = capsys.readouterr().out
    assert "64 cells" in out and "targetVol" in out and f"simulate --start {snapshot}" in out
    saved = load_snapshot(snapshot)
    assert saved.step == 222 and saved.colony.cells.n == 64 and saved.colony.cell_data["targetVol"].shape == (64,)
    assert main(["import-cellmodeller", str(RUN), "--out", str(snapshot)]) == 2  # refuses to replace it
    assert "exists; pass --overwrite" in capsys.readouterr().err
    assert main(["import-cellmodeller", str(RUN), "--out", str(snapshot), "--overwrite", "--step", "200"]) == 0

    assert main(["import-cellmodeller", str(RUN), "--out", str(snapshot), "--overwrite"]) == 0
    run = tmp_path / "run"
    assert main(["simulate", "--start", str(snapshot), "--cells", "72", "--out", str(run), "--quiet"]) == 0
    final = load_snapshot(sorted((run / "snapshots").glob("step_*.npz"))[-1])
    colony = final.colony
    assert colony.cells.n >= 72 and final.step > 222 and colony.time > saved.colony.time
    born = ~np.isin(colony.ids, saved.colony.ids)
    assert born.any() and np.all(np.isin(colony.parent_ids[born], saved.colony.ids))  # CellModeller's cells divided
    assert np.all(colony.cell_types == 0) and set(colony.cell_data) == set(saved.colony.cell_data)
    mother = {int(i): k for k, i in enumerate(saved.colony.ids)}
    for k in np.flatnonzero(born):  # a daughter inherits her mother's per-cell data
        assert colony.cell_data["targetVol"][k] == saved.colony.cell_data["targetVol"][mother[int(colony.parent_ids[k])]]
    np.testing.assert_allclose(colony.rates, 1.0)  # CellModeller's growthRate, rate_noise 0
    assert final.settings["model"]["radius"] == 0.5 and final.settings["run"]["dimensions"] == 2


def test_command_line_mistakes_are_one_line_and_exit_2(tmp_path, capsys):
    for argv, message in [
        ([str(RUN), "--step", "3"], "no pickle of step 3"),
        ([str(RUN / "step-00200.pickle"), "--step", "200"], "only in a run folder"),
        ([str(tmp_path / "nothing")], "no such file or folder"),
        ([str(RUN), "--dt", "0"], "--dt"),
    ]:
        assert main(["import-cellmodeller", *argv, "--out", str(tmp_path / "x.npz")]) == 2
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1
    assert main(["import-cellmodeller", str(RUN), "--out", str(tmp_path)]) == 2
    assert "a folder" in capsys.readouterr().err
    assert not (tmp_path / "x.npz").exists()


# --- hostile and broken pickles -------------------------------------------------------------

class RunsACommand:
    """What an attacker pickles: loading it calls os.system."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return os.system, (f"touch {self.marker}",)


class Evaluates:
    def __reduce__(self):
        return eval, ("__import__('os').getcwd()",)


@pytest.mark.parametrize("inside", [False, True], ids=["alone", "inside a CellModeller state"])
def test_a_pickle_that_would_run_a_command_is_refused_and_runs_nothing(tmp_path, inside, capsys):
    marker = tmp_path / "it-ran"
    path = tmp_path / "step-00001.pickle"
    if inside:  # after a good cell, as the value of a cell's attribute
        write_state(path, [dict(id=1, pos=[0, 0, 0], time=0.1), dict(id=2, pos=[3, 0, 0], targetVol=RunsACommand(marker))], 1)
    else:
        path.write_bytes(pickle.dumps(RunsACommand(marker), protocol=pickle.HIGHEST_PROTOCOL))
    with pytest.raises(RefusedPickleError, match=r"refused: it asks to build (posix|nt)\.system"):
        load_pickle(path)
    with pytest.raises(RefusedPickleError):
        read_cellmodeller(tmp_path)
    assert main(["import-cellmodeller", str(path), "--out", str(tmp_path / "x.npz")]) == 2
    err = capsys.readouterr().err
    assert "system" in err and len(err.strip().splitlines()) == 1
    assert not marker.exists() and not (tmp_path / "x.npz").exists()


def test_other_builtins_and_copyreg_tricks_are_refused(tmp_path):
    path = tmp_path / "evil.pickle"
    for payload, name in [(Evaluates(), r"(builtins|__builtin__)\.eval"), (pickle.loads, r"_?pickle\.loads"),
                          (getattr, r"(builtins|__builtin__)\.getattr")]:
        for protocol in (2, pickle.HIGHEST_PROTOCOL):  # Python 2's names at protocol 2 (__builtin__)
            path.write_bytes(pickle.dumps(payload, protocol=protocol))
            with pytest.raises(RefusedPickleError, match=name):
                load_pickle(path)
    path.write_bytes(b"c_codecs\nencode\n(X\x03\x00\x00\x00abcX\x06\x00\x00\x00base64tR.")
    with pytest.raises(RefusedPickleError, match="encoding 'base64'"):
        load_pickle(path)
    # copyreg._reconstructor is let through for CellState only
    path.write_bytes(b"ccopyreg\n_reconstructor\n(cnumpy\nndarray\nc__builtin__\nobject\nNtR.")
    with pytest.raises(RefusedPickleError, match="builtins.object|__builtin__.object|ndarray"):
        load_pickle(path)
    path.write_bytes(b"(I1\nP0\n\x85.")  # a persistent id: an object from outside the file
    with pytest.raises(RefusedPickleError, match="persistent id"):
        load_pickle(path)


def test_what_a_cellmodeller_state_holds_is_built(tmp_path):
    """NumPy arrays (both pickle protocols), scalars, sets and CellState, at protocols 0 to 5."""
    fake = fake_cellmodeller_module()
    cell = fake.CellState()
    cell.ends = (np.arange(3.0, dtype=np.float32), np.ones((2, 2)))
    cell.tags = {1, 2}
    for protocol in range(pickle.HIGHEST_PROTOCOL + 1):
        path = tmp_path / f"p{protocol}.pickle"
        with fake_modules(fake):
            path.write_bytes(pickle.dumps({"cellStates": {1: cell}, "x": np.float32(2.5)}, protocol=protocol))
        data = load_pickle(path)
        loaded = data["cellStates"][1]
        assert isinstance(loaded, CellState) and data["x"] == np.float32(2.5) and loaded.tags == {1, 2}
        np.testing.assert_array_equal(loaded.ends[1], np.ones((2, 2)))


def test_broken_pickles_and_other_contents_are_named(tmp_path):
    path = tmp_path / "step-00001.pickle"
    path.write_bytes((RUN / "step-00200.pickle").read_bytes()[:2000])
    with pytest.raises(InvalidSnapshotError, match="truncated or corrupted"):
        read_cellmodeller(path)
    path.write_bytes(pickle.dumps([1, 2, 3]))
    with pytest.raises(InvalidSnapshotError, match="not a CellModeller state"):
        read_cellmodeller(path)


# --- synthetic CellModeller states: what real runs seldom show ------------------------------

def fake_cellmodeller_module() -> types.ModuleType:
    module = types.ModuleType("CellModeller.CellState")

    class CellStateOfCellModeller:  # pickled under CellModeller's own name
        pass

    CellStateOfCellModeller.__module__, CellStateOfCellModeller.__qualname__ = "CellModeller.CellState", "CellState"
    CellStateOfCellModeller.__name__ = "CellState"
    module.CellState = CellStateOfCellModeller
    return module


class fake_modules:
    """``CellModeller.CellState`` importable while pickling (the fake module above)."""

    def __init__(self, module: types.ModuleType) -> None:
        self.modules = {"CellModeller": types.ModuleType("CellModeller"), "CellModeller.CellState": module}

    def __enter__(self):
        self.saved = {name: sys.modules.get(name) for name in self.modules}
        sys.modules.update(self.modules)

    def __exit__(self, *exc):
        for name, module in self.saved.items():
            if module is None:
                sys.modules.pop(name, None)
            else:
                sys.modules[name] = module


def write_state(path: Path, cells: list[dict], step: int, lineage: dict | None = None) -> Path:
    fake = fake_cellmodeller_module()
    states = {}
    for values in cells:
        cell = fake.CellState()
        cell.__dict__.update(dict(growthRate=1.0, cellType=0, radius=0.5, length=2.0, dir=[1.0, 0.0, 0.0]), **values)
        states[cell.id] = cell
    with fake_modules(fake):
        path.write_bytes(pickle.dumps({"cellStates": states, "stepNum": step, "lineage": lineage or {},
                                       "moduleName": "test"}, protocol=pickle.HIGHEST_PROTOCOL))
    return path


def test_a_pickle_of_step_0_needs_dt_and_a_given_dt_must_agree(tmp_path):
    path = write_state(tmp_path / "step-00000.pickle", [dict(id=1, pos=[0, 0, 0], time=0.0)], 0)
    with pytest.raises(InvalidArgumentError, match="step 0 does not tell"):
        read_cellmodeller(path)
    assert read_cellmodeller(path, dt=0.1).colony.time == pytest.approx(0.1)
    later = write_state(tmp_path / "step-00004.pickle", [dict(id=1, pos=[0, 0, 0], time=0.2)], 4)
    assert read_cellmodeller(later).dt == pytest.approx(0.05)
    with pytest.raises(InvalidArgumentError, match="contradicts the pickle"):
        read_cellmodeller(later, dt=0.1)


def test_types_3d_states_and_values_that_are_not_numbers(tmp_path):
    cells = [dict(id=3, pos=[0, 0, 0.5], cellType=1, growthRate=0.5, label="a", time=1.0),
             dict(id=4, pos=[3, 0, 0.5], cellType=0, signal=2.0, label="b", time=1.0)]
    state = read_cellmodeller(write_state(tmp_path / "step-00010.pickle", cells, 10, {3: 1, 4: 1}))
    np.testing.assert_array_equal(state.colony.cell_types, [1, 0])
    np.testing.assert_array_equal(state.colony.parent_ids, [1, 1])
    assert state.colony.next_id == 5 and state.settings["run"]["dimensions"] == 3
    assert state.settings["model"] == {"rate_noise": 0.0, "radius": 0.5, "type_rates": [1.0, 0.5],
                                       "growth_inertia_ratio": 1000.0}
    assert [note.split(":")[0] for note in state.notes] == [
        "the pickle holds no model with a CLBacterium(gamma=...)", "time is CellModeller's own unit (growthRate per that unit; its step dt 0.1), not qpcontact's doubling times"]
    assert state.left_out["label"].startswith("not a number") and state.left_out["signal"] == "only some cells have it"
    assert state.colony.cell_data == {}
    cells[1]["cellType"] = 2  # no cell of type 1: no rate for it
    state = read_cellmodeller(write_state(tmp_path / "step-00010.pickle", cells, 10, {3: 1, 4: 1}))
    assert set(state.settings["model"]) == {"rate_noise", "radius", "growth_inertia_ratio"}
    assert "share no growth rate" in state.notes[0]


def test_per_type_rates_are_continued_by_simulate(tmp_path, capsys):
    """A 2D pair of types growing at 1.0 and 0.5: the snapshot's type_rates give each newborn
    her type's rate (before, every newborn grew at [model] rate)."""
    cells = [dict(id=1, pos=[0, 0, 0], cellType=0, growthRate=1.0, time=0.5),
             dict(id=2, pos=[0, 1.0, 0], cellType=1, growthRate=0.5, time=0.5)]
    write_state(tmp_path / "step-00010.pickle", cells, 10)
    assert main(["import-cellmodeller", str(tmp_path / "step-00010.pickle"), "--out", str(tmp_path / "two.npz")]) == 0
    assert "model.type_rates = 1, 0.5" in capsys.readouterr().out
    run = tmp_path / "run"
    assert main(["simulate", "--start", str(tmp_path / "two.npz"), "--cells", "6", "--out", str(run), "--quiet"]) == 0
    colony = load_snapshot(sorted((run / "snapshots").glob("step_*.npz"))[-1]).colony
    assert colony.cells.n >= 6
    np.testing.assert_allclose(colony.rates, np.where(colony.cell_types == 0, 1.0, 0.5))


@pytest.mark.parametrize("change, message", [
    (dict(pos=[0, 0]), "pos must be three finite numbers"),
    (dict(length=float("nan")), "length must be one finite number"),
    (dict(cellType=0.5), "cellType must be one integer"),
    (dict(length=-1.0), "lengths"),
    (dict(radius=0.0), "radii"),
])
def test_cells_that_fail_the_checks_are_named(tmp_path, change, message):
    path = write_state(tmp_path / "step-00002.pickle", [{"id": 1, "pos": [0, 0, 0], "time": 0.1, **change}], 2)
    with pytest.raises(InvalidSnapshotError, match=message):
        read_cellmodeller(path)


def test_a_cell_without_a_position_is_named(tmp_path):
    path = write_state(tmp_path / "step-00002.pickle", [dict(id=1, pos=[0, 0, 0], time=0.1), dict(id=2, time=0.1)], 2)
    with pytest.raises(InvalidSnapshotError, match="cell 2 has no pos"):
        read_cellmodeller(path)
