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
