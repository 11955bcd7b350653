"""The position-level step (qpcontact.timestep.position): the end positions are free of overlap
(decided by an independent brute-force capsule distance), analytic cases come out exact, overlap
present at the start shrinks at the set speed, turning and shrinking are bounded, and a step that
does not converge is reported and not applied."""

import numpy as np
import pytest

import qpcontact as qc
from qpcontact.colony import Colony, divide, grow_position, growth_time_step
from qpcontact.errors import InvalidArgumentError, StepFailedError
from qpcontact.geometry import substrate
from qpcontact.studies import scenes
from qpcontact.timestep.position import PositionSettings, move, position_step


def segment_distance(p0, p1, q0, q1, samples=4001):
    """Distance between two segments by brute force: the exact distance from every sample of one
    segment to the other (a convex function of the sample's parameter: the dense samples bracket
    the minimum to (length/samples)² · curvature)."""
    s = np.linspace(0.0, 1.0, samples)[:, None]
    points = p0 + s * (p1 - p0)
    d = q1 - q0
    t = np.clip(((points - q0) @ d) / max(d @ d, 1e-300), 0.0, 1.0)
    return float(np.min(np.linalg.norm(points - (q0 + t[:, None] * d), axis=1)))


def brute_force_overlap(cells):
    """Largest overlap (fraction of ρ_a + ρ_b) over every pair of cells, by brute force."""
    worst = 0.0
    half = 0.5 * cells.lengths[:, None] * cells.axes
    ends = list(zip(cells.centers - half, cells.centers + half, strict=True))
    for i in range(cells.n):
        for j in range(i + 1, cells.n):
            gap = np.linalg.norm(cells.centers[i] - cells.centers[j]) - 0.5 * (cells.lengths[i] + cells.lengths[j])
            if gap > cells.radii[i] + cells.radii[j]:
                continue
            d = segment_distance(*ends[i], *ends[j])
            worst = max(worst, (cells.radii[i] + cells.radii[j] - d) / (cells.radii[i] + cells.radii[j]))
    return worst


LN2 = float(np.log(2.0))


def growing(cells, rate=LN2, dt=0.05):
    """The drive that grows every cell by ``e^{rate·dt} − 1`` of its length over ``dt``."""
    drive = np.zeros((cells.n, 7))
    drive[:, 6] = cells.growth_inertia * cells.lengths * np.expm1(rate * dt) / dt
    return drive


def rods(centers, axes, lengths, growth_inertia=1000.0, radius=0.5):
    centers, axes = np.asarray(centers, float), np.asarray(axes, float)
    lengths = np.broadcast_to(np.asarray(lengths, float), (len(centers),))
    masses = np.pi * radius**2 * (lengths + 4 / 3 * radius)
    return qc.Cells(centers=centers, axes=axes, lengths=lengths, radii=radius, masses=masses,
                    growth_inertia=growth_inertia * masses)


def test_two_rods_end_to_end_are_pushed_apart_by_the_growth():
    """Two equal collinear rods touching end to end, both growing by Δl: the only overlap-free
    answer of least kinetic energy moves each centre by Δl/2 outwards (growth is 1000 times
    harder to compress than translation), exactly, not only to first order."""
    cells = rods([[-2.5, 0, 0], [2.5, 0, 0]], [[1, 0, 0], [1, 0, 0]], 4.0)
    dt = 0.05
    drive = growing(cells, dt=dt)
    out = position_step(cells, dt, drive=drive, settings=PositionSettings(aim=0.0))
    assert out.converged
    grown = 4.0 * np.expm1(np.log(2.0) * dt)
    # Compressing growth costs G = 1000 m: the push shortens each rod by a thousandth-ish of Δl.
    assert np.allclose(out.cells.lengths, 4.0 + grown, rtol=0, atol=2e-3 * grown)
    separation = out.cells.centers[1, 0] - out.cells.centers[0, 0] - out.cells.lengths.mean() - 1.0
    assert -0.01 <= separation <= 1e-6
    assert np.allclose(out.cells.centers[:, 1:], 0.0) and np.allclose(out.cells.axes, [[1, 0, 0]] * 2)
    assert np.isclose(out.cells.centers[0, 0], -out.cells.centers[1, 0])
    # The linearizations aim at a gap of aim: the rods end that far apart (0 leaves them
    # touching, above; the default is 0.001).
    aimed = position_step(cells, dt, drive=drive, settings=PositionSettings(aim=0.03))
    gap = aimed.cells.centers[1, 0] - aimed.cells.centers[0, 0] - aimed.cells.lengths.mean() - 1.0
    assert PositionSettings().aim == 0.001 and gap == pytest.approx(0.03, abs=1e-3)


def test_a_rod_sinking_onto_a_plane_comes_to_rest_on_it():
    cells = rods([[0, 0, 0.52]], [[1, 0, 0]], 3.0)
    drive = np.zeros((1, 7))
    drive[0, 2] = -2.0 * cells.masses[0]  # driven down by 2 µm per unit time
    out = position_step(cells, 0.1, drive=drive, planes=[substrate()])
    assert out.converged
    # It rests within the tolerance below, and at most the aim above, the height of its radius.
    settings = PositionSettings()
    assert 0.5 - settings.overlap_tolerance <= out.cells.centers[0, 2] <= 0.5 + settings.aim * 1.0 + 1e-9


@pytest.mark.parametrize("seed", [0, 1])
def test_end_positions_are_free_of_overlap_by_brute_force(seed):
    """A 2D colony snapshot (overlapping neighbours removed first), grown one large step: the
    brute-force overlap of the end positions is within the tolerance."""
    cells = scenes.colony_2d(150, seed)
    settled = position_step(cells, 0.05, drive=np.zeros((cells.n, 7)), settings=PositionSettings(relaxation=1.0))
    assert settled.converged
    start = settled.cells.replace(momenta=0.0, angular_momenta=0.0, growth_momenta=0.0)
    out = position_step(start, 0.05, drive=growing(start))
    assert out.converged
    assert out.max_overlap <= 0.01 + 1e-9
    assert brute_force_overlap(out.cells) <= 0.01 + 1e-6


def test_impulses_only_push_and_the_velocity_level_answer_agrees_for_a_small_step():
    """For a small step the position-level impulses approach the velocity-level ones with a
    speculative margin (first order in dt)."""
    cells = rods([[0, 0, 0], [0.5, 1.0, 0], [5.0, 0.1, 0]], [[1, 0, 0], [1, 0, 0], [1, 0, 0]], 4.0)
    dt = 1e-3
    drive = growing(cells, dt=dt)
    out = position_step(cells, dt, drive=drive, settings=PositionSettings(aim=0.0))
    assert out.converged
    assert np.all(out.contact_impulses >= 0)
    velocity = qc.step(cells, dt, drive=drive, margin=0.5, solver="clarabel", tolerance=1e-10)
    moved_position = out.cells.centers - cells.centers
    moved_velocity = velocity.cells.centers - cells.centers
    assert np.allclose(moved_position, moved_velocity, atol=0.02 * np.abs(moved_velocity).max())


def test_overlap_present_at_the_start_shrinks_at_the_relaxation_speed_and_nothing_spins():
    """A state with overlaps up to 0.15 diameters (another simulator's): in one step no overlap
    grows, each shrinks by up to the relaxation (0.05 diameters) and no cell turns its tips by
    more than the turn limit."""
    rng = np.random.default_rng(4)
    cells = scenes.colony_2d(200, 4)
    squeezed = cells.replace(centers=cells.centers * 0.93 + rng.normal(0, 0.02, cells.centers.shape) * [1, 1, 0])
    before = brute_force_overlap(squeezed)
    assert 0.1 < before < 0.6
    settings = PositionSettings(relaxation=0.05, turn_limit=0.2)
    out = position_step(squeezed, 0.05, drive=np.zeros((cells.n, 7)), settings=settings)
    assert out.converged
    assert out.max_overlap <= before
    assert out.max_overlap <= before - 0.05 + 0.01 + 1e-9
    turned = np.arccos(np.clip(np.einsum("ij,ij->i", squeezed.axes, out.cells.axes), -1, 1))
    tip = turned * (squeezed.lengths / 2 + squeezed.radii)
    assert np.all(tip <= settings.turn_limit * 2 * squeezed.radii + 1e-9)


@pytest.mark.parametrize("turn_limit", [None, 0.2])
def test_cells_never_shrink_and_turning_is_bounded(turn_limit):
    """A rod between two walls with 0.05 of room at each end, growing by 0.14: growth is stopped,
    never reversed; the walls push along its axis, so it does not turn (and with a cap, by no
    more than the cap)."""
    cells = rods([[0, 0, 0]], [[1, 0, 0]], 4.0)
    walls = [qc.Plane((-2.55, 0, 0), (1, 0, 0)), qc.Plane((2.55, 0, 0), (-1, 0, 0))]
    settings = PositionSettings(turn_limit=turn_limit)
    out = position_step(cells, 0.05, drive=growing(cells), planes=walls, planar=True, settings=settings)
    assert out.converged and out.excess <= settings.overlap_tolerance
    assert 4.0 <= out.cells.lengths[0] <= 4.0 + 0.1 + 0.02
    turned = np.arccos(np.clip(out.cells.axes[0] @ cells.axes[0], -1, 1))
    assert turned * (2.0 + 0.5) <= (1e-6 if turn_limit is None else turn_limit * 1.0 + 1e-9)


def test_a_step_that_does_not_converge_is_reported_and_not_applied():
    cells = scenes.colony_2d(300, 2)
    settings = PositionSettings(max_iterations=1, overlap_tolerance=1e-9, aim=0.0)  # the linearization error shows
    with pytest.raises(StepFailedError) as caught:
        position_step(cells, 0.05, drive=growing(cells), settings=settings)
    assert caught.value.result is not None and not caught.value.result.converged
    colony = Colony.founder(cells, np.log(2.0))
    after, result = grow_position(colony, 0.05, settings=settings, on_failure="return")
    assert not result.converged and after is colony


def test_move_turns_exactly_and_ignores_spin():
    cells = rods([[0, 0, 0]], [[1, 0, 0]], 2.0)
    inertia = cells.masses[0] * (3 * 0.25 + 4.0) / 12
    p = np.zeros((1, 7))
    p[0, 5] = inertia * np.pi / 2  # a quarter turn about z in unit time
    p[0, 3] = 1e6  # a spin about the cell's own axis (x) turns nothing
    moved = move(cells, 1.0, p)
    assert np.allclose(moved.axes, [[0, 1, 0]])


def test_settings_and_arguments_are_checked():
    with pytest.raises(InvalidArgumentError, match="overlap_tolerance"):
        PositionSettings(overlap_tolerance=-1)
    with pytest.raises(InvalidArgumentError, match="max_iterations"):
        PositionSettings(max_iterations=0)
    with pytest.raises(InvalidArgumentError, match="trust"):
        PositionSettings(trust=0.0)
    with pytest.raises(InvalidArgumentError, match="aim: expected a number >= 0"):
        PositionSettings(aim=-0.1)
    with pytest.raises(InvalidArgumentError, match="early_tolerance: .* at least tolerance"):
        PositionSettings(early_tolerance=1e-5)
    cells = rods([[0, 0, 0]], [[1, 0, 0]], 2.0)
    with pytest.raises(InvalidArgumentError, match="dt"):
        position_step(cells, -1.0)
    with pytest.raises(InvalidArgumentError, match="drive"):
        position_step(cells, 0.1, drive=np.zeros((2, 7)))
    with pytest.raises(InvalidArgumentError, match="takes no bounds"):
        position_step(cells, 0.1, settings=PositionSettings(solver="linear"))
    with pytest.raises(InvalidArgumentError, match="growth_per_step"):
        growth_time_step(Colony.founder(cells, 1.0), growth_per_step=0.0)


def test_growth_time_step_follows_growth_not_colony_size():
    small = Colony.founder(rods([[0, 0, 0]], [[1, 0, 0]], 2.0), np.log(2.0))
    big_cells = scenes.colony_2d(500, 0)
    big = Colony.founder(big_cells, np.log(2.0))
    assert growth_time_step(small, growth_per_step=0.035) == pytest.approx(np.log1p(0.035) / np.log(2.0))
    assert growth_time_step(big) == growth_time_step(small)
    assert growth_time_step(small, max_dt=0.01) == 0.01
    assert growth_time_step(Colony.founder(small.cells, 0.0), still=0.03) == 0.03


def test_a_grown_colony_stays_free_of_overlap_over_many_steps():
    """Grow from one cell to about 60 cells with the position step; every step converges and the
    brute-force overlap of the final state is within the tolerance."""
    rng = np.random.default_rng(0)
    colony = Colony.founder(rods([[0, 0, 0]], [[1, 0, 0]], 2.0), np.log(2.0))
    dt = growth_time_step(colony)
    while colony.cells.n < 60:
        colony, out = grow_position(colony, dt, planar=True)
        assert out.converged and out.excess <= 0.01
        colony = divide(colony, 4.0, rng, planar=True)
    # The end of the last step (before its divisions): overlaps within the tolerance, beyond the
    # targets of pairs that overlapped at the start of the step (divisions' axis noise).
    assert brute_force_overlap(out.cells) <= 0.01 + out.start_overlap


def test_warm_start_carries_contact_impulses_by_cell_id():
    """The contact impulses of a step are keyed by cell ids and kind: looked up after the cells
    are reordered they are the same; a solver that takes a warm start (MPRGP, so no bounds) starts
    from them and reaches the same answer as from zero. (It is not faster: docs/performance.md.)"""
    cells = scenes.colony_2d(200, 5)
    settings = PositionSettings(solver="mprgp", turn_limit=None, allow_shrinking=True, tolerance=1e-8)
    drive = growing(cells)
    ids = np.arange(cells.n) * 3 + 7
    first = position_step(cells, 0.05, drive=drive, settings=settings, ids=ids)
    warm = first.warm
    assert np.all(warm.impulse >= 0) and warm.impulse.max() > 0
    assert np.array_equal(warm.lookup(warm.a, warm.b, warm.kind), warm.impulse)
    reverse = np.arange(cells.n)[::-1]
    index_of = {int(i): k for k, i in enumerate(ids[reverse])}
    # the same contacts, named through the reversed order's indices, give the same impulses
    a_rev = np.array([index_of[int(i)] for i in warm.a])
    b_rev = np.array([index_of[int(i)] if i >= 0 else int(i) for i in warm.b])
    assert np.array_equal(warm.lookup(ids[reverse][a_rev], np.where(b_rev >= 0, ids[reverse][np.maximum(b_rev, 0)], b_rev),
                                      warm.kind), warm.impulse)
    assert np.all(warm.lookup(warm.a + 1, warm.b, warm.kind)[np.isin(warm.a + 1, warm.a, invert=True)] == 0)
    cold = position_step(first.cells, 0.05, drive=drive, settings=settings, ids=ids)
    flipped = position_step(first.cells.subset(reverse), 0.05, drive=drive[reverse], settings=settings,
                            ids=ids[reverse], warm=warm)
    assert cold.converged and flipped.converged
    # both stop within the overlap tolerance of the same fixed point, not necessarily at the same iterate
    assert np.allclose(flipped.cells.centers[::-1], cold.cells.centers, atol=0.01)
    with pytest.raises(InvalidArgumentError, match="ids"):
        position_step(cells, 0.05, ids=np.zeros(3, dtype=int))
    with pytest.raises(InvalidArgumentError, match="warm"):
        position_step(cells, 0.05, warm=[1, 2])


def test_an_answer_the_solver_did_not_stand_by_is_never_applied(monkeypatch):
    """Before: only a missing or non-finite answer failed the step; a stalled solve was applied."""
    import dataclasses

    import qpcontact.timestep.position as position

    real = position.solve
    monkeypatch.setattr(position, "solve", lambda *a, **k: dataclasses.replace(real(*a, **k), found=False,
                                                                               status="stalled"))
    cells = scenes.colony_2d(60, 1)
    with pytest.raises(StepFailedError, match="stalled") as caught:
        position_step(cells, 0.05, drive=growing(cells))
    assert not caught.value.result.converged
    # ... and says what to try, with the settings' values (issue 27: "stalled" and nothing else).
    assert ("try: a smaller dt" in str(caught.value) and "max_iterations, now 30" in str(caught.value)
            and "solver, now ipm: mprgp or clarabel" in str(caught.value))


def test_an_update_that_throws_cells_into_each_other_is_backtracked(monkeypatch):
    """A linearization whose answer drives two rods through each other (as on a jammed 27,601-cell
    colony) is not kept: the step goes back towards the last iterate and still converges."""
    import dataclasses

    import qpcontact.timestep.position as position

    real, calls = position.solve, []

    def wild_first(*args, **kwargs):
        out = real(*args, **kwargs)
        calls.append(1)
        return dataclasses.replace(out, y=-15.0 * out.y) if len(calls) == 1 else out

    monkeypatch.setattr(position, "solve", wild_first)
    # (The wild answer stands for one that meets its linearization and lands far outside where it
    # holds; the acceptance checks would refuse this fake one outright.)
    monkeypatch.setattr(position, "acceptance_failure", lambda *args, **kwargs: "")
    cells = rods([[0, 0, 0], [0, 0.95, 0]], [[1, 0, 0], [1, 0, 0]], 2.0)
    out = position_step(cells, 0.05, drive=np.zeros((2, 7)), planar=True,
                        settings=PositionSettings(relaxation=1.0))
    assert out.converged and out.max_overlap <= 0.01
    assert max(out.overlaps) <= max(position.BACKTRACK_OVERLAP, out.overlaps[0])  # no kept iterate crossed


def test_a_free_motion_within_the_tolerance_is_taken_without_a_solve():
    """Before: a solve was forced; with nothing pushing, its scale (the largest approach, ~0) made
    it ill-posed and the interior-point method stalled (a settled layer, no drive)."""
    cells = rods([[0, 0, 0], [0, 1.003, 0]], [[1, 0, 0], [1, 0, 0]], 2.0)
    out = position_step(cells, 0.05, drive=np.zeros((2, 7)), planar=True)
    assert out.converged and out.iterations == 0 and out.solver_iterations == 0
    assert np.array_equal(out.cells.centers, cells.centers) and not np.any(out.contact_impulses)


def test_the_linearization_is_the_exact_derivative_of_the_end_of_step_separations_in_3d():
    """The rows of a linearization (rotations through the left Jacobian of each cell's turn,
    growth along the end axis) are the derivative of the true separations at the moved positions
    with respect to the step's impulses: central differences agree to second order, with cells
    turned by up to 0.6 rad out of the plane. The rotation about the moved axes that the step
    used before differs by O(θ) (the reason 3D steps needed 3–6 linearizations)."""
    from qpcontact.assembly.system import Turned, velocity_changes
    from qpcontact.geometry import evaluate_contacts
    from qpcontact.geometry.motion import left_jacobian, turning_vectors

    rng = np.random.default_rng(4)
    n = 12
    axes = rng.standard_normal((n, 3))
    axes /= np.linalg.norm(axes, axis=1)[:, None]
    cells = qc.Cells(centers=rng.uniform(0, 3, (n, 3)), axes=axes, lengths=rng.uniform(0.5, 3, n), radii=0.5,
                     masses=rng.uniform(0.5, 2, n), growth_inertia=rng.uniform(2, 20, n))
    dt = 0.7
    base = rng.standard_normal((n, 7)) * 0.6
    a, b = np.triu_indices(n, 1)
    kind = np.zeros(a.size, dtype=np.intp)

    def separations(x):
        return evaluate_contacts(move(cells, dt, x), a, b, kind).separation

    now = move(cells, dt, base)
    assert np.max(np.linalg.norm(turning_vectors(cells, dt, base), axis=1)) > 0.6
    contacts = evaluate_contacts(now, a, b, kind)
    turned = Turned(axes=now.axes, jacobian=left_jacobian(turning_vectors(cells, dt, base)))
    moved_axes_frame = Turned(axes=now.axes, jacobian=np.broadcast_to(np.eye(3), (n, 3, 3)).copy())
    exact, naive = [], []
    for _ in range(5):
        direction = rng.standard_normal((n, 7))
        h = 1e-6
        numeric = (separations(base + h * direction) - separations(base - h * direction)) / (2 * h)
        exact.append(np.max(np.abs(dt * velocity_changes(cells, contacts, direction, turned) - numeric)))
        naive.append(np.max(np.abs(dt * velocity_changes(cells, contacts, direction, moved_axes_frame) - numeric)))
        scale = np.max(np.abs(numeric))
    assert max(exact) <= 1e-6 * scale
    assert max(naive) >= 1e-2 * scale  # the test can tell the two apart


def test_an_answer_that_fails_the_acceptance_checks_is_never_applied(monkeypatch):
    """The position step's answers pass resolve's acceptance checks (with the bounds): an answer
    the solver reports as converged but that penetrates is refused, and the step fails unapplied."""
    import dataclasses

    import qpcontact.timestep.position as position

    real = position.solve
    monkeypatch.setattr(position, "solve", lambda *a, **k: dataclasses.replace(real(*a, **k), y=np.zeros_like(
        real(*a, **k).y)))
    cells = rods([[0, 0, 0], [0, 0.9, 0]], [[1, 0, 0], [1, 0, 0]], 2.0)
    out = position_step(cells, 0.05, planar=True, on_failure="return")
    assert not out.converged and "penetrates" in out.message
    assert np.allclose(out.impulses, 0.0)


@pytest.mark.parametrize("dimensions, n_cells", [(2, 400), (3, 250)])
def test_end_positions_agree_with_a_tight_step_to_a_thousandth_of_a_diameter(dimensions, n_cells):
    """Issue 22: accuracy is not bought with speed. On a colony grown by ``simulate``'s defaults,
    one default step ends within 10⁻³ of a diameter (every cell's centre and tips) of the same
    step solved at a tight tolerance (10⁻⁵, the tightest of a second-order step's solves;
    ``qpcontact bench-grown`` reports the same on the large states)."""
    from qpcontact.simulation import Settings, run_colony
    from qpcontact.simulation.steps import step_function
    from qpcontact.studies.grown import end_difference, reference_changes

    settings = Settings().updated({"cells": n_cells, "dimensions": dimensions}, "test")
    colony = run_colony(settings, progress=False).colony
    drive = None
    if dimensions == 3:
        drive = np.zeros((colony.cells.n, 7))
        drive[:, 2] = -settings.model.sink_speed * colony.cells.masses
    default = step_function(settings, {})(colony, settings.time_step_of(colony), drive=drive)
    tight_settings = settings.updated(reference_changes(settings), "test")
    tight = step_function(tight_settings, {})(colony, default.dt, drive=drive)
    assert default.result.converged and tight.result.converged
    assert tight.result.solver_iterations >= default.result.solver_iterations  # a tighter solve,
    assert not np.array_equal(tight.colony.cells.centers, default.colony.cells.centers)  # not the same one
    assert default.result.max_overlap <= settings.position.overlap_tolerance
    assert end_difference(default.colony, tight.colony) <= 1e-3


def test_a_deep_starting_overlap_is_relaxed_by_relaxation_per_step_as_the_docs_say():
    """docs/usage.md: the 0.01 bound is for overlap a step makes; one the cells start with is
    removed by ``relaxation`` (0.05 of a diameter) per step, so a deep start takes steps to clear
    (0.3 deep: 0.25, 0.20, 0.15, ..., 0)."""
    import re
    from pathlib import Path

    import qpcontact as qc

    usage = " ".join((Path(__file__).resolve().parents[2] / "docs" / "usage.md").read_text().split())
    assert re.search(r"removes only `relaxation`, 0\.05 of a diameter, of an overlap it starts with, so that no "
                     r"cell is thrown \(0\.3 deep: 0\.25, 0\.20, 0\.15, \.\.\., 0 after each step\)", usage)
    settings = qc.PositionSettings()
    assert (settings.relaxation, settings.aim, settings.overlap_tolerance) == (0.05, 0.001, 0.01)
    cells = qc.Cells([[0.0, 0.0, 0.0], [0.0, 0.7, 0.0]], [1, 0, 0], 2.0, 0.5)  # 0.3 of a diameter deep
    overlaps = []
    for _ in range(8):
        out = qc.position_step(cells, 0.01, settings=settings)
        cells = out.cells
        overlaps.append(out.max_overlap)
    per_step = settings.relaxation + settings.aim  # the floor of a pair's target, and the aim beyond it
    assert overlaps[:3] == pytest.approx([0.3 - per_step * k for k in (1, 2, 3)], abs=0.002)
    assert overlaps[-1] <= settings.overlap_tolerance


def test_resolve_on_a_grown_state_finds_its_contacts_with_the_documented_margin():
    """The position step leaves its contacts touching to within the solver's accuracy, some a
    hair apart: resolve at the documented margin 0.05 µm finds every touching pair, and more than
    at margin 0."""
    import qpcontact as qc
    from qpcontact.simulation.loop import run_colony
    from qpcontact.simulation.settings import Settings

    cells = run_colony(Settings().updated({"cells": 60}), progress=False).colony.cells
    offset = cells.centers - cells.centers.mean(axis=0)
    pushed = qc.Cells(cells.centers, cells.axes, cells.lengths, cells.radii, momenta=-offset)
    near = len(qc.resolve(pushed, solver="clarabel").contacts)
    documented = len(qc.resolve(pushed, solver="clarabel", margin=0.05).contacts)
    assert near < documented and documented >= cells.n
    assert "margin=0.05" in qc.resolve.__doc__


def test_the_default_search_margin_is_075_diameters_in_a_monolayer_and_05_in_3d():
    """PositionSettings.margin none: pairs 0.6 diameters apart are searched (and kept as
    contacts) in a monolayer, not in 3D; a margin given is used as given."""
    cells = rods([[0, 0, 0], [0, 1.6, 0]], [[1, 0, 0]] * 2, 2.0)  # radius 0.5: a gap of 0.6 diameters
    assert PositionSettings().margin is None
    assert len(position_step(cells, 0.01).contacts) > 0  # detected planar
    assert len(position_step(cells, 0.01, planar=False).contacts) == 0
    assert len(position_step(cells, 0.01, settings=PositionSettings(margin=0.5)).contacts) == 0
    assert len(position_step(cells, 0.01, planar=False, settings=PositionSettings(margin=0.75)).contacts) > 0


def _lever():
    """A rod whose tip is pushed sideways by a wall that moves into it: it must turn a lot (its
    tip 0.8 of a diameter) or move; the least-effort answer turns it, about its far end."""
    cells = rods([[0, 0, 0], [1.8, 2.2, 0]], [[1, 0, 0], [0, 1, 0]], [4.0, 2.0])
    drive = np.zeros((2, 7))
    drive[1, 1] = -cells.masses[1] * 1.0 / 0.05  # the second rod comes down 1 µm in the step, 0.2 to touch
    return cells, drive


def test_a_turn_larger_than_the_trust_region_is_not_clipped():
    """The trust region only sets how many linearizations a turn takes: a small one (0.05 of a
    diameter per linearization, widening as the linearizations hold) ends where none ends."""
    cells, drive = _lever()
    free = position_step(cells, 0.05, drive=drive, planar=True, settings=PositionSettings(trust=None))
    small = position_step(cells, 0.05, drive=drive, planar=True, settings=PositionSettings(trust=0.05, trust_rounds=30))
    assert free.converged and small.converged and small.iterations > free.iterations
    turned = np.arccos(np.clip(free.cells.axes[0] @ cells.axes[0], -1, 1)) * (2.0 + 0.5)
    assert turned > 0.2  # the tip of rod 0 turns by more than the old cap (0.2 of a diameter)
    assert abs(np.arccos(np.clip(small.cells.axes[0] @ cells.axes[0], -1, 1)) * (2.0 + 0.5) - turned) < 0.02
    assert np.allclose(small.cells.centers, free.cells.centers, atol=0.03)  # each within the tolerances


def test_a_cap_on_turning_still_caps_when_asked_for():
    cells, drive = _lever()
    capped = position_step(cells, 0.05, drive=drive, planar=True, settings=PositionSettings(turn_limit=0.1))
    turned = np.arccos(np.clip(capped.cells.axes[0] @ cells.axes[0], -1, 1)) * (2.0 + 0.5)
    assert capped.converged and turned <= 0.1 * 1.0 + 1e-9


def test_contacts_rest_touching_not_at_a_gap():
    """Two rods pressed together side by side end touching (within the solver's accuracy), not
    at a gap that would make the cells thicker (aim 0.03 left 0.03 of a diameter)."""
    cells = rods([[0, 0, 0], [0, 1.0, 0]], [[1, 0, 0], [1, 0, 0]], 3.0)
    drive = np.zeros((2, 7))
    drive[0, 1], drive[1, 1] = cells.masses[0] * 2.0, -cells.masses[1] * 2.0  # 0.1 µm each in the step
    out = position_step(cells, 0.05, drive=drive, planar=True)
    gap = np.linalg.norm(out.cells.centers[1] - out.cells.centers[0]) - 1.0
    assert out.converged and -0.01 <= gap <= 0.002


def test_a_step_that_moves_the_cells_far_searches_each_configuration_alone():
    """A predicted motion of several diameters (a large step of a fast colony) would widen every
    cell's search by that much (2.4·10⁶ candidate pairs at 5,000 cells, TooManyContactsError):
    the start, the free motion and the prediction are searched on their own instead."""
    cells = scenes.colony_2d(400, 1)
    ids = np.arange(cells.n)
    motion = qc.CellMotion(ids, np.tile([200.0, 0.0, 0.0], (cells.n, 1)), np.zeros((cells.n, 3)))
    out = position_step(cells, 0.05, drive=growing(cells), ids=ids, motion=motion)
    assert out.converged and out.excess <= 0.01


def test_a_second_order_step_meets_the_overlap_tolerance_in_fewer_linearizations():
    """PositionSettings.second_order: the contacts' curvature in each linearization, updates
    taken whole, and a last first-order one. On a grown 2D colony its step ends within the overlap
    tolerance, in about as many linearizations as the first-order step (on grown colonies of
    5,000 cells a quarter fewer: docs/model-notes.md); it needs a solver that takes the curvature."""
    from qpcontact.simulation import Settings, run_colony
    from qpcontact.simulation.steps import step_function

    settings = Settings().updated({"cells": 400, "dimensions": 2}, "test")
    colony = run_colony(settings, progress=False).colony
    dt = settings.time_step_of(colony)
    first = step_function(settings, {})(colony, dt)
    second = step_function(settings.updated({"position_second_order": True}, "test"), {})(colony, dt)
    # At most one halving: on an Intel Xeon (2026-12-05, ninth session) the 400-cell colony's last
    # bits differ from the AMD machine's, and there the opt-in second-order step was halved once.
    assert first.result.converged and second.result.converged and first.rejected == 0 and second.rejected <= 1
    assert second.result.max_overlap <= settings.position.overlap_tolerance
    assert second.result.iterations <= first.result.iterations + 1  # its last, first order, included
    assert not np.array_equal(second.colony.cells.centers, first.colony.cells.centers)
    with pytest.raises(InvalidArgumentError, match="second_order"):
        position_step(colony.cells, dt, planar=True, settings=PositionSettings(second_order=True, solver="mprgp"))


def test_early_linearizations_are_solved_loosely_and_a_step_never_ends_on_one(monkeypatch):
    """PositionSettings.early_tolerance: a linearization taken while some overlap is more than
    six overlap tolerances beyond its target is solved to early_tolerance, the step's last one
    to tolerance, and the step takes fewer interior-point iterations than with every solve to
    tolerance (docs/model-notes.md, "Early linearizations")."""
    import qpcontact.timestep.position as position
    from qpcontact.simulation import Settings, run_colony
    from qpcontact.simulation.steps import step_function

    settings = Settings().updated({"cells": 400, "dimensions": 2}, "test")
    colony = run_colony(settings, progress=False).colony
    dt = settings.time_step_of(colony)
    asked: list[float] = []
    solve = position.solve

    def recorded(*args, tolerance, **kwargs):
        asked.append(tolerance)
        return solve(*args, tolerance=tolerance, **kwargs)

    monkeypatch.setattr(position, "solve", recorded)
    early = step_function(settings, {})(colony, dt)
    assert early.result.converged and early.rejected == 0
    assert settings.position.early_tolerance in asked and asked[-1] == settings.position.tolerance
    assert early.result.max_overlap <= settings.position.overlap_tolerance
    asked.clear()
    strict = step_function(settings.updated({"position_early_tolerance": None}, "test"), {})(colony, dt)
    assert set(asked) == {settings.position.tolerance}
    assert early.result.solver_iterations < strict.result.solver_iterations
