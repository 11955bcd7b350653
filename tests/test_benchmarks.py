"""The developer's tools in benchmarks/ (not installed with the package) still run."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

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


def _script(name: str):
    """benchmarks/cellmodeller/<name>.py as a module."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(name, BENCHMARKS / "cellmodeller" / f"{name}.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _cellmodeller_harness():
    """benchmarks/cellmodeller/grow_cellmodeller.py as a module (CellModeller itself is imported
    only when it runs, so its helpers are tested here without it)."""
    return _script("grow_cellmodeller")


def test_the_model_comparison_counts_sectors_at_the_rim_and_takes_the_packages_statistics():
    """compare_models.py: a ring of 40 tangential cells (every cell at the rim), two halves of
    one type each: two sectors; alternating types: none; its other statistics are the package's."""
    import numpy as np

    from qpcontact.colony.statistics import colony_statistics
    from qpcontact.geometry import Cells

    angle = np.linspace(0.0, 2 * np.pi, 40, endpoint=False)
    centers = np.column_stack([21.0 * np.cos(angle), 21.0 * np.sin(angle), np.zeros(40)])
    axes = np.column_stack([-np.sin(angle), np.cos(angle), np.zeros(40)])
    cells = Cells(centers=centers, axes=axes, lengths=np.full(40, 2.0), radii=np.full(40, 0.5))
    compare = _script("compare_models")
    halves = compare.statistics(cells, (np.arange(40) >= 20).astype(int))
    assert halves["sectors"] == 2 and halves["type1_fraction"] == 0.5
    assert compare.statistics(cells, np.arange(40) % 2)["sectors"] == 0
    package = colony_statistics(cells, dimensions=2)
    assert halves["packing"] == package.packing and halves["edge_alignment"] == package.edge_alignment
    assert halves["edge_alignment"] < -0.99  # tangential


def test_the_cellmodeller_harness_writes_the_step_log_bench_grown_reads(tmp_path):
    """Issue 28: the side-by-side harness is the project's own (before, a script outside the
    repository); its step log is what ``bench-grown --peer-log`` sums."""
    import argparse

    import numpy as np

    from qpcontact.studies.grown import peer_times

    harness = _cellmodeller_harness()

    class Physics:  # CellModeller's CLBacterium, as far as the timers see it
        def step(self, dt):
            self.CGSSolve(dt, 10.0)
            return True

        def CGSSolve(self, dt, alpha, substep=False):
            return 7, 0.004

    physics = Physics()
    timers = harness.Timers(physics)
    assert physics.step(0.025) is True and timers.solves[0][:2] == (7, 0.004) and timers.physics_seconds > 0
    log = [harness.step_row(1, 1, 1, 0.5, timers, 0), harness.step_row(2, 2, 1, 0.25, timers, 1)]
    two = dict(centers=np.array([[0.0, 0, 0], [0.0, 0.9, 0]]), axes=np.array([[1.0, 0, 0], [1.0, 0, 0]]),
               lengths=np.array([2.0, 2.0]), radii=np.array([0.5, 0.5]))
    log[1].update(harness.overlaps(two))
    assert log[1]["max_overlap"] == pytest.approx(0.1) and log[1]["overlapping_contacts"] == 2  # side by side: two contact points
    harness.write_log(tmp_path / "steps.json", argparse.Namespace(out=tmp_path, seed=1), log)
    peer = peer_times(tmp_path / "steps.json", [1, 2])
    assert peer["steps"] == 2 and peer["reached"][2] == dict(seconds=0.75, step=2, cells=2, max_overlap=pytest.approx(0.1))


def test_the_cellmodeller_patch_guards_the_renderer(tmp_path):
    """headless-ex1.patch applies (git apply) to the lines it says CellModeller has and puts the
    renderer under ``if sim.is_gui:``."""
    patch = BENCHMARKS / "cellmodeller" / "headless-ex1.patch"
    hunk = patch.read_text().split("\n@@ ", 1)[1].splitlines()[1:]
    before = [line[1:] for line in hunk if line[:1] in (" ", "-")]
    target = tmp_path / "Examples" / "ex1_simpleGrowth.py"
    target.parent.mkdir()
    target.write_text("\n" * 19 + "\n".join(before) + "\n")
    done = subprocess.run(["git", "apply", str(patch)], cwd=tmp_path, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    text = target.read_text()
    assert "    if sim.is_gui:" in text and "\n        from CellModeller.GUI import Renderers" in text
    assert "#if sim.is_gui" not in text


def test_the_plain_solve_timing_runs_on_a_snapshot(tmp_path):
    from qpcontact.cli import main

    assert main(["simulate", "--cells", "40", "--out", str(tmp_path / "run"), "--quiet"]) == 0
    snapshot = sorted((tmp_path / "run" / "snapshots").glob("step_*.npz"))[-1]
    done = subprocess.run([sys.executable, str(BENCHMARKS / "linear_grown.py"), str(snapshot), "--margin", "0.1"],
                          capture_output=True, text=True, timeout=120, cwd=ROOT)
    assert done.returncode == 0, done.stderr
    assert "| cholesky |" in done.stdout and "| lsmr |" in done.stdout and "compare_with_linear" in done.stdout


def test_the_step_profile_writes_its_phase_table(tmp_path):
    """benchmarks/profile_step.py on a small grown colony: one line with the phases of a step."""
    from qpcontact.io.runs import RunFolder, latest_snapshot
    from qpcontact.simulation import Settings, run_colony

    folder = RunFolder.create(tmp_path / "run")
    run_colony(Settings().updated({"cells": 150}), progress=False, folder=folder)
    out = tmp_path / "profile.md"
    done = subprocess.run([sys.executable, str(BENCHMARKS / "profile_step.py"), str(latest_snapshot(tmp_path / "run")),
                           "--steps", "1", "--set", "position_early_tolerance=null", "--out", str(out)],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    rows = [line for line in out.read_text().splitlines() if line.startswith("| step_")]
    assert len(rows) == 1 and "%" in rows[0]
    assert "settings changed: {'position_early_tolerance': None}" in out.read_text()
    bad = subprocess.run([sys.executable, str(BENCHMARKS / "profile_step.py"), str(latest_snapshot(tmp_path / "run")),
                          "--set", "position_early_tolerances=null"], capture_output=True, text=True, timeout=300)
    assert bad.returncode == 2 and "position_early_tolerances" in bad.stderr


def test_the_linearization_counts_compare_variants_from_a_state(tmp_path):
    """benchmarks/linearization_counts.py on a small grown colony: a row per variant, and every
    solve of the variant without early solves at the one tolerance."""
    from qpcontact.io.runs import RunFolder, latest_snapshot
    from qpcontact.simulation import Settings, run_colony

    folder = RunFolder.create(tmp_path / "run")
    run_colony(Settings().updated({"cells": 300}), progress=False, folder=folder)
    out = tmp_path / "counts.md"
    done = subprocess.run([sys.executable, str(BENCHMARKS / "linearization_counts.py"),
                           str(latest_snapshot(tmp_path / "run")), "--steps", "2", "--variant",
                           "strict:position_early_tolerance=none", "--variant", "defaults:", "--out", str(out)],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    rows = {line.split("|")[2].strip(): line.split("|")[3:-1] for line in out.read_text().splitlines()
            if line.startswith("| step_")}
    assert set(rows) == {"strict", "defaults"}
    assert int(rows["strict"][0]) == 2 and int(rows["strict"][2]) == 0 and int(rows["strict"][3]) > 0


def test_the_step_error_compares_one_step_with_substeps(tmp_path):
    """benchmarks/step_error.py on a small 3D biofilm: a row per scale, and at a tenth of the
    run's step one step and its substeps agree (the reference it stands on)."""
    from qpcontact.io.runs import RunFolder, latest_snapshot
    from qpcontact.simulation import Settings, run_colony

    folder = RunFolder.create(tmp_path / "run")
    run_colony(Settings().updated({"cells": 60, "dimensions": 3}), progress=False, folder=folder)
    out = tmp_path / "error.md"
    done = subprocess.run([sys.executable, str(BENCHMARKS / "step_error.py"), str(latest_snapshot(tmp_path / "run")),
                           "--scales", "1", "0.1", "--substeps", "2", "--out", str(out)],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    rows = [line.split("|") for line in out.read_text().splitlines() if line.startswith("| 1 |") or line.startswith("| 0.1 |")]
    assert len(rows) == 2
    rms_small = float(rows[1][8])
    assert rms_small < 0.01, rows[1]


def test_the_error_against_time_table_puts_each_simulator_against_its_own_finest_step(tmp_path):
    """benchmarks/cellmodeller/error_against_time.py: CellModeller's folders (their step and seed
    from steps.json) and qpcontact's run folders, grouped by simulator and step, each statistic's
    error against the same simulator's finest step, and the time to the size."""
    import json
    import shutil

    data = ROOT / "tests" / "data" / "cellmodeller" / "cellmodeller_64.npz"
    folders = []
    for dt, seed, seconds in ((0.025, 1, 2.0), (0.05, 1, 1.0)):
        folder = tmp_path / f"cm-{dt}-{seed}"
        folder.mkdir()
        shutil.copy(data, folder / "cellmodeller_64.npz")
        log = [{"step": 1, "n": 32, "t_sim": seconds}, {"step": 2, "n": 64, "t_sim": seconds}]
        (folder / "steps.json").write_text(json.dumps({"args": {"dt": dt, "seed": seed}, "log": log}))
        folders.append(str(folder))
    run = tmp_path / "qp"
    done = subprocess.run([sys.executable, "-m", "qpcontact", "simulate", "--cells", "64", "--seed", "2", "--quiet",
                           "--out", str(run)], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    out = tmp_path / "table.md"
    done = subprocess.run([sys.executable, str(BENCHMARKS / "cellmodeller" / "error_against_time.py"), "--size", "64",
                           "--cellmodeller", *folders, "--qpcontact", str(run), "--out", str(out),
                           "--plot", str(tmp_path / "plot.png")],
                          capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    rows = [line for line in out.read_text().splitlines() if line.startswith("| CellModeller") or line.startswith("| qpcontact")]
    assert [row.split(" | ")[1] for row in rows] == ["dt 0.025", "dt 0.05", "growth 0.05"]
    assert " | 4.0 | " in rows[0] and " | 2.0 | " in rows[1]  # the time to 64 cells: both steps' times
    # the same state at both steps: no error; the finest step's own row has none to show
    assert "Δ+0.000" in rows[1] and "Δ" not in rows[0] and "Δ" not in rows[2]
    assert (tmp_path / "plot.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def _process_counts(processes: int, own: float) -> dict[str, list[float]]:
    """A made-up ``mpi-scaling.json`` run on ``processes``: MUMPS's work divided evenly, ``own``
    CPU seconds of own work on each process."""
    each = lambda value: [value / processes] * processes  # noqa: E731
    return {"cells": [10_000.0], "own": [own] * processes, "factor": each(12.0), "first_factor_cpu": each(3.0),
            "problems": [10.0] * processes, "factorizations": [100.0] * processes, "solve_cpu": each(4.0),
            "product_cpu": each(1.0), "normal_cpu": each(2.0), "flops": each(5e11), "entry_solves": each(4e9), "solves": [400.0] * processes,
            "products": [1000.0] * processes, "collectives": [3000.0] * processes, "sent": each(1e8),
            "linearizations": [5.0] * processes}


def test_the_distributed_model_is_built_from_counts_not_from_waiting(tmp_path, monkeypatch):
    """benchmarks/mpi_model.py on made-up counts: the own work's repeated part is what does not fall
    with P, the analysis stays on one process, the factorization divides, and a larger colony costs
    more."""
    import json

    monkeypatch.syspath_prepend(str(BENCHMARKS))
    import mpi_model

    runs = {p: _process_counts(p, 1.0 + 8.0 / p) for p in (1, 2, 4, 8)}  # own work: 1 repeated, 8 divided
    counts = mpi_model.counts_of(runs)
    assert counts.repeated == pytest.approx(1.0) and counts.divided == pytest.approx(8.0)
    # the first factorization of each of 10 problems took 3 s in all, a numeric one (12 - 3) / 90 s
    assert counts.analysis == pytest.approx(3.0 - 10 * 0.1) and counts.numeric == pytest.approx(10.0)
    flops, entries = mpi_model.growths(2, None, counts.cells)
    parts = {p: mpi_model.step_parts(counts, 1e6, p, 2e-6, 25e9, flops, entries) for p in (64.0, 256.0)}
    assert parts[64.0]["analysis (one process)"] == parts[256.0]["analysis (one process)"] == pytest.approx(200.0)
    assert parts[64.0]["numeric factorization"] == pytest.approx(4 * parts[256.0]["numeric factorization"])
    assert parts[64.0]["numeric factorization"] == pytest.approx(10.0 * 100 ** 1.5 / 64)
    assert parts[256.0]["own, repeated"] == pytest.approx(100.0)
    assert parts[256.0]["normal matrix"] == pytest.approx(2.0 * 100 / 256 + 100 * 2 * 2e-6)
    measured = tmp_path / "mpi-scaling.json"
    measured.write_text(json.dumps({"per_process": {f"2d-10000, {p} MPI processes, ipm-petsc": v
                                                    for p, v in runs.items()}}))
    out = tmp_path / "model.md"
    done = subprocess.run([sys.executable, str(BENCHMARKS / "mpi_model.py"), str(measured), "--state", "2d-10000",
                           "--out", str(out)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-3000:]
    rows = [line.split("|")[1:-1] for line in out.read_text().splitlines() if line.startswith("| 64 |")
            or line.startswith("| 256 |")]
    assert len(rows) == 2 and float(rows[1][-2]) < float(rows[0][-2])  # a step on 256 is shorter than on 64
    # a step of twice the linearizations costs twice as much
    again = tmp_path / "model-10.md"
    subprocess.run([sys.executable, str(BENCHMARKS / "mpi_model.py"), str(measured), "--state", "2d-10000",
                    "--linearizations", "10", "--out", str(again)], check=True, capture_output=True, timeout=120)
    twice = [line.split("|")[1:-1] for line in again.read_text().splitlines() if line.startswith("| 64 |")]
    assert float(twice[0][-2]) == pytest.approx(2 * float(rows[0][-2]), rel=1e-3)
    # what if the repeated work and the analysis were divided too: each alone, then both
    divided = mpi_model.step_parts(counts, 1e6, 256.0, 2e-6, 25e9, flops, entries, ("repeated", "analysis"), 1.5)
    assert divided["own, repeated"] == pytest.approx(100.0 / 256)
    assert divided["analysis (one process)"] == pytest.approx(200.0 / 256)
    assert divided["numeric factorization"] == pytest.approx(1.5 * parts[256.0]["numeric factorization"])
    whatif = tmp_path / "model-divided.md"
    subprocess.run([sys.executable, str(BENCHMARKS / "mpi_model.py"), str(measured), "--state", "2d-10000",
                    "--divide", "repeated,analysis", "--out", str(whatif)], check=True, capture_output=True,
                   timeout=120)
    labels = [line.split("|")[1].strip() for line in whatif.read_text().splitlines() if line.startswith("| 256")]
    assert labels == ["256", "256, repeated divided", "256, analysis divided", "256, repeated and analysis divided"]
    bad = subprocess.run([sys.executable, str(BENCHMARKS / "mpi_model.py"), str(measured), "--state", "2d-10000",
                          "--divide", "gathers"], capture_output=True, text=True, timeout=120)
    assert bad.returncode == 2 and "--divide" in bad.stderr
    for flag, value in (("--linearizations", "0"), ("--cells", "50"), ("--processes", "0,64"),
                        ("--steps-per-efold", "nan")):
        bad = subprocess.run([sys.executable, str(BENCHMARKS / "mpi_model.py"), str(measured), "--state", "2d-10000",
                              flag, value], capture_output=True, text=True, timeout=120)
        assert bad.returncode == 2 and flag in bad.stderr, (flag, bad.stderr)
