"""The sweep measurement of docs/colony.md ("Sweeps on Dask"): the same runs one after the other
and as a sweep on a local Dask cluster, then a sweep on a scheduler and workers started as
separate processes with one worker killed in the middle of a run.

``python benchmarks/sweep_benchmark.py [--cells 2000] [--runs 8] [--workers 2] [--out DIR]`` (a developer's
tool, from the repository root; not installed with the package)

1. *One after the other*: :func:`qpcontact.ensembles.tasks.run_task` for seeds 1..runs in this
   process (the work of each task, without Dask): wall time of each and in total.
2. *Sweep*: ``qpcontact sweep`` of the same runs on a ``LocalCluster`` of ``--workers`` worker
   processes (cluster start included): wall time, speed-up over 1, and the overhead per task,
   ``(workers × wall − Σ task time) / runs`` (what the workers spend not running a task: start,
   scheduling, waiting for the last run), and each task's own time against its time in 1.
3. *Killed worker*: ``dask scheduler`` and two ``dask worker --no-nanny`` processes, a sweep of
   ``--kill-runs`` runs on them (``--scheduler``); once a run has a snapshot past step 0 the worker
   running it is killed (SIGKILL). Reported: runs lost (not done at the end), runs started more
   than once (only the killed one should be), the step the killed run continued from and the
   steps it had reached, the wall time.

Prints a Markdown report and writes it with the raw numbers (``sweep_benchmark.json``) into
``--out``. It takes several times one run; run it on a quiet machine.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import platform
import signal
import subprocess
import sys
import time
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

from qpcontact.cli import positive_int, run_standalone
from qpcontact.ensembles import sweep, tasks
from qpcontact.errors import OutputFolderError
from qpcontact.io.outputs import prepare_folder, write_text
from qpcontact.io.runs import RunFolder
from qpcontact.simulation.settings import Settings


def one_after_the_other(cells: int, runs: int, out: Path) -> dict[str, Any]:
    seconds = []
    t0 = time.perf_counter()
    for seed in range(1, runs + 1):
        t = time.perf_counter()
        outcome = tasks.run_task(f"seed-{seed}", Settings().updated({"cells": cells, "seed": seed}).to_tables(),
                                 str(out / "runs" / f"seed-{seed}"))
        if outcome["status"] != "done":
            raise RuntimeError(f"run seed-{seed} failed: {outcome['error']}")
        seconds.append(time.perf_counter() - t)
        print(f"  seed {seed}: {seconds[-1]:.1f} s", file=sys.stderr)
    return {"wall": time.perf_counter() - t0, "run_seconds": seconds}


def as_a_sweep(cells: int, runs: int, workers: int, out: Path) -> dict[str, Any]:
    t0 = time.perf_counter()
    code = sweep.main(["--cells", str(cells), "--replicates", str(runs), "--workers", str(workers), "--quiet",
                       "--out", str(out)])
    wall = time.perf_counter() - t0
    if code != 0:
        raise RuntimeError(f"the sweep exited with {code}")
    with (out / sweep.SUMMARY_FILE).open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    return {"wall": wall, "task_seconds": [float(r["task_seconds"]) for r in rows]}


def wait_for(condition: Any, what: str = "a condition", timeout: float = 600.0, every: float = 0.05) -> Any:
    """The first true value of ``condition()``, asked every ``every`` seconds.

    Raises:
        TimeoutError: none within ``timeout`` seconds (naming ``what``).
    """
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = condition()
        if value:
            return value
        time.sleep(every)
    raise TimeoutError(f"timed out waiting for {what}")


def killed_worker(cells: int, runs: int, out: Path) -> dict[str, Any]:
    out.mkdir(parents=True, exist_ok=True)
    processes: list[subprocess.Popen[bytes]] = []

    def start(*argv: str) -> subprocess.Popen[bytes]:
        process = subprocess.Popen([sys.executable, "-m", *argv], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        processes.append(process)
        return process

    file = out / "scheduler.json"
    try:
        start("distributed.cli.dask_scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard",
              "--dashboard-address", ":0", "--scheduler-file", str(file))
        wait_for(lambda: tasks.read_json(file), "the scheduler")
        workers = {start("distributed.cli.dask_worker", "--scheduler-file", str(file), "--nthreads", "1", "--no-nanny",
                         "--no-dashboard").pid for _ in range(2)}
        folder = out / "sweep"
        t0 = time.perf_counter()
        client = start("qpcontact", "sweep", "--cells", str(cells), "--replicates", str(runs), "--scheduler", str(file),
                       "--snapshot-every", "20", "--quiet", "--out", str(folder))

        def victim() -> tuple[str, int, int] | None:
            for seed in range(1, runs + 1):
                run = folder / "runs" / f"seed-{seed}"
                started = tasks.attempts_of(run)
                latest = RunFolder(run).latest_snapshot() if started else None
                if latest is not None and not (run / tasks.RESULT_FILE).exists() and started[-1]["pid"] in workers:
                    rows = RunFolder(run).read_history_rows()
                    return f"seed-{seed}", started[-1]["pid"], int(rows[-1]["step"]) if rows else -1
            return None

        name, pid, reached = wait_for(victim, "a run past a snapshot")
        time.sleep(2.0)  # in the middle of the run, past its snapshot
        reached = max(reached, int(RunFolder(folder / "runs" / name).read_history_rows()[-1]["step"]))
        os.kill(pid, signal.SIGKILL)
        code = client.wait(3600)
        wall = time.perf_counter() - t0
    finally:
        for process in reversed(processes):
            if process.poll() is None:
                process.kill()
            process.wait()
    with (folder / sweep.SUMMARY_FILE).open(newline="") as fh:
        rows = list(csv.DictReader(fh))
    starts = {f"seed-{seed}": tasks.attempts_of(folder / "runs" / f"seed-{seed}") for seed in range(1, runs + 1)}
    return {"exit_status": code, "wall": wall, "killed_run": name, "killed_at_step": reached,
            "continued_from_step": starts[name][-1]["from_step"] if len(starts[name]) > 1 else None,
            "runs_lost": sum(r["status"] != "done" for r in rows),
            "runs_started_twice": sorted(n for n, s in starts.items() if len(s) > 1)}


def report(cells: int, runs: int, workers: int, a: dict[str, Any], b: dict[str, Any], c: dict[str, Any]) -> str:
    load = os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3
    overhead = (workers * b["wall"] - sum(b["task_seconds"])) / runs
    return "\n".join([
        f"Measured {datetime.now(UTC):%Y-%m-%d %H:%M} UTC on {platform.machine()} ({os.cpu_count()} cores), Python "
        f"{platform.python_version()}; load average at the end {load[0]:.2f} / {load[1]:.2f} / {load[2]:.2f} (1 / 5 / 15 "
        f"min); {runs} 2D runs of {cells} cells (seeds 1-{runs}, the defaults of qpcontact simulate otherwise).",
        "",
        "| | wall [s] | per run [s] |",
        "|---|---:|---:|",
        f"| one after the other, in one process | {a['wall']:.1f} | {a['wall'] / runs:.1f} (median "
        f"{sorted(a['run_seconds'])[runs // 2]:.1f}) |",
        f"| qpcontact sweep, LocalCluster of {workers} workers (start included) | {b['wall']:.1f} | task median "
        f"{sorted(b['task_seconds'])[runs // 2]:.1f} |",
        "",
        f"Speed-up **{a['wall'] / b['wall']:.2f}×** on {workers} workers; overhead per task (workers × wall − Σ task "
        f"time) / runs = **{overhead:.1f} s**; a task's own time is {sum(b['task_seconds']) / sum(a['run_seconds']):.2f}× "
        "its time alone.",
        "",
        f"Killed worker ({c.get('runs', '?')} runs on a scheduler and 2 workers started as separate processes, one worker "
        f"killed with SIGKILL in the middle of run {c['killed_run']} at step {c['killed_at_step']}): exit status "
        f"{c['exit_status']}, **runs lost: {c['runs_lost']}**, runs started twice: "
        f"{', '.join(c['runs_started_twice']) or 'none'} (continued from step {c['continued_from_step']}, its latest "
        f"snapshot), wall {c['wall']:.1f} s.",
    ])


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--cells", type=positive_int, default=2000, help="cells per run (default: 2000)")
    parser.add_argument("--runs", type=positive_int, default=8, help="runs (seeds 1..N; default: 8)")
    parser.add_argument("--workers", type=positive_int, default=2, help="workers of the local cluster (default: 2)")
    parser.add_argument("--kill-runs", type=positive_int, default=4, help="runs of the killed-worker sweep (default: 4)")
    parser.add_argument("--out", type=Path, default=Path("sweep-benchmark-out"), metavar="FOLDER",
                        help="output folder (default: ./sweep-benchmark-out)")
    parser.add_argument("--overwrite", action="store_true", help="replace an earlier measurement in --out")


def run_command(args: argparse.Namespace) -> int:
    out = prepare_folder(args.out, ("sweep_benchmark.json", "sweep_benchmark.md"), overwrite=args.overwrite)
    for part in ("sequential", "sweep", "killed"):
        if (out / part).exists() and any((out / part).iterdir()) and not args.overwrite:
            raise OutputFolderError(f"{out / part} is not empty; pass --overwrite or choose another folder")
    if args.overwrite:
        import shutil

        for part in ("sequential", "sweep", "killed"):
            shutil.rmtree(out / part, ignore_errors=True)
    print("one after the other", file=sys.stderr)
    a = one_after_the_other(args.cells, args.runs, out / "sequential")
    print("as a sweep", file=sys.stderr)
    b = as_a_sweep(args.cells, args.runs, args.workers, out / "sweep")
    print("killed worker", file=sys.stderr)
    c = {**killed_worker(args.cells, args.kill_runs, out / "killed"), "runs": args.kill_runs}
    text = report(args.cells, args.runs, args.workers, a, b, c)
    write_text(out / "sweep_benchmark.json", json.dumps({"cells": args.cells, "runs": args.runs, "workers": args.workers,
                                                           "one_after_the_other": a, "sweep": b, "killed": c},
                                                          indent=1) + "\n")
    write_text(out / "sweep_benchmark.md", text + "\n")
    print(text)
    return 0


def main(argv: list[str] | None = None) -> int:
    return run_standalone("python benchmarks/sweep_benchmark.py", add_arguments, run_command, argv,
                          description=__doc__.split("\n\n")[0] if __doc__ else None)


if __name__ == "__main__":
    sys.exit(main())
