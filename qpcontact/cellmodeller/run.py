"""``qpcontact cellmodeller MODEL.py --cells N --out FOLDER``: a CellModeller model script,
unchanged, on qpcontact's physics; and the library call :func:`run_model`.

The model's ``setup(sim)`` builds the cells, planes and options (:func:`~.model.load_model`:
what qpcontact cannot run is refused first, in one line, exit status 2); then
:func:`qpcontact.simulation.run_colony` grows the colony with the model as its hook
(:class:`~.bridge.ModelHook`: ``update(cells)``, ``divideFlag``, ``divide(parent, d1, d2)``),
one step of the model's ``sim.dt`` at a time, on qpcontact's position step (no contact overlaps
by more than 0.01 of a diameter at the end of a step). The run folder is ``simulate``'s:
``config.toml``, ``history.csv``, ``snapshots/`` (every ``sim.pickleSteps`` steps and the last,
with the types and the model's own numbers; ``--resume`` continues from the latest),
``colony.png`` (the cells in the model's ``color``), ``history.png``, ParaView files with
``--vtk``; and ``pickles/step-NNNNN.pickle`` in CellModeller's layout
(:mod:`~.pickles`) and ``model.py``, the model's source.

Time is in the model's own time unit (its ``growthRate`` is per that unit); lengths in µm.
docs/cellmodeller.md is the guide: what maps onto what, and what differs.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..cli import output_folder, positive_float, positive_int, run_standalone
from ..errors import InvalidArgumentError, OutputFolderError
from ..io.cellmodeller import CellModellerState, load_pickle, read_cellmodeller
from ..io.runs import RunFolder, latest_snapshot
from ..io.snapshots import Snapshot, load_snapshot
from ..simulation.loop import Run, run_colony
from ..simulation.settings import ModelSettings, OutputSettings, RunSettings, Settings
from ..simulation.simulate import report_stop
from .bridge import ModelHook
from .model import Model, load_model
from .pickles import PickleWriter
from .standins import serving

#: CellModeller's division jitter: each component of a daughter's axis moves by U(−0.001, 0.001),
#: a turn of standard deviation 0.001/√3 rad about each perpendicular axis.
AXIS_JITTER = 0.001 / np.sqrt(3.0)


@dataclass
class ModelRun:
    """The outcome of :func:`run_model`.

    Attributes:
        run: the run (:class:`qpcontact.simulation.Run`: ``colony``, ``history``, ``steps``,
            ``error``, ``interrupted``, ...).
        model: the loaded model.
        settings: the run's settings.
        hook: the model's hook (its ``states``: the cells as the model sees them; ``lineage``;
            ``left_out``: attributes not kept in snapshots, with the reason).
        folder: the run folder (None: nothing written).
        pickles: the CellModeller-layout pickles written.
        notes: what is ignored or approximated (said once at the start).
    """

    run: Run
    model: Model
    settings: Settings
    hook: ModelHook
    folder: RunFolder | None = None
    pickles: list[Path] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


def model_settings(model: Model, *, cells: int, steps: int | None, seed: int, snapshot_every: int | None = None,
                   vtk: bool = False) -> Settings:
    """The run's settings for ``model``: its dimensions, no substrate sinking, CellModeller's
    division jitter, daughters' rates from the model, ``cells`` capped by ``max_cells``,
    snapshots every ``sim.pickleSteps`` steps."""
    radius = float(np.median([s.radius for s in model.founders]))
    return Settings(
        model=ModelSettings(radius=radius, division_length=max(4.0, 2 * radius + 1.0), rate_noise=0.0,
                            axis_noise=AXIS_JITTER, sink_speed=0.0),
        run=RunSettings(cells=min(cells, model.max_cells), dimensions=2 if model.planar else 3, seed=seed,
                        max_steps=RunSettings().max_steps if steps is None else steps),
        output=OutputSettings(snapshot_every=max(int(model.sim.pickleSteps or 1), 1) if snapshot_every is None
                              else snapshot_every, vtk=vtk))


def run_model(path: str | Path, *, cells: int = 2000, out: str | Path | None = None, steps: int | None = None,
              dt: float | None = None, seed: int = 1, resume: bool = False, overwrite: bool = False,
              pickles: bool = True, vtk: bool = False, progress: bool = False,
              start: str | Path | None = None) -> ModelRun:
    """Run the CellModeller model script ``path`` on qpcontact's physics (module docstring).

    Args:
        path: the model file (``setup``, ``init``, ``update``, optionally ``divide``).
        cells: grow until the colony has this many cells (or the model's ``max_cells``).
        out: the run folder (None: nothing is written, no pickles, no resume).
        steps: stop at this step index (counted from the start, across resumed runs).
        dt: the time step [the model's time unit]; default the model's ``sim.dt`` (0.025).
        seed: seeds the model's random numbers (each step's) and qpcontact's division jitter.
        resume: continue the run in ``out`` from its latest snapshot.
        overwrite: replace a run already in ``out``.
        pickles: write CellModeller-layout pickles (``out/pickles``).
        vtk: ParaView files with each snapshot.
        progress: a progress bar on stderr.
        start: a CellModeller state to continue with the model (a ``step-NNNNN.pickle``, or a
            run folder of them: its last), as CellModeller's own run would go on from it: its
            cells, ids, lineage, types and numbers (``targetVol``, ``color``, ...), its step and
            time; its ``dt`` unless ``dt`` is given.

    Raises:
        ModelRefused: (an InvalidArgumentError) the model uses what qpcontact does not run.
        InvalidArgumentError: the model does not load, bad arguments, ``resume`` without ``out``.
        OutputFolderError: ``out`` cannot be used.
    """
    if resume and out is None:
        raise InvalidArgumentError("resume: needs the run folder (out)")
    if resume and start is not None:
        raise InvalidArgumentError("start and resume: give one (resume continues the run in out)")
    state = None if start is None else read_cellmodeller(start, dt=dt)
    with serving():
        model = load_model(path, seed=seed, dt=dt if state is None else state.dt)
        settings = model_settings(model, cells=cells, steps=steps, seed=seed, vtk=vtk)
        snapshot, folder, writer = _open(model, settings, out, resume=resume, overwrite=overwrite, pickles=pickles)
        hook = ModelHook(model, seed=seed, pickles=writer, lineage=writer.lineage() if writer and snapshot else None)
        first: Any = snapshot if snapshot is not None else hook.founders()
        if state is not None:
            first = imported(hook, state)
        if folder is not None:
            folder.write_config(settings.to_tables(applying=True), f"qpcontact cellmodeller {model.path}: the run's "
                                "settings (the model's own are in model.py)")
        run = run_colony(settings, start=first, progress=progress, folder=folder, hook=hook, planes=model.planes)
        hook.finish(run.colony, run.steps)
    outcome = ModelRun(run, model, settings, hook, folder, list(writer.written) if writer else [], list(model.notes))
    if folder is not None:
        draw(outcome)
    return outcome


def imported(hook: ModelHook, state: CellModellerState) -> CellModellerState:
    """A CellModeller state (:func:`qpcontact.io.cellmodeller.read_cellmodeller`) as the start of
    the model's run: its ``growthRate`` among the cells' numbers, the whole lineage of its
    pickle, and its cells' state already as the pickle's physics left it (the first step does
    not update them again)."""
    colony = state.colony
    if colony.cells.is_monolayer() != hook.model.planar:
        raise InvalidArgumentError(f"{state.path}: a {'2D' if colony.cells.is_monolayer() else '3D'} state, but the "
                                   f"model is {'2D (jitter_z=False)' if hook.model.planar else '3D'}")
    data = {**colony.cell_data, "growthRate": colony.rates.copy()}
    hook.adopt(colony.replace(cell_data=data))
    hook.synced = state.step
    raw = load_pickle(state.path) if state.path is not None else {}
    hook.lineage.update({int(k): int(v) for k, v in raw.get("lineage", {}).items()})
    return dataclasses.replace(state, colony=hook.numbers(colony, [hook.states[int(i)] for i in colony.ids]),
                               settings=None)


def _open(model: Model, settings: Settings, out: str | Path | None, *, resume: bool, overwrite: bool,
          pickles: bool) -> tuple[Snapshot | None, RunFolder | None, PickleWriter | None]:
    """The start (a snapshot when resuming), the run folder and the pickle writer."""
    if out is None:
        return None, None, None
    out = Path(out)
    snapshot = load_snapshot(latest_snapshot(out)) if resume else None
    if snapshot is not None:
        stored = (snapshot.settings or {}).get("run", {}).get("dimensions")
        if stored not in (None, settings.run.dimensions):
            raise InvalidArgumentError(f"{snapshot.path}: a {stored}D run, but the model is {settings.run.dimensions}D")
        folder = RunFolder.resume(out, snapshot, overwrite=overwrite, vtk=settings.output.vtk)
    else:
        if not overwrite and any((out / "pickles").glob("step-*.pickle")):
            raise OutputFolderError(f"{out}: holds an earlier run's pickles; pass --overwrite to replace it, or choose "
                                    "another folder")
        folder = RunFolder.create(out, overwrite=overwrite, vtk=settings.output.vtk)
        for stale in (out / "pickles").glob("step-*.pickle"):
            stale.unlink()
    (folder.path / "model.py").write_text(model.source)
    folder.note(folder.path / "model.py")
    writer = PickleWriter(folder.path / "pickles", model.name, model.source) if pickles else None
    if writer is not None and snapshot is not None:
        writer.drop_after(snapshot.step - 1)
    return snapshot, folder, writer


def describe(outcome: ModelRun) -> str:
    """What ran, for the pictures' titles and the summary."""
    settings, model = outcome.settings, outcome.model
    return (f"{model.name} (CellModeller model) on qpcontact: {settings.run.dimensions}D, "
            f"{settings.describe_step()}; step {model.dt:g} of the model's time unit")


def draw(outcome: ModelRun) -> None:
    """``colony.png`` (the cells in the model's ``color``, from above, and from the side in
    3D) and ``history.png``."""
    from ..io.plots import plot_history, save_colony_picture

    folder, colony = outcome.folder, outcome.run.colony
    assert folder is not None
    color = colony.cell_data.get("color")
    values = color if color is not None and color.shape == (colony.cells.n, 3) else None
    when = f"{colony.cells.n} cells at t = {colony.time:.3f} (the model's time unit)"
    folder.note(save_colony_picture(folder.path / "colony.png", colony.cells, f"{when}\n{describe(outcome)}",
                                    side_view=not outcome.model.planar, planes=outcome.model.planes, values=values))
    history = folder.read_history()
    if history["step"]:
        folder.note(plot_history(folder.path / "history.png", history, describe(outcome), time_unit="the model's time unit"))


# ------------------------------------------------------------------------------------------
# Command line
# ------------------------------------------------------------------------------------------
def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.description = (
        "Run a CellModeller model script (setup(sim), init(cell), update(cells), divide(parent, d1, d2)) unchanged "
        "on qpcontact's physics: the run folder of qpcontact simulate (snapshots, history, pictures) and pickles in "
        "CellModeller's layout (pickles/step-NNNNN.pickle). Lengths in µm, time in the model's own unit. A model "
        "with signalling or an integrator is refused (exit status 2). Guide: docs/cellmodeller.md.")
    parser.add_argument("model", type=Path, metavar="MODEL.py", help="the CellModeller model script")
    parser.add_argument("--cells", type=positive_int, default=2000, metavar="N",
                        help="grow until the colony has N cells (or the model's max_cells; default 2000)")
    parser.add_argument("--out", type=output_folder, default=Path("cellmodeller-out"), metavar="FOLDER",
                        help="the run folder (default: ./cellmodeller-out)")
    parser.add_argument("--steps", type=positive_int, metavar="N",
                        help="stop at step N (counted from the start, across resumed runs; default 100000)")
    parser.add_argument("--dt", type=positive_float, metavar="X",
                        help="the time step [the model's time unit] (default: the model's sim.dt, else 0.025 as "
                             "CellModeller's Scripts/batch.py)")
    parser.add_argument("--seed", type=int, default=1, metavar="N",
                        help="seeds the model's random numbers (random, numpy.random) and the division jitter")
    parser.add_argument("--resume", action="store_true", help="continue the run in --out from its latest snapshot")
    parser.add_argument("--start", type=Path, metavar="PICKLE_OR_FOLDER",
                        help="continue a CellModeller state (a step-NNNNN.pickle, or a run folder of them: its last) "
                             "with the model, as CellModeller would: cells, ids, lineage, types, the model's numbers, "
                             "step and time")
    parser.add_argument("--overwrite", action="store_true", help="replace the run already in --out")
    parser.add_argument("--no-pickles", action="store_true", help="write no CellModeller-layout pickles")
    parser.add_argument("--vtk", action="store_true", help="ParaView files with each snapshot (needs meshio)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def run_command(args: argparse.Namespace) -> int:
    from ..io.outputs import describe_written

    if args.seed < 0:
        raise InvalidArgumentError(f"--seed: must be >= 0, got {args.seed}")
    outcome = run_model(args.model, cells=args.cells, out=args.out, steps=args.steps, dt=args.dt, seed=args.seed,
                        resume=args.resume, overwrite=args.overwrite, pickles=not args.no_pickles, vtk=args.vtk,
                        progress=not args.quiet, start=args.start)
    run, folder = outcome.run, outcome.folder
    assert folder is not None
    for note in outcome.notes:
        print(f"note: {note}", file=sys.stderr)
    history = folder.read_history()
    print(f"{run.colony.cells.n} cells at step {run.steps}, t = {run.colony.time:.4g} (the model's time unit); this "
          f"run: {run.steps - run.first_step} steps in {run.wall_seconds:.1f} s; largest overlap "
          f"{max(history['max_overlap'], default=0.0):.4f} of a diameter; {describe(outcome)}")
    if outcome.hook.left_out:
        print("not kept in snapshots (kept in the pickles): " + "; ".join(f"{k} ({v})" for k, v in
                                                                          outcome.hook.left_out.items()))
    print(describe_written([*folder.written, *outcome.pickles[-1:]]))
    status = report_stop(run, outcome.settings, "qpcontact cellmodeller",
                         f"qpcontact cellmodeller {args.model} --resume --out {folder.path}",
                         f"(--steps) with {run.colony.cells.n} of {outcome.settings.run.cells} cells; continue with "
                         "--resume --steps N")
    if outcome.settings.run.cells < args.cells and not run.error:
        print(f"note: the model's max_cells {outcome.model.max_cells} stops the run before --cells {args.cells}",
              file=sys.stderr)
    return status


def main(argv: list[str] | None = None) -> int:
    return run_standalone("qpcontact cellmodeller", add_arguments, run_command, argv)
