"""The benchmark command, and the speed-ups behind it giving the same answers as before.

No timing is asserted here: speed is measured by ``qpcontact bench`` (docs/performance.md).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import scipy.sparse as sp
from conftest import random_scene

import qpcontact as qc
from qpcontact.assembly.system import slot_basis, slot_directions
from qpcontact.geometry.contacts import candidate_pairs, narrow_phase
from qpcontact.resolve import metrics
from qpcontact.solvers import Problem, blocks, solve
from qpcontact.studies import bench, scenes


def test_quick_bench_writes_the_table_plot_and_data(tmp_path):
    out = tmp_path / "docs"
    (out).mkdir()
    (out / "performance.md").write_text("# Performance\n\nanalysis kept\n\n<!-- bench:start -->\nold\n<!-- bench:end -->\ntail kept\n")
    code = bench.main(["--quick", "--out-dir", str(out), "--cache-dir", "none", "--repeats", "1",
                       "--solvers", "linear", "cg@1e-9", "osqp/contact"])
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


def test_scaling_exponent_of_a_power_law():
    n = [1e3, 1e4, 1e5]
    assert bench.scaling_exponent(n, [2e-6 * x**1.1 for x in n]) == pytest.approx(1.1)


# ------------------------------------------------------------------------------------------
# Optimizations keep the answers
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize("seed", range(4))
def test_broad_phase_keeps_the_sorted_unique_pairs(seed):
    """Rods of many pieces (lengths up to 6× the median) produce repeated piece pairs; the result
    is the sorted unique list, the same as np.unique(axis=0) over all touching pairs."""
    rng = np.random.default_rng(seed)
    n = 60
    cells = qc.Cells(rng.uniform(0, 6, (n, 3)), rng.normal(size=(n, 3)), rng.choice([0.0, 1.0, 6.0], n), 0.4,
                     normalize_axes=True)
    pairs = candidate_pairs(cells)
    assert np.array_equal(pairs, np.unique(pairs, axis=0))
    everything = np.array([(i, j) for i in range(n) for j in range(i + 1, n)])
    touching = narrow_phase(cells, everything)
    found = narrow_phase(cells, pairs)
    assert np.array_equal(found.cell_a, touching.cell_a) and np.array_equal(found.cell_b, touching.cell_b)
    assert np.allclose(found.normal, touching.normal, rtol=0, atol=1e-12)


def test_broad_phase_of_cells_whose_only_close_pieces_are_their_own():
    """One long rod alone: its pieces are within reach of each other but no pair remains."""
    cells = qc.Cells([[0.0, 0.0, 0.0], [50.0, 0.0, 0.0], [0.0, 50.0, 0.0]], [1.0, 0.0, 0.0], [9.0, 1.0, 1.0], 0.5)
    assert candidate_pairs(cells).shape == (0, 2)


def test_narrow_phase_order_does_not_depend_on_the_pair_order():
    cells = scenes.colony_2d(300, seed=1)
    pairs = candidate_pairs(cells)
    shuffled = pairs[np.random.default_rng(0).permutation(len(pairs))]
    a, b = narrow_phase(cells, pairs, planar=True), narrow_phase(cells, shuffled, planar=True)
    for name in ("cell_a", "cell_b", "normal", "offset_a", "separation", "normal_velocity"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    # by pair, then along a (two contacts of parallel neighbours in increasing s)
    key = a.cell_a.astype(np.int64) * cells.n + a.cell_b
    assert np.all(np.diff(key) >= 0)


def test_slot_directions_are_the_rows_of_the_slot_basis():
    cells = random_scene(5, n=40)
    cell = np.repeat(np.arange(cells.n), 7)
    slot = np.tile(np.arange(7), cells.n)
    assert np.array_equal(slot_directions(cells, cell, slot), slot_basis(cells, np.arange(cells.n)).reshape(-1, 7))


@pytest.mark.parametrize("seed", range(3))
def test_assembly_matches_the_dense_definition(seed):
    """B̃ = J W^{1/2}/σ_B built densely from the slot basis (the previous, unvectorized way)."""
    cells = random_scene(seed, n=40)
    active, b = qc.colliding(qc.find_contacts(cells))
    system = qc.build_system(cells, active, b)
    basis = slot_basis(cells, np.arange(cells.n))  # (N, 7, 7)
    inverse_mass = np.stack([cells.inverse_masses] * 3 + [cells.inverse_inertia_parallel]
                            + [cells.inverse_inertia_perpendicular] * 2 + [cells.inverse_growth_inertia], axis=1)
    dense = np.zeros((len(active), cells.n * 7))
    for k in range(len(active)):  # reference only: a loop over the contacts of a small scene
        for cell, offset, stretch, sign in ((active.cell_a[k], active.offset_a[k], active.stretch_a[k], 1.0),
                                            (active.cell_b[k], active.offset_b[k], active.stretch_b[k], -1.0)):
            n_k = active.normal[k]
            world = np.concatenate([n_k, np.cross(offset, n_k), [stretch * cells.axes[cell] @ n_k]])
            dense[k, cell * 7:(cell + 1) * 7] += sign * (basis[cell] @ world) * np.sqrt(inverse_mass[cell])
    columns = system.column_cell * 7 + system.column_slot
    assert np.allclose(system.matrix.toarray() * system.operator_scale, dense[:, columns], rtol=0, atol=1e-12)
    rest = np.setdiff1d(np.arange(cells.n * 7), columns)
    assert np.abs(dense[:, rest]).max() < 1e-12  # the left-out unknowns never mattered
    assert np.array_equal(system.column_basis, basis[system.column_cell, system.column_slot])


def _many_components():
    """A colony whose colliding contacts form several independent components."""
    cells = scenes.colony_2d(400, seed=2)
    active, b = qc.colliding(qc.find_contacts(cells, planar=True))
    return cells, qc.build_system(cells, active, b)


def test_independent_blocks_partition_the_system_into_uncoupled_parts():
    _, system = _many_components()
    k, n = system.shape
    parts = blocks.independent_blocks(system.matrix)
    assert len(parts) > 3
    rows = np.concatenate([r for r, _ in parts])
    cols = np.concatenate([c for _, c in parts])
    assert np.array_equal(np.sort(rows), np.arange(k)) and np.array_equal(np.sort(cols), np.arange(n))
    coo = sp.coo_matrix(system.matrix)
    merged = blocks.independent_blocks(system.matrix, min_rows=k // 3)
    assert 1 < len(merged) < len(parts)
    for partition in (parts, merged):
        row_block, col_block = np.empty(k, int), np.empty(n, int)
        for i, (r, c) in enumerate(partition):
            row_block[r], col_block[c] = i, i
        assert np.array_equal(row_block[coo.row], col_block[coo.col])  # no non-zero links two blocks


@pytest.mark.parametrize("solver,form", [("osqp", "contact"), ("osqp", "primal"), ("clarabel", "primal")])
@pytest.mark.parametrize("formulation", ["complementarity", "least_squares"])
def test_split_solve_equals_the_unsplit_solve(solver, form, formulation, monkeypatch):
    _, system = _many_components()
    reference = qc.reference_solution(system, formulation)
    monkeypatch.setattr(blocks, "BLOCK_ROWS", 50)
    split = solve(Problem.of(system), solver, formulation, form, tolerance=1e-8, split=True)
    whole = solve(Problem.of(system), solver, formulation, form, tolerance=1e-8, split=False)
    assert split.found and whole.found and split.extras["blocks"] > 1
    assert metrics.distance(split.y, whole.y) < 1e-4
    # as accurate as the unsplit solve (Clarabel's ỹ is only ~1e-5 accurate at tolerance 1e-8)
    assert metrics.distance(split.y, reference) < max(1e-6, 3 * metrics.distance(whole.y, reference))
    if split.lam is not None and whole.lam is not None:
        assert np.allclose(split.lam, whole.lam, atol=1e-4 * np.abs(whole.lam).max())
