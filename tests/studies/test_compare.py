"""The comparison command (qpcontact compare): every run a row, failures included."""

import csv

import numpy as np
import pytest

from qpcontact.studies import compare
from tests.helpers import interrupt_on_call


def read(path):
    with open(path, newline="") as fh:
        return list(csv.DictReader(fh))


def test_quick_run_writes_csv_png_and_table(tmp_path):
    out = tmp_path / "cmp"
    code = compare.main(["--quick", "--scenes", "two_rods,colony_3d_100", "--solvers", "linear,cg,bbpgd,osqp",
                         "--tolerances", "1e-3,1e-6", "--out", str(out)])
    assert code == 0
    rows = read(out / "solvers.csv")
    assert tuple(rows[0].keys()) == compare.COLUMNS
    methods = {r["method"] for r in rows}
    assert methods == {"linear/linear/contact", "cg/linear/normal_equations", "bbpgd/complementarity/contact",
                       *(f"osqp/{f}/{form}" for f in ("complementarity", "least_squares") for form in ("primal", "contact"))}
    assert len(rows) == 2 * 7 * 2  # scenes × methods × tolerances: every run is a row
    assert {r["scene"] for r in rows} == {"two_rods", "colony_3d_100"}
    for r in rows:
        assert r["outcome"] in ("success", "converged_inaccurate", "not_converged", "time_limit", "timeout", "error", "crashed")
        assert float(r["tolerance"]) in (1e-3, 1e-6)
    # The plain solve is its own reference; OSQP at 1e-6 on complementarity is accurate.
    assert all(float(r["distance"]) < 1e-10 for r in rows if r["solver"] == "linear")
    assert all(r["success"] == "True" for r in rows if r["method"] == "osqp/complementarity/primal")
    assert (out / "solvers_scenes.png").stat().st_size > 1000
    png = (out / "solvers.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000
    text = (out / "solvers.md").read_text()
    assert "| method (solver/formulation/form) |" in text and "SGM" in text
    for m in methods:
        assert f"| {m} |" in text


def test_failures_and_time_outs_are_rows(tmp_path):
    out = tmp_path / "cmp"
    compare.main(["--scenes", "colony_2d_100", "--solvers", "cg,bbpgd", "--tolerances", "1e-9", "--repeats", "1",
                  "--time-limit", "1e-9", "--out", str(out)])
    rows = read(out / "solvers.csv")
    assert len(rows) == 2
    for r in rows:
        assert r["outcome"] == "time_limit" and r["success"] == "False" and r["converged"] == "False"
        assert "time_limit" in r["message"]
    text = (out / "solvers.md").read_text()
    assert "| cg/linear/normal_equations | 1 | 0 % | 0 | 1 |" in text


def test_shifted_geometric_mean():
    assert compare.shifted_geometric_mean(np.array([0.01, 0.01])) == pytest.approx(0.01)
    # exp(mean(log 0.01, log 0.04)) − 0.01 = 0.02 − 0.01
    assert compare.shifted_geometric_mean(np.array([0.0, 0.03])) == pytest.approx(0.01)


def test_ctrl_c_writes_the_runs_that_were_done_and_earlier_results_are_kept(tmp_path, monkeypatch, capsys):
    out = tmp_path / "cmp"
    args = ["--scenes", "two_rods", "--solvers", "linear,osqp", "--tolerances", "1e-3", "--repeats", "1", "--out", str(out)]
    interrupt_on_call(monkeypatch, compare, "run_one", 3)
    assert compare.main(args) == 130
    assert len(read(out / "solvers.csv")) == 2
    assert "Interrupted (Ctrl-C) after 2 runs" in (out / "solvers.md").read_text()
    capsys.readouterr()
    assert compare.main(args) == 2  # the earlier results are not overwritten by accident
    assert "pass --overwrite" in capsys.readouterr().err and len(read(out / "solvers.csv")) == 2
