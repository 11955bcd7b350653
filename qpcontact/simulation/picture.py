"""The pictures of a colony run, and ``qpcontact plot SNAPSHOT``, which draws a saved snapshot
again as its run drew ``colony.png``.

- :func:`draw_pictures`: what a run draws at its end (``colony.png``, ``history.png``,
  ``pressure.png`` in 2D, ``colony.gif``), titled with what ran (:func:`describe_run`);
- :func:`colony_picture`: the picture of a colony as a run draws it;
- :func:`plot_snapshot` and the command ``qpcontact plot``.

The picture of ``qpcontact plot`` is :func:`colony_picture` of the snapshot's colony, with
the run's settings stored in the snapshot (dimensions, planes, the step and solver in the
title; with ``--statistics`` the colony's statistics under it, docs/statistics.md): from above,
and from the side too in 3D, coloured by ``--color`` (orientation, pressure, cell_type, or the
name of one of the model's own per-cell arrays, :func:`qpcontact.io.plots.colony_colors`). A
snapshot without settings (version 1, or written by another tool) is drawn with the default
settings, in 3D if a cell lies off the plane ``z = 0``.
"""

from __future__ import annotations

import argparse
import sys
import textwrap
from pathlib import Path

import numpy as np

from ..colony.growth import Colony
from ..colony.statistics import colony_statistics
from ..errors import InvalidArgumentError, OutputFolderError
from ..io.runs import RunFolder
from ..io.snapshots import Snapshot, load_snapshot
from ..io.tables import snapshot_file
from ..timestep.mechanics import CellMechanics
from .loop import Run
from .settings import COLORS, Settings

__all__ = ["add_arguments", "colony_picture", "describe_run", "draw_pictures", "main", "plot_snapshot", "run_command",
           "snapshot_settings"]


def describe_run(settings: Settings) -> str:
    """What ran, for the pictures' titles: ``"2D, position step, ipm at tolerance 0.001,
    overlap ≤ 0.01"`` (:meth:`Settings.describe_step`), with the pressure-dependent growth on a
    second line if it is on (:meth:`Settings.describe_growth`)."""
    label = f"{settings.run.dimensions}D, {settings.describe_step()}"
    return label if settings.model.pressure_growth == "off" else f"{label}\n{settings.describe_growth()}"


def colony_picture(path: Path, colony: Colony, mechanics: CellMechanics | None, settings: Settings, color: str,
                   title: str) -> Path:
    """The picture of a colony as a run draws it (``colony.png``): from above, and from the side
    too in 3D, with the run's planes, coloured as ``color`` says
    (:func:`~qpcontact.io.plots.colony_colors`: orientation, pressure, cell_type, or a
    ``cell_data`` array's name)."""
    from ..io.plots import colony_colors, save_colony_picture

    planar = settings.run.dimensions == 2
    return save_colony_picture(path, colony.cells, title, side_view=not planar, planes=settings.planes(),
                               **colony_colors(color, colony, mechanics, planar))


def draw_pictures(folder: RunFolder, settings: Settings, result: Run, *, gif: bool, color: str = "orientation") -> None:
    """``colony.png`` (and a side view in 3D, :func:`colony_picture`), coloured by the cells'
    orientation or, with ``color="pressure"``, by their pressure of the last step
    (:attr:`Run.mechanics`, with a colour bar in its units), or with ``"cell_type"`` by their
    type; ``history.png`` of the whole run (earlier attempts of a resumed run
    included); in 2D ``pressure.png``, the radial pressure profile
    (:func:`~qpcontact.io.plots.plot_pressure_profile`); ``colony.gif`` from this run's
    frames. Titled with what ran (:func:`describe_run`).

    Raises:
        InvalidArgumentError: ``color`` is not one of :data:`COLORS`.
    """
    from ..io.plots import animate, plot_history, plot_pressure_profile

    if color not in COLORS:
        raise InvalidArgumentError(f"color: expected one of {', '.join(COLORS)}, got {color!r}")
    label = describe_run(settings)
    cells, planar = result.colony.cells, settings.run.dimensions == 2
    mechanics = result.mechanics or CellMechanics.zero(cells.n, planar)
    when = f"{cells.n} cells at t = {result.colony.time:.2f} doubling times"
    folder.note(colony_picture(folder.path / "colony.png", result.colony, mechanics, settings, color,
                               f"{when} ({label})"))
    if planar and cells.n:
        folder.note(plot_pressure_profile(folder.path / "pressure.png", cells, mechanics.pressure,
                                          f"{when}: pressure over the last step\n{label}"))
    history = folder.read_history()
    if history["step"]:
        folder.note(plot_history(folder.path / "history.png", history, label))
    if gif and len(result.frames) > 1:
        folder.note(animate(folder.path / "colony.gif", result.frames))


def snapshot_settings(snapshot: Snapshot) -> Settings:
    """The run's settings stored in the snapshot, or (none stored) the defaults, in 3D when a
    cell lies off the plane ``z = 0``."""
    if snapshot.settings is not None:
        return Settings.from_stored(snapshot.settings, f"{snapshot.path} (settings)")
    flat = not np.any(snapshot.colony.cells.centers[:, 2]) and not np.any(snapshot.colony.cells.axes[:, 2])
    return Settings().updated({"dimensions": 2 if flat else 3})


def plot_snapshot(snapshot: Snapshot, path: str | Path, color: str = "orientation", *,
                  statistics: bool = False) -> Path:
    """Draw ``snapshot`` into ``path`` (PNG, SVG, PDF, ... by the suffix) as its run drew
    ``colony.png`` (module docstring); with ``statistics``, the colony's statistics
    (:meth:`qpcontact.colony.ColonyStatistics.summary`) under the title. Returns the path.

    Raises:
        InvalidArgumentError: ``color`` names nothing to colour by, or ``pressure`` for a
            snapshot without the cells' mechanics.
    """
    if color == "pressure" and snapshot.mechanics is None:
        raise InvalidArgumentError(f"--color pressure: {snapshot.path} holds no pressure (written before issue 19, or "
                                   "by another tool)")
    settings = snapshot_settings(snapshot)
    colony = snapshot.colony
    title = f"{colony.cells.n} cells at t = {colony.time:.2f} doubling times ({describe_run(settings)})"  # the run's
    if "cellmodeller.dt" in snapshot.extra:  # a CellModeller state (import-cellmodeller), or a run continuing one
        extra = snapshot.extra
        dt, step = float(extra["cellmodeller.dt"][0]), int(extra["cellmodeller.step"][0])
        when = f"{colony.cells.n} cells at t = {colony.time:.4g} (CellModeller's time unit, its step {dt:g})"
        title = (f"{when}: a CellModeller state (its step {step}), largest overlap "
                 f"{float(extra['cellmodeller.max_overlap'][0]):.3g} of a diameter as measured"
                 if snapshot.step == step + 1 else f"{when}; continued by qpcontact: {describe_run(settings)}")
    if statistics:
        title += "\n" + textwrap.fill(colony_statistics(snapshot, dimensions=settings.run.dimensions).summary(), 80)
    return colony_picture(Path(path), colony, snapshot.mechanics, settings, color, title)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.description = ("Draw a saved snapshot again as its run drew colony.png: from above (and from the side in "
                          "3D), coloured by orientation, pressure, cell type or one of the model's own per-cell arrays.")
    parser.add_argument("source", type=Path, metavar="SNAPSHOT",
                        help="a snapshot (.npz), or a run's folder (its latest snapshot, or --snapshot)")
    parser.add_argument("--snapshot", metavar="N|NAME",
                        help="of a run's folder: the snapshot of step N, or the file NAME in its snapshots/")
    parser.add_argument("--out", type=Path, metavar="FILE",
                        help="the picture (.png, .svg, .pdf, ...; default: the snapshot's name with .png, in the "
                             "current folder)")
    parser.add_argument("--color", default="orientation", metavar="NAME",
                        help="orientation (default), pressure, cell_type, or the name of a per-cell array of the "
                             "model (cell_data) with one number per cell")
    parser.add_argument("--statistics", action="store_true",
                        help="write the colony's statistics under the title: packing, contacts per cell, nematic "
                             "length, local order, edge alignment (3D: the biofilm's layers; docs/statistics.md)")
    parser.add_argument("--overwrite", action="store_true", help="replace --out if it exists (default: refuse)")


def run_command(args: argparse.Namespace) -> int:
    from matplotlib.figure import Figure

    path = snapshot_file(args.source, args.snapshot)
    out: Path = args.out if args.out is not None else Path(path.with_suffix(".png").name)
    kinds = Figure().canvas.get_supported_filetypes()
    if out.suffix.lower().lstrip(".") not in kinds:
        raise InvalidArgumentError(f"--out {out}: unknown picture suffix {out.suffix!r}; one of "
                                   f"{', '.join('.' + kind for kind in sorted(kinds))}")
    if out.exists() and not args.overwrite:
        raise OutputFolderError(f"--out {out}: exists; pass --overwrite to replace it")
    snapshot = load_snapshot(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    print(f"wrote {plot_snapshot(snapshot, out, args.color, statistics=args.statistics)}", file=sys.stderr)
    return 0


def main(argv: list[str] | None = None) -> int:
    from ..cli import run_standalone

    return run_standalone("qpcontact plot", add_arguments, run_command, argv)
