"""The developer's tools in benchmarks/ (not installed with the package) still run."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BENCHMARKS = ROOT / "benchmarks"


def test_the_before_after_timing_runs_against_a_checkout():
    """(It re-imports qpcontact from another folder, so it runs in its own process; here the
    "old" checkout is this one.)"""
    done = subprocess.run([sys.executable, str(BENCHMARKS / "performance_ab.py"), str(ROOT), "--sizes", "200",
                           "--dimensions", "2", "--repeats", "1", "--cache-dir", "none", "--solvers", "osqp/contact"],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert "| 2D | 200 | detect |" in done.stdout and "| True |" in done.stdout


def test_the_plain_solve_timing_runs_on_a_snapshot(tmp_path):
    from qpcontact.cli import main

    assert main(["simulate", "--cells", "40", "--out", str(tmp_path / "run"), "--quiet"]) == 0
    snapshot = sorted((tmp_path / "run" / "snapshots").glob("step_*.npz"))[-1]
    done = subprocess.run([sys.executable, str(BENCHMARKS / "linear_grown.py"), str(snapshot), "--margin", "0.1"],
                          capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert done.returncode == 0, done.stderr
    assert "| cholesky |" in done.stdout and "| lsmr |" in done.stdout and "compare_with_linear" in done.stdout
