"""One colony over two and four MPI processes (docs/distributed.md): runs under ``mpiexec -n 2``
and ``-n 4`` (oversubscribed where the machine has fewer cores), checked against the same runs in
one process.

They need the distributed stack (``scripts/install-mpi VENV``: petsc4py, mpi4py, mpiexec). Where it
is missing they are skipped, except under ``QPCONTACT_REQUIRE_MPI=1`` (``.ci/run`` sets it), where a
missing stack fails them."""

from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from qpcontact import load_colony
from qpcontact.io.runs import latest_snapshot

HERE = Path(__file__).parent
STACK = all(importlib.util.find_spec(name) is not None for name in ("petsc4py", "mpi4py")) \
    and shutil.which("mpiexec") is not None
if not STACK:
    if os.environ.get("QPCONTACT_REQUIRE_MPI") == "1":
        raise RuntimeError("QPCONTACT_REQUIRE_MPI=1 but petsc4py, mpi4py or mpiexec is missing (scripts/install-mpi)")
    pytest.skip("needs the distributed stack: scripts/install-mpi VENV (docs/distributed.md)", allow_module_level=True)

#: The positions of two runs from the same state may differ by this much (of a diameter): the
#: step's accuracy contract (its solver tolerance 10⁻⁴ gives ~3·10⁻⁴ of a diameter).
CONTRACT = 1e-3


def environment() -> dict[str, str]:
    env = dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", OMPI_MCA_rmaps_base_oversubscribe="1")
    if os.geteuid() == 0:  # Open MPI refuses root unless told (CI machines run as root)
        env.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    return env


def simulate(*flags: str, processes: int = 1, check: bool = True) -> subprocess.CompletedProcess[str]:
    """``qpcontact simulate FLAGS`` in one process or under ``mpiexec -n processes``."""
    command = [sys.executable, "-m", "qpcontact", "simulate", "--quiet", *flags]
    if processes > 1:
        command = ["mpiexec", "-n", str(processes), *command]
    done = subprocess.run(command, capture_output=True, text=True, env=environment(), timeout=600)
    if check:
        assert done.returncode in (0, 3), done.stderr[-3000:]
    return done


@pytest.fixture(scope="module")
def grown(tmp_path_factory) -> dict[int, Path]:
    """A grown 2D colony (about 400 cells) and a 3D biofilm (about 150), from one process."""
    out = {}
    for dimensions, cells in ((2, 400), (3, 150)):
        folder = tmp_path_factory.mktemp(f"grown{dimensions}d")
        simulate("--dimensions", str(dimensions), "--cells", str(cells), "--out", str(folder))
        out[dimensions] = latest_snapshot(folder)
    return out


def steps_from(state: Path, folder: Path, steps: int, processes: int) -> subprocess.CompletedProcess[str]:
    """``steps`` more steps of the run that saved ``state``, into ``folder``."""
    start = int(state.stem.split("_")[1])
    return simulate("--start", str(state), "--cells", "100000", "--max-steps", str(start + steps), "--out",
                    str(folder), processes=processes)


@pytest.mark.parametrize("dimensions", [2, 3])
def test_two_processes_take_the_steps_of_one(grown, tmp_path, dimensions):
    """From the same saved state, steps on two processes and in one give the same cells and ids,
    end positions within the step's accuracy contract, and every state within the overlap
    tolerance."""
    one = steps_from(grown[dimensions], tmp_path / "one", 6, processes=1)
    two = steps_from(grown[dimensions], tmp_path / "two", 6, processes=2)
    assert "running on 2 MPI processes" in two.stderr and "ipm-petsc" in two.stdout and "on 2 MPI processes" in two.stdout
    a, _ = load_colony(latest_snapshot(tmp_path / "one"))
    b, _ = load_colony(latest_snapshot(tmp_path / "two"))
    assert a.cells.n == b.cells.n and np.array_equal(a.ids, b.ids) and np.array_equal(a.parent_ids, b.parent_ids)
    diameter = 2.0 * float(np.median(a.cells.radii))
    tips = lambda c: np.concatenate([c.centers + 0.5 * c.lengths[:, None] * c.axes,  # noqa: E731
                                     c.centers - 0.5 * c.lengths[:, None] * c.axes])
    assert float(np.max(np.abs(tips(a.cells) - tips(b.cells)))) / diameter <= CONTRACT
    for folder in (tmp_path / "one", tmp_path / "two"):
        history = np.genfromtxt(folder / "history.csv", delimiter=",", names=True)
        assert history["max_overlap"].size == 6 and np.all(history["max_overlap"] <= 0.01)
    assert one.returncode == two.returncode == 3  # stopped by --max-steps, said


#: How far two runs over MPI processes from the same state may part in a few steps [diameters]:
#: MUMPS hands the rows of its large fronts to the processes by their load at run time, so the
#: order of its sums, and the last bits, change from run to run; the next interior-point solve,
#: whose iterates start near their bounds, can amplify that to what one solve at its tolerance
#: leaves open. Measured on the colony these tests grow: 10⁻¹¹ or 2.15·10⁻⁶ over three steps, run
#: by run, with either trust setting (docs/model-notes.md, "Trust rounds"). A hundredth of the
#: step's contract (:data:`CONTRACT`); in one process a resumed run is the same bit for bit
#: (tests/io/test_runs.py).
ROUNDING = 1e-5


def test_a_distributed_run_resumes_to_rounding_and_writes_one_snapshot(grown, tmp_path):
    """A run on two processes stopped and resumed follows the uninterrupted one to rounding (not
    bit for bit: :data:`ROUNDING`); its snapshots are single files that load_colony reads, with
    the cells' ids."""
    straight = steps_from(grown[2], tmp_path / "straight", 6, processes=2)
    assert straight.returncode == 3
    steps_from(grown[2], tmp_path / "parts", 3, processes=2)
    start = int(grown[2].stem.split("_")[1])
    simulate("--resume", "--max-steps", str(start + 6), "--cells", "100000", "--out", str(tmp_path / "parts"),
             processes=2)
    a, _ = load_colony(latest_snapshot(tmp_path / "straight"))
    b, _ = load_colony(latest_snapshot(tmp_path / "parts"))
    assert np.array_equal(a.ids, b.ids)
    diameter = 2.0 * float(np.median(a.cells.radii))
    assert float(np.max(np.abs(a.cells.centers - b.cells.centers))) / diameter <= ROUNDING
    assert float(np.max(np.abs(a.cells.axes - b.cells.axes))) <= ROUNDING
    assert sorted(p.name for p in (tmp_path / "parts" / "snapshots").iterdir())[-1] == latest_snapshot(
        tmp_path / "parts").name
    # and one process continues what two wrote (the solver back to ipm, said)
    done = simulate("--resume", "--max-steps", str(start + 8), "--cells", "100000", "--position-solver", "ipm",
                    "--out", str(tmp_path / "parts"))
    assert done.returncode == 3 and "position_solver: ipm-petsc -> ipm" in done.stderr
    assert len((tmp_path / "parts" / "history.csv").read_text().splitlines()) - 1 == 8


def tips(cells) -> np.ndarray:
    """The two ends of every cell's axis."""
    half = 0.5 * cells.lengths[:, None] * cells.axes
    return np.concatenate([cells.centers + half, cells.centers - half])


def test_four_processes_grow_the_colony_of_one_to_rounding(grown, tmp_path):
    """Every phase divided among four processes (the rows each assembles, the slabs that own the
    cells, the solve): from the same state, the same cells and ids as one process, the tips
    within :data:`ROUNDING` of a diameter."""
    one = steps_from(grown[2], tmp_path / "one", 3, processes=1)
    four = steps_from(grown[2], tmp_path / "four", 3, processes=4)
    assert one.returncode == four.returncode == 3 and "running on 4 MPI processes" in four.stderr
    a, _ = load_colony(latest_snapshot(tmp_path / "one"))
    b, _ = load_colony(latest_snapshot(tmp_path / "four"))
    assert a.cells.n == b.cells.n and np.array_equal(a.ids, b.ids) and np.array_equal(a.parent_ids, b.parent_ids)
    diameter = 2.0 * float(np.median(a.cells.radii))
    assert float(np.max(np.abs(tips(a.cells) - tips(b.cells)))) / diameter <= ROUNDING


def test_a_run_saved_on_four_processes_continues_on_two_and_on_one(grown, tmp_path):
    """A run on four processes, resumed on two and then in one process, follows the run of one
    process from the same state to rounding."""
    start = int(grown[2].stem.split("_")[1])
    straight = steps_from(grown[2], tmp_path / "straight", 4, processes=1)
    assert straight.returncode == 3
    steps_from(grown[2], tmp_path / "parts", 2, processes=4)
    two = simulate("--resume", "--max-steps", str(start + 3), "--cells", "100000", "--out", str(tmp_path / "parts"),
                   processes=2)
    assert two.returncode == 3 and "on 2 MPI processes" in two.stdout
    done = simulate("--resume", "--max-steps", str(start + 4), "--cells", "100000", "--position-solver", "ipm",
                    "--out", str(tmp_path / "parts"))
    assert done.returncode == 3 and "position_solver: ipm-petsc -> ipm" in done.stderr
    assert len((tmp_path / "parts" / "history.csv").read_text().splitlines()) - 1 == 4
    a, _ = load_colony(latest_snapshot(tmp_path / "straight"))
    b, _ = load_colony(latest_snapshot(tmp_path / "parts"))
    assert np.array_equal(a.ids, b.ids)
    diameter = 2.0 * float(np.median(a.cells.radii))
    assert float(np.max(np.abs(tips(a.cells) - tips(b.cells)))) / diameter <= ROUNDING


@pytest.mark.parametrize(("flags", "message"), [(("--position-solver", "clarabel"), "every process"),
                                                (("--step", "velocity"), "--step position"),
                                                (("--position-second-order", "true"), "first-order linearizations")])
def test_what_two_processes_cannot_do_is_refused_before_the_run(tmp_path, flags, message):
    done = simulate("--cells", "20", "--out", str(tmp_path / "run"), *flags, processes=2, check=False)
    assert done.returncode == 2 and message in done.stderr
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("processes", [2, 4])
def test_the_distributed_interior_point_gives_the_answer_of_one_process(tmp_path, processes):
    """The QPs of grown colonies' steps, with bounds, solved on two and four processes (METIS's
    partition, and slabs of owners given by the caller): the same answer as ipm's in one process
    (each process holds the whole answer), with MUMPS's analysis on every process (two) or on one
    (four)."""
    # On two processes MUMPS is asked for its analysis on every process (PT-Scotch's ordering).
    parallel = {"PETSC_OPTIONS": "-mat_mumps_icntl_28 2 -mat_mumps_icntl_29 1"} if processes == 2 else {}
    done = subprocess.run(["mpiexec", "-n", str(processes), sys.executable, str(HERE / "solve_check.py")],
                          capture_output=True, text=True, env={**environment(), **parallel}, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    lines = [line.split() for line in done.stdout.splitlines() if line.startswith("checked")]
    assert len(lines) >= 6
    for _, count, _how, status, difference in lines:
        assert count == str(processes) and status == "converged" and float(difference) < 1e-6
    assert {line[2] for line in lines} == {"metis", "owners"}
    # Asked for, the PT-Scotch MUMPS was loaded and MUMPS's analysis ran on every process (CI
    # installs it; elsewhere MUMPS refuses it, and the solves above fail); by default neither:
    # PETSc's own MUMPS, the analysis on one process.
    analysis = [line.split() for line in done.stdout.splitlines() if line.startswith("analysis")]
    assert analysis and analysis[0][2] == analysis[0][4] == ("1" if parallel else "0")


def test_a_users_own_loop_runs_over_two_processes(tmp_path):
    """examples/mpi_loop.py: a timestep loop of the user's own, with position_step, under mpiexec."""
    example = HERE.parents[1] / "examples" / "mpi_loop.py"
    done = subprocess.run(["mpiexec", "-n", "2", sys.executable, str(example), "--steps", "5"], capture_output=True,
                          text=True, env=environment(), timeout=600, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "2 processes" in done.stdout and done.stdout.count("step ") == 5
    assert "every process holds the same cells: True" in done.stdout


def test_ctrl_c_of_mpiexec_saves_the_state_reached_on_every_process(tmp_path):
    """mpiexec turns Ctrl-C into SIGTERM for its processes: they end the step they are in (none
    is left waiting in a solve), process 0 saves the state reached and says how to resume; the
    resumed run goes on from it."""
    import signal
    import time

    folder = tmp_path / "run"
    command = ["mpiexec", "-n", "2", sys.executable, "-m", "qpcontact", "simulate", "--quiet", "--cells", "5000",
               "--out", str(folder)]
    run = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=environment())
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and (not (folder / "history.csv").is_file()
                                           or len((folder / "history.csv").read_text().splitlines()) < 30):
        time.sleep(0.2)
    run.send_signal(signal.SIGINT)
    _, stderr = run.communicate(timeout=120)
    assert "stopped by signal" in stderr and "--resume" in stderr, stderr[-3000:]
    rows = len((folder / "history.csv").read_text().splitlines()) - 1
    state = latest_snapshot(folder)
    assert int(state.stem.split("_")[1]) == rows  # the last step taken is saved
    done = simulate("--resume", "--max-steps", str(rows + 2), "--out", str(folder), processes=2)
    assert done.returncode == 3
    assert len((folder / "history.csv").read_text().splitlines()) - 1 == rows + 2


def test_the_scaling_benchmark_measures_and_compares(grown, tmp_path):
    """benchmarks/mpi_scaling.py on a small state: a line per process count with every process's
    numbers, the agreement of 2 processes with one, and the table written where it is told."""
    states = tmp_path / "states"
    states.mkdir()
    shutil.copy(grown[2], states / "2d-small.npz")
    out = tmp_path / "measured"
    done = subprocess.run([sys.executable, str(HERE.parents[1] / "benchmarks" / "mpi_scaling.py"), "--states",
                           str(states), "--names", "2d-small", "--steps", "1", "--processes", "1,2", "--folder",
                           str(out), "--profile"], capture_output=True, text=True, env=environment(), timeout=600, cwd=tmp_path)
    assert done.returncode == 0, done.stderr[-3000:]
    text = (out / "mpi-scaling.md").read_text()
    # 3 runs, their 3 lines of counts, 1 agreement
    assert sum(line.startswith("| 2d-small |") for line in text.splitlines()) == 3 + 3 + 1
    agreement = [line for line in text.splitlines() if line.startswith("| 2d-small | 2 |")]
    cells = [c.strip() for c in agreement[0].strip("|").split("|")]
    assert cells[3] == "yes" and float(cells[4]) <= ROUNDING
    import json

    numbers = json.loads((out / "mpi-scaling.json").read_text())["per_process"]
    two = numbers["2d-small, 2 MPI processes, ipm-petsc"]
    assert len(two["cpu"]) == 2 and all(c > 0 for c in two["cpu"]) and all(f > 0 for f in two["flops"])
    assert all(b > 0 for b in two["sent"]) and all(m > 0 for m in two["memory"])
    # the counts the model is built from: every process solved, multiplied and took part in collectives,
    # and its own work is what is left of its CPU seconds
    assert all(n > 0 for key in ("solves", "products", "collectives", "problems", "entry_solves", "owned_iterations",
                                                                           "normal_cpu")
               for n in two[key])
    assert all(0 < own < cpu for own, cpu in zip(two["own"], two["cpu"], strict=True))
    assert two["factorizations"][0] >= two["problems"][0]
    assert "tottime" in (out / "profile-2d-small-ipm-petsc-2.txt").read_text()  # process 0's profile
