"""The settings of a colony run (qpcontact.simulation.settings): one description per setting, from
which the flags, the TOML tables and the sweep's names are generated; one merge; every flag
applies to the run or is refused (exit status 2, one line saying why) before anything is
written; a continued run refuses the changes that would corrupt it."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from qpcontact import cli
from qpcontact.colony.growth import Colony
from qpcontact.errors import InvalidArgumentError
from qpcontact.geometry import Cells
from qpcontact.io.runs import read_toml
from qpcontact.io.snapshots import load_snapshot, save_colony
from qpcontact.schema import find_setting, settings_of
from qpcontact.simulation import Settings, run_colony
from qpcontact.simulation.settings import FORMER_NAMES
from qpcontact.simulation.simulate import EXIT_SHORT
from qpcontact.timestep import PositionSettings


def simulate_parser():
    return cli.command_parser(cli.build_parser("simulate"), "simulate")


# ------------------------------------------------------------------------------------------
# One description, everything generated from it
# ------------------------------------------------------------------------------------------
def test_every_setting_is_described_once_and_has_a_flag_a_table_key_and_a_name():
    flags = {flag for action in simulate_parser()._actions for flag in action.option_strings}
    sweep_flags = {flag for action in cli.command_parser(cli.build_parser("sweep"), "sweep")._actions
                   for flag in action.option_strings}
    tables = Settings().to_tables()
    for s in settings_of(Settings):
        assert s.description.help and not s.description.help[0].isupper(), s.path  # a phrase, shown after the flag
        assert s.flag in flags and s.flag in sweep_flags, s.flag
        assert s.key in tables[s.table], s.path
        assert find_setting(Settings, s.name) is find_setting(Settings, s.path) is find_setting(Settings, s.flag[2:]) is s
        if s.kind in (int, float) and not s.description.choices and s.name != "seed":  # a seed has no unit
            assert s.description.unit, f"{s.path}: a number without a unit"


def test_every_field_of_the_position_step_is_a_setting_of_the_run():
    """Settings.position_settings() passed on 4 of PositionSettings' 10 fields."""
    keys = {s.key for s in settings_of(Settings) if s.table == "position"}
    assert keys == {f.name for f in dataclasses.fields(PositionSettings)}
    changed = {"position_overlap_tolerance": 0.02, "position_margin": 0.4, "position_max_iterations": 12,
               "position_turn_limit": None, "position_trust": 0.5, "position_relaxation": 0.1, "position_aim": 0.0,
               "position_allow_shrinking": True, "position_solver": "mprgp", "position_tolerance": 1e-4}
    settings = Settings().updated(changed)
    assert settings.position == PositionSettings(**{name[len("position_"):]: v for name, v in changed.items()})


def test_position_flags_reach_the_step_and_config_toml(tmp_path, capsys):
    out = tmp_path / "run"
    assert cli.main(["simulate", "--cells", "3", "--position-margin", "0.4", "--position-aim", "0.005",
                     "--position-turn-limit", "none", "--position-allow-shrinking", "--position-solver", "clarabel",
                     "--out", str(out), "--quiet"]) == 0
    position = read_toml(out / "config.toml")["position"]
    assert (position["margin"], position["aim"], position["turn_limit"], position["allow_shrinking"],
            position["solver"]) == (0.4, 0.005, "none", True, "clarabel")
    snapshot = load_snapshot(max((out / "snapshots").iterdir()))
    assert Settings.from_stored(snapshot.settings, "s").position.turn_limit is None
    assert f"position step, clarabel at tolerance {PositionSettings().tolerance:g}" in capsys.readouterr().out


def test_the_api_reference_shows_the_one_description():
    from qpcontact.simulation import ModelSettings

    assert "growth_inertia_ratio: each cell's growth inertia G" in (ModelSettings.__doc__ or "")
    assert "[dimensionless, G/m] (default: 1000; > 0)" in (ModelSettings.__doc__ or "")
    assert "tolerance: its tolerance" in (PositionSettings.__doc__ or "")


# ------------------------------------------------------------------------------------------
# Refused before anything is written: exit status 2 and one line saying why
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("argv, message", [
    # velocity-step settings with the default (position) step
    (["--velocity-solver", "osqp"], "--velocity-solver: a setting of the velocity step; this run takes position steps"),
    (["--velocity-tolerance", "1e-4"], "--velocity-tolerance: a setting of the velocity step"),
    (["--velocity-margin", "0.1"], "--velocity-margin: a setting of the velocity step"),
    (["--velocity-position-correction", "0.2"], "--velocity-position-correction: a setting of the velocity step"),
    (["--velocity-overlap-limit", "0.1"], "--velocity-overlap-limit: a setting of the velocity step"),
    # the flags of earlier versions: each step has its own, or renamed
    (["--solver", "osqp"], "--solver: each step has its own: --position-solver (the position step's) or "
                           "--velocity-solver (the velocity step's)"),
    (["--tolerance", "1e-4"], "--tolerance: each step has its own: --position-tolerance"),
    (["--margin", "0.1"], "--margin: each step has its own: --position-margin"),
    (["--position-correction", "0.2"], "--position-correction: use --velocity-position-correction"),
    (["--overlap-limit", "0.1"], "--overlap-limit: use --velocity-overlap-limit"),
    (["--overlap-tolerance", "0.02"], "--overlap-tolerance: use --position-overlap-tolerance"),
    (["--model", "x.py"], "--model: use --hook"),
    (["--growth-inertia", "100"], "--growth-inertia: use --growth-inertia-ratio"),
    # settings of a time step, a dimension or dynamics the run does not have
    (["--cfl", "0.2"], "--cfl: used by the expansion time step (--time-step expansion) and the velocity step only"),
    (["--step", "velocity", "--growth-per-step", "0.1"], "--growth-per-step: used by the growth time step only"),
    (["--sink-speed", "1"], "--sink-speed: 3D only"),
    (["--step", "velocity", "--velocity-damping", "0.5"], "--velocity-damping: used by inertial dynamics only"),
    (["--step", "velocity", "--position-solver", "mprgp"], "--position-solver: a setting of the position step"),
    # values no run can use
    (["--position-tolerance", "2"], "argument --position-tolerance: expected a number in (0, 1), got 2.0"),
    (["--velocity-tolerance", "2"], "argument --velocity-tolerance: expected a number in (0, 1), got 2.0"),
    (["--division-length", "0.5"], "--division-length: must exceed 2 × radius = 1 µm (daughters are born at "
                                   "division_length/2 − radius = -0.25 µm)"),
    (["--radius", "2"], "--division-length: must exceed 2 × radius = 4 µm"),
    (["--out", ""], "argument --out: expected a folder, got an empty path"),
    (["--position-solver", "linear"], "--position-solver: 'linear' takes no bounds"),
    (["--position-trust", "0"], "argument --position-trust: expected a number > 0, got 0.0"),
    (["--vtk", "maybe"], "argument --vtk: cannot read 'maybe' as on or off"),
    (["--hook", "nosuch.py"], "nosuch.py: no such file"),
    # pressure-dependent growth and the picture's colour (issue 21)
    (["--stall-pressure", "50"], "--stall-pressure: used by pressure-dependent growth only (--pressure-growth linear "
                                 "or exponential); this run's pressure growth is off"),
    (["--pressure-growth", "off", "--stall-pressure", "50"], "--stall-pressure: used by pressure-dependent growth only"),
    (["--pressure-growth", "quadratic"], "argument --pressure-growth: expected one of off, linear, exponential, got "
                                         "'quadratic'"),
    (["--pressure-growth", "linear", "--stall-pressure", "0"], "argument --stall-pressure: expected a number > 0, got 0.0"),
    (["--pressure-growth", "linear", "--stall-pressure", "inf"], "argument --stall-pressure: expected a finite number"),
    (["--color", "red"], "argument --color: expected one of orientation, pressure, cell_type, got 'red'"),
    # a second-order step needs a solver that takes the curvature, and reaches 10⁻⁵ at best
    (["--position-second-order", "true", "--position-solver", "clarabel"],
     "--position-second-order: solver 'clarabel' takes no curvature of the objective"),
    (["--position-second-order", "true", "--position-tolerance", "1e-6"],
     "its solves reach a tolerance of 1e-05 at best; got tolerance 1e-06"),
])
def test_a_flag_that_does_not_apply_or_cannot_be_used_is_refused_before_the_run(argv, message, tmp_path, capsys,
                                                                                monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert cli.main(["simulate", *argv, "--quiet"]) == 2
    out, err = capsys.readouterr()
    assert err.count("\n") == 1 and message in err and not out, err
    assert list(tmp_path.iterdir()) == []  # no run folder, no step taken


def test_a_flag_of_the_step_that_runs_is_taken(tmp_path):
    out = tmp_path / "run"
    assert cli.main(["simulate", "--step", "velocity", "--velocity-solver", "osqp", "--velocity-tolerance", "1e-4",
                     "--cfl", "0.2", "--max-steps", "3", "--out", str(out), "--quiet"]) == EXIT_SHORT  # short of --cells at --max-steps
    saved = read_toml(out / "config.toml")
    assert (saved["velocity"]["solver"], saved["velocity"]["tolerance"], saved["run"]["cfl"]) == ("osqp", 1e-4, 0.2)
    assert "position" not in saved and "growth_per_step" not in saved["run"]  # only what applies


@pytest.mark.parametrize("flags, message", [
    (["--dimensions", "3"], "--dimensions 3: the state is 2D"),
    (["--step", "velocity"], "--step velocity: the run's history, its warm start and its time-step rule belong to its "
                             "step (position)"),
    (["--radius", "0.4"], "--radius 0.4: it sets the founder only"),
    (["--growth-inertia-ratio", "10"], "--growth-inertia-ratio 10: it sets the founder only"),
    (["--seed", "9"], "--seed 9: the snapshot carries the random generator's state"),
])
def test_resume_refuses_the_changes_that_would_corrupt_the_run_and_names_them(flags, message, tmp_path, capsys):
    """--resume --dimensions 3 on a 2D run was accepted: overlaps jumped to 0.35, config.toml said 3D."""
    out = tmp_path / "run"
    assert cli.main(["simulate", "--cells", "4", "--snapshot-every", "5", "--out", str(out), "--quiet"]) == 0
    before = sorted(p.name for p in out.rglob("*")), (out / "config.toml").read_text()
    capsys.readouterr()
    assert cli.main(["simulate", "--resume", *flags, "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "a run continued from a snapshot keeps these settings" in err and message in err, err
    assert (sorted(p.name for p in out.rglob("*")), (out / "config.toml").read_text()) == before  # untouched
    # Several at once are named together.
    assert cli.main(["simulate", "--resume", "--dimensions", "3", "--step", "velocity", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "--dimensions 3" in err and "--step velocity" in err


def test_a_new_run_from_a_snapshot_may_change_the_step_but_not_the_dimensions(tmp_path, capsys):
    first = tmp_path / "first"
    assert cli.main(["simulate", "--cells", "4", "--out", str(first), "--quiet"]) == 0
    start = max((first / "snapshots").iterdir())
    assert cli.main(["simulate", "--start", str(start), "--step", "velocity", "--max-steps", "40",
                     "--out", str(tmp_path / "second"), "--quiet"]) == 0
    capsys.readouterr()
    assert cli.main(["simulate", "--start", str(start), "--dimensions", "3", "--out", str(tmp_path / "third")]) == 2
    assert "--dimensions 3: the state is 2D" in capsys.readouterr().err


def test_a_run_with_a_relative_hook_resumes_from_any_directory(tmp_path, monkeypatch):
    """A relative --model path could not be found when the run was resumed from elsewhere."""
    project, elsewhere = tmp_path / "project", tmp_path / "elsewhere"
    project.mkdir()
    elsewhere.mkdir()
    (project / "model.py").write_text("def hook(colony, step):\n    return None\n")
    monkeypatch.chdir(project)
    out = tmp_path / "run"
    assert cli.main(["simulate", "--hook", "model.py", "--cells", "4", "--snapshot-every", "5", "--max-steps", "20",
                     "--out", str(out), "--quiet"]) == EXIT_SHORT  # short of --cells at --max-steps
    assert read_toml(out / "config.toml")["model"]["hook"] == str(project / "model.py")
    monkeypatch.chdir(elsewhere)
    assert cli.main(["simulate", "--resume", "--max-steps", "25", "--out", str(out), "--quiet"]) == EXIT_SHORT
    # In a config file, a path is relative to the file's folder.
    (project / "run.toml").write_text('[model]\nhook = "model.py"\n[run]\ncells = 2\n')
    assert cli.main(["simulate", "--config", str(project / "run.toml"), "--out", str(tmp_path / "b"), "--quiet"]) == 0
    assert read_toml(tmp_path / "b" / "config.toml")["model"]["hook"] == str(project / "model.py")


def test_a_snapshot_of_an_earlier_version_with_flat_settings_continues(tmp_path):
    first = tmp_path / "first"
    assert cli.main(["simulate", "--cells", "4", "--out", str(first), "--quiet"]) == 0
    snapshot = load_snapshot(max((first / "snapshots").iterdir()))
    settings = Settings.from_stored(snapshot.settings, "s")
    flat = {former: getattr(getattr(settings, path.split(".")[0]), path.split(".")[1])
            for former, path in FORMER_NAMES.items()}
    flat["model"] = ""
    flat.update(dimensions=2, seed=1, max_steps=100_000, step="position", radius=0.5, division_length=4.0,
                rate=math.log(2.0), overlap_tolerance=0.01, turn_limit=0.2)
    old = tmp_path / "old.npz"
    save_colony(old, snapshot.colony, snapshot.step, settings=flat, rng=snapshot.generator())
    assert cli.main(["simulate", "--start", str(old), "--max-steps", str(snapshot.step + 3),
                     "--out", str(tmp_path / "second"), "--quiet"]) == 0


# ------------------------------------------------------------------------------------------
# Units that say what they mean
# ------------------------------------------------------------------------------------------
def test_the_cycle_time_is_the_time_from_birth_to_division_of_a_free_cell():
    """The time unit is the doubling time of a cylinder's length; daughters are born at
    l/2 − ρ, so a cell's cycle is longer (1.27 units at the defaults, not 1)."""
    from qpcontact.simulation import ModelSettings

    settings = Settings().updated({"cells": 4, "rate_noise": 0.0, "axis_noise": 0.0, "growth_per_step": 0.002})
    run = run_colony(settings, progress=False)
    cells, times = np.asarray(run.history["cells"]), np.asarray(run.history["time"])
    born, divided = times[np.flatnonzero(cells >= 2)[0]], times[np.flatnonzero(cells >= 4)[0]]
    cycle = ModelSettings().cycle_time()
    assert cycle == pytest.approx(1.27, abs=0.005)
    assert divided - born == pytest.approx(cycle, abs=0.02)  # two daughters touching end to end grow freely
    assert ModelSettings(rate=0.0).cycle_time() == math.inf


# ------------------------------------------------------------------------------------------
# Pressure-dependent growth and the picture's colour (issue 21)
# ------------------------------------------------------------------------------------------
def test_the_pressure_settings_are_described_once_with_their_units():
    growth, stall, color = (find_setting(Settings, name) for name in ("pressure_growth", "stall_pressure", "color"))
    assert (growth.path, growth.flag, growth.default, growth.description.choices) == (
        "model.pressure_growth", "--pressure-growth", "off", ("off", "linear", "exponential"))
    assert (stall.path, stall.flag, stall.default, stall.description.bounds()) == (
        "model.stall_pressure", "--stall-pressure", 100.0, "> 0")
    assert "F/µm in 2D, F/µm² in 3D" in stall.description.unit
    assert (color.path, color.flag, color.default, color.description.choices) == (
        "output.color", "--color", "orientation", ("orientation", "pressure", "cell_type"))
    help_text = simulate_parser().format_help()
    assert "--pressure-growth {off,linear,exponential}" in help_text and "--color {orientation,pressure,cell_type}" in help_text
    settings = Settings().updated({"pressure_growth": "exponential", "stall_pressure": 20})
    assert settings.describe_growth() == "pressure growth exponential, stall pressure 20 F/µm"
    assert settings.updated({"dimensions": 3}).describe_growth().endswith("F/µm²")
    assert Settings().describe_growth() == "pressure growth off"


def test_pressure_growth_flags_slow_the_run_as_the_law_does_and_are_named_where_the_run_is_told(tmp_path, capsys):
    """--pressure-growth linear --stall-pressure 0.5 runs what run_colony(pressure_growth=
    PressureGrowth("linear", 0.5)) runs, bit for bit; config.toml, the snapshots and the last
    line say so; the same steps without it reach an earlier time (growth is not slowed)."""
    from qpcontact.colony import PressureGrowth

    common = ["--cells", "1000000", "--max-steps", "40", "--quiet"]
    slowed_out, free_out = tmp_path / "slowed", tmp_path / "free"
    assert cli.main(["simulate", "--pressure-growth", "linear", "--stall-pressure", "0.5", *common,
                     "--out", str(slowed_out)]) == EXIT_SHORT  # short of --cells at --max-steps
    printed = capsys.readouterr().out
    assert "pressure growth linear, stall pressure 0.5 F/µm" in printed
    saved = read_toml(slowed_out / "config.toml")["model"]
    assert (saved["pressure_growth"], saved["stall_pressure"]) == ("linear", 0.5)
    slowed = load_snapshot(max((slowed_out / "snapshots").iterdir()))
    settings = Settings.from_stored(slowed.settings, "s")
    assert (settings.model.pressure_growth, settings.model.stall_pressure) == ("linear", 0.5)
    explicit = run_colony(settings.updated({"pressure_growth": "off"}), progress=False,
                          pressure_growth=PressureGrowth("linear", 0.5))
    np.testing.assert_array_equal(explicit.colony.cells.centers, slowed.colony.cells.centers)
    np.testing.assert_array_equal(explicit.colony.cells.lengths, slowed.colony.cells.lengths)
    assert explicit.colony.time == slowed.colony.time
    assert cli.main(["simulate", *common, "--out", str(free_out)]) == EXIT_SHORT  # short of --cells at --max-steps
    printed = capsys.readouterr().out
    assert "pressure growth off" in printed
    saved = read_toml(free_out / "config.toml")["model"]
    assert saved["pressure_growth"] == "off" and "stall_pressure" not in saved  # only what applies
    free = load_snapshot(max((free_out / "snapshots").iterdir()))
    assert free.step == slowed.step and free.colony.time < slowed.colony.time  # slowed: longer steps


def test_the_color_flag_colours_colony_png_by_pressure_and_the_default_by_orientation(tmp_path, monkeypatch):
    from qpcontact.io import plots

    drawn = {}
    original = plots.save_colony_picture

    def spy(path, cells, title=None, **kwargs):
        drawn[path.parent.name] = (title, kwargs.get("values"), kwargs.get("value_label", ""))
        return original(path, cells, title, **kwargs)

    monkeypatch.setattr(plots, "save_colony_picture", spy)
    for name, flags in (("orientation", []), ("pressure", ["--color", "pressure"]),
                        ("slowed", ["--color", "pressure", "--pressure-growth", "exponential", "--stall-pressure", "3"])):
        assert cli.main(["simulate", "--cells", "6", *flags, "--out", str(tmp_path / name), "--quiet"]) == 0
    title, values, label = drawn["orientation"]
    assert values is None and label == "" and "pressure growth" not in title
    assert read_toml(tmp_path / "orientation" / "config.toml")["output"]["color"] == "orientation"
    title, values, label = drawn["pressure"]
    last = load_snapshot(max((tmp_path / "pressure" / "snapshots").iterdir()))
    np.testing.assert_array_equal(values, last.mechanics.pressure)  # the pressure of the last state
    assert "2D pressure [F/µm]" in label and "position step, ipm" in title
    assert read_toml(tmp_path / "pressure" / "config.toml")["output"]["color"] == "pressure"
    title, _, _ = drawn["slowed"]
    assert title.endswith("overlap ≤ 0.01, search margin 0.75 (by the scene), growth per step 0.05 (by the scene)\npressure growth exponential, "
                          "stall pressure 3 F/µm)")  # names what ran
    for name in drawn:
        assert (tmp_path / name / "colony.png").stat().st_size > 1000


def test_a_config_file_with_the_pressure_settings(tmp_path, capsys):
    config = tmp_path / "run.toml"
    config.write_text('[model]\npressure_growth = "exponential"\nstall_pressure = 2.5\n'
                      '[run]\ncells = 5\n[output]\ncolor = "pressure"\n')
    out = tmp_path / "run"
    assert cli.main(["simulate", "--config", str(config), "--out", str(out), "--quiet"]) == 0
    saved = read_toml(out / "config.toml")
    assert (saved["model"]["pressure_growth"], saved["model"]["stall_pressure"], saved["output"]["color"]) == (
        "exponential", 2.5, "pressure")
    assert "pressure growth exponential, stall pressure 2.5 F/µm" in capsys.readouterr().out
    # Flags override the file; the run's own config.toml runs again.
    assert cli.main(["simulate", "--config", str(config), "--pressure-growth", "linear", "--out", str(tmp_path / "b"),
                     "--quiet"]) == 0
    assert read_toml(tmp_path / "b" / "config.toml")["model"]["pressure_growth"] == "linear"
    assert cli.main(["simulate", "--config", str(out / "config.toml"), "--out", str(tmp_path / "c"), "--quiet"]) == 0
    # A stall pressure in a file whose pressure growth is off: refused unless it is the default.
    capsys.readouterr()
    config.write_text('[model]\nstall_pressure = 2.5\n[run]\ncells = 2\n')
    assert cli.main(["simulate", "--config", str(config), "--out", str(tmp_path / "d"), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "[model] stall_pressure: used by pressure-dependent growth only" in err, err
    assert not (tmp_path / "d").exists()
    config.write_text('[model]\npressure_growth = "off"\nstall_pressure = 100.0\n[run]\ncells = 2\n')
    assert cli.main(["simulate", "--config", str(config), "--out", str(tmp_path / "e"), "--quiet"]) == 0
    config.write_text('[model]\npressure_growth = "fast"\n')
    assert cli.main(["simulate", "--config", str(config), "--out", str(tmp_path / "f"), "--quiet"]) == 2
    assert "[model] pressure_growth: expected one of off, linear, exponential, got 'fast'" in capsys.readouterr().err


def test_the_step_in_words_names_the_search_margin_and_the_step_the_scene_picked():
    assert Settings().describe_step().endswith(", search margin 0.75 (by the scene), growth per step 0.05 (by the scene)")
    assert Settings().updated({"dimensions": 3}).describe_step().endswith(
        ", search margin 0.5 (by the scene), growth per step 0.00625 (by the scene)")
    given = Settings().updated({"position_margin": 0.4, "growth_per_step": 0.1}).describe_step()
    assert "search margin" not in given and "growth per step" not in given  # given: in config
    # What changes the colony is named (issue 32): a cap on turning, an aim other than the default.
    assert "capped" not in Settings().describe_step() and "aim" not in Settings().describe_step()
    bent = Settings().updated({"position_turn_limit": 0.2, "position_aim": 0.03}).describe_step()
    assert ", turns capped at 0.2 diameters, aim 0.03" in bent
    # and what ran: a second-order step, given or chosen by its solver (none), says so
    assert "second order" not in Settings().describe_step()
    assert "second order" in Settings().updated({"position_second_order": True}).describe_step()
    assert "second order" in Settings().updated({"position_second_order": None}).describe_step()
    assert "second order" not in Settings().updated({"position_second_order": None,
                                                     "position_solver": "clarabel"}).describe_step()


def test_the_growth_step_is_the_scenes_unless_given():
    """Issue 32: 0.05 in 2D, 0.00625 in 3D (the 3D biofilm is bent at 0.05), or the setting."""
    colony = Colony.founder(Cells(centers=[[0.0, 0.0, 0.5]], axes=[[1.0, 0.0, 0.0]], lengths=2.0, radii=0.5), 0.7)
    rate = 0.7
    assert Settings().time_step_of(colony) == pytest.approx(np.log1p(0.05) / rate)
    assert Settings().updated({"dimensions": 3}).time_step_of(colony) == pytest.approx(np.log1p(0.00625) / rate)
    assert Settings().updated({"dimensions": 3, "growth_per_step": 0.05}).time_step_of(colony) == \
        pytest.approx(np.log1p(0.05) / rate)
    with pytest.raises(InvalidArgumentError, match="growth_per_step"):
        Settings().updated({"growth_per_step": 0.0})
