"""``qpcontact simulate``: grow a colony from one cell, save snapshots and draw pictures.

Settings: :class:`qpcontact.simulation.settings.Settings`, one table per concern (``[model]``,
``[run]``, ``[output]``, ``[position]``, ``[velocity]``), each setting described once with its
unit; the flags, ``config.toml`` and ``--config`` are generated from them, and merged in one
place (:func:`qpcontact.simulation.settings.merge`: defaults, the snapshot of ``--start``/``--resume``,
``--config``, the flags). Every setting is checked before the output folder is made: a flag that
does not apply to the run (a velocity-step setting with the default position step, ``--cfl`` with
the growth time step, ``--sink-speed`` in 2D) or a continued run's change of its dimensions or
step is exit status 2 and one line saying why.

Units: lengths in µm, time in doubling times (the time a cell's cylinder length takes to double at
the default rate ln 2; a free cell divides every 1.27 of them: :mod:`qpcontact.simulation.settings`),
masses in units of volume. Every step: the model hook, if any (:mod:`qpcontact.colony.hooks`), then
:func:`qpcontact.colony.divide` (every cell that reached its division length), then the run's step
function (:func:`step_function`), whose contact solve clears the overlap the daughters' axis noise
made: every state a run saves or returns is the end of a step, within its overlap tolerance. Two
steps (``--step``):

- ``position`` (default): :func:`qpcontact.colony.grow_position`, non-penetration at the end of
  the step (:mod:`qpcontact.timestep.position`; settings ``--position-*``), with a time step set by
  growth (:func:`qpcontact.colony.growth_time_step`: the fastest cell grows ``--growth-per-step``
  of its length); a step that does not reach the overlap tolerance is retried with half the step;
- ``velocity`` (the earlier default, kept for comparison; settings ``--velocity-*``):
  :func:`qpcontact.colony.grow`, contacts stop approaching at the start of the step, with a time
  step that follows the colony's expansion (:func:`qpcontact.colony.expansion_time_step`), and a
  step that turns some cell too fast (or, with ``--velocity-overlap-limit``, leaves too large an
  overlap) is retried with half the step (:func:`grow_with_retries`).

Outputs in ``--out`` (default ``./simulate-out``), checked before the run starts
(:class:`qpcontact.io.runs.RunFolder`):

- ``config.toml``: the settings that apply to the run, by table (``--config`` reads such a file);
- ``snapshots/step_NNNNNN.npz``: colony snapshots (format: :mod:`qpcontact.io.snapshots`),
  every ``--snapshot-every`` steps and the last state, written atomically, each with all the
  settings, enough to continue the run exactly (``--resume``);
- ``history.csv``: one row per step, appended as the step completes (time, dt, cells, contacts,
  largest/mean overlap as a fraction of the diameter, solver seconds, step seconds, the velocity
  step's solver residuals, linearizations, the mean and largest cell pressure);
- ``colony.png`` (cells coloured by orientation, or by pressure with ``--color pressure``; a side
  view too in 3D), ``history.png`` (cell count, overlap, solver time, and the solver residuals or
  the linearizations per step, against time), titled with the step, solver and tolerance that
  ran (and the pressure-dependent growth, if on); in 2D ``pressure.png`` (the radial pressure
  profile); with ``--gif`` an animation ``colony.gif``, with ``--vtk`` ParaView files
  (``colony.pvd``, ``vtk/step_NNNNNN.vtu``).

Every snapshot (and ParaView file) carries each cell's pressure and stress over the step that
led to it (:mod:`qpcontact.timestep.mechanics`; :func:`step_mechanics`), from the contact forces
of the step: in 2D per footprint area [force/µm], in 3D per volume [force/µm²], where the force
unit is the drive's (mass·µm/doubling time, masses = volumes in µm³: a free cell of volume V
driven by a force f moves at f/V µm per doubling time). With ``--pressure-growth linear`` or
``exponential`` each cell's growth rate is slowed by its pressure of the step before
(:class:`~qpcontact.colony.PressureGrowth`, ``--stall-pressure``).

A step whose contact solve fails is never applied: the run stops there, says why, saves what
it has and exits with status 1. Ctrl-C (or SIGTERM) stops the run cleanly: the state reached,
the history and the pictures are saved, and ``--resume`` continues it (exit status 128 + the
signal's number: 130 for SIGINT, 143 for SIGTERM). A run that stops at ``--max-steps`` short of
``--cells`` says so and exits with status 3 (:data:`EXIT_SHORT`); a target it can never reach
(rate 0 without a hook) is refused before it starts (:func:`check_target`).

Under ``mpiexec -n P`` (the distributed stack: ``scripts/install-mpi``), one colony grows over P
processes: contact detection is shared by region and the contact solve is split among them
(solver ``ipm-petsc``), process 0 writes; :mod:`qpcontact.simulation.ranks`, docs/distributed.md.
"""

from __future__ import annotations

import argparse
import sys
import traceback
from collections.abc import Mapping
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from .. import moved
from ..cli import output_folder, run_standalone
from ..colony.hooks import load_hook
from ..errors import InvalidArgumentError, ModelHookError
from ..io.runs import RunFolder, is_inside, latest_snapshot, read_toml
from ..io.snapshots import Snapshot, load_snapshot
from ..schema import Layer, settings_of, show
from . import loop, picture
from .ranks import distributed_settings, processes
from .settings import (
    Settings,
    add_setting_flags,
    check_continuation,
    file_layer,
    flag_layer,
    merge,
    refuse_unused,
    stored_values,
)

__all__ = ["EXIT_SHORT", "add_arguments", "configure", "describe_changes", "exit_status", "main", "open_run",
           "run_command", "settings_layers"]

#: Exit status of ``qpcontact simulate`` for a run that stopped at ``--max-steps`` short of its
#: ``--cells`` target (1: the run failed; 2: it could not start; 128 + N: stopped by signal N).
EXIT_SHORT = 3


def __getattr__(name: str) -> Any:
    """The names that moved out of this module (deprecated; :mod:`qpcontact.moved`)."""
    return moved.attribute(__name__, name, moved.NAMES[__name__])


# ------------------------------------------------------------------------------------------
# Command line
# ------------------------------------------------------------------------------------------
def add_arguments(parser: argparse.ArgumentParser) -> None:
    """The options of ``qpcontact simulate``: where the run starts and writes, then a flag per
    setting (:func:`qpcontact.simulation.settings.add_setting_flags`)."""
    parser.description = (
        "Grow a colony from one cell (or from a snapshot), with snapshots, history, pictures and, with --vtk, ParaView "
        "files.\n\nUnits: lengths in µm, time in doubling times (the time a cell's cylinder length takes to double at "
        "the default rate ln 2; a cell growing freely divides every 1.27 of them). Settings come from (later wins): "
        "the defaults, the snapshot of --start/--resume, --config, the flags; every one is checked before the run "
        "starts, and a flag that does not apply to the run (e.g. a --velocity-* flag with the default position step) "
        "is refused.\nCtrl-C stops cleanly: the state, history and pictures are saved; --resume continues.")
    group = parser.add_argument_group("start and output folder")
    group.add_argument("--config", type=Path, metavar="FILE",
                       help="read settings from a TOML file with the tables of the config.toml a run saves ([model], "
                            "[run], [output], [position], [velocity]; the flat files of earlier versions too); paths "
                            "in it are relative to its folder; flags override it")
    start = group.add_mutually_exclusive_group()
    start.add_argument("--start", type=Path, metavar="SNAPSHOT",
                       help="start from this snapshot (.npz): its state, step index, random state and settings. A "
                            "snapshot of --out's own run continues that run (history appended)")
    start.add_argument("--resume", action="store_true", help="continue the run in --out from its latest snapshot")
    group.add_argument("--out", type=output_folder, default=Path("simulate-out"), metavar="FOLDER",
                       help="output folder (default: ./simulate-out); checked before the run starts")
    group.add_argument("--overwrite", action="store_true",
                       help="replace the run already in --out (its files are removed first; default: refuse); with "
                            "--start/--resume of an earlier snapshot of --out, drop the later ones")
    group.add_argument("--quiet", action="store_true", help="no progress bar")
    add_setting_flags(parser, " (a table of --config and config.toml)")


def settings_layers(args: argparse.Namespace, snapshot: Snapshot | None, in_place: bool) -> list[Layer]:
    """The sources of the run's settings, in order: the snapshot's settings, ``--config``, the
    flags. (A snapshot of an earlier version carries no output settings: a run continued in
    its own folder takes them from its ``config.toml``.)"""
    layers = []
    if snapshot is not None and snapshot.settings is not None:
        source = f"{snapshot.path} (settings)"
        state = stored_values(snapshot.settings, source)
        earlier = args.out / "config.toml"
        if in_place and not any(path.startswith("output.") for path in state) and earlier.exists():
            state.update({p: v for p, v in stored_values(read_toml(earlier), str(earlier)).items()
                          if p.startswith("output.")})
        layers.append(Layer(source, state, "state"))
    if args.config is not None:
        layers.append(file_layer(args.config))
    layers.append(flag_layer(args))
    return layers


def configure(args: argparse.Namespace, snapshot: Snapshot | None, in_place: bool) -> Settings:
    """The run's settings (:func:`qpcontact.simulation.settings.merge` of :func:`settings_layers`),
    with every check that needs the whole run: given settings that do not apply refused, and
    the changes a continued run cannot take."""
    layers = settings_layers(args, snapshot, in_place)
    settings = merge(layers)
    refuse_unused([settings], layers)
    if snapshot is not None and snapshot.settings is not None:
        check_continuation(merge(layers[:1]), layers[1:], in_place=in_place,
                           has_generator=snapshot.rng_state is not None)
    return settings


def open_run(args: argparse.Namespace, comm: Any = None) -> tuple[Settings, Snapshot | None, RunFolder | None, str]:
    """Read the start, settle the settings and open the output folder: every check a run needs
    before it starts (so that nothing fails at its end). Over MPI processes (``comm``), every
    process reads the start and settles the settings (:func:`~.ranks.distributed_settings`, whose
    note is returned), then process 0 alone opens the folder (the others get None)."""
    path = latest_snapshot(args.out) if args.resume else args.start
    snapshot = None if path is None else load_snapshot(path)
    in_place = snapshot is not None and is_inside(Path(path), args.out)
    settings = configure(args, snapshot, in_place)
    if snapshot is not None:
        loop.check_types(settings, snapshot.colony)
    if settings.output.vtk:
        from ..io.paraview import _meshio

        _meshio()  # a named error now if meshio is missing
    if settings.model.hook:
        load_hook(settings.model.hook)
    loop.check_target(settings, loop.initial_state(settings, snapshot)[0], settings.model.hook)
    note = ""
    if comm is not None:
        settings, note = distributed_settings(settings, comm)
        comm.Barrier()  # every process has read the start before process 0 opens the folder
        if comm.Get_rank() != 0:
            if not comm.bcast(None, root=0):
                raise InvalidArgumentError("process 0 could not open the output folder (its message says why)")
            return settings, snapshot, None, note
    folder = None
    try:
        if snapshot is not None and in_place:
            folder = RunFolder.resume(args.out, snapshot, overwrite=args.overwrite, vtk=settings.output.vtk)
        else:
            folder = RunFolder.create(args.out, overwrite=args.overwrite, vtk=settings.output.vtk,
                                      first_step=0 if snapshot is None else max(snapshot.step, 0))
    finally:
        if comm is not None:  # the other processes wait for it (and stop if it failed)
            comm.bcast(folder is not None, root=0)
    return settings, snapshot, folder, note


def describe_changes(before: Mapping[str, Any] | None, after: Settings) -> str:
    """The settings that differ from a snapshot's, as ``name: old -> new`` ("" if none)."""
    if before is None:
        return ""
    old = merge([Layer("snapshot", stored_values(before, "snapshot"), "state")])
    changed = []
    for s in settings_of(Settings):
        was, now = getattr(getattr(old, s.table), s.key), getattr(getattr(after, s.table), s.key)
        if was != now:
            changed.append(f"{s.name}: {show(was)} -> {show(now)}")
    return "; ".join(changed)


def run_command(args: argparse.Namespace) -> int:
    from ..io.outputs import describe_written

    comm = processes()  # None unless launched on several MPI processes
    try:
        settings, snapshot, folder, note = open_run(args, comm)  # a QPContactError here: exit 2 (run_checked)
    except KeyboardInterrupt:
        print("qpcontact simulate: interrupted before the run started", file=sys.stderr)
        return 130
    if folder is None:  # a process of a distributed run other than the first: it steps, process 0 writes
        return exit_status(loop.run_colony(settings, start=snapshot, progress=False, comm=comm), settings)
    if note:
        print(note, file=sys.stderr)
    folder.write_config(settings.to_tables(applying=True),
                        f"qpcontact simulate settings, {datetime.now(UTC):%Y-%m-%d %H:%M} UTC: those that apply to "
                        "this run (every snapshot holds them all)"
                        + (f"\nstarted from {snapshot.path} (step {snapshot.step})" if snapshot else "")
                        + "\nrun again: qpcontact simulate --config config.toml --out ANOTHER_FOLDER")
    if snapshot is not None:
        changes = describe_changes(snapshot.settings, settings)
        print(f"continuing from {snapshot.path} (step {snapshot.step}, t = {snapshot.colony.time:.4g}, "
              f"{snapshot.colony.cells.n} cells)" + (f"; settings changed: {changes}" if changes else ""), file=sys.stderr)
    result = loop.run_colony(settings, start=snapshot, progress=not args.quiet, folder=folder,
                        frame_growth=1.08 if settings.output.gif else 0.0, comm=comm)
    try:
        if not (result.interrupted and comm is not None):  # mpiexec kills its processes soon after a signal
            picture.draw_pictures(folder, settings, result, gif=settings.output.gif, color=settings.output.color)
    except KeyboardInterrupt:
        print("qpcontact simulate: interrupted while drawing; the snapshot and the history are saved", file=sys.stderr)
        return 130
    history = folder.read_history()
    cycle = settings.model.cycle_time()
    print(f"{result.colony.cells.n} cells at step {result.steps}, t = {result.colony.time:.3f} doubling times "
          f"(= {result.colony.time / cycle:.1f} cycles of a free cell, {cycle:.2f} each); this run: "
          f"{result.steps - result.first_step} steps in {result.wall_seconds:.1f} s; largest overlap "
          f"{max(history['max_overlap'], default=0.0):.4f} of a diameter; {settings.describe_step()}"
          f"{'' if comm is None else f' on {comm.Get_size()} MPI processes'}: contact solve "
          f"{np.sum(result.history['solve_seconds']):.1f} s; {settings.describe_growth()}")
    print(describe_written(folder.written))
    return report_stop(result, settings, "qpcontact simulate", f"qpcontact simulate --resume --out {folder.path}",
                       f"(--max-steps {settings.run.max_steps}) with {result.colony.cells.n} of the {settings.run.cells} "
                       f"cells of --cells; continue with: qpcontact simulate --resume --max-steps N --out {folder.path}")


def report_stop(result: loop.Run, settings: Settings, program: str, resume: str, short: str) -> int:
    """Say on stderr why a run stopped before its end, if it did, and return its
    :func:`exit_status`: a signal (and ``resume``, the command that continues it), an error (a
    model hook's own traceback first), or too few cells (``short``: which limit stopped it and how
    to go on)."""
    status = exit_status(result, settings)
    if result.interrupted:
        print(f"{program}: stopped by signal {result.interrupted} at step {result.steps}; continue with: {resume}",
              file=sys.stderr)
    elif result.error:
        if isinstance(result.exception, ModelHookError) and result.exception.__cause__ is not None:
            traceback.print_exception(result.exception.__cause__, file=sys.stderr)
        print(f"{program}: {result.error}", file=sys.stderr)
    elif status == EXIT_SHORT:
        print(f"{program}: stopped at step {result.steps} {short} (exit status {EXIT_SHORT})", file=sys.stderr)
    return status


def exit_status(result: loop.Run, settings: Settings) -> int:
    """The exit status of a run: 128 + the signal that stopped it, 1 after an error,
    :data:`EXIT_SHORT` when it stopped short of its cells, else 0."""
    if result.interrupted:
        return 128 + result.interrupted
    if result.error:
        return 1
    return EXIT_SHORT if result.colony.cells.n < settings.run.cells else 0


def main(argv: list[str] | None = None) -> int:
    return run_standalone("qpcontact simulate", add_arguments, run_command, argv)
