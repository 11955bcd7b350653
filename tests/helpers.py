"""Shared scene builders and checks for the tests (small, seeded, fast)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import qpcontact as qc
from qpcontact.assembly import ContactSystem
from qpcontact.geometry import inertia_times


def random_scene(
    seed: int,
    n_cells: int = 30,
    *,
    planar: bool = False,
    box: float = 5.0,
    converging: float = 1.0,
    mass_spread: float = 4.0,
    growing: bool = True,
    unit_length: float = 1.0,
    unit_mass: float = 1.0,
) -> qc.Cells:
    """Rods of random length and orientation in a box, moving towards the box centre (so most
    contacts approach), with random extra momenta and growth. ``unit_length``/``unit_mass``
    express the same scene in other units (time unit unchanged)."""
    rng = np.random.default_rng(seed)
    n = n_cells
    centres = rng.uniform(0.0, box, (n, 3))
    axes = rng.normal(size=(n, 3))
    if planar:
        centres[:, 2] = 0.0
        axes[:, 2] = 0.0
    axes /= np.linalg.norm(axes, axis=1)[:, None]
    lengths = rng.uniform(0.5, 2.5, n)
    radii = rng.uniform(0.3, 0.6, n)
    masses = rng.uniform(1.0, mass_spread, n)
    velocity = -converging * (centres - centres.mean(axis=0)) + rng.normal(0, 0.3, (n, 3))
    omega = rng.normal(0, 0.3, (n, 3))
    if planar:
        velocity[:, 2] = 0.0
        omega[:, :2] = 0.0
    momenta = masses[:, None] * velocity
    angular = inertia_times(axes, lengths, radii, masses, omega)  # L = I ω
    growth = (masses * rng.uniform(0.0, 0.5, n)) if growing else np.zeros(n)
    return qc.Cells(
        centres * unit_length, axes, lengths * unit_length, radii * unit_length,
        masses=masses * unit_mass, growth_inertia=(masses if growing else np.full(n, np.inf)) * unit_mass,
        momenta=momenta * unit_mass * unit_length, angular_momenta=angular * unit_mass * unit_length**2,
        growth_momenta=growth * unit_mass * unit_length,
    )


def pulling_scene(n_cells: int = 30, seeds: int = 50) -> qc.Cells:
    """The first :func:`random_scene` whose plain solve pulls at some contact (a contact impulse
    below −1e-6 of the largest), so that the complementarity answer differs from it; fails the
    test if none of ``seeds`` seeds gives one."""
    for seed in range(seeds):
        cells = random_scene(seed, n_cells=n_cells)
        linear = qc.resolve(cells, solver="linear")
        if np.any(linear.contact_impulses < -1e-6 * np.max(np.abs(linear.contact_impulses))):
            return cells
    pytest.fail(f"no scene among {seeds} seeds where the plain solve pulls")


def system_of(cells: qc.Cells, **colliding_options) -> ContactSystem:
    """The assembled system of the colliding contacts of ``cells``."""
    active, b = qc.colliding(qc.find_contacts(cells), **colliding_options)
    return qc.build_system(cells, active, b)


def assert_kkt(system: ContactSystem, y: np.ndarray, lam: np.ndarray, tolerance: float) -> None:
    """The KKT conditions of the complementarity QP ``min ½‖ỹ‖², B̃ỹ ≥ b̃`` hold to
    ``tolerance`` (relative to the largest contact impulse): ``ỹ = B̃ᵀλ̃`` (stationarity),
    ``B̃ỹ ≥ b̃`` (primal feasibility), ``λ̃ ≥ 0`` (dual feasibility) and ``λ̃ₖ(B̃ỹ − b̃)ₖ = 0``
    (complementary slackness). They certify the unique optimum whatever solver produced it."""
    scale = max(float(np.abs(lam).max(initial=0.0)), 1.0)
    slack = system.matrix @ y - system.rhs
    assert np.linalg.norm(y - system.matrix.T @ lam) <= tolerance * max(np.linalg.norm(y), 1.0), "stationarity"
    assert slack.min(initial=0.0) >= -tolerance, f"penetration {-slack.min():.3g}"
    assert lam.min(initial=0.0) >= -tolerance * scale, f"pulling impulse {lam.min():.3g}"
    assert np.max(np.abs(lam * slack), initial=0.0) <= tolerance * scale, "complementary slackness"


def world_operators(cells: qc.Cells, contacts: qc.Contacts) -> tuple[np.ndarray, np.ndarray]:
    """Dense ``J`` (K × 7N) and ``W`` (7N × 7N) in the world frame, straight from model.md's
    formulas (no slot basis, no reduction): J rows ``[nᵀ, (r × n)ᵀ, (s/l)(â·n)]`` per side (minus
    for side b), ``W`` block-diagonal with ``1/m``, the axisymmetric ``I⁻¹`` and ``1/G``; fixed
    cells and non-growing lengths get zeros. ``M = J W``."""
    n_cells, k = cells.n, len(contacts)
    J = np.zeros((k, 7 * n_cells))
    for side, sign in (("a", 1.0), ("b", -1.0)):
        cell = getattr(contacts, f"cell_{side}")
        r = getattr(contacts, f"offset_{side}")
        stretch = getattr(contacts, f"stretch_{side}")
        for row in range(k):  # reference only: a loop over the contacts of a small scene
            c = cell[row]
            if c < 0:
                continue
            normal = contacts.normal[row]
            J[row, 7 * c:7 * c + 3] += sign * normal
            J[row, 7 * c + 3:7 * c + 6] += sign * np.cross(r[row], normal)
            J[row, 7 * c + 6] += sign * stretch[row] * (cells.axes[c] @ normal)
    W = np.zeros((7 * n_cells, 7 * n_cells))
    for c in range(n_cells):
        W[7 * c:7 * c + 3, 7 * c:7 * c + 3] = np.eye(3) / cells.masses[c]
        W[7 * c + 3:7 * c + 6, 7 * c + 3:7 * c + 6] = cells.subset([c]).apply_inverse_inertia(np.eye(3))
        W[7 * c + 6, 7 * c + 6] = 1.0 / cells.growth_inertia[c] if np.isfinite(cells.masses[c]) else 0.0
    return J, W


def interrupt_on_call(monkeypatch: pytest.MonkeyPatch, module: object, name: str, call: int) -> None:
    """Make ``module.name`` raise ``KeyboardInterrupt`` (as Ctrl-C would) on its ``call``-th call;
    the calls before it run as they are."""
    real, calls = getattr(module, name), []

    def interrupted(*args, **kwargs):
        calls.append(args)
        if len(calls) == call:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(module, name, interrupted)


def gate_model(folder: Path, step: int, *, stop_flag: Path | None = None, skip_first: bool = False) -> Path:
    """A model hook file (``--hook``) whose hook holds a run at a known step, so that a test can
    signal or kill it there instead of racing a signal against the machine's speed.

    At step ``step`` the hook writes ``folder/"held"`` (with the process id) and waits: until
    ``stop_flag`` exists (a sweep's stop flag; then it returns and the run goes on), or for ever
    (the test signals or kills the process). It holds one run once: later runs, and the run
    resumed, pass (``held`` exists). ``skip_first``: the first run to reach the step passes
    (``folder/"passed"``), the next one is held."""
    path = folder / "gate.py"
    path.write_text(f'''"""A test's gate (tests/helpers.py::gate_model)."""
import os
import pathlib
import time

FOLDER = pathlib.Path({str(folder)!r})
STOP = {None if stop_flag is None else str(stop_flag)!r}


def hook(colony, step):
    if step != {step} or (FOLDER / "held").exists():
        return None
    if {skip_first!r} and not (FOLDER / "passed").exists():
        (FOLDER / "passed").write_text(str(os.getpid()))
        return None
    (FOLDER / "held").write_text(str(os.getpid()))
    while STOP is None or not pathlib.Path(STOP).exists():
        time.sleep(0.05)
    return None
''')
    return path


def wait_for(condition, what: str, timeout: float):
    """The first true value of ``condition()``, polled every 0.05 s (a wait for an event, not a
    guess of how long something takes); ``TimeoutError`` naming ``what`` after ``timeout`` s."""
    import time

    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = condition()
        if value:
            return value
        time.sleep(0.05)
    raise TimeoutError(f"timed out waiting for {what}")


def default_signals() -> None:
    """``preexec_fn`` of a child that a test signals: SIGINT and SIGTERM at their defaults, as in a
    terminal. A child inherits an *ignored* SIGINT (something earlier in the test process, such as
    a multiprocessing or Dask helper, may have ignored it) and Python then installs no
    KeyboardInterrupt handler: the child would not hear Ctrl-C at all."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_DFL)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
