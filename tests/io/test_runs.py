"""Runs that lose nothing (qpcontact.io.runs): the output folder is checked first, Ctrl-C
saves the state reached, a resumed run continues the same trajectory bit for bit, and the
settings travel with the run (config.toml, snapshots)."""

from __future__ import annotations

import csv
import os
import signal
import subprocess
import sys

import numpy as np
import pytest

from qpcontact.cli import main
from qpcontact.errors import OutputFolderError
from qpcontact.io.runs import HISTORY_FIELDS, TIMING_FIELDS, RunFolder, read_toml, write_toml
from qpcontact.io.snapshots import load_snapshot
from qpcontact.simulation import loop
from qpcontact.simulation.loop import run_colony
from qpcontact.simulation.settings import Settings
from qpcontact.simulation.simulate import EXIT_SHORT
from tests.helpers import default_signals, gate_model, wait_for

#: A 3D run with divisions (random axis turns and rates) in both halves, in about a second.
SETTINGS = Settings().updated({"cells": 10**6, "dimensions": 3, "max_dt": 0.1, "growth_per_step": 0.1, "max_steps": 48})
#: The same run with a snapshot every 10 steps (the trajectory does not change).
EVERY_10 = SETTINGS.updated({"snapshot_every": 10})
TRAJECTORY = [name for name in HISTORY_FIELDS if name not in TIMING_FIELDS]


def history(folder) -> list[dict[str, str]]:
    with (folder / "history.csv").open(newline="") as fh:
        return [{k: row[k] for k in TRAJECTORY} for row in csv.DictReader(fh)]


def assert_identical(a, b) -> None:
    for name in ("centers", "axes", "lengths", "radii", "masses", "growth_inertia", "momenta", "angular_momenta",
                 "growth_momenta"):
        np.testing.assert_array_equal(getattr(a.cells, name), getattr(b.cells, name), err_msg=name)
    for name in ("ids", "parent_ids", "rates", "owed", "cell_types"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)
    assert sorted(a.cell_data) == sorted(b.cell_data)
    for name in a.cell_data:
        np.testing.assert_array_equal(a.cell_data[name], b.cell_data[name], err_msg=name)
    assert (a.time, a.next_id) == (b.time, b.next_id)


@pytest.mark.parametrize("when", ["during a step", "between steps"])
def test_an_interrupted_and_resumed_run_equals_the_uninterrupted_one(tmp_path, monkeypatch, when):
    """Before, --start restarted the step counter at 0 and the random generator at the seed."""
    full = run_colony(SETTINGS, progress=False, folder=RunFolder.create(tmp_path / "full"))
    assert full.steps == SETTINGS.run.max_steps and full.colony.cells.n > 8 and not full.error

    fired = []

    def ctrl_c(step: int) -> None:
        if step == 21 and not fired:
            fired.append(step)
            os.kill(os.getpid(), signal.SIGINT)

    if when == "during a step":  # the model hook runs inside the step: the step is abandoned
        hook = lambda colony, step: ctrl_c(step)  # noqa: E731
    else:  # after the step's history row: the step is kept, the run stops after it
        hook = None
        append = RunFolder.append_history
        monkeypatch.setattr(RunFolder, "append_history", lambda self, row: (append(self, row), ctrl_c(row["step"])))
    part = run_colony(EVERY_10, progress=False, folder=RunFolder.create(tmp_path / "part"), hook=hook)
    stopped = 21 if when == "during a step" else 22
    assert part.interrupted == signal.SIGINT and part.steps == stopped and not part.error
    assert sorted(p.name for p in (tmp_path / "part" / "snapshots").iterdir()) == [
        "step_000010.npz", "step_000020.npz", f"step_{stopped:06d}.npz"]
    monkeypatch.undo()

    snapshot = load_snapshot(tmp_path / "part" / "snapshots" / f"step_{stopped:06d}.npz")
    assert Settings.from_stored(snapshot.settings, "snapshot") == EVERY_10  # the settings travel with the state
    resumed = run_colony(EVERY_10, start=snapshot, progress=False, folder=RunFolder.resume(tmp_path / "part", snapshot))
    assert (resumed.first_step, resumed.steps) == (stopped, SETTINGS.run.max_steps)
    assert_identical(resumed.colony, full.colony)
    assert history(tmp_path / "part") == history(tmp_path / "full")  # appended, one row per step


def held_run(tmp_path, step, *argv):
    """``qpcontact simulate`` in its own process, held by a gate model at ``step`` (inside the
    step: tests/helpers.py::gate_model); returns the process once it is held there."""
    gate = gate_model(tmp_path, step)
    out = tmp_path / "run"
    process = subprocess.Popen([sys.executable, "-m", "qpcontact", "simulate", "--cells", "100000", "--out", str(out),
                                "--quiet", "--max-dt", "0.1", "--hook", str(gate), *argv],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=default_signals)
    try:
        wait_for(lambda: (tmp_path / "held").exists() or process.poll() is not None, "the run held at its gate", 120)
    except BaseException:
        process.kill()
        raise
    assert process.poll() is None, process.communicate()[1]
    return process, out


@pytest.mark.slow
@pytest.mark.parametrize("signal_number, status", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_ctrl_c_or_sigterm_stops_simulate_cleanly_and_resume_continues_it(tmp_path, signal_number, status):
    """Before: a KeyboardInterrupt traceback, no history, no pictures, no snapshot. The signal
    lands at a known step (the run is held inside step 6 by its model: no race with the machine's
    speed), so that step is abandoned and the state after six steps is saved."""
    process, out = held_run(tmp_path, 6, "--snapshot-every", "0")
    process.send_signal(signal_number)
    stdout, stderr = process.communicate(timeout=120)
    assert process.returncode == status, stderr
    assert "Traceback" not in stderr and f"stopped by signal {int(signal_number)} at step 6" in stderr
    assert "--resume --out" in stderr
    snapshots = sorted((out / "snapshots").glob("step_*.npz"))
    assert [p.name for p in snapshots] == ["step_000006.npz"]
    assert load_snapshot(snapshots[0]).step == 6 and len(history(out)) == 6
    for name in ("colony.png", "history.png", "config.toml"):
        assert (out / name).stat().st_size > 0, name
    assert str(snapshots[0].parent) in stdout  # it says what it wrote

    assert main(["simulate", "--resume", "--out", str(out), "--quiet", "--max-steps", "9"]) == EXIT_SHORT  # short of --cells at --max-steps
    assert [int(row["step"]) for row in history(out)] == list(range(9))
    assert load_snapshot(out / "snapshots" / "step_000009.npz").step == 9


def test_an_output_folder_that_cannot_be_written_fails_before_the_run(tmp_path, monkeypatch, capsys):
    """Before: the run went to the end and the final save_colony failed with a traceback."""
    monkeypatch.setattr(loop, "run_colony", lambda *a, **k: pytest.fail("the run started"))
    (tmp_path / "file").write_text("")
    assert main(["simulate", "--out", str(tmp_path / "file" / "run"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "cannot write there" in err


def test_an_output_folder_holding_another_run_is_refused_unless_overwrite(tmp_path, capsys):
    """Before: overwritten silently, stale files kept."""
    out = tmp_path / "run"
    assert main(["simulate", "--cells", "2", "--out", str(out), "--quiet", "--snapshot-every", "1"]) == 0
    before = sorted(p.name for p in (out / "snapshots").iterdir())
    assert len(before) > 3
    capsys.readouterr()
    assert main(["simulate", "--cells", "2", "--out", str(out), "--quiet"]) == 2
    assert "holds the outputs of an earlier run" in capsys.readouterr().err
    assert sorted(p.name for p in (out / "snapshots").iterdir()) == before
    assert main(["simulate", "--cells", "2", "--out", str(out), "--quiet", "--overwrite", "--snapshot-every", "0"]) == 0
    assert len(list((out / "snapshots").iterdir())) == 1  # no stale snapshot of the earlier run


def test_a_run_started_from_another_runs_snapshot_continues_its_numbering(tmp_path):
    first = tmp_path / "first"
    assert main(["simulate", "--cells", "4", "--out", str(first), "--quiet", "--snapshot-every", "5",
                 "--max-dt", "0.1"]) == 0
    start = first / "snapshots" / "step_000010.npz"
    second = tmp_path / "second"
    assert main(["simulate", "--start", str(start), "--out", str(second), "--quiet", "--max-steps", "13",
                 "--snapshot-every", "0"]) == EXIT_SHORT  # short of --cells at --max-steps
    assert [int(row["step"]) for row in history(second)] == [10, 11, 12]
    assert history(second) == history(first)[10:13]  # the same trajectory: settings and random state travel along
    assert [p.name for p in (second / "snapshots").iterdir()] == ["step_000013.npz"]
    assert (first / "snapshots" / "step_000005.npz").exists()  # the first run is untouched


def test_resuming_from_an_earlier_snapshot_of_the_same_run_needs_overwrite(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(["simulate", "--cells", "4", "--out", str(out), "--quiet", "--snapshot-every", "5", "--max-dt", "0.1"]) == 0
    rows = history(out)
    capsys.readouterr()
    assert main(["simulate", "--start", str(out / "snapshots" / "step_000005.npz"), "--out", str(out), "--quiet"]) == 2
    assert "has snapshots after step 5" in capsys.readouterr().err
    assert main(["simulate", "--start", str(out / "snapshots" / "step_000005.npz"), "--out", str(out), "--quiet",
                 "--overwrite", "--snapshot-every", "0"]) == 0
    assert history(out) == rows  # dropped after step 5, then the same steps again
    assert sorted(p.name for p in (out / "snapshots").iterdir())[0] == "step_000005.npz"


def test_a_history_that_does_not_belong_to_the_snapshot_is_refused(tmp_path):
    out = tmp_path / "run"
    assert main(["simulate", "--cells", "4", "--out", str(out), "--quiet", "--snapshot-every", "5", "--max-dt", "0.1"]) == 0
    lines = (out / "history.csv").read_text().splitlines()
    (out / "history.csv").write_text("\n".join(lines[:3]) + "\n")  # ends at step 1
    snapshot = load_snapshot(out / "snapshots" / "step_000005.npz")
    with pytest.raises(OutputFolderError, match="ends at step 1, but the snapshot is of step 5"):
        RunFolder.resume(out, snapshot, overwrite=True)
    (out / "history.csv").write_text("a,b\n1,2\n")
    with pytest.raises(OutputFolderError, match="not the history of a qpcontact run"):
        RunFolder.resume(out, snapshot, overwrite=True)


def test_resume_without_a_snapshot_is_a_one_line_error(tmp_path, capsys):
    assert main(["simulate", "--resume", "--out", str(tmp_path / "nothing"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "holds no snapshot" in err


def test_a_config_file_sets_the_run_flags_override_it_and_it_is_saved_with_the_run(tmp_path):
    config = tmp_path / "run.toml"
    config.write_text("[run]\ncells = 3\nmax_dt = 0.1\nseed = 7\n[output]\nsnapshot_every = 4\n"
                      "[position]\ntolerance = 1e-4\nmargin = 0.4\n")
    out = tmp_path / "run"
    assert main(["simulate", "--config", str(config), "--seed", "8", "--out", str(out), "--quiet"]) == 0
    settings = Settings().updated({"cells": 3, "max_dt": 0.1, "seed": 8, "snapshot_every": 4, "position_tolerance": 1e-4,
                                   "position_margin": 0.4})
    # What applies to the run, by table (TOML has no null: None is written "none").
    assert read_toml(out / "config.toml") == {table: {key: "none" if value is None else value
                                                      for key, value in values.items()}
                                              for table, values in settings.to_tables(applying=True).items()}
    assert "velocity" not in read_toml(out / "config.toml") and "cfl" not in read_toml(out / "config.toml")["run"]
    assert Settings.from_stored(load_snapshot(max((out / "snapshots").iterdir())).settings, "snapshot") == settings
    assert len(list((out / "snapshots").iterdir())) > 2
    # The saved file runs the same run again.
    again = tmp_path / "again"
    assert main(["simulate", "--config", str(out / "config.toml"), "--out", str(again), "--quiet"]) == 0
    assert history(again) == history(out)


def test_a_flat_config_file_of_an_earlier_version_still_loads(tmp_path):
    """config.toml as runs wrote it before the settings had tables: every setting, flat."""
    flat = ('n_cells = 3\ndimensions = 2\nsolver = "clarabel"\nformulation = "complementarity"\nform = "auto"\n'
            "tolerance = 1e-06\nposition_correction = 0.5\nmargin = 0.3\ncfl = 0.3\nmax_dt = 0.1\nradius = 0.5\n"
            "division_length = 4.0\nrate = 0.6931471805599453\nrate_noise = 0.1\naxis_noise = 0.02\n"
            'growth_inertia = 500.0\ndynamics = "overdamped"\ndamping = 0.0\nsink_speed = 0.5\nseed = 7\n'
            'max_steps = 100000\nmax_halvings = 3\noverlap_limit = 0.0\nmodel = ""\nstep = "position"\n'
            'time_step = "auto"\ngrowth_per_step = 0.05\noverlap_tolerance = 0.02\nturn_limit = 0.2\n'
            'position_solver = "ipm"\nposition_tolerance = 0.001\nsnapshot_every = 4\nvtk = false\ngif = false\n')
    (tmp_path / "old.toml").write_text(flat)
    out = tmp_path / "run"
    assert main(["simulate", "--config", str(tmp_path / "old.toml"), "--out", str(out), "--quiet"]) == 0
    saved = Settings.from_stored(read_toml(out / "config.toml"), "saved")
    assert (saved.run.cells, saved.run.seed, saved.model.growth_inertia_ratio, saved.position.overlap_tolerance,
            saved.output.snapshot_every) == (3, 7, 500.0, 0.02, 4)
    # A value the run would have ignored is refused now, naming it and why.
    (tmp_path / "ignored.toml").write_text(flat.replace('solver = "clarabel"', 'solver = "osqp"'))
    assert main(["simulate", "--config", str(tmp_path / "ignored.toml"), "--out", str(tmp_path / "x"), "--quiet"]) == 2


@pytest.mark.parametrize("text, message", [
    ("n_celss = 3\n", "unknown setting 'n_celss'; known: [model] radius, division_length"),
    ("[run]\ncels = 3\n", "unknown setting 'cels' in [run]; known: [model] radius"),
    ('[run]\ncells = "many"\n', "[run] cells: expected an integer, got 'many'"),
    ("[run]\ncfl = -1.0\n", "[run] cfl: expected a number > 0, got -1.0"),
    ("[simulate]\ncells = 3\n", "unknown table [simulate]"),
    ("[output]\nvtk = 1\n", "[output] vtk: expected true or false, got 1"),
    ("[output]\nsnapshot_every = -2\n", "[output] snapshot_every: expected an integer >= 0, got -2"),
    ("n_cells = \n", "not a TOML file"),
    ('[position]\nsolver = "nosuch"\n', "unknown solver 'nosuch'"),
    ("[position]\ntolerance = 2.0\n", "[position] tolerance: expected a number in (0, 1), got 2.0"),
    ('[velocity]\nsolver = "osqp"\n', "[velocity] solver: a setting of the velocity step; this run takes position steps"),
    ("[model]\nsink_speed = 1.0\n", "[model] sink_speed: 3D only"),
    ("[model]\ndivision_length = 0.5\n", "[model] division_length: must exceed 2 × radius = 1 µm"),
])
def test_a_bad_config_file_is_a_one_line_error(tmp_path, capsys, text, message):
    (tmp_path / "run.toml").write_text(text)
    assert main(["simulate", "--config", str(tmp_path / "run.toml"), "--out", str(tmp_path / "run"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and message in err and not (tmp_path / "run").exists(), err


def test_a_config_files_known_keys_are_every_setting():
    """The config error's list of known keys left out keys it accepted."""
    from qpcontact.schema import known_names, settings_of

    listing = known_names(Settings)
    for s in settings_of(Settings):
        assert f"[{s.table}] " in listing and s.key in listing.split(f"[{s.table}] ")[1].split(";")[0], s.path


def test_toml_round_trip_is_exact():
    values = {**Settings().to_tables(), "extra": {"tolerance": 1.0000000000000002e-06, "model": 'a "quoted" \\ name\n',
                                                  "flag": True, "big": float("inf")}, "top": 1}
    import tomllib

    # TOML has no null: a setting that is None (e.g. position.margin, "none: by the scene") is
    # written as the word the settings read back as None.
    def spelled(value):
        return {k: spelled(v) for k, v in value.items()} if isinstance(value, dict) else ("none" if value is None else value)

    assert tomllib.loads(write_toml(values, "two\nlines")) == spelled(values)
    assert Settings.from_stored(tomllib.loads(write_toml(Settings().to_tables(), "")), "test") == Settings()


@pytest.mark.parametrize("change, message", [
    ({"seed": -1}, "seed: expected an integer >= 0, got -1"),
    ({"max_steps": 2.5}, "max_steps: expected an integer, got 2.5"),
    ({"velocity_dynamics": "wobbly"}, "velocity_dynamics: expected one of overdamped, inertial"),
    ({"step": "velocity", "velocity_solver": "nosuch"}, "unknown solver 'nosuch'"),
    ({"velocity_formulation": "nosuch"}, "velocity_formulation: expected one of least_squares, complementarity"),
    ({"position_solver": "linear"}, "position_solver: 'linear' takes no bounds"),
    ({"nosuch": 1}, "unknown setting 'nosuch'"),
])
def test_settings_no_run_can_use_are_refused_when_made(change, message):
    from qpcontact.errors import QPContactError

    with pytest.raises(QPContactError, match=message):
        Settings().updated(change)


@pytest.mark.slow
def test_a_killed_run_leaves_whole_snapshots_and_resumes_with_a_contiguous_history(tmp_path):
    """SIGKILL (no chance to save anything), at a known step (held inside step 10 by its model):
    the snapshots written so far are whole (written atomically), the history runs past the last
    one, and --resume continues from it."""
    process, out = held_run(tmp_path, 10, "--snapshot-every", "3")
    process.kill()
    process.wait(timeout=60)
    snapshots = sorted((out / "snapshots").glob("step_*.npz"))
    assert [load_snapshot(p).step for p in snapshots] == [3, 6, 9]  # none truncated
    assert len(history(out)) == 10
    assert main(["simulate", "--resume", "--out", str(out), "--quiet", "--max-steps", "13"]) == EXIT_SHORT  # short of --cells at --max-steps
    assert [int(row["step"]) for row in history(out)] == list(range(13))
    assert not [p for p in out.rglob(".*.tmp")]


def test_a_run_with_pressure_growth_resumed_from_a_snapshot_equals_the_uninterrupted_one(tmp_path):
    """The growth of each step depends on the pressure of the step before: the snapshots keep it,
    so a run resumed from one continues exactly (a run that forgot it would grow the first step
    after the resume unslowed)."""
    from qpcontact.colony import PressureGrowth

    settings = Settings().updated({"cells": 10**6, "max_steps": 40})
    growth = PressureGrowth("exponential", 5.0)
    full = run_colony(settings, progress=False, pressure_growth=growth)
    part = run_colony(settings.updated({"max_steps": 25}), progress=False, pressure_growth=growth,
                      folder=RunFolder.create(tmp_path / "part"))
    snapshot = load_snapshot(tmp_path / "part" / "snapshots" / "step_000025.npz")
    np.testing.assert_array_equal(snapshot.mechanics.pressure, part.mechanics.pressure)
    resumed = run_colony(settings, start=snapshot, progress=False, pressure_growth=growth)
    assert_identical(resumed.colony, full.colony)
    np.testing.assert_array_equal(resumed.mechanics.stress, full.mechanics.stress)
    # The law did act: slower growth, so longer steps (the fastest cell grows 5 % per step).
    assert full.colony.time > run_colony(settings, progress=False).colony.time


def test_a_run_folder_written_before_the_pressure_columns_is_resumed(tmp_path):
    """history.csv without mean_pressure and max_pressure (an earlier qpcontact): its rows are
    kept, with those columns NaN, and the resumed steps have them."""
    out = tmp_path / "run"
    assert main(["simulate", "--cells", "3", "--out", str(out), "--quiet", "--snapshot-every", "5", "--max-dt", "0.1",
                 "--max-steps", "10"]) == EXIT_SHORT  # short of --cells at --max-steps
    legacy = [name for name in HISTORY_FIELDS if name not in ("mean_pressure", "max_pressure")]
    with (out / "history.csv").open(newline="") as fh:
        rows = [{k: row[k] for k in legacy} for row in csv.DictReader(fh)]
    with (out / "history.csv").open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=legacy)
        writer.writeheader()
        writer.writerows(rows)
    assert main(["simulate", "--resume", "--out", str(out), "--quiet", "--max-steps", "13"]) == EXIT_SHORT  # short of --cells at --max-steps
    history = RunFolder(out).read_history()
    assert len(history["step"]) == 13 and np.all(np.isnan(history["mean_pressure"][:10]))
    assert np.all(np.isfinite(history["mean_pressure"][10:]))


def typed_hook(colony, step):
    """A model with its own per-cell state: each cell's age in steps (a daughter starts from her
    mother's), and at step 20 each cell takes a type by its id, which her daughters inherit."""
    age = colony.cell_data.get("age", np.zeros(colony.cells.n, dtype=np.int64)) + 1
    types = colony.ids % 2 if step == 20 else colony.cell_types
    return colony.replace(cell_types=types, cell_data={"age": age, "tag": np.stack([age, 2 * age], axis=1)})


def test_a_run_resumed_from_a_snapshot_keeps_the_cell_types_and_the_models_per_cell_arrays(tmp_path):
    """Issue 27: before, a hook's own per-cell dictionary was lost on resume; now its state lives
    in the colony's cell_data and cell_types, which the snapshots save: the resumed run follows
    the uninterrupted one bit for bit, and the per-type growth rates act on the newborns."""
    settings = Settings().updated({"cells": 10**6, "max_steps": 90, "rate_noise": 0.0, "type_rates": [0.7, 0.35]})
    full = run_colony(settings, progress=False, hook=typed_hook)
    part = run_colony(settings.updated({"max_steps": 55}), progress=False, hook=typed_hook,
                      folder=RunFolder.create(tmp_path / "part"))
    snapshot = load_snapshot(tmp_path / "part" / "snapshots" / "step_000055.npz")
    assert_identical(snapshot.colony, part.colony)
    assert Settings.from_stored(snapshot.settings, "snapshot").model.type_rates == (0.7, 0.35)
    resumed = run_colony(settings, start=snapshot, progress=False, hook=typed_hook)
    assert_identical(resumed.colony, full.colony)
    colony = full.colony
    assert set(colony.cell_types) == {0, 1} and colony.cell_data["age"].max() == 90
    # Per-type rates: a cell born after the types were set grows at her type's rate (no noise);
    # the founder and her descendants before that grew at type 0's.
    born_after = colony.ids > part.colony.ids.max()  # born after step 55, long after step 20
    assert born_after.any() and (colony.cell_types[born_after] == 1).any()
    np.testing.assert_array_equal(colony.rates[born_after], np.where(colony.cell_types[born_after] == 1, 0.35, 0.7))
    assert np.all(np.isin(colony.rates, [0.7, 0.35]))
