"""The benchmark command. No timing is asserted here: speed is measured by ``qpcontact bench``
(docs/performance.md)."""

from __future__ import annotations

import json

import pytest

from qpcontact.studies import bench


def test_quick_bench_writes_the_table_plot_and_data(tmp_path):
    out = tmp_path / "docs"
    (out).mkdir()
    (out / "performance.md").write_text("# Performance\n\nanalysis kept\n\n<!-- bench:start -->\nold\n<!-- bench:end -->\ntail kept\n")
    args = ["--quick", "--out", str(out), "--cache-dir", "none", "--repeats", "1",
            "--solvers", "linear,linear/primal,cg@1e-9,mprgp@1e-7,osqp/contact"]
    # An existing performance.md is updated only when asked: the docs are not rewritten by accident.
    assert bench.main(args) == 2
    assert "\nold\n" in (out / "performance.md").read_text()
    code = bench.main([*args, "--overwrite"])
    assert code == 0
    text = (out / "performance.md").read_text()
    assert "analysis kept" in text and "tail kept" in text and "\nold\n" not in text
    assert "| 2D | 300 |" in text and "| 3D | 1000 |" in text
    assert "Fitted scaling exponent" in text
    assert (out / "img" / "performance.png").stat().st_size > 1000
    data = json.loads((out / "data" / "performance.json").read_text())
    assert {(r["dimensions"], r["cells"]) for r in data["records"]} == {(2, 300), (2, 1000), (3, 300), (3, 1000)}
    for record in data["records"]:
        assert record["peak_rss_mib"] > 0
        for spec, row in record["solvers"].items():
            assert row["verified"], (record["dimensions"], record["cells"], spec, row)
        # The plain solvers are checked against the linear solve, the QP solvers against the QP.
        assert {spec: row["reference"] for spec, row in record["solvers"].items()} == {
            "linear": "linear", "linear/primal": "linear", "cg@1e-9": "linear", "mprgp@1e-7": "complementarity",
            "osqp/contact": "complementarity"}
        assert record["solvers"]["linear/primal"]["status"].startswith("solved (lsmr")


def test_scaling_exponent_of_a_power_law():
    n = [1e3, 1e4, 1e5]
    assert bench.scaling_exponent(n, [2e-6 * x**1.1 for x in n]) == pytest.approx(1.1)


def test_run_times_are_extrapolated_by_what_the_registry_says_about_each_solver():
    """Matrix-free solves (MPRGP, CG, the linear solve's LSMR route) grow like cells^1.5,
    factorizations like cells^2 in 2D: at 10x the cells, 1 s becomes 31.6 s or 100 s."""
    solve_one_second = {"solve": {"median": 1.0}}
    previous = {"dimensions": 2, "cells": 1000, "solvers": dict.fromkeys(
        ["mprgp", "cg", "linear/primal", "linear", "osqp/contact"], solve_one_second)}
    skipped = bench._too_slow(previous, 10_000, list(previous["solvers"]), limit=40.0)
    assert set(skipped) == {"linear", "osqp/contact"}
    assert "extrapolated 100 s" in skipped["osqp/contact"]
