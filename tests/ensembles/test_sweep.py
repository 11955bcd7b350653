"""qpcontact sweep (qpcontact.ensembles.sweep) and the Dask helpers (qpcontact.ensembles.cluster): the
grid and its checks before anything starts, a small sweep on a 2-worker local cluster, failed runs
reported by name, a stopped sweep resumed, a killed worker, and compare/stability on Dask with
their time limits kept. The runs are tiny (10-60 cells, a few seconds each)."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from qpcontact import cli
from qpcontact.ensembles import cluster, submit, sweep, tasks
from qpcontact.ensembles import grid as grids
from qpcontact.errors import InvalidArgumentError
from qpcontact.io.runs import HISTORY_FIELDS, TIMING_FIELDS, RunFolder
from qpcontact.simulation.loop import run_colony
from qpcontact.simulation.settings import Settings
from qpcontact.studies import harness
from qpcontact.timestep import PositionSettings
from tests.helpers import default_signals, gate_model, wait_for

distributed = pytest.importorskip("distributed")

ROOT = Path(__file__).resolve().parents[2]
#: Seconds any wait of these tests may take before it fails the test.
PATIENCE = 120.0


def read_summary(out: Path) -> dict[str, dict[str, str]]:
    with (out / sweep.SUMMARY_FILE).open(newline="") as fh:
        return {row["name"]: row for row in csv.DictReader(fh)}


def attempts(out: Path, name: str) -> list[dict]:
    return tasks.attempts_of(out / "runs" / name)


@pytest.fixture(scope="module")
def scheduler():
    """A local cluster of 2 worker processes as Dask starts them by default (daemon processes),
    shared by the tests that pass --scheduler ADDRESS."""
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None,
                                  **cluster.NO_DASHBOARD) as local:
        yield local.scheduler_address


# ------------------------------------------------------------------------------------------
# The grid, checked before anything starts
# ------------------------------------------------------------------------------------------
def test_the_grid_is_seeds_times_the_product_of_the_varied_lists_or_their_zip():
    grid = grids.Grid({"growth_inertia_ratio": [100.0, 1000.0], "position_overlap_tolerance": [0.01, 0.02]}, [1, 2])
    runs = grids.plan_runs(Settings().updated({"cells": 10}), grid)
    assert len(runs) == 8 and len({r["name"] for r in runs}) == 8
    assert runs[0]["name"] == "growth_inertia_ratio-100__position_overlap_tolerance-0.01__seed-1"
    assert runs[0]["settings"]["run"]["cells"] == 10 and runs[-1]["settings"]["run"]["seed"] == 2
    assert runs[-1]["settings"]["position"]["overlap_tolerance"] == 0.02
    assert runs[-1]["varied"] == {"growth_inertia_ratio": 1000.0, "position_overlap_tolerance": 0.02, "seed": 2}
    zipped = grids.plan_runs(Settings(), grids.Grid({"cells": [10, 20], "dimensions": [2, 3]}, [5], zip=True))
    assert [r["name"] for r in zipped] == ["cells-10__dimensions-2__seed-5", "cells-20__dimensions-3__seed-5"]
    assert [r["name"] for r in grids.plan_runs(Settings(), grids.Grid({}, [3, 4]))] == ["seed-3", "seed-4"]


def test_the_grid_from_a_configuration_file_with_flags_overriding_it(tmp_path):
    config = tmp_path / "sweep.toml"
    config.write_text('[run]\ncells = 12\n[position]\nsolver = "mprgp"\n[output]\nsnapshot_every = 7\n\n'
                      '[sweep]\nseeds = [4, 5]\n\n[sweep.vary]\ngrowth_inertia_ratio = [100, 1000]\novershoot = []\n')
    args = cli.command_parser(cli.build_parser("sweep"), "sweep").parse_args(["--config", str(config)])
    with pytest.raises(InvalidArgumentError, match="unknown setting 'overshoot'"):
        sweep.configure(args)
    config.write_text(config.read_text().replace("overshoot = []\n", ""))
    base, grid, _ = sweep.configure(args)
    assert (base.run.cells, base.position.solver, base.output.snapshot_every) == (12, "mprgp", 7)
    assert grid.vary == {"growth_inertia_ratio": [100, 1000]} and grid.seeds == [4, 5]
    args = cli.command_parser(cli.build_parser("sweep"), "sweep").parse_args(
        ["--config", str(config), "--cells", "20", "--seeds", "9", "--vary", "growth-inertia-ratio=5",
         "--snapshot-every", "3"])
    base, grid, _ = sweep.configure(args)
    assert (base.run.cells, base.output.snapshot_every, grid.seeds, grid.vary) == (20, 3, [9],
                                                                                   {"growth_inertia_ratio": [5.0]})


@pytest.mark.parametrize("argv, message", [
    (["--vary", "growth_inertia_ratio=100,-1"], "growth_inertia_ratio=-1: expected a number > 0, got -1.0"),
    (["--vary", "nosuch=1,2"], "unknown setting 'nosuch' to vary"),
    (["--vary", "dimensions=2,4"], "dimensions=4: expected one of 2, 3, got 4"),
    (["--vary", "position_solver=ipm,nosuch"], "nosuch"),
    (["--vary", "seed=1,2"], "vary the seed with --seeds"),
    (["--vary", "cells=10,20", "--vary", "dimensions=2", "--zip"], "the varied lists must have the same length"),
    (["--vary", "velocity_solver=clarabel,osqp"],
     "--vary: velocity_solver: a setting of the velocity step; this run takes position steps"),
    (["--velocity-tolerance", "1e-4"], "command line: --velocity-tolerance: a setting of the velocity step"),
    (["--vary", "growth_inertia_ratio=100,100"], "two runs named 'growth_inertia_ratio-100__seed-1'"),
    (["--vary", "hook=nosuch.py"], "nosuch.py"),
    (["--snapshot-every", "0"], "snapshot_every: a sweep's run continues from its latest snapshot"),
    (["--solver", "osqp"], "--solver: each step has its own: --position-solver"),
    (["--resume"], "holds no sweep to resume"),
    (["--vary", "stall_pressure=10,50"], "--vary: stall_pressure: used by pressure-dependent growth only"),
    (["--stall-pressure", "10"], "command line: --stall-pressure: used by pressure-dependent growth only"),
    (["--vary", "pressure_growth=off,quadratic"],
     "run pressure_growth-quadratic__seed-1: pressure_growth: expected one of off, linear, exponential, got "
     "'quadratic'"),
    (["--vary", "color=orientation,red"], "run color-red__seed-1: color: expected one of orientation, pressure, cell_type, got 'red'"),
])
def test_a_bad_setting_is_rejected_before_any_task_starts(argv, message, tmp_path, capsys, monkeypatch):
    def no_cluster(*args, **kwargs):
        raise AssertionError("a cluster was started")

    monkeypatch.setattr(cluster, "open_client", no_cluster)
    out = tmp_path / "out"
    assert cli.main(["sweep", "--out", str(out), *argv]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("qpcontact sweep: ") and message in err, err
    assert not out.exists()


def test_a_sweep_of_pressure_growth_off_and_on_is_planned_with_each_runs_law(tmp_path, monkeypatch):
    """--vary pressure_growth=off,linear with --stall-pressure: the stall pressure applies to the
    linear runs, so it is not refused; each run's settings carry its law, and summary.csv names
    the growth that ran next to the step (checked on the planned sweep: no cluster started)."""
    def no_cluster(*args, **kwargs):
        raise AssertionError("a cluster was started")

    monkeypatch.setattr(cluster, "open_client", no_cluster)
    out = tmp_path / "out"
    args = cli.command_parser(cli.build_parser("sweep"), "sweep").parse_args(
        ["--cells", "5", "--seeds", "1,2", "--vary", "pressure_growth=off,linear", "--stall-pressure", "40",
         "--color", "pressure", "--out", str(out)])
    planned, runs = sweep.prepare(args)
    assert [r["name"] for r in runs] == ["pressure_growth-off__seed-1", "pressure_growth-off__seed-2",
                                         "pressure_growth-linear__seed-1", "pressure_growth-linear__seed-2"]
    for run in runs:
        model = run["settings"]["model"]
        assert (model["pressure_growth"], model["stall_pressure"]) == (run["varied"]["pressure_growth"], 40.0)
        assert run["settings"]["output"]["color"] == "pressure"
    planned.write_summary()
    summary = read_summary(out)
    assert summary["pressure_growth-off__seed-1"]["growth"] == "pressure growth off"
    assert summary["pressure_growth-linear__seed-2"]["growth"] == "pressure growth linear, stall pressure 40 F/µm"
    assert summary["pressure_growth-linear__seed-2"]["pressure_growth"] == "linear"


def test_sweep_without_dask_says_which_extra_to_install(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed -> ImportError
    assert cli.main(["sweep", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "pip install 'qpcontact[sweep]'" in err, err
    assert not (tmp_path / "out").exists()


def test_an_earlier_sweep_is_refused_unless_resumed_or_overwritten(tmp_path, capsys):
    (tmp_path / sweep.SWEEP_FILE).write_text("{}")
    assert cli.main(["sweep", "--out", str(tmp_path)]) == 2
    assert "holds a sweep (sweep.json); continue it with --resume" in capsys.readouterr().err
    assert cli.main(["sweep", "--out", str(tmp_path), "--resume", "--cells", "5"]) == 2
    err = capsys.readouterr().err
    assert "--resume continues the sweep" in err and "drop --cells" in err, err


def test_nematic_order():
    assert tasks.nematic_order(np.array([[1.0, 0, 0]] * 5), 2) == pytest.approx(1.0)
    assert tasks.nematic_order(np.array([[1.0, 0, 0], [0, 1.0, 0]]), 2) == pytest.approx(0.0, abs=1e-12)
    assert tasks.nematic_order(np.eye(3), 3) == pytest.approx(0.0, abs=1e-12)
    assert tasks.nematic_order(np.array([[0, 0, 1.0]] * 3), 3) == pytest.approx(1.0)


# ------------------------------------------------------------------------------------------
# One run's task: idempotent, continued from its folder
# ------------------------------------------------------------------------------------------
def test_a_run_task_continues_a_cut_run_from_its_snapshot_exactly_and_is_done_once(tmp_path):
    settings = Settings().updated({"cells": 12, "seed": 3, "snapshot_every": 5})
    values = settings.to_tables()
    whole = tasks.run_task("whole", values, str(tmp_path / "whole"))
    assert whole["status"] == "done" and whole["attempts"] == 1 and whole["cells"] >= 12
    # A run cut short: snapshots to step 15, history rows beyond it (a worker killed at step 18).
    cut = tmp_path / "cut"
    folder = RunFolder.create(cut)
    run_colony(settings.updated({"max_steps": 18}), progress=False, folder=folder)
    (cut / "snapshots" / "step_000018.npz").unlink()
    outcome = tasks.run_task("cut", values, str(cut))
    assert outcome["status"] == "done" and [a["from_step"] for a in tasks.attempts_of(cut)] == [15]
    ours, theirs = RunFolder(cut).read_history(), RunFolder(tmp_path / "whole").read_history()
    for name in set(HISTORY_FIELDS) - set(TIMING_FIELDS):
        np.testing.assert_array_equal(ours[name], theirs[name], err_msg=name)
    assert {k: outcome[k] for k in ("cells", "steps", "largest_overlap", "order")} == \
        {k: whole[k] for k in ("cells", "steps", "largest_overlap", "order")}
    assert tasks.run_task("cut", values, str(cut)) == json.loads((cut / tasks.RESULT_FILE).read_text())
    assert len(tasks.attempts_of(cut)) == 1  # done: not started again


# ------------------------------------------------------------------------------------------
# Sweeps on Dask
# ------------------------------------------------------------------------------------------
def test_a_small_sweep_on_a_two_worker_local_cluster(tmp_path, capsys):
    out = tmp_path / "sweep"
    code = sweep.main(["--cells", "10", "--seeds", "1,2", "--vary", "growth_inertia_ratio=100,1000", "--workers", "2",
                       "--snapshot-every", "10", "--quiet", "--out", str(out)])
    printed = capsys.readouterr().out
    assert code == 0, printed
    assert "4 runs: 4 done, 0 failed, 0 not finished" in printed
    summary = read_summary(out)
    names = ["growth_inertia_ratio-100__seed-1", "growth_inertia_ratio-100__seed-2", "growth_inertia_ratio-1000__seed-1",
             "growth_inertia_ratio-1000__seed-2"]
    assert list(summary) == names
    assert tuple(next(iter(summary.values()))) == sweep.Sweep.load(out).summary_columns()
    for name, row in summary.items():
        assert row["status"] == "done" and row["attempts"] == "1" and not row["error"]
        assert int(row["cells"]) >= 10 and 0 <= float(row["order"]) <= 1 and float(row["largest_overlap"]) >= 0
        folder = out / "runs" / name
        assert {"config.toml", "history.csv", "colony.png", "history.png", "result.json"} <= {p.name for p in folder.iterdir()}
        assert RunFolder(folder).latest_snapshot() is not None
        assert f"growth_inertia_ratio = {float(row['growth_inertia_ratio'])!r}" in (folder / "config.toml").read_text()
        assert row["step"] == (f"position step, ipm at tolerance {PositionSettings().tolerance:g}, overlap ≤ 0.01, "
                               "search margin 0.75 (by the scene), growth per step 0.05 (by the scene)")  # what ran
    assert len({row["worker"] for row in summary.values()}) == 2  # both workers ran runs
    assert (out / sweep.ENSEMBLE_FILE).stat().st_size > 10_000
    assert all(run["status"] == "done" for run in json.loads((out / sweep.SWEEP_FILE).read_text())["runs"])


def test_failed_runs_are_reported_by_name_with_their_error_and_resume_redoes_only_them(scheduler, tmp_path, capsys):
    (tmp_path / "good.py").write_text("def hook(colony, step):\n    return None\n")
    (tmp_path / "bad.py").write_text("def hook(colony, step):\n    if step == 3:\n"
                                     "        raise ValueError('the model broke at step 3')\n")
    out = tmp_path / "sweep"
    argv = ["--cells", "8", "--seeds", "1,2", "--vary", f"hook={tmp_path / 'good.py'},{tmp_path / 'bad.py'}",
            "--scheduler", scheduler, "--quiet", "--out", str(out)]
    assert sweep.main(argv) == 1
    printed, err = capsys.readouterr()
    assert "4 runs: 2 done, 2 failed, 0 not finished" in printed
    for seed in (1, 2):
        assert f"failed: hook-bad.py__seed-{seed}: step 3 (t = " in printed
        assert "the model broke at step 3" in printed.split(f"hook-bad.py__seed-{seed}")[1].splitlines()[0]
    assert "2 runs failed" in err
    summary = read_summary(out)
    assert summary["hook-bad.py__seed-1"]["status"] == "failed" and "the model broke" in summary["hook-bad.py__seed-1"]["error"]
    runs = {r["name"]: r for r in json.loads((out / sweep.SWEEP_FILE).read_text())["runs"]}
    assert "ValueError: the model broke at step 3" in runs["hook-bad.py__seed-2"]["traceback"]
    # --resume runs the failed ones again (they fail again), not the done ones.
    assert sweep.main(["--resume", "--scheduler", scheduler, "--quiet", "--out", str(out)]) == 1
    assert "sweep of 4 runs into" in (err := capsys.readouterr().err) and "; 2 to do" in err
    assert [len(attempts(out, n)) for n in summary] == [1, 1, 2, 2]


def _sweep_process(argv: list[str], log: Path) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "qpcontact", "sweep", "--quiet", *argv], cwd=ROOT,
                            stdout=log.open("w"), stderr=subprocess.STDOUT, preexec_fn=default_signals)


@pytest.mark.slow
def test_ctrl_c_in_a_terminal_stops_the_sweep_in_seconds_and_tells_each_runs_state(tmp_path):
    """A terminal's Ctrl-C goes to the whole process group, the local cluster's workers
    included (issue 27: they died of it, about 100 lines of Dask tracebacks, the sweep waited out
    STOP_WAIT and called the runs they had cut short "not started"). Now the workers do not hear
    it: the sweep stops them through its flag, each saving its state, well before STOP_WAIT, and
    says truly where each run got to."""
    out = tmp_path / "sweep"
    log = tmp_path / "sweep.log"
    process = subprocess.Popen([sys.executable, "-m", "qpcontact", "sweep", "--cells", "400", "--seeds", "1,2,3",
                                "--workers", "2", "--snapshot-every", "5", "--out", str(out)], cwd=ROOT,
                               stdout=log.open("w"), stderr=subprocess.STDOUT, preexec_fn=default_signals,
                               start_new_session=True)  # its own process group, as a terminal's job
    try:
        wait_for(lambda: len(list(out.glob("runs/*/snapshots/step_000005.npz"))) == 2 or process.poll() is not None,
                 "two runs past their snapshot of step 5", PATIENCE)
        assert process.poll() is None, log.read_text()
        signalled = time.monotonic()
        os.killpg(process.pid, signal.SIGINT)
        assert process.wait(PATIENCE) == 130, log.read_text()
        took = time.monotonic() - signalled
    finally:
        if process.poll() is None:
            os.killpg(process.pid, signal.SIGKILL)
            process.wait()
    text = log.read_text()
    assert "Traceback" not in text and "KeyboardInterrupt" not in text, text
    assert took < submit.STOP_WAIT, text  # the runs answered the flag: nobody waited for dead workers
    runs = {line.split(": ")[1]: line.split(": ", 2)[2] for line in text.splitlines() if line.startswith("  pending: ")}
    assert sorted(runs) == ["seed-1", "seed-2", "seed-3"], text
    started = [name for name in runs if attempts(out, name)]
    assert len(started) >= 2, text
    for name, said in runs.items():
        assert (said == "not started") == (name not in started), (name, said)
    assert "interrupted; continue with: qpcontact sweep --resume" in text


def test_a_run_not_finished_is_said_to_be_started_or_not_from_its_folder(tmp_path):
    folder = tmp_path / "run"
    folder.mkdir()
    assert sweep.progress_of(folder) == "not started"
    (folder / tasks.ATTEMPTS_FILE).write_text('{"from_step": 0}\n')
    assert sweep.progress_of(folder) == "started, cut short; no snapshot yet"
    (folder / "snapshots").mkdir()
    (folder / "snapshots" / "step_000010.npz").write_bytes(b"")
    assert sweep.progress_of(folder) == "started, cut short; its latest snapshot: step 10"


@pytest.mark.slow
def test_a_stopped_sweep_resumes_without_redoing_finished_runs(scheduler, tmp_path):
    """Ctrl-C stops the sweep (status 130); the run cut short continues from its snapshot; the
    finished runs are not run again. Deterministic: the second run is held at step 8 by its model
    (tests/helpers.py::gate_model) until the sweep's stop flag appears, so the signal always lands
    with one run done and one cut after its snapshot of step 5 (no race with the machine's speed)."""
    out = tmp_path / "sweep"
    names = ["seed-1", "seed-2", "seed-3"]
    gates = tmp_path / "gates"
    gates.mkdir()
    gate = gate_model(gates, 8, stop_flag=out / tasks.STOP_FILE, skip_first=True)
    process = _sweep_process(["--cells", "150", "--seeds", "1,2,3", "--snapshot-every", "5", "--workers", "1",
                              "--hook", str(gate), "--out", str(out)], tmp_path / "first.log")
    try:
        wait_for(lambda: (gates / "held").exists() or process.poll() is not None, "the second run held", PATIENCE)
        assert process.poll() is None, (tmp_path / "first.log").read_text()
        process.send_signal(signal.SIGINT)
        assert process.wait(PATIENCE) == 130, (tmp_path / "first.log").read_text()
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
    assert "interrupted; continue with: qpcontact sweep --resume" in (tmp_path / "first.log").read_text()
    done = [n for n in names if (out / "runs" / n / tasks.RESULT_FILE).exists()]

    def reached(name: str) -> int:
        latest = RunFolder(out / "runs" / name).latest_snapshot()
        return -1 if latest is None else int(latest.stem[5:])

    cut = [n for n in names if n not in done and reached(n) >= 5]
    assert len(done) == 1 and len(cut) == 1, {n: reached(n) for n in names}
    # the third: not started, or (a cancellation racing its start) stopped by the flag at once
    assert all(reached(n) <= 0 for n in names if n not in done + cut)
    assert not (out / tasks.STOP_FILE).exists()  # removed once the local cluster is closed
    assert sweep.main(["--resume", "--workers", "2", "--quiet", "--out", str(out)]) == 0
    summary = read_summary(out)
    assert all(row["status"] == "done" for row in summary.values())
    for name in names:
        starts = [a["from_step"] for a in attempts(out, name)]
        if name in done:
            assert starts == [0], name  # not redone
        elif name in cut:
            assert len(starts) == 2 and starts[1] >= 5, (name, starts)  # continued from its snapshot
        else:
            assert starts[-1] == 0, name


@pytest.mark.slow
def test_a_killed_worker_loses_no_run_and_only_its_run_is_redone(tmp_path):
    """A scheduler and two workers as separate processes (dask scheduler / dask worker); one
    worker is killed (SIGKILL) in the middle of a run: every run finishes, the killed one is
    continued from its latest snapshot on the other worker, no other run is started twice, and
    the continued run ends exactly where an uninterrupted one does."""
    processes: list[subprocess.Popen] = []
    logs = tmp_path / "logs"
    logs.mkdir()

    def start(name: str, *argv: str) -> subprocess.Popen:
        process = subprocess.Popen([sys.executable, "-m", *argv], stdout=(logs / f"{name}.log").open("w"),
                                   stderr=subprocess.STDOUT, cwd=tmp_path)
        processes.append(process)
        return process

    try:
        scheduler_file = tmp_path / "scheduler.json"
        start("scheduler", "distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
              "--dashboard-address", ":0", "--scheduler-file", str(scheduler_file))
        wait_for(lambda: scheduler_file.exists() and tasks.read_json(scheduler_file), "the scheduler", PATIENCE)
        workers = [start(f"worker{i}", "distributed.cli.dask_worker", "--scheduler-file", str(scheduler_file),
                         "--nthreads", "1", "--no-nanny", "--no-dashboard", "--name", f"w{i}") for i in (1, 2)]
        out = tmp_path / "sweep"
        names = ["seed-1", "seed-2", "seed-3"]
        # The first run to reach step 8 is held there (after its snapshot of step 5) until its
        # worker is killed: a known point, not a race with the machine's speed.
        gates = tmp_path / "gates"
        gates.mkdir()
        gate = gate_model(gates, 8)
        client = _sweep_process(["--cells", "150", "--seeds", "1,2,3", "--snapshot-every", "5", "--hook", str(gate),
                                 "--scheduler", str(scheduler_file), "--out", str(out)], logs / "sweep.log")
        processes.append(client)
        pids = {w.pid: w for w in workers}
        held = gates / "held"  # (written after it is created: wait for its content)
        wait_for(lambda: held.exists() and held.read_text().strip(), "a run held at step 8", PATIENCE)
        pid = int((gates / "held").read_text())
        victim = next(name for name in names if any(a["pid"] == pid for a in attempts(out, name)))
        assert pid in pids and RunFolder(out / "runs" / victim).latest_snapshot() is not None
        os.kill(pid, signal.SIGKILL)
        pids[pid].wait(PATIENCE)
        assert client.wait(PATIENCE) == 0, (logs / "sweep.log").read_text()
    finally:
        for process in reversed(processes):
            if process.poll() is None:
                process.kill()
            process.wait()
    summary = read_summary(out)
    assert all(row["status"] == "done" for row in summary.values())  # runs lost: 0
    for name in names:
        starts = attempts(out, name)
        if name == victim:  # redone: only the killed one, from its latest snapshot, on the other worker
            assert len(starts) == 2 and starts[1]["from_step"] > 0 and starts[1]["pid"] != pid, starts
        else:
            assert len(starts) == 1, (name, starts)
    # The continued run is the uninterrupted run.
    whole = tasks.run_task("whole", Settings().updated({"cells": 150, "seed": int(victim.split("-")[1]),
                                                        "snapshot_every": 5}).to_tables(), str(tmp_path / "whole"))
    ours, theirs = RunFolder(out / "runs" / victim).read_history(), RunFolder(tmp_path / "whole").read_history()
    assert ours["max_overlap"] == theirs["max_overlap"] and ours["cells"] == theirs["cells"]
    assert int(summary[victim]["cells"]) == whole["cells"]


@pytest.mark.slow
def test_a_run_folder_is_locked_while_its_task_runs_and_freed_when_it_dies(tmp_path):
    """Two tasks of one run must never write its folder at once (Dask may start a task again while
    the first still runs): the first holds ``.run.lock`` for as long as it runs; killed, it frees
    it, and the next task continues the run from its snapshot."""
    import fcntl

    folder = tmp_path / "run"
    gate = gate_model(tmp_path, 8)
    values = Settings().updated({"cells": 60, "seed": 2, "hook": str(gate), "snapshot_every": 5}).to_tables()
    code = (f"from qpcontact.ensembles import tasks; tasks.run_task('r', {values!r}, {str(folder)!r})")
    first = subprocess.Popen([sys.executable, "-c", code], cwd=ROOT, stdout=subprocess.DEVNULL,
                             stderr=subprocess.PIPE, text=True)
    try:
        wait_for(lambda: (tmp_path / "held").exists() or first.poll() is not None, "the task held at step 8",
                 PATIENCE)
        assert first.poll() is None, first.communicate()[1]
        with open(folder / tasks.LOCK_FILE, "a") as fh:
            with pytest.raises(BlockingIOError):  # held by the running task
                fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
            first.kill()
            first.wait(PATIENCE)
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)  # freed by its death
            fcntl.flock(fh, fcntl.LOCK_UN)
    finally:
        if first.poll() is None:
            first.kill()
            first.wait()
    outcome = tasks.run_task("r", values, str(folder))
    assert outcome["status"] == "done" and outcome["attempts"] == 2
    assert [a["from_step"] for a in tasks.attempts_of(folder)] == [0, 5]


def test_a_scheduler_that_does_not_answer_is_one_line(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(cluster, "CONNECT_TIMEOUT", 1.0)
    assert sweep.main(["--cells", "5", "--scheduler", "tcp://127.0.0.1:9", "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert "--scheduler tcp://127.0.0.1:9: cannot connect" in err and err.count("\n") <= 2, err


# ------------------------------------------------------------------------------------------
# compare and stability on Dask
# ------------------------------------------------------------------------------------------
def test_the_guarded_child_keeps_its_time_limit_inside_a_dask_task(scheduler):
    """Dask's worker processes are daemons, which multiprocessing forbids to start children:
    the task allows them, and the guard still kills a case at its limit."""
    with distributed.Client(scheduler) as client:
        t0 = time.perf_counter()
        answer = client.submit(cluster.call, harness.guarded, (time.sleep, (60,), 2.0), {}, pure=False).result(PATIENCE)
        assert answer == ("timeout", None) and time.perf_counter() - t0 < 30
        assert client.submit(cluster.call, harness.guarded, (abs, (-3,), 30.0), {}, pure=False).result(PATIENCE) == ("ok", 3)


def test_stability_and_compare_hand_their_cases_to_dask(scheduler, tmp_path):
    from qpcontact.studies import compare, stability

    common = ["--cases", "crossing,parallel_0", "--solvers", "linear,osqp", "--formulations", "complementarity",
              "--scaling", "on", "--repeats", "1"]
    assert stability.main([*common, "--out", str(tmp_path / "here")]) == 0
    assert stability.main([*common, "--scheduler", scheduler, "--out", str(tmp_path / "dask")]) == 0

    def rows(folder: Path, columns: int) -> list[list[str]]:
        return [line.split(",")[:columns] for line in folder.read_text().splitlines()]

    assert rows(tmp_path / "dask" / "stability.csv", 7) == rows(tmp_path / "here" / "stability.csv", 7)
    assert compare.main(["--scenes", "two_rods", "--solvers", "linear,osqp", "--tolerances", "1e-6", "--repeats", "1",
                         "--scheduler", scheduler, "--out", str(tmp_path / "compare")]) == 0
    with (tmp_path / "compare" / "solvers.csv").open(newline="") as fh:
        outcomes = [(r["method"], r["outcome"]) for r in csv.DictReader(fh)]
    assert outcomes[0] == ("linear/linear/contact", "success") and len(outcomes) == 5
    assert all(outcome == "success" for _, outcome in outcomes)
