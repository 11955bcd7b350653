"""The pressure-profile study (qpcontact.studies.pressure_profile) on a small grown colony: its
pictures and numbers are written, and the continuum model it compares with holds roughly."""

from __future__ import annotations

import re

import pytest

from qpcontact.errors import InvalidArgumentError
from qpcontact.io import RunFolder
from qpcontact.simulation import Settings, run_colony
from qpcontact.studies import pressure_profile


@pytest.fixture(scope="module")
def snapshot(tmp_path_factory):
    folder = RunFolder.create(tmp_path_factory.mktemp("colony"))
    run_colony(Settings().updated({"cells": 200}), progress=False, folder=folder)
    return sorted((folder.path / "snapshots").glob("*.npz"))[-1]


def test_the_study_writes_its_pictures_and_numbers(snapshot, tmp_path, capsys):
    out = tmp_path / "out"
    assert pressure_profile.main([str(snapshot), "--out", str(out), "--bins", "8"]) == 0
    for name in pressure_profile.OUTPUTS:
        assert (out / name).stat().st_size > 1000, name
    report = (out / "pressure_profile.md").read_text()
    ratio = float(re.search(r"continuum a from s \(measured velocity\); fitted/predicted \| [\d.]+; ([\d.]+)", report)[1])
    assert 0.6 < ratio < 1.4  # Darcy friction and the cells' virial pressure agree roughly even at 200 cells
    assert "| cells with negative pressure | 0 |" in report
    assert pressure_profile.main([str(snapshot), "--out", str(out)]) == 2  # refuses to replace its outputs
    assert "--overwrite" in capsys.readouterr().err


def test_a_3d_colony_is_refused(snapshot):
    from qpcontact.io import load_colony

    colony, _ = load_colony(snapshot)
    with pytest.raises(InvalidArgumentError, match="2D monolayer"):
        pressure_profile.measure(colony, Settings().updated({"dimensions": 3}))
