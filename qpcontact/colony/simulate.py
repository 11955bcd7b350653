"""``qpcontact simulate``: grow a colony from one cell, save snapshots and draw pictures.

Units: lengths in µm (cells of radius 0.5 µm dividing at a cylinder length of 4 µm), time in
mean doubling times (growth rate ln 2), masses in arbitrary units (mass = volume, growth inertia
``G`` = ``--growth-inertia`` × mass). Every step: :func:`qpcontact.colony.grow` (growth drive,
contact solve, move), then :func:`qpcontact.colony.divide`; the step size follows the colony's
expansion (:func:`qpcontact.colony.expansion_time_step`, with the run's dimensions), and a step that turns some cell too
fast (or, with ``--overlap-limit``, leaves too large an overlap) is retried with half the step
(:func:`grow_with_retries`).

Outputs in ``--out`` (default ``colony-run``):

- ``snapshots/step_NNNNNN.npz``: colony snapshots (format: :mod:`qpcontact.colony.snapshots`), every
  ``--snapshot-every`` steps and the last one;
- ``history.csv``: one row per step (time, dt, cells, contacts, largest/mean overlap as a
  fraction of the diameter, solver seconds, step seconds, residuals);
- ``colony.png`` (cells coloured by orientation), ``history.png`` (cell count, overlap, solver
  time and residual against time), and with ``--gif`` an animation ``colony.gif``.

A step whose contact solve fails is never applied: the run stops there, says why, saves what
it has and exits with status 1.
"""

from __future__ import annotations

import argparse
import csv
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InvalidArgumentError, QPContactError, SolverFailedError
from ..geometry import Cells, capsule_volume
from ..geometry.surfaces import substrate
from ..solvers import FORMS, QP_FORMULATIONS, available_solvers
from .growth import Colony, divide, expansion_time_step, grow
from .snapshots import load_colony, save_colony
from .step import largest_overlap

HISTORY_FIELDS = ("step", "time", "dt", "cells", "contacts", "max_overlap", "mean_overlap", "solve_seconds",
                  "step_seconds", "penetration", "complementarity", "rejected")


@dataclass
class Settings:
    """Everything that defines a colony run (the command-line options, as values)."""

    n_cells: int = 2000
    dimensions: int = 2
    solver: str = "clarabel"
    formulation: str = "complementarity"
    form: str = "auto"
    tolerance: float = 1e-6
    position_correction: float = 0.5
    margin: float = 0.3
    cfl: float = 0.3
    max_dt: float = 0.02
    radius: float = 0.5
    division_length: float = 4.0
    rate: float = float(np.log(2.0))
    rate_noise: float = 0.1
    axis_noise: float = 0.02
    growth_inertia: float = 1000.0
    dynamics: str = "overdamped"
    damping: float = 0.0
    sink_speed: float = 0.5
    seed: int = 1
    max_steps: int = 100_000
    max_halvings: int = 3
    #: Largest overlap (fraction of the diameter) a step may leave; a step leaving more (and more
    #: than before it) is retried with half the step. 0 = off (the default: docs/colony.md
    #: measures the cost, 4.5× the time of a 3D run).
    overlap_limit: float = 0.0

    def __post_init__(self) -> None:
        """Reject settings no run can use, naming the setting."""
        positive = ("cfl", "max_dt", "radius", "division_length", "growth_inertia", "tolerance")
        non_negative = ("margin", "position_correction", "rate", "rate_noise", "axis_noise", "damping", "sink_speed",
                        "overlap_limit")
        for name in positive + non_negative:
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and np.isfinite(value) and (value > 0 if name in positive else value >= 0)):
                raise InvalidArgumentError(f"{name}: must be finite and {'> 0' if name in positive else '>= 0'}, got {value!r}")
        for name in ("n_cells", "max_steps", "max_halvings"):
            value = getattr(self, name)
            if not (isinstance(value, int) and value >= (0 if name == "max_halvings" else 1)):
                raise InvalidArgumentError(f"{name}: must be an integer >= {0 if name == 'max_halvings' else 1}, got {value!r}")
        if self.dimensions not in (2, 3):
            raise InvalidArgumentError(f"dimensions: must be 2 or 3, got {self.dimensions!r}")
        if not self.position_correction <= 1:
            raise InvalidArgumentError(f"position_correction: must be in [0, 1], got {self.position_correction!r}")


@dataclass
class Run:
    """The outcome of :func:`run_colony`."""

    colony: Colony
    history: dict[str, list[float]]
    wall_seconds: float
    steps: int
    error: str = ""
    frames: list[tuple[float, Cells]] = field(default_factory=list)


def founder(settings: Settings) -> Colony:
    """One cell at the origin along x (on the substrate in 3D), half the division length long."""
    z = settings.radius if settings.dimensions == 3 else 0.0
    volume = capsule_volume(settings.division_length / 2, settings.radius)
    cell = Cells(centers=[[0.0, 0.0, z]], axes=[[1.0, 0.0, 0.0]], lengths=settings.division_length / 2,
                 radii=settings.radius, masses=volume, growth_inertia=settings.growth_inertia * volume)
    return Colony.founder(cell, settings.rate)


def grow_with_retries(colony: Colony, dt: float, settings: Settings, **grow_options: Any) -> tuple[Colony, Any, float, int]:
    """:func:`qpcontact.colony.grow` by ``dt``, rejected and retried with half the step (up to
    ``max_halvings`` times; the last attempt is kept) when

    - the contact solve turns some cell so fast that its tips would move more than ``cfl``
      diameters in the step (:func:`turning_reach`): the contact constraints hold to first
      order in the step, and a fast-turning short cell (a newborn squeezed between neighbours)
      is where the second-order error shows as overlap;
    - ``overlap_limit > 0`` and the new state's largest overlap exceeds both that limit and the
      largest overlap before the step (:func:`largest_overlap`).

    Returns ``(colony, step_result, dt_taken, rejected_attempts)``."""
    reach_limit = settings.cfl * 2.0 * float(np.median(colony.cells.radii))
    for attempt in range(settings.max_halvings + 1):
        grown, out = grow(colony, dt, **grow_options)
        accept = turning_reach(out.result.cells, dt) <= reach_limit
        if accept and settings.overlap_limit > 0:
            # out.max_overlap is the overlap of the state the step starts from.
            bound = max(settings.overlap_limit, out.max_overlap)
            accept = largest_overlap(grown.cells, grow_options.get("planes", ())) <= bound
        if attempt == settings.max_halvings or accept:
            return grown, out, dt, attempt
        dt /= 2.0
    raise AssertionError("unreachable")


def turning_reach(cells: Cells, dt: float) -> float:
    """Largest distance a cell tip moves by the cell's turning alone in ``dt``:
    ``max |ω| (l/2 + ρ) dt`` [length]."""
    speed = np.linalg.norm(cells.angular_velocities, axis=1) * (cells.lengths / 2 + cells.radii)
    return float(speed.max(initial=0.0)) * dt


def run_colony(settings: Settings, *, start: Colony | None = None, progress: bool = True,
               snapshot_dir: Path | None = None, snapshot_every: int = 0, frame_growth: float = 0.0) -> Run:
    """Grow a colony until it has ``settings.n_cells`` cells (or ``max_steps`` steps).

    Args:
        settings: the run's parameters.
        start: the colony to start from (default: :func:`founder`).
        progress: show a tqdm progress bar (cells reached out of the target).
        snapshot_dir: where to save snapshots (None: none saved).
        snapshot_every: save every this many steps (0: only the last state).
        frame_growth: keep a frame for an animation whenever the cell count has grown by this
            factor since the last frame (0: no frames).

    Returns:
        A :class:`Run`. A failed contact solve, or a step that cannot be taken (a cell
        compressed to a negative length), ends the run early with ``error`` set (that step is
        not applied).
    """
    from tqdm import tqdm  # the progress bar: only when a colony is run

    rng = np.random.default_rng(settings.seed)
    colony = founder(settings) if start is None else start
    planar = settings.dimensions == 2
    planes = [] if planar else [substrate(0.0)]
    options: dict[str, Any] = dict(
        solver=settings.solver, formulation=settings.formulation, form=settings.form, tolerance=settings.tolerance,
        margin=settings.margin, position_correction=settings.position_correction, planes=planes,
        planar=True if planar else None, dynamics=settings.dynamics)
    if settings.dynamics == "inertial":
        options["damping"] = settings.damping
    history: dict[str, list[float]] = {name: [] for name in HISTORY_FIELDS}
    frames = [(colony.time, colony.cells)] if frame_growth else []
    bar = tqdm(total=settings.n_cells, initial=colony.cells.n, unit="cell", disable=not progress, file=sys.stderr)
    error = ""
    t_start = time.perf_counter()
    step = 0
    while colony.cells.n < settings.n_cells and step < settings.max_steps:
        dt = expansion_time_step(colony, max_dt=settings.max_dt, cfl=settings.cfl, dimensions=settings.dimensions)
        drive = None
        if not planar and settings.sink_speed:
            drive = np.zeros((colony.cells.n, 7))
            drive[:, 2] = -settings.sink_speed * np.where(np.isfinite(colony.cells.masses), colony.cells.masses, 0.0)
        t0 = time.perf_counter()
        try:
            grown, out, dt, rejected = grow_with_retries(colony, dt, settings, drive=drive, **options)
        except SolverFailedError as exc:
            error = f"step {step} (t = {colony.time:.4g}, {colony.cells.n} cells): contact solve failed, not applied: {exc}"
            break
        except InvalidArgumentError as exc:  # e.g. contacts compressed a cell to a negative length
            error = f"step {step} (t = {colony.time:.4g}, {colony.cells.n} cells): step not applied: {exc}"
            break
        colony = grown
        colony = divide(colony, settings.division_length, rng, axis_noise=settings.axis_noise,
                        rate_noise=settings.rate_noise, base_rate=settings.rate, planar=planar)
        result = out.result
        row = dict(step=step, time=colony.time, dt=dt, cells=colony.cells.n, contacts=len(result.contacts),
                   max_overlap=out.max_overlap, mean_overlap=out.mean_overlap,
                   solve_seconds=result.times["setup"] + result.times["solve"], step_seconds=time.perf_counter() - t0,
                   penetration=result.errors.get("penetration", 0.0),
                   complementarity=result.errors.get("complementarity", np.nan), rejected=rejected)
        for name in HISTORY_FIELDS:
            history[name].append(row[name])
        step += 1
        bar.update(colony.cells.n - bar.n)
        bar.set_postfix(t=f"{colony.time:.2f}", overlap=f"{out.max_overlap:.3f}", refresh=False)
        if snapshot_dir is not None and snapshot_every and step % snapshot_every == 0:
            save_colony(snapshot_dir / f"step_{step:06d}.npz", colony, step)
        if frame_growth and colony.cells.n >= frame_growth * frames[-1][1].n:
            frames.append((colony.time, colony.cells))
    bar.close()
    wall = time.perf_counter() - t_start
    if snapshot_dir is not None:
        save_colony(snapshot_dir / f"step_{step:06d}.npz", colony, step)
    if frame_growth and frames[-1][1] is not colony.cells:
        frames.append((colony.time, colony.cells))
    return Run(colony, history, wall, step, error, frames)


def write_history(path: Path, history: dict[str, list[float]]) -> Path:
    """The per-step history as CSV (columns :data:`HISTORY_FIELDS`)."""
    with open(path, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(HISTORY_FIELDS)
        writer.writerows(zip(*(history[name] for name in HISTORY_FIELDS), strict=True))
    return path


def parse_args(argv: list[str]) -> argparse.Namespace:
    d = Settings()
    p = argparse.ArgumentParser(prog="qpcontact simulate", description=__doc__.split("\n\n")[0],
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("--cells", dest="n_cells", type=int, default=d.n_cells, help="grow until the colony has this many cells")
    p.add_argument("--dimensions", type=int, choices=(2, 3), default=d.dimensions,
                   help="2: monolayer in the xy-plane (planar unknowns only); 3: a biofilm on a substrate plane z = 0")
    p.add_argument("--solver", default=d.solver, help=f"an installed solver: {', '.join(available_solvers())}")
    p.add_argument("--formulation", default=d.formulation, choices=QP_FORMULATIONS,
                   help="QP formulation (a plain solver such as 'linear' solves the plain problem)")
    p.add_argument("--form", default=d.form, choices=("auto", *FORMS))
    p.add_argument("--tolerance", type=float, default=d.tolerance, help="solver tolerance (dimensionless)")
    p.add_argument("--position-correction", type=float, default=d.position_correction,
                   help="β: fraction of each overlap cleared per step (0 = off)")
    p.add_argument("--margin", type=float, default=d.margin, help="speculative contact margin [µm]")
    p.add_argument("--cfl", type=float, default=d.cfl, help="edge displacement per step [diameters]")
    p.add_argument("--max-dt", type=float, default=d.max_dt, help="largest time step [doubling times]")
    p.add_argument("--radius", type=float, default=d.radius, help="cell radius [µm]")
    p.add_argument("--division-length", type=float, default=d.division_length, help="cylinder length at division [µm]")
    p.add_argument("--rate", type=float, default=d.rate, help="mean growth rate [1/doubling time]")
    p.add_argument("--rate-noise", type=float, default=d.rate_noise, help="relative spread of newborn growth rates")
    p.add_argument("--axis-noise", type=float, default=d.axis_noise, help="daughter axis turn at division [rad]")
    p.add_argument("--growth-inertia", type=float, default=d.growth_inertia,
                   help="G/m: how hard contacts find it to compress growth")
    p.add_argument("--dynamics", choices=("overdamped", "inertial"), default=d.dynamics)
    p.add_argument("--damping", type=float, default=d.damping, help="inertial only: damping rate [1/time]")
    p.add_argument("--sink-speed", type=float, default=d.sink_speed,
                   help="3D only: every cell is driven towards the substrate at this speed [µm/time]")
    p.add_argument("--max-halvings", type=int, default=d.max_halvings,
                   help="a step that turns a cell's tips by more than --cfl diameters (or leaves more overlap than "
                        "--overlap-limit) is retried with half the step, at most this many times (0: never)")
    p.add_argument("--overlap-limit", type=float, default=d.overlap_limit,
                   help="retry a step that leaves a larger overlap than this [fraction of the diameter] and than "
                        "before the step (0: off)")
    p.add_argument("--seed", type=int, default=d.seed, help="random seed (division noise)")
    p.add_argument("--max-steps", type=int, default=d.max_steps)
    p.add_argument("--start", type=Path, help="start from this snapshot (.npz) instead of one cell")
    p.add_argument("--out", type=Path, default=Path("colony-run"), help="output folder")
    p.add_argument("--snapshot-every", type=int, default=0, help="save a snapshot every N steps (0: only the last)")
    p.add_argument("--gif", action="store_true", help="also write an animation colony.gif")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    return p.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(sys.argv[1:] if argv is None else argv)
    names = {f for f in Settings.__dataclass_fields__}
    from .plots import animate, plot_history, save_colony_picture  # matplotlib only when drawing

    try:
        settings = Settings(**{k: v for k, v in vars(args).items() if k in names})
        start = load_colony(args.start)[0] if args.start else None
        run = run_colony(settings, start=start, progress=not args.quiet, snapshot_dir=args.out / "snapshots",
                         snapshot_every=args.snapshot_every, frame_growth=1.08 if args.gif else 0.0)
    except QPContactError as exc:
        print(f"qpcontact simulate: {exc}", file=sys.stderr)
        return 2
    out = args.out
    write_history(out / "history.csv", run.history)
    label = f"{settings.dimensions}D, {settings.solver}/{settings.formulation}, tol {settings.tolerance:g}"
    save_colony_picture(out / "colony.png", run.colony.cells,
                        f"{run.colony.cells.n} cells at t = {run.colony.time:.2f} ({label})")
    if run.steps:
        plot_history(out / "history.png", run.history, label)
    if args.gif:
        animate(out / "colony.gif", run.frames)
    h = run.history
    print(f"{run.colony.cells.n} cells in {run.steps} steps, t = {run.colony.time:.3f}, wall {run.wall_seconds:.1f} s; "
          f"largest overlap {max(h['max_overlap'], default=0.0):.4f} of a diameter; "
          f"contact solve {np.sum(h['solve_seconds']):.1f} s in total; outputs in {out}/")
    if run.error:
        print(f"qpcontact simulate: {run.error}", file=sys.stderr)
        return 1
    return 0
