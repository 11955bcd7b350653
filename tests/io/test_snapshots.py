"""Colony snapshots and the NPZ cell arrays: what is written loads back equal; what is
corrupted or inconsistent is a named error; version 1 files still load."""

import json
import zipfile

import numpy as np
import pytest

import qpcontact as q
from qpcontact.colony import Colony
from qpcontact.errors import InvalidArgumentError, InvalidSnapshotError
from qpcontact.io.snapshots import (
    MECHANICS_FIELDS,
    VERSION,
    cell_arrays,
    load_cells,
    load_colony,
    load_snapshot,
    save_cells,
    save_colony,
)
from qpcontact.timestep import CellMechanics

CELL_NAMES = ("centers", "axes", "lengths", "radii", "masses", "growth_inertia", "momenta", "angular_momenta",
              "growth_momenta")


def a_colony(**changes) -> Colony:
    cells = q.Cells(centers=[[0, 0, 0], [3, 0, 1]], axes=[[1, 0, 0], [0, 0.6, 0.8]], lengths=[1.0, 2.5],
                    radii=[0.5, 0.4], masses=[1.0, np.inf], growth_inertia=[10.0, np.inf],
                    momenta=[[1, 2, 3], [0, 0, 0]], angular_momenta=[[0.1, 0, 0], [0, 0, 0]], growth_momenta=[0.5, 0])
    return Colony(cells, [7, 9], [3, -1], [0.7, 0.0], [0.1, 0.0], time=12.5, next_id=11).replace(**changes)


def assert_same_colony(loaded: Colony, colony: Colony) -> None:
    for name in CELL_NAMES:
        np.testing.assert_array_equal(getattr(loaded.cells, name), getattr(colony.cells, name))
    for name in ("ids", "parent_ids", "rates", "owed", "cell_types"):
        np.testing.assert_array_equal(getattr(loaded, name), getattr(colony, name))
    assert sorted(loaded.cell_data) == sorted(colony.cell_data)
    for name, value in colony.cell_data.items():
        assert loaded.cell_data[name].dtype == value.dtype
        np.testing.assert_array_equal(loaded.cell_data[name], value)
    assert (loaded.time, loaded.next_id) == (colony.time, colony.next_id)


def test_snapshot_loads_back_equal(tmp_path):
    colony = a_colony()
    path = save_colony(tmp_path / "sub" / "step_000001.npz", colony, step=42)
    loaded, step = load_colony(path)
    assert step == 42
    assert_same_colony(loaded, colony)
    np.savez(tmp_path / "other.npz", centers=np.zeros((1, 3)))
    with pytest.raises(InvalidArgumentError, match="not a qpcontact-colony"):
        load_colony(tmp_path / "other.npz")


def test_version_2_carries_settings_random_state_and_extra_arrays(tmp_path):
    rng = np.random.default_rng(5)
    rng.normal(size=3)
    extra = {"warm_start.lambda": np.arange(4.0), "flags": np.array([True, False])}
    path = save_colony(tmp_path / "s.npz", a_colony(), 3, settings={"solver": "clarabel", "tolerance": 1e-6}, rng=rng,
                       extra=extra)
    snapshot = load_snapshot(path)
    assert snapshot.version == VERSION == 3 and snapshot.step == 3
    assert snapshot.settings == {"solver": "clarabel", "tolerance": 1e-6}
    assert snapshot.generator().normal(size=5).tolist() == rng.normal(size=5).tolist()  # the same random numbers
    assert sorted(snapshot.extra) == sorted(extra)
    for name, value in extra.items():
        np.testing.assert_array_equal(snapshot.extra[name], value)
    with pytest.raises(InvalidSnapshotError, match="extra array 'a b'"):
        save_colony(tmp_path / "t.npz", a_colony(), extra={"a b": np.zeros(1)})


def a_mechanics() -> CellMechanics:
    stress = np.zeros((2, 3, 3))
    stress[0] = [[-2.0, 0.5, 0.0], [0.1, -1.0, 0.0], [0.0, 0.0, 0.0]]
    return CellMechanics(np.array([1.5, 0.0]), stress, True)


def test_snapshots_carry_the_cells_pressure_and_stress_and_stay_loadable_both_ways(tmp_path):
    """The mechanics are three optional keys (since version 2): a reader that does not know them
    (an earlier qpcontact reads only the keys it names) ignores them, and a file without them
    loads with ``mechanics`` None."""
    path = save_colony(tmp_path / "s.npz", a_colony(), 4, mechanics=a_mechanics())
    snapshot = load_snapshot(path)
    np.testing.assert_array_equal(snapshot.mechanics.pressure, [1.5, 0.0])
    np.testing.assert_array_equal(snapshot.mechanics.stress, a_mechanics().stress)
    assert snapshot.mechanics.planar and snapshot.version == VERSION
    with np.load(path) as data:
        assert set(MECHANICS_FIELDS) <= set(data.files) and int(data["version"]) == VERSION
        assert int(data["stress_dimensions"]) == 2
    assert load_snapshot(save_colony(tmp_path / "t.npz", a_colony())).mechanics is None
    with pytest.raises(InvalidSnapshotError, match="mechanics: expected pressure"):
        save_colony(tmp_path / "u.npz", a_colony(), mechanics=CellMechanics.zero(3, False))


@pytest.mark.parametrize("changes, message", [
    (dict(stress=None), "misses stress"),
    (dict(pressure=np.array([1.0, np.nan])), "pressure must be"),
    (dict(stress=np.zeros((2, 3))), "stress must be"),
    (dict(stress_dimensions=np.array(4)), "stress_dimensions must be 2 or 3"),
])
def test_inconsistent_mechanics_in_a_snapshot_are_a_named_error(tmp_path, changes, message):
    path = save_colony(tmp_path / "s.npz", a_colony(), 1, mechanics=a_mechanics())
    rewrite(path, **changes)
    with pytest.raises(InvalidSnapshotError, match=message):
        load_snapshot(path)


def test_version_1_snapshots_written_by_other_tools_still_load(tmp_path):
    """The documented version 1 format: no settings, no random state (a run from it is seeded)."""
    colony = a_colony()
    arrays = dict(cell_arrays(colony.cells), ids=colony.ids, parent_ids=colony.parent_ids, rates=colony.rates,
                  owed=colony.owed)
    np.savez_compressed(tmp_path / "v1.npz", format=np.array("qpcontact-colony"), version=np.array(1),
                        time=np.array(12.5), step=np.array(7), next_id=np.array(11), **arrays)
    snapshot = load_snapshot(tmp_path / "v1.npz")
    assert (snapshot.version, snapshot.step, snapshot.settings, snapshot.rng_state, snapshot.extra) == (1, 7, None, None, {})
    assert_same_colony(snapshot.colony, colony)


def test_cell_types_and_a_models_per_cell_arrays_load_back_equal(tmp_path):
    """Version 3: the types and every cell_data array (any dtype and trailing shape) are saved
    and load back equal, under the checksum."""
    colony = a_colony(cell_types=[2, 0], cell_data={"targetVol": [3.5, 4.25], "signals": np.arange(6.0).reshape(2, 3),
                                                    "infected": np.array([True, False]), "count": np.array([3, 1])})
    path = save_colony(tmp_path / "s.npz", colony, 5)
    assert_same_colony(load_colony(path)[0], colony)
    with np.load(path) as data:
        assert {"cell_types", "data.targetVol", "data.signals", "data.infected", "data.count"} <= set(data.files)
    damaged = np.array([2, 1])  # a changed type is caught by the checksum
    rewrite(path, keep_checksum=True, cell_types=damaged)
    with pytest.raises(InvalidSnapshotError, match="damaged"):
        load_colony(path)


def test_version_2_snapshots_load_with_type_0_and_no_cell_data(tmp_path):
    path = save_colony(tmp_path / "s.npz", a_colony(cell_types=[1, 1], cell_data={"x": [1.0, 2.0]}), 5)
    rewrite(path, version=np.array(2), cell_types=None, **{"data.x": None})
    snapshot = load_snapshot(path)
    assert snapshot.version == 2
    np.testing.assert_array_equal(snapshot.colony.cell_types, [0, 0])
    assert snapshot.colony.cell_data == {}


def test_save_colony_returns_the_file_it_wrote(tmp_path):
    """It wrote snap.npz and returned Path('snap')."""
    path = save_colony(tmp_path / "snap", a_colony())
    assert path == tmp_path / "snap.npz" and path.is_file()
    assert load_colony(path)[0].cells.n == 2
    assert save_cells(tmp_path / "cells", a_colony().cells) == tmp_path / "cells.npz"


def test_a_snapshot_is_written_atomically(tmp_path, monkeypatch):
    """A write that dies half way (SIGKILL, disk full) leaves the previous snapshot whole."""
    path = save_colony(tmp_path / "step_000001.npz", a_colony(), 1)
    before = path.read_bytes()

    def dies(file, **arrays):
        file.write(b"PK\x03\x04 half a zip")
        raise OSError("disk full")

    monkeypatch.setattr(np, "savez_compressed", dies)
    with pytest.raises(OSError, match="disk full"):
        save_colony(path, a_colony(), 2)
    assert path.read_bytes() == before and [p.name for p in tmp_path.iterdir()] == [path.name]


def corrupt(path, how):
    data = path.read_bytes()
    if how == "truncated":
        path.write_bytes(data[: len(data) // 2])
    elif how == "one byte":
        path.write_bytes(data[:1])
    elif how == "empty":
        path.write_bytes(b"")
    elif how == "garbage":
        path.write_bytes(b"\x00\x01 this is not a snapshot" * 10)
    elif how == "bad member":  # a zip whose member is damaged: CRC or zlib error on reading
        with zipfile.ZipFile(path) as zf:
            info = zf.infolist()[-1]
        start = info.header_offset + 30 + len(info.filename) + len(info.extra) + 5
        path.write_bytes(data[:start] + bytes(b ^ 0xFF for b in data[start:start + 20]) + data[start + 20:])


@pytest.mark.parametrize("how", ["truncated", "one byte", "empty", "garbage", "bad member"])
def test_a_corrupted_snapshot_is_a_named_error(tmp_path, how):
    """Raw EOFError, BadZipFile, zlib.error or "pickled data" came out before."""
    path = save_colony(tmp_path / "s.npz", a_colony(), 1)
    corrupt(path, how)
    with pytest.raises(InvalidSnapshotError, match=rf"^{tmp_path / 's.npz'}: "):
        load_colony(path)


def test_a_missing_snapshot_is_a_named_error(tmp_path):
    with pytest.raises(InvalidSnapshotError, match="no such file"):
        load_colony(tmp_path / "nosuch.npz")
    with pytest.raises(InvalidSnapshotError, match="no such file"):
        load_cells(tmp_path / "nosuch.npz")


def rewrite(path, keep_checksum=False, **changes):
    """Write the file again with some arrays changed, as another tool would (without the
    checksum, unless ``keep_checksum``: then it no longer matches the arrays)."""
    with np.load(path) as data:
        arrays = {name: data[name] for name in data.files}
    if not keep_checksum:
        arrays.pop("checksum", None)
    arrays.update(changes)
    for name in [k for k, v in changes.items() if v is None]:
        del arrays[name]
    np.savez(path, **arrays)


@pytest.mark.parametrize("changes, message", [
    (dict(time=np.array(np.nan)), "time must be a finite number"),
    (dict(step=np.array(2.7)), "step must be an integer"),
    (dict(step=np.array(-5)), "step must be >= -1"),
    (dict(ids=np.array([7.0, 9.0])), "ids must be integers"),
    (dict(parent_ids=np.array([np.nan, -1.0])), "parent_ids must be integers"),
    (dict(ids=np.array([7, 7])), "ids: must be unique"),
    (dict(rates=np.array([0.7, np.nan])), "rates: must be finite"),
    (dict(centers=np.array([[0, 0, np.nan], [3, 0, 1]])), "centers"),
    (dict(lengths=np.array([1.0, 2.0, 3.0])), "lengths"),
    (dict(version=np.array(4)), "snapshot version 4 .newer than this qpcontact"),
    (dict(cell_types=None), "misses cell_types"),
    (dict(cell_types=np.array([0.0, 1.0])), "cell_types: expected integers"),
    (dict(cell_types=np.array([0, -1])), "cell_types: must be >= 0"),
    (dict(cell_types=np.array([0, 1, 2])), r"cell_types: expected shape \(2,\)"),
    (dict(**{"data.signal": np.zeros(3)}), r"cell_data\['signal'\]: expected one row per cell"),
    (dict(**{"data.a-b": np.zeros(2)}), "names must be Python identifiers"),
    (dict(format=np.array("something-else")), "not a qpcontact-colony snapshot"),
    (dict(owed=None), "misses owed"),
    (dict(settings=np.array("[1, 2]")), "settings must be a JSON object"),
    (dict(rng_state=np.array(json.dumps({"bit_generator": "Nonsense"}))), "rng_state names no NumPy bit generator"),
    (dict(rng_state=np.array(json.dumps({"bit_generator": "PCG64", "state": {}}))), "not a valid PCG64 state"),
])
def test_an_inconsistent_snapshot_is_a_named_error(tmp_path, changes, message):
    """NaN time, a float step, float ids and NaN parent ids loaded silently before."""
    path = save_colony(tmp_path / "s.npz", a_colony(), 1, rng=np.random.default_rng(0))
    rewrite(path, **changes)
    with pytest.raises(InvalidSnapshotError, match=message):
        load_colony(path)


def test_cells_alone_load_back_equal_and_from_a_snapshot(tmp_path):
    cells = q.Cells(centers=[[0, 0, 0], [3, 0, 1]], axes=[[1, 0, 0], [0, 0.6, 0.8]], lengths=[1.0, 0.0],
                    radii=[0.5, 0.4], masses=[1.0, np.inf], growth_inertia=[10.0, np.inf], momenta=[[1, 2, 3], [0, 0, 0]])
    path = save_cells(tmp_path / "cache" / "cells.npz", cells)
    assert sorted(np.load(path).files) == sorted(CELL_NAMES)
    for source in (path, save_colony(tmp_path / "snapshot.npz", Colony.founder(cells, 0.5))):
        loaded = load_cells(source)
        for name in CELL_NAMES:
            np.testing.assert_array_equal(getattr(loaded, name), getattr(cells, name))
    assert [p.name for p in (tmp_path / "cache").iterdir()] == ["cells.npz"]  # written through a temporary file


# ------------------------------------------------------------------------------------------
# Issue 19, item 5: files that loaded silently or failed raw
# ------------------------------------------------------------------------------------------
def test_a_npy_file_is_a_named_error(tmp_path):
    np.save(tmp_path / "a.npy", np.zeros(3))
    for load in (load_colony, load_snapshot, load_cells):
        with pytest.raises(InvalidSnapshotError, match="a single .npy array, not an NPZ snapshot"):
            load(tmp_path / "a.npy")


def test_a_snapshot_without_a_version_is_a_named_error(tmp_path):
    path = save_colony(tmp_path / "s.npz", a_colony(), 1)
    rewrite(path, version=None)
    with pytest.raises(InvalidSnapshotError, match="misses version"):
        load_colony(path)


@pytest.mark.parametrize("load", [load_colony, load_cells])
def test_a_snapshot_of_a_newer_format_is_refused_with_a_clear_message(tmp_path, load):
    path = save_colony(tmp_path / "s.npz", a_colony(), 1)
    rewrite(path, version=np.array(VERSION + 1))
    with pytest.raises(InvalidSnapshotError, match=f"snapshot version {VERSION + 1} .newer than this qpcontact: update"):
        load(path)


@pytest.mark.parametrize("name", ["centers", "ids", "rates", "time", "extra.warm.impulse", "settings", "cell_types",
                                  "data.signal"])
def test_a_snapshot_with_a_flipped_byte_in_an_array_is_refused(tmp_path, name):
    """Arrays damaged and written again (the ZIP's CRC then matches): loaded silently before;
    the checksum stored with the arrays refuses them now."""
    colony = a_colony(cell_types=[1, 0], cell_data={"signal": [0.25, 0.5]})
    path = save_colony(tmp_path / "s.npz", colony, 1, settings={"seed": 1}, extra={"warm.impulse": np.array([0.5, 0.25])})
    assert_same_colony(load_colony(path)[0], colony)
    with np.load(path) as data:
        damaged = data[name].copy()
    damaged.reshape(-1).view(np.uint8)[min(3, damaged.nbytes - 1)] ^= 0x10
    rewrite(path, keep_checksum=True, **{name: damaged})
    for load in (load_colony, load_cells):
        with pytest.raises(InvalidSnapshotError, match="damaged: its arrays do not match the checksum"):
            load(path)


def test_snapshots_without_a_checksum_still_load(tmp_path):
    """Written before the checksum existed (or by another tool)."""
    path = save_colony(tmp_path / "s.npz", a_colony(), 4)
    assert "checksum" in np.load(path).files
    rewrite(path)
    assert "checksum" not in np.load(path).files
    colony, step = load_colony(path)
    assert step == 4
    assert_same_colony(colony, a_colony())


def test_saving_to_a_folder_or_saving_none_is_a_named_error(tmp_path):
    """issue 28: save_colony given an existing folder wrote FOLDER.npz beside it; save_colony of
    None raised an AttributeError."""
    import qpcontact as qc
    from qpcontact.colony import Colony
    from qpcontact.errors import InvalidArgumentError
    from qpcontact.io import save_colony
    from qpcontact.io.snapshots import save_cells

    colony = Colony.founder(qc.Cells([[0, 0, 0]], [1, 0, 0], [2.0], 0.5), 0.7)
    folder = tmp_path / "run"
    folder.mkdir()
    for save, what in ((save_colony, colony), (save_cells, colony.cells)):
        with pytest.raises(InvalidArgumentError, match=r"path: .*run is a folder; give a file name"):
            save(folder, what)
        with pytest.raises(InvalidArgumentError, match="path: expected a file name"):
            save(None, what)
        with pytest.raises(InvalidArgumentError, match="expected .*, got NoneType"):
            save(tmp_path / "x.npz", None)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run"]  # nothing written beside
    assert save_colony(folder / "colony", colony) == folder / "colony.npz"
