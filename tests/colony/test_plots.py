"""Pictures of a colony: drawn without pyplot, so importing them leaves matplotlib alone."""

from __future__ import annotations

import subprocess
import sys

import numpy as np

import qpcontact as q


def test_importing_plots_neither_sets_the_backend_nor_loads_pyplot():
    code = ("import sys, matplotlib; from qpcontact.colony import plots; "
            "print('matplotlib.pyplot' in sys.modules, matplotlib.rcParams._get_backend_or_none())")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "None"]


def test_pictures_are_written(tmp_path):
    from qpcontact.colony import plots

    cells = q.Cells(centers=[[0, 0, 0], [3, 0, 0], [0, 3, 0.5]], axes=[[1, 0, 0], [0, 1, 0], [0.6, 0.8, 0]],
                    lengths=[2.0, 1.0, 0.0], radii=0.5)
    assert plots.save_colony_picture(tmp_path / "colony.png", cells, "three cells").stat().st_size > 1000
    history = {"time": [0.0, 1.0], "cells": [1, 2], "max_overlap": [0.0, 0.01], "mean_overlap": [0.0, 0.005],
               "solve_seconds": [0.01, 0.02], "penetration": [0.0, 1e-9], "complementarity": [np.nan, 1e-8]}
    assert plots.plot_history(tmp_path / "history.png", history, "a run").stat().st_size > 1000
    assert plots.animate(tmp_path / "colony.gif", [(0.0, cells.subset([0])), (1.0, cells)]).stat().st_size > 100
    outline = plots.capsule_outlines(cells.subset([0]))[0]
    assert np.allclose(outline.min(axis=0), [-1.5, -0.5], atol=0.05) and np.allclose(outline.max(axis=0), [1.5, 0.5], atol=0.05)
