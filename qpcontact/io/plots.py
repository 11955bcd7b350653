"""Pictures of a colony run (matplotlib's object-oriented API: figures are drawn and saved
without pyplot, so importing this module leaves the process's matplotlib backend alone).

- :func:`draw_colony`: the cells seen from above (+z, the x–y plane) or from the side (−y, the
  x–z plane), each capsule outlined exactly and coloured by the orientation of its axis in the
  xy-plane (a cyclic colour map: a rod and its reverse have the same colour), or by a value per
  cell such as its pressure (``values``, with a colour bar in its units), or by a category such
  as its type (``discrete``: one colour per integer); static planes (walls, the substrate) seen
  edge-on in that view are drawn as thick grey lines. :func:`colony_colors` picks the values a
  run's ``--color`` names.
- :func:`save_colony_picture`: the top view, and with ``side_view`` (3D colonies) a side view
  under it.
- :func:`plot_pressure_profile`: the pressure of each cell of a 2D colony against its distance
  from the colony's centre, the mean in rings, and the parabola ``a (R² − r²)`` fitted to it.
- :func:`plot_history`: cell count, largest and mean overlap (fraction of the diameter),
  solver time per step, and the velocity step's solver residuals (scaled) or the position
  step's linearizations per step, against simulated time: each panel a different quantity in
  its own unit. Values that a log axis cannot show (zero: no overlap, no contact) are left out,
  not drawn at a floor.
- :func:`animate`: a GIF of saved snapshots (matplotlib's ``PillowWriter``).
- :func:`plot_ensemble`: a sweep's ``ensemble.png``, cell count and largest overlap against
  time, mean and range across the runs of each group of settings.

Lengths are labelled in µm and time in doubling times, the units of ``qpcontact simulate``
(``length_unit``/``time_unit`` change the labels).
"""

from __future__ import annotations

import textwrap
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import matplotlib
import numpy as np
from matplotlib.animation import FuncAnimation, PillowWriter
from matplotlib.axes import Axes
from matplotlib.collections import PolyCollection
from matplotlib.colors import Colormap, ListedColormap
from matplotlib.figure import Figure

from ..colony.growth import Colony
from ..errors import InvalidArgumentError
from ..geometry import Cells
from ..timestep.mechanics import CellMechanics, fit_parabola, radial_distances, radial_profile

#: Points per semicircular cap of a drawn capsule.
CAP_POINTS = 8
#: The coordinates each view shows (x, y indices) and the one it looks along.
VIEWS = {"top": (0, 1, 2), "side": (0, 2, 1)}
#: The force unit of ``qpcontact simulate`` (masses = volumes in µm³, overdamped: a force f moves a
#: free cell of volume V at f/V): what the pressure's units are made of.
FORCE_UNIT = "F: moves 1 µm³ of cell at 1 µm per doubling time"
ORIENTATION_LABEL = "axis orientation in the xy-plane [deg]"
#: What a colony picture can be coloured by besides a model's own per-cell arrays (``cell_data``):
#: :func:`colony_colors`.
COLORINGS = ("orientation", "pressure", "cell_type")


def colony_colors(color: str, colony: Colony, mechanics: CellMechanics | None, planar: bool) -> dict[str, Any]:
    """The colouring options of :func:`draw_colony` / :func:`save_colony_picture` that ``color``
    names: ``orientation`` (none: by axis angle), ``pressure`` (``mechanics.pressure``, zero
    without mechanics, with its units), ``cell_type`` (one colour per type), or the name of one
    of ``colony.cell_data``'s arrays with one number per cell.

    Raises:
        InvalidArgumentError: ``color`` names none of these, or an array with more than one
            number per cell.
    """
    if color == "orientation":
        return {}
    if color == "pressure":
        pressure = np.zeros(colony.cells.n) if mechanics is None else mechanics.pressure
        return dict(values=pressure, value_label=pressure_label(planar))
    if color == "cell_type":
        return dict(values=colony.cell_types, value_label="cell type", discrete=True)
    if color in colony.cell_data:
        values = colony.cell_data[color]
        if values.ndim != 1:
            raise InvalidArgumentError(f"color: cell_data {color!r} has {values.shape[1:]} numbers per cell; a colour "
                                       "needs one")
        return dict(values=values.astype(float), value_label=f"{color} (cell_data)")
    known = [*COLORINGS, *(name for name, v in colony.cell_data.items() if v.ndim == 1)]
    raise InvalidArgumentError(f"color: {color!r} is none of {', '.join(known)}")


def category_map(count: int) -> Colormap:
    """A colour map of ``count`` distinct colours for the integers 0..count-1 (matplotlib's
    ``tab10``, or ``tab20`` beyond ten; beyond twenty, colours repeat)."""
    base = matplotlib.colormaps["tab10" if count <= 10 else "tab20"]
    colors = [base(i % base.N) for i in range(max(count, 1))]
    return ListedColormap(colors)


def pressure_label(planar: bool, length_unit: str = "µm") -> str:
    """The axis or colour-bar label of a cell pressure (:mod:`qpcontact.timestep.mechanics`):
    2D [F/µm] or 3D [F/µm²], with what F is (:data:`FORCE_UNIT`)."""
    unit = f"F/{length_unit}" if planar else f"F/{length_unit}²"
    return f"{'2D ' if planar else ''}pressure [{unit}]\n({FORCE_UNIT})"


def capsule_outlines(cells: Cells, view: str = "top") -> np.ndarray:
    """(N, 2·CAP_POINTS, 2) the outline of each capsule projected on the view's plane (the
    x–y plane from the top, x–z from the side) [length]."""
    i, j, _ = VIEWS[view]
    axis = cells.axes[:, [i, j]]
    norm = np.linalg.norm(axis, axis=1, keepdims=True)
    axis = np.where(norm > 1e-12, axis / np.where(norm > 0, norm, 1.0), [1.0, 0.0])
    half = 0.5 * cells.lengths[:, None] * norm  # projected half length
    angle0 = np.arctan2(axis[:, 1], axis[:, 0])
    cap = np.linspace(-np.pi / 2, np.pi / 2, CAP_POINTS)
    # Cap at the + end sweeps −90°..90° around the axis direction, the − end 90°..270°.
    angles = np.concatenate([angle0[:, None] + cap, angle0[:, None] + np.pi + cap], axis=1)
    ends = np.concatenate([np.repeat(half, CAP_POINTS, axis=1), np.repeat(-half, CAP_POINTS, axis=1)], axis=1)
    centre = cells.centers[:, None][:, :, [i, j]] + ends[:, :, None] * axis[:, None, :]
    offset = cells.radii[:, None, None] * np.stack([np.cos(angles), np.sin(angles)], axis=2)
    return centre + offset


def draw_planes(ax: Axes, planes: Sequence[Any], view: str = "top") -> int:
    """Draw the static planes (:class:`qpcontact.Plane`) that the view sees edge-on (normal in
    the view's plane) as lines; returns how many were drawn."""
    i, j, k = VIEWS[view]
    drawn = 0
    for plane in planes:
        normal, point = np.asarray(plane.normal), np.asarray(plane.point)
        if abs(normal[k]) > 1e-9:
            continue  # seen face-on or at a slant: it fills the view, nothing to draw
        start = point[[i, j]]
        ax.axline(tuple(start), tuple(start + [-normal[j], normal[i]]), color="0.45", lw=3, zorder=0,
                  label="wall" if drawn == 0 else None)
        drawn += 1
    return drawn


def draw_colony(ax: Axes, cells: Cells, *, title: str | None = None, colorbar: bool = True, view: str = "top",
                planes: Sequence[Any] = (), length_unit: str = "µm", values: Any = None,
                value_label: str = "", discrete: bool = False) -> PolyCollection:
    """Draw the cells on ``ax`` from above (``view="top"``) or from the side (``"side"``),
    coloured by axis orientation in the xy-plane (0–180°), or by ``values`` (one number per
    cell, e.g. :func:`qpcontact.cell_pressure`; colour bar labelled ``value_label``, with its
    units: :func:`pressure_label`; with ``discrete``, integers >= 0 such as cell types, one
    colour each; an (N, 3) array: each cell's own RGB colour in [0, 1], as a CellModeller
    model's ``color``, no colour bar), with the planes seen edge-on."""
    i, j, k = VIEWS[view]
    # Cells farther from the viewer are drawn first: the top layer of a 3D biofilm from above,
    # the front row (small y) from the side.
    order = np.argsort(cells.centers[:, k] if view == "top" else -cells.centers[:, k], kind="stable")
    if values is not None and not discrete and np.shape(values) == (cells.n, 3):
        return _draw_rgb(ax, cells, np.asarray(values, dtype=float), order, view, planes, length_unit, title)
    edges = 0.2
    cmap: str | Colormap
    if values is not None and discrete:
        colour = np.asarray(values)
        if colour.shape != (cells.n,) or colour.dtype.kind not in "iu" or np.any(colour < 0):
            raise InvalidArgumentError(f"values: expected one integer >= 0 per cell ({cells.n}) to colour by category")
        count = int(colour.max(initial=0)) + 1
        cmap, limits, label = category_map(count), (-0.5, count - 0.5), value_label
        colour = colour.astype(float)
    elif values is None:
        colour, cmap, limits = np.degrees(np.arctan2(cells.axes[:, 1], cells.axes[:, 0])) % 180.0, "twilight", (0.0, 180.0)
        label = ORIENTATION_LABEL
    else:
        colour, cmap, label = np.asarray(values, dtype=float), "viridis", value_label
        if colour.shape != (cells.n,):
            raise InvalidArgumentError(f"values: expected one number per cell ({cells.n}), got shape {colour.shape}")
        finite = colour[np.isfinite(colour)]
        # The top of the scale at the 99th percentile of many cells: a few cells on a force chain
        # would otherwise leave the others in the dark end of the map (the colour bar says so).
        top = float(np.percentile(finite, 99)) if finite.size >= 100 else float(finite.max(initial=0.0))
        limits = (float(finite.min(initial=0.0)), top)
        limits = limits if limits[1] > limits[0] else (limits[0], limits[0] + 1.0)
        edges = 0.2 if cells.n <= 1000 else 0.0  # outlines of thousands of cells hide their colours
    polys = PolyCollection(list(capsule_outlines(cells, view)[order]), array=colour[order], cmap=cmap,
                           edgecolors="k", linewidths=edges)
    polys.set_clim(*limits)
    ax.add_collection(polys)
    ax.set_aspect("equal")
    ax.autoscale_view()
    draw_planes(ax, planes, view)
    names = "xyz"
    ax.set_xlabel(f"{names[i]} [{length_unit}]")
    ax.set_ylabel(f"{names[j]} [{length_unit}]")
    if title:
        ax.set_title(fit_title(title, 80))
    if colorbar and ax.figure is not None:
        ax.figure.colorbar(polys, ax=ax, label=label, shrink=0.8, extend=_beyond(polys), ticks=_ticks(polys, discrete))
    return polys


def _draw_rgb(ax: Axes, cells: Cells, rgb: np.ndarray, order: np.ndarray, view: str, planes: Sequence[Any],
              length_unit: str, title: str | None) -> PolyCollection:
    """:func:`draw_colony` with each cell in its own RGB colour (clipped to [0, 1])."""
    i, j, _ = VIEWS[view]
    rgb = np.clip(np.nan_to_num(rgb), 0.0, 1.0)
    polys = PolyCollection(list(capsule_outlines(cells, view)[order]), facecolors=rgb[order], edgecolors="k",
                           linewidths=0.2 if cells.n <= 1000 else 0.0)
    ax.add_collection(polys)
    ax.set_aspect("equal")
    ax.autoscale_view()
    draw_planes(ax, planes, view)
    ax.set_xlabel(f"{'xyz'[i]} [{length_unit}]")
    ax.set_ylabel(f"{'xyz'[j]} [{length_unit}]")
    if title:
        ax.set_title(fit_title(title, 80))
    return polys


def _ticks(polys: PolyCollection, discrete: bool) -> Any:
    """The colour bar's ticks: each integer of a discrete colouring (at most 20 shown), else
    matplotlib's choice."""
    if not discrete:
        return None
    top = int(round(polys.get_clim()[1] + 0.5))
    return np.arange(0, top, max(1, -(-top // 20)))


def _beyond(polys: PolyCollection) -> str:
    """The colour bar's ``extend``: "max" when some cells lie above the top of the scale."""
    values = np.asarray(polys.get_array(), dtype=float)
    return "max" if values.size and np.nanmax(values) > polys.get_clim()[1] else "neither"


def save_colony_picture(path: str | Path, cells: Cells, title: str | None = None, *, side_view: bool = False,
                        planes: Sequence[Any] = (), values: Any = None, value_label: str = "",
                        discrete: bool = False) -> Path:
    """Draw the colony from above (and, with ``side_view``, from the side under it) and save it
    as an image (PNG, SVG, ... by the file suffix), coloured by orientation or by ``values``
    (:func:`draw_colony`; :func:`colony_colors` gives the values a run's ``--color`` names). The
    figure's height follows the colony's shape (a colony in a channel is a strip)."""
    fig = Figure(figsize=(7, 6), dpi=120, layout="constrained")
    colours = dict(values=values, value_label=value_label, discrete=discrete)
    if not side_view:
        top = fig.subplots()
        draw_colony(top, cells, planes=planes, **colours)
        height = 0.0
    else:
        top, side = fig.subplots(2, 1)
        polys = draw_colony(top, cells, planes=planes, colorbar=False, **colours)
        draw_colony(side, cells, title="side view (from −y)", planes=planes, view="side", colorbar=False, **colours)
        # The same x range as the top view, and at least a quarter of it in height (a flat
        # biofilm is a thin strip otherwise), from just below the lowest cell or plane.
        x_range = top.get_xlim()
        z = capsule_outlines(cells, "side")[..., 1]
        bottom = min([float(z.min())] + [p.point[2] for p in planes if abs(p.normal[1]) < 1e-9]) - 0.3
        height = max(float(z.max()) + 0.3 - bottom, 0.25 * (x_range[1] - x_range[0]))
        side.set_xlim(*x_range)
        side.set_ylim(bottom, bottom + height)
        top.get_gridspec().set_height_ratios([top.get_ylim()[1] - top.get_ylim()[0], height])
        if polys.get_array() is not None:  # (cells in their own RGB colours have no scale)
            fig.colorbar(polys, ax=[top, side], label=ORIENTATION_LABEL if values is None else value_label,
                         shrink=0.8, extend=_beyond(polys), ticks=_ticks(polys, discrete))
    x_range, y_range = top.get_xlim(), top.get_ylim()
    ratio = (y_range[1] - y_range[0] + height) / (x_range[1] - x_range[0])  # of the panels together
    fig.set_size_inches(7, float(np.clip(5.2 * ratio + 1.6, 3, 12)))
    if title:
        fig.suptitle(fit_title(title, 95), fontsize=10)
    fig.savefig(path)
    return Path(path)


def pressure_profile_figure(cells: Cells, pressure: Any, *, title: str | None = None, bins: int = 20,
                            label: str | None = None, length_unit: str = "µm") -> Figure:
    """The figure of :func:`plot_pressure_profile`."""
    pressure = np.asarray(pressure, dtype=float)
    r, _ = radial_distances(cells)
    profile = radial_profile(cells, pressure, bins=bins)
    fig = Figure(figsize=(7, 4.8), dpi=120, layout="constrained")
    ax = fig.subplots()
    ax.plot(r, pressure, ".", ms=1.5, color="0.65", alpha=0.6, label="cells")
    kept = profile.counts > 0
    ax.errorbar(profile.radius[kept], profile.mean[kept], yerr=profile.std[kept], fmt="o-", ms=4, lw=1, capsize=2,
                color="C0", label="mean in rings (± std)")
    if cells.n >= 2:
        fit = fit_parabola(r, pressure)
        grid = np.linspace(0.0, float(r.max(initial=0.0)), 200)
        ax.plot(grid, fit.amplitude * (np.nan_to_num(fit.radius) ** 2 - grid**2), "--", color="C3",
                label=f"fit a(R² − r²): a = {fit.amplitude:.3g}, R = {fit.radius:.3g} {length_unit}")
    ax.set_xlabel(f"distance from the colony's centre r [{length_unit}]")
    ax.set_ylabel(label or pressure_label(True, length_unit))
    ax.axhline(0.0, color="0.3", lw=0.5)
    ax.legend(fontsize=8)
    if title:
        ax.set_title(fit_title(title, 80), fontsize=10)
    return fig


def plot_pressure_profile(path: str | Path, cells: Cells, pressure: Any, title: str | None = None, *, bins: int = 20,
                          label: str | None = None) -> Path:
    """The radial pressure profile of a 2D colony: each cell's pressure (:func:`qpcontact.cell_pressure`)
    against the distance of its centre from the colony's centre (the mean of the centres), the mean
    and standard deviation in ``bins`` rings, and the least-squares parabola ``a (R² − r²)``
    (:func:`~qpcontact.timestep.mechanics.fit_parabola`; what a continuum model of a growing colony
    with friction predicts, docs/mechanics.md). ``label``: the pressure axis (default: the 2D
    pressure of ``qpcontact simulate``, :func:`pressure_label`)."""
    pressure_profile_figure(cells, pressure, title=title, bins=bins, label=label).savefig(path)
    return Path(path)


def fit_title(title: str, width: int) -> str:
    """``title`` with each of its lines wrapped at ``width`` characters (about the figure's
    width at the title's font size), so that no title is clipped at the figure's edges."""
    return "\n".join(textwrap.fill(line, width, break_on_hyphens=False) or line for line in title.splitlines())


def positive(values: Sequence[float]) -> np.ndarray:
    """The values as floats, with those a log axis cannot show (≤ 0, NaN) as NaN: not drawn."""
    array = np.asarray(values, dtype=float)
    return np.where(array > 0, array, np.nan)


def history_figure(history: Mapping[str, Sequence[float]], title: str | None = None, time_unit: str = "doubling times") -> Figure:
    """The four panels of :func:`plot_history` as a figure."""
    t = np.asarray(history["time"])
    fig = Figure(figsize=(10, 7), dpi=110, layout="constrained")
    axes = fig.subplots(2, 2, sharex=True)
    axes[0, 0].semilogy(t, positive(history["cells"]))
    axes[0, 0].set_ylabel("cells")
    axes[0, 1].semilogy(t, positive(history["max_overlap"]), label="largest", lw=0.8)
    axes[0, 1].semilogy(t, positive(history["mean_overlap"]), label="mean (overlapping contacts)", lw=0.8)
    axes[0, 1].set_ylabel("overlap [fraction of the diameter]")
    axes[0, 1].legend()
    axes[1, 0].semilogy(t, positive(history["solve_seconds"]))
    axes[1, 0].set_ylabel("contact solve per step [s]")
    residuals = [key for key in ("penetration", "complementarity")
                 if key in history and np.any(np.isfinite(np.asarray(history[key], dtype=float)))]
    if residuals:  # the velocity step: what its contact solve left, in the solver's scaled units
        for key in residuals:
            axes[1, 1].semilogy(t, positive(history[key]), label=f"{key} residual", lw=0.8)
        axes[1, 1].set_ylabel("contact solve residual [dimensionless, scaled]")
        axes[1, 1].legend()
    elif "linearizations" in history:  # the position step: its overlap is measured above; its work here
        axes[1, 1].plot(t, np.asarray(history["linearizations"], dtype=float), lw=0.8, label="linearizations")
        if "rejected" in history:
            axes[1, 1].plot(t, np.asarray(history["rejected"], dtype=float), lw=0.8, label="halved attempts")
        axes[1, 1].set_ylabel("per step [count]")
        axes[1, 1].legend()
    for ax in axes[1]:
        ax.set_xlabel(f"time [{time_unit}]")
    fig.supxlabel("steps without overlap, contacts or residual have no point on the log axes", fontsize=7, color="0.4")
    if title:
        fig.suptitle(fit_title(title, 110))
    return fig


def plot_history(path: str | Path, history: Mapping[str, Sequence[float]], title: str | None = None,
                 time_unit: str = "doubling times") -> Path:
    """Four panels against simulated time: cell count; largest and mean overlap as a fraction
    of the diameter; solver time per step [s]; the velocity step's penetration and
    complementarity residuals (scaled), or, where the history has none (the position step, which
    measures the true overlap instead), its linearizations and halved attempts per step.
    ``history`` holds equal-length sequences ``time``, ``cells``, ``max_overlap``,
    ``mean_overlap``, ``solve_seconds`` and, optionally, ``penetration``, ``complementarity``,
    ``linearizations``, ``rejected``. Zeros (no overlap, no contact) are not drawn
    (:func:`positive`)."""
    history_figure(history, title, time_unit).savefig(path)
    return Path(path)


def animate(path: str | Path, frames: Sequence[tuple[float, Cells]], fps: int = 10) -> Path:
    """A GIF of ``(time, cells)`` frames, all drawn with the limits of the last (largest) one."""
    fig = Figure(figsize=(6, 6), dpi=90)
    ax = fig.subplots()
    last = capsule_outlines(frames[-1][1]).reshape(-1, 2)
    lo, hi = last.min(axis=0), last.max(axis=0)
    pad = 0.05 * float((hi - lo).max())

    def draw(i: int) -> None:
        ax.clear()
        time, cells = frames[i]
        draw_colony(ax, cells, title=f"t = {time:.2f} doubling times, {cells.n} cells", colorbar=False)
        ax.set_xlim(lo[0] - pad, hi[0] + pad)
        ax.set_ylim(lo[1] - pad, hi[1] + pad)

    animation = FuncAnimation(fig, draw, frames=len(frames))
    animation.save(str(path), writer=PillowWriter(fps=fps))
    return Path(path)


def plot_ensemble(path: Path, groups: Mapping[str, Sequence[Mapping[str, Sequence[float]]]]) -> Path:
    """Cell count and largest overlap against time: for each group of runs (the same settings,
    different seeds) the mean across the runs (a line) and their range (a band), each run's
    history taken at common times up to its own end."""
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, 4.5), dpi=110, layout="constrained")
    ax_cells, ax_overlap = fig.subplots(1, 2)
    for index, (name, histories) in enumerate(groups.items()):
        color = f"C{index % 10}"
        end = max(h["time"][-1] for h in histories)
        times = np.linspace(0.0, end, 300)
        for ax, column in ((ax_cells, "cells"), (ax_overlap, "max_overlap")):
            values = np.full((len(histories), len(times)), np.nan)
            for row, history in enumerate(histories):
                t = np.asarray(history["time"])
                inside = times <= t[-1]
                values[row, inside] = np.interp(times[inside], t, np.asarray(history[column]))
            counted = np.sum(np.isfinite(values), axis=0) > 0
            with np.errstate(all="ignore"):
                mean = np.nanmean(values[:, counted], axis=0)
                low, high = np.nanmin(values[:, counted], axis=0), np.nanmax(values[:, counted], axis=0)
            ax.plot(times[counted], mean, color=color, lw=1.5,
                    label=f"{name} ({len(histories)} run{'s' if len(histories) > 1 else ''})")
            ax.fill_between(times[counted], low, high, color=color, alpha=0.2, lw=0)
    ax_cells.set(xlabel="time [doubling times]", ylabel="cells", yscale="log", title="cell count: mean and range")
    ax_overlap.set(xlabel="time [doubling times]", ylabel="largest overlap [fraction of the diameter]",
                   title="largest overlap per step: mean and range")
    ax_cells.legend(fontsize="small")
    for ax in (ax_cells, ax_overlap):
        ax.grid(alpha=0.3)
    fig.savefig(path)
    return path
