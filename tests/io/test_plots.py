"""Pictures of a colony: drawn without pyplot, so importing them leaves matplotlib alone."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

import qpcontact as q


def test_importing_plots_neither_sets_the_backend_nor_loads_pyplot():
    code = ("import sys, matplotlib; from qpcontact.io import plots; "
            "print('matplotlib.pyplot' in sys.modules, matplotlib.rcParams._get_backend_or_none())")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "None"]


def test_pictures_are_written(tmp_path):
    from qpcontact.io import plots

    cells = q.Cells(centers=[[0, 0, 0], [3, 0, 0], [0, 3, 0.5]], axes=[[1, 0, 0], [0, 1, 0], [0.6, 0.8, 0]],
                    lengths=[2.0, 1.0, 0.0], radii=0.5)
    assert plots.save_colony_picture(tmp_path / "colony.png", cells, "three cells").stat().st_size > 1000
    history = {"time": [0.0, 1.0], "cells": [1, 2], "max_overlap": [0.0, 0.01], "mean_overlap": [0.0, 0.005],
               "solve_seconds": [0.01, 0.02], "penetration": [0.0, 1e-9], "complementarity": [np.nan, 1e-8]}
    assert plots.plot_history(tmp_path / "history.png", history, "a run").stat().st_size > 1000
    assert plots.animate(tmp_path / "colony.gif", [(0.0, cells.subset([0])), (1.0, cells)]).stat().st_size > 100
    outline = plots.capsule_outlines(cells.subset([0]))[0]
    assert np.allclose(outline.min(axis=0), [-1.5, -0.5], atol=0.05) and np.allclose(outline.max(axis=0), [1.5, 0.5], atol=0.05)


def test_history_panels_do_not_plot_clipped_floors_as_data():
    """Zeros (no overlap, no contact) were drawn at 1e-6 and 1e-16 as if measured."""
    from qpcontact.io import plots

    history = {"time": [0.0, 1.0, 2.0], "cells": [1, 2, 2], "max_overlap": [0.0, 0.01, 0.0],
               "mean_overlap": [0.0, 0.005, 0.0], "solve_seconds": [0.0, 0.02, 0.01],
               "penetration": [0.0, 1e-9, 0.0], "complementarity": [np.nan, 1e-8, 0.0]}
    figure = plots.history_figure(history)
    lines = [line for ax in figure.axes for line in ax.get_lines()]
    assert len(lines) == 6
    for line in lines:
        y = np.asarray(line.get_ydata(), dtype=float)
        assert not np.any(np.isin(y, [1e-6, 1e-16])), line.get_label()
        assert np.all(np.isnan(y) | (y > 0))
    assert np.isnan(lines[1].get_ydata()[0]) and lines[1].get_ydata()[1] == 0.01
    labels = [ax.get_xlabel() for ax in figure.axes[2:]] + [figure.axes[1].get_ylabel(), figure.axes[2].get_ylabel()]
    assert labels == ["time [doubling times]"] * 2 + ["overlap [fraction of the diameter]", "contact solve per step [s]"]
    assert figure.axes[3].get_ylabel() == "contact solve residual [dimensionless, scaled]"


def test_each_history_panel_of_a_position_run_shows_its_own_quantity():
    """history.png plotted the position step's overlap twice: as "largest overlap" and as a
    solver "penetration" labelled dimensionless and scaled."""
    from qpcontact.io import plots

    history = {"time": [0.0, 1.0, 2.0], "cells": [1, 2, 3], "max_overlap": [0.004, 0.009, 0.008],
               "mean_overlap": [0.001, 0.002, 0.002], "solve_seconds": [0.01, 0.02, 0.03],
               "penetration": [np.nan] * 3, "complementarity": [np.nan] * 3, "linearizations": [1, 2, 1],
               "rejected": [0, 1, 0]}
    figure = plots.history_figure(history)
    panels = [[tuple(np.asarray(line.get_ydata(), dtype=float)) for line in ax.get_lines()] for ax in figure.axes]
    series = [s for panel in panels for s in panel]
    assert len(series) == len(set(series)) == 6  # no quantity drawn twice
    assert figure.axes[3].get_ylabel() == "per step [count]" and panels[3][0] == (1.0, 2.0, 1.0)
    assert len({ax.get_ylabel() for ax in figure.axes}) == 4


def test_a_3d_colony_is_drawn_from_above_and_from_the_side_with_walls_and_units(tmp_path, monkeypatch):
    """3D colonies were seen from above only, walls were not drawn, axes had no units."""
    from matplotlib.figure import Figure

    from qpcontact.io import plots

    saved = []
    monkeypatch.setattr(Figure, "savefig", lambda self, path, **kw: saved.append(self))
    cells = q.Cells(centers=[[0, 0, 0.5], [3, 0, 0.5], [1.5, 0, 1.5]], axes=[[1, 0, 0], [1, 0, 0], [0.8, 0, 0.6]],
                    lengths=2.0, radii=0.5)
    plots.save_colony_picture(tmp_path / "c.png", cells, "biofilm", side_view=True,
                              planes=[q.substrate(), *q.channel(4.0)])
    top, side = saved[0].axes[:2]
    assert (top.get_xlabel(), top.get_ylabel(), side.get_xlabel(), side.get_ylabel()) == (
        "x [µm]", "y [µm]", "x [µm]", "z [µm]")
    # From above: the two channel walls (the substrate is seen face-on); from the side: the substrate.
    assert len(top.get_lines()) == 2 and len(side.get_lines()) == 1
    z_outline = plots.capsule_outlines(cells, "side")[2][:, 1]
    assert z_outline.max() == pytest.approx(1.5 + 0.6 + 0.5, abs=0.02)  # the tilted cell rises in the side view
    assert side.get_ylim()[0] <= 0.0 <= side.get_ylim()[1]


def test_cells_coloured_by_pressure_have_a_colour_bar_with_units_and_the_profile_a_fit(tmp_path, monkeypatch):
    from matplotlib.figure import Figure

    from qpcontact.errors import InvalidArgumentError
    from qpcontact.io import plots

    saved = []
    monkeypatch.setattr(Figure, "savefig", lambda self, path, **kw: saved.append(self))
    rng = np.random.default_rng(1)
    xy = rng.uniform(-8, 8, (300, 2))
    cells = q.Cells(centers=np.c_[xy, np.zeros(300)], axes=[[1, 0, 0]] * 300, lengths=1.0, radii=0.5)
    r = np.linalg.norm(xy - xy.mean(axis=0), axis=1)
    pressure = 2.0 * (11.0**2 - r**2)
    plots.save_colony_picture(tmp_path / "c.png", cells, values=pressure, value_label=plots.pressure_label(True))
    top, colorbar = saved[0].axes
    assert colorbar.get_ylabel().startswith("2D pressure [F/µm]") and "1 µm³" in colorbar.get_ylabel()
    # The scale tops out at the 99th percentile (a force chain would leave the rest dark), and says so.
    assert top.collections[0].get_clim() == (pytest.approx(pressure.min()), pytest.approx(np.percentile(pressure, 99)))
    assert plots._beyond(top.collections[0]) == "max"
    assert plots.pressure_label(False).startswith("pressure [F/µm²]")
    plots.plot_pressure_profile(tmp_path / "p.png", cells, pressure)
    legend = [text.get_text() for text in saved[1].axes[0].get_legend().get_texts()]
    assert any("a = 2, R = 11 µm" in text for text in legend), legend
    with pytest.raises(InvalidArgumentError, match="values: expected one number per cell"):
        plots.save_colony_picture(tmp_path / "c.png", cells, values=pressure[:3])
