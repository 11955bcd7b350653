"""Model hooks (qpcontact.colony.hooks): the user's per-step function sets growth rates, the
division rule and extra forces; what it gets wrong is a named error that stops the run cleanly."""

from __future__ import annotations

import re

import numpy as np
import pytest

from qpcontact.cli import main
from qpcontact.colony import StepControl, push
from qpcontact.errors import ModelHookError
from qpcontact.io.runs import RunFolder
from qpcontact.simulation.loop import run_colony
from qpcontact.simulation.settings import Settings

SETTINGS = Settings().updated({"cells": 10**6, "max_dt": 0.1, "max_steps": 30, "rate_noise": 0.0})


def test_a_hook_sets_growth_rates_and_division_lengths():
    calls, longest = [], {"hook": 0.0, "plain": 0.0}

    def hook(colony, step):
        calls.append(step)
        longest["hook"] = max(longest["hook"], colony.cells.lengths.max())
        rates = np.where(colony.ids % 2 == 0, 1.0, 0.0)  # odd ids stop growing
        return StepControl(colony.replace(rates=rates), division_length=np.full(colony.cells.n, 3.0))

    def watch(colony, step):
        longest["plain"] = max(longest["plain"], colony.cells.lengths.max())

    run = run_colony(SETTINGS, progress=False, hook=hook)
    run_colony(SETTINGS, progress=False, hook=watch)
    assert calls == list(range(SETTINGS.run.max_steps)) and not run.error
    # Cells with odd ids do not grow: they keep their length at birth, half of 3 µm (and what
    # grew in the last step) less a radius.
    odd = run.colony.ids % 2 == 1
    assert odd.any() and np.all((run.colony.cells.lengths[odd] >= 1.0) & (run.colony.cells.lengths[odd] < 1.2))
    # Divided at 3 µm instead of 4: the hook sees the cells before this step's division (at its
    # start, issue 19), so at most one step's growth (5 %, or 10 % while paying owed length) past it.
    assert 3.0 <= longest["hook"] < 3.0 * 1.1 < 3.9 < longest["plain"]


def test_a_hook_pushes_cells_with_extra_momenta():
    """A free cell driven at 1 µm per doubling time along x moves exactly that far."""
    settings = Settings().updated({"cells": 10**6, "max_dt": 0.1, "max_steps": 12, "rate": 0.0, "rate_noise": 0.0})
    run = run_colony(settings, progress=False, hook=lambda colony, step: StepControl(drive=push(colony, [1.0, 0, 0])))
    assert run.colony.cells.n == 1
    assert run.colony.cells.centers[0] == pytest.approx([run.colony.time, 0.0, 0.0], abs=1e-9)


def test_a_hook_that_takes_mechanics_gets_each_cells_pressure_of_the_step_before():
    """One entry per cell of the colony it is given (after division: a newborn has its mother's),
    zero before the first step, 2D pressure in a 2D run; the pressure the run's history records
    for the step before (over the cells before division) has the same largest value."""
    from qpcontact.timestep import CellMechanics

    seen = []

    def hook(colony, step, mechanics):
        assert isinstance(mechanics, CellMechanics) and mechanics.planar
        assert mechanics.pressure.shape == (colony.cells.n,) and mechanics.stress.shape == (colony.cells.n, 3, 3)
        seen.append(mechanics.pressure.max())

    run = run_colony(SETTINGS, progress=False, hook=hook)
    assert not run.error and len(seen) == SETTINGS.run.max_steps
    assert seen[0] == 0.0 and max(seen) > 0
    assert seen[1:] == pytest.approx(run.history["max_pressure"][:-1], rel=0, abs=0)


def test_a_hook_may_return_a_colony_or_none():
    seen = []

    def hook(colony, step):
        seen.append(colony.cells.n)
        return colony.replace(rates=np.zeros(colony.cells.n)) if step >= 5 else None

    run = run_colony(SETTINGS, progress=False, hook=hook)
    assert run.colony.cells.n == seen[5]  # no growth after step 5, so no division


@pytest.mark.parametrize("answer, message", [
    (lambda colony: 3, "returned int; expected None, a Colony or a StepControl"),
    (lambda colony: StepControl(drive=np.zeros((colony.cells.n, 6))), r"drive must be a finite \(1, 7\) array"),
    (lambda colony: StepControl(division_length=-1.0), "division_length must be a number"),
    (lambda colony: StepControl(division_length=0.9), r"division_length: must exceed 2 × radius = 1 µm"),
    (lambda colony: 1 / 0, "raised ZeroDivisionError: division by zero"),
])
def test_a_bad_hook_stops_the_run_with_a_named_error_and_the_state_saved(tmp_path, answer, message):
    run = run_colony(SETTINGS, progress=False, hook=lambda colony, step: answer(colony),
                     folder=RunFolder.create(tmp_path))
    assert run.steps == 0 and re.search(message, run.error) and isinstance(run.exception, ModelHookError)
    assert (tmp_path / "snapshots" / "step_000000.npz").exists()


def test_simulate_runs_a_model_file_and_saves_it_in_the_settings(tmp_path, capsys):
    model = tmp_path / "model.py"
    model.write_text("import numpy as np\n\ndef hook(colony, step):\n"
                     "    return colony.replace(rates=np.full(colony.cells.n, 2.0))\n")
    out = tmp_path / "run"
    assert main(["simulate", "--hook", str(model), "--cells", "4", "--out", str(out), "--quiet"]) == 0
    assert f'hook = "{model}"' in (out / "config.toml").read_text()
    broken = tmp_path / "broken.py"
    broken.write_text("def hook(colony, step):\n    raise RuntimeError('my model is wrong')\n")
    capsys.readouterr()
    assert main(["simulate", "--hook", str(broken), "--out", str(tmp_path / "b"), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert "Traceback" in err and "broken.py" in err and "my model is wrong" in err  # the model's own traceback
    assert main(["simulate", "--hook", str(tmp_path / "nosuch.py"), "--out", str(tmp_path / "c"), "--quiet"]) == 2
    assert "nosuch.py: no such file" in capsys.readouterr().err


@pytest.mark.parametrize("command", ["simulate", "sweep"])
@pytest.mark.parametrize(("source", "error"), [
    ("def hook(colony, step:\n    pass\n", "line 1: SyntaxError"),
    ("import numpy\nimport no_such_module_for_qpcontact\n", "line 2: ModuleNotFoundError"),
    ("raise RuntimeError('my model does not load')\n", "line 1: RuntimeError: my model does not load"),
])
def test_a_hook_that_does_not_load_is_one_line_and_exit_2(tmp_path, capsys, command, source, error):
    """docs/colony.md: a model hook that does not load is exit status 2 and one line, no
    traceback, before anything is written."""
    model = tmp_path / "model.py"
    model.write_text(source)
    out = tmp_path / "out"
    assert main([command, "--hook", str(model), "--cells", "3", "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and len(err.strip().splitlines()) == 1
    assert f"model {model}: does not load: {error}" in err
    assert not out.exists()


def test_a_dividing_mother_gives_each_daughter_half_her_hook_drive():
    """The hook's drive is per cell of the colony it was given; division now comes after the
    hook, at the start of the step: each daughter gets half her mother's row (a push m·v then
    still moves each daughter at v), the other cells keep theirs."""
    import qpcontact as q
    from qpcontact.colony import Colony, daughters_share, divide

    cells = q.Cells([[0, 0, 0], [0, 3, 0], [0, 6, 0]], [1, 0, 0], [4.2, 2.0, 4.5], 0.5)
    colony = Colony.founder(cells, 0.7)
    drive = push(colony, [[1.0, 0, 0], [0, 2.0, 0], [0, 0, 3.0]])
    divided = divide(colony, 4.0, np.random.default_rng(0), planar=True)
    shared = daughters_share(drive, colony, divided)
    assert divided.cells.n == 5 and shared.shape == (5, 7)
    np.testing.assert_array_equal(shared[1], drive[1])
    np.testing.assert_array_equal(shared[[0, 3]], [drive[0] / 2] * 2)
    np.testing.assert_array_equal(shared[[2, 4]], [drive[2] / 2] * 2)
    velocities = shared[:, :3] / divided.cells.masses[:, None]
    np.testing.assert_allclose(velocities[[0, 3]], [[1.0, 0, 0]] * 2)
    assert daughters_share(drive, colony, colony) is not None
