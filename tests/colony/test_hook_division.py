"""What a model hook gained for CellModeller's models, for every ``simulate`` user: cells marked
to divide (``StepControl.dividing``), a fixed time step (``StepControl.dt``), a divide callback
(``hook.divided``: daughters' own numbers at birth), and a run from several founders."""

from __future__ import annotations

import numpy as np
import pytest

from qpcontact.colony import Colony, StepControl, divide
from qpcontact.colony.growth import births
from qpcontact.colony.hooks import load_hook
from qpcontact.errors import InvalidArgumentError
from qpcontact.geometry import Cells
from qpcontact.simulation.loop import run_colony
from qpcontact.simulation.settings import Settings

SETTINGS = Settings().updated({"cells": 10**6, "max_steps": 60, "rate_noise": 0.0})


def founders(n: int) -> Colony:
    """``n`` founders 10 µm apart along y, 2 µm long, with a target length of their own."""
    cells = Cells(centers=[[0.0, 10.0 * k, 0.0] for k in range(n)], axes=[[1.0, 0.0, 0.0]] * n, lengths=2.0, radii=0.5,
                  masses=1.0, growth_inertia=1000.0)
    colony = Colony.founder(cells, np.log(2.0))
    return colony.replace(cell_data={"target": np.full(n, 3.0), "generation": np.zeros(n, dtype=np.int64)})


class TargetModel:
    """Divide at each cell's own target; daughters draw theirs at birth and count generations."""

    def __init__(self) -> None:
        self.rng = np.random.default_rng(5)
        self.steps: list[float] = []

    def __call__(self, colony: Colony, step: int) -> StepControl:
        self.steps.append(colony.time)
        return StepControl(dividing=colony.cells.lengths >= colony.cell_data["target"], dt=0.05)

    def divided(self, before: Colony, after: Colony, born: tuple[np.ndarray, np.ndarray, np.ndarray]) -> Colony:
        mothers, first, second = born
        target, generation = after.cell_data["target"].copy(), after.cell_data["generation"].copy()
        for rows in (first, second):
            target[rows] = 2.6 + 0.4 * self.rng.random(rows.size)
            generation[rows] = before.cell_data["generation"][mothers] + 1
        return after.replace(cell_data={"target": target, "generation": generation})


def test_division_at_each_cells_own_target_drawn_at_birth_from_several_founders():
    model = TargetModel()
    run = run_colony(SETTINGS, start=founders(3), progress=False, hook=model)
    colony = run.colony
    assert not run.error and colony.cells.n >= 12
    assert np.allclose(np.diff(model.steps), 0.05)  # the hook's fixed step
    target = colony.cell_data["target"]
    assert np.all((target >= 2.6) & (target <= 3.0)) and np.unique(target).size > colony.cells.n // 2
    # marked at the start of a step once at its target: no cell past it by more than a step's growth
    assert np.all(colony.cells.lengths <= target * np.exp(2 * np.log(2.0) * 0.05) + 1e-9)
    assert colony.cell_data["generation"].max() >= 2
    # three founders' descendants: each cell's lineage ends at one of the ids 0, 1, 2
    assert set(np.unique(colony.cells.centers[:, 1] // 5).tolist()) >= {0.0, 2.0, 4.0}


def test_divide_marks_cells_and_births_names_mothers_and_daughters():
    colony = founders(3).replace(cells=founders(3).cells.replace(lengths=[2.0, 1.5, 2.5]))
    after = divide(colony, 4.0, np.random.default_rng(0), dividing=np.array([True, False, True]))
    mothers, first, second = births(colony, after)
    assert mothers.tolist() == [0, 2] and first.tolist() == [0, 2] and second.tolist() == [3, 4]
    assert np.allclose(after.cells.lengths[[0, 3]], 2.0 / 2 - 0.5)
    with pytest.raises(InvalidArgumentError, match="longer than 2 × radius"):
        divide(colony.replace(cells=colony.cells.replace(lengths=[0.9, 1.5, 2.5])), 4.0, np.random.default_rng(0),
               dividing=np.array([True, False, False]))


def test_a_model_files_divided_function_becomes_the_hooks_callback(tmp_path):
    model = tmp_path / "model.py"
    model.write_text("import numpy as np\nfrom qpcontact.colony import StepControl\n\n"
                     "def hook(colony, step):\n    return StepControl(dividing=colony.cells.lengths > 3.0)\n\n"
                     "def divided(before, after, born):\n"
                     "    mothers, first, second = born\n"
                     "    count = after.cell_data.get('births', np.zeros(after.cells.n, dtype=int)).copy()\n"
                     "    count[first] += 1\n    count[second] += 1\n"
                     "    return after.replace(cell_data={'births': count})\n")
    hook = load_hook(model)
    start = founders(1).replace(cell_data={"births": np.zeros(1, dtype=int)})
    run = run_colony(SETTINGS.updated({"max_steps": 80}), start=start, progress=False, hook=hook)
    assert run.colony.cells.n >= 4 and np.all(run.colony.cell_data["births"] >= 1)


def test_simulate_starts_from_several_founders_a_hook_places(tmp_path, capsys):
    """No snapshot needed: at step 0 a hook replaces the default founder with its own cells."""
    from qpcontact.cli import main

    model = tmp_path / "founders.py"
    model.write_text(
        "import numpy as np\nfrom qpcontact.colony import Colony\nfrom qpcontact.geometry import Cells\n\n"
        "def hook(colony, step):\n"
        "    if step == 0:\n"
        "        c = colony.cells\n"
        "        cells = Cells(centers=[[-10.0, 0, 0], [10.0, 0, 0], [0, 15.0, 0]], axes=[[1.0, 0, 0]] * 3, lengths=c.lengths[0],\n"
        "                      radii=0.5, masses=c.masses[0], growth_inertia=c.growth_inertia[0])\n"
        "        return Colony(cells, np.arange(3), np.full(3, -1), np.full(3, colony.rates[0]), cell_types=[0, 1, 2])\n")
    out = tmp_path / "run"
    assert main(["simulate", "--hook", str(model), "--cells", "24", "--out", str(out), "--quiet"]) == 0
    capsys.readouterr()
    from qpcontact.io.runs import latest_snapshot
    from qpcontact.io.snapshots import load_snapshot

    colony = load_snapshot(latest_snapshot(out)).colony
    assert colony.cells.n >= 24 and set(colony.cell_types.tolist()) == {0, 1, 2}
    for kind, x in ((0, -10.0), (1, 10.0)):
        assert abs(np.mean(colony.cells.centers[colony.cell_types == kind, 0]) - x) < 4.0
