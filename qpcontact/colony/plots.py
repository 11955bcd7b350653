"""Pictures of a colony run (matplotlib's object-oriented API: figures are drawn and saved
without pyplot, so importing this module leaves the process's matplotlib backend alone).

- :func:`draw_colony`: the cells seen from above (+z), each capsule outlined exactly and
  coloured by the orientation of its axis in the xy-plane (a cyclic colour map: a rod and its
  reverse have the same colour).
- :func:`plot_history`: cell count, largest and mean overlap (fraction of the diameter),
  solver time per step and the solver's residuals against simulated time.
- :func:`animate`: a GIF of saved snapshots (matplotlib's ``PillowWriter``).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from matplotlib.animation import FuncAnimation, PillowWriter
from matplotlib.axes import Axes
from matplotlib.collections import PolyCollection
from matplotlib.figure import Figure

from ..geometry import Cells

#: Points per semicircular cap of a drawn capsule.
CAP_POINTS = 8


def capsule_outlines(cells: Cells) -> np.ndarray:
    """(N, 2·CAP_POINTS, 2) the outline of each capsule projected on the xy-plane [length]."""
    axis = cells.axes[:, :2]
    norm = np.linalg.norm(axis, axis=1, keepdims=True)
    axis = np.where(norm > 1e-12, axis / np.where(norm > 0, norm, 1.0), [1.0, 0.0])
    half = 0.5 * cells.lengths[:, None] * norm  # projected half length
    angle0 = np.arctan2(axis[:, 1], axis[:, 0])
    cap = np.linspace(-np.pi / 2, np.pi / 2, CAP_POINTS)
    # Cap at the + end sweeps −90°..90° around the axis direction, the − end 90°..270°.
    angles = np.concatenate([angle0[:, None] + cap, angle0[:, None] + np.pi + cap], axis=1)
    ends = np.concatenate([np.repeat(half, CAP_POINTS, axis=1), np.repeat(-half, CAP_POINTS, axis=1)], axis=1)
    centre = cells.centers[:, None, :2] + ends[:, :, None] * axis[:, None, :]
    offset = cells.radii[:, None, None] * np.stack([np.cos(angles), np.sin(angles)], axis=2)
    return centre + offset


def draw_colony(ax: Axes, cells: Cells, *, title: str | None = None, colorbar: bool = True) -> PolyCollection:
    """Draw the cells on ``ax`` from above, coloured by axis orientation (0–180°)."""
    orientation = np.degrees(np.arctan2(cells.axes[:, 1], cells.axes[:, 0])) % 180.0
    # Cells lower down are drawn first, so the top layer of a 3D biofilm is what one sees.
    order = np.argsort(cells.centers[:, 2], kind="stable")
    polys = PolyCollection(list(capsule_outlines(cells)[order]), array=orientation[order], cmap="twilight",
                           edgecolors="k", linewidths=0.2)
    polys.set_clim(0.0, 180.0)
    ax.add_collection(polys)
    ax.set_aspect("equal")
    ax.autoscale_view()
    ax.set_xlabel("x")
    ax.set_ylabel("y")
    if title:
        ax.set_title(title)
    if colorbar and ax.figure is not None:
        ax.figure.colorbar(polys, ax=ax, label="axis orientation in the xy-plane [deg]", shrink=0.8)
    return polys


def save_colony_picture(path: str | Path, cells: Cells, title: str | None = None) -> Path:
    """Draw the colony and save it as an image (PNG, SVG, ... by the file suffix)."""
    fig = Figure(figsize=(7, 6), dpi=120)
    draw_colony(fig.subplots(), cells, title=title)
    fig.tight_layout()
    fig.savefig(path)
    return Path(path)


def plot_history(path: str | Path, history: Mapping[str, Sequence[float]], title: str | None = None) -> Path:
    """Four panels against simulated time: cell count; largest and mean overlap as a fraction
    of the diameter; solver time per step [s]; the solver's penetration and complementarity
    residuals. ``history`` holds equal-length sequences ``time``, ``cells``, ``max_overlap``,
    ``mean_overlap``, ``solve_seconds``, ``penetration`` and (optionally) ``complementarity``."""
    t = np.asarray(history["time"])
    fig = Figure(figsize=(10, 7), dpi=110)
    axes = fig.subplots(2, 2, sharex=True)
    axes[0, 0].semilogy(t, history["cells"])
    axes[0, 0].set_ylabel("cells")
    axes[0, 1].semilogy(t, np.maximum(history["max_overlap"], 1e-6), label="largest", lw=0.8)
    axes[0, 1].semilogy(t, np.maximum(history["mean_overlap"], 1e-6), label="mean (overlapping contacts)", lw=0.8)
    axes[0, 1].set_ylabel("overlap / diameter")
    axes[0, 1].legend()
    axes[1, 0].semilogy(t, np.maximum(history["solve_seconds"], 1e-6))
    axes[1, 0].set_ylabel("contact solve per step [s]")
    for key in ("penetration", "complementarity"):
        if key in history and len(history[key]):
            values = np.asarray(history[key], dtype=float)
            axes[1, 1].semilogy(t, np.maximum(values, 1e-16), label=key, lw=0.8)
    axes[1, 1].set_ylabel("residual (scaled)")
    axes[1, 1].legend()
    for ax in axes[1]:
        ax.set_xlabel("time")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path)
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
        draw_colony(ax, cells, title=f"t = {time:.2f}, {cells.n} cells", colorbar=False)
        ax.set_xlim(lo[0] - pad, hi[0] + pad)
        ax.set_ylim(lo[1] - pad, hi[1] + pad)

    animation = FuncAnimation(fig, draw, frames=len(frames))
    animation.save(str(path), writer=PillowWriter(fps=fps))
    return Path(path)
