"""Colony statistics (issue 32): each against a hand-built colony whose answer is known."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq
from scipy.special import j0, j1

import qpcontact as qc
from qpcontact.colony.statistics import (
    BIOFILM_ONLY,
    DEFINITIONS,
    ColonyStatistics,
    StatisticsOptions,
    colony_statistics,
    crossing,
    footprint,
    rim,
)
from qpcontact.io.snapshots import load_snapshot, save_colony

FINE = StatisticsOptions(pixel=0.02)


def planar_cells(xy, theta, lengths=2.0, radii=0.5):
    xy = np.asarray(xy, dtype=float)
    centers = np.column_stack([xy, np.zeros(len(xy))])
    axes = np.column_stack([np.cos(theta), np.sin(theta), np.zeros(len(xy))])
    return qc.Cells(centers=centers, axes=axes, lengths=lengths, radii=radii)


def lattice(nx, ny, sx, sy):
    """An nx × ny grid of points with spacings sx, sy, centred on the origin."""
    x, y = np.meshgrid((np.arange(nx) - (nx - 1) / 2) * sx, (np.arange(ny) - (ny - 1) / 2) * sy, indexing="ij")
    return np.column_stack([x.ravel(), y.ravel()])


def aligned_block(nx=20, ny=30, gap=0.01, length=2.0, radius=0.5):
    """Capsules along x, touching but for ``gap`` end to end and side by side."""
    sx, sy = length + 2 * radius + gap, 2 * radius + gap
    return planar_cells(lattice(nx, ny, sx, sy), np.zeros(nx * ny), length, radius), sx, sy


def ring(radius, spacing, radial, length=2.0):
    """Cells around a circle of ``radius``, pointing along it (tangential) or out of it (radial)."""
    count = int(2 * np.pi * radius / spacing)
    phi = 2 * np.pi * np.arange(count) / count
    xy = radius * np.column_stack([np.cos(phi), np.sin(phi)])
    return xy, phi if radial else phi + np.pi / 2


def rings(specs, length=2.0):
    """Concentric rings, each ``(radius, spacing, radial)``."""
    parts = [ring(*spec, length=length) for spec in specs]
    return planar_cells(np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts]), length)


def test_an_aligned_block_has_full_order_no_crossing_and_its_computed_packing_and_contacts():
    cells, sx, sy = aligned_block()
    s = colony_statistics(cells, options=FINE)
    assert s.dimensions == 2 and s.cells == 600
    assert s.local_order == pytest.approx(1.0) and s.order == pytest.approx(1.0)
    assert s.nematic_length == math.inf  # the correlation is 1 at every distance
    # each capsule (π ρ² + 2 ρ l) in its cell of the lattice, the block's outline nx·sx × ny·sy less the gap
    capsule = np.pi * 0.25 + 2 * 0.5 * 2.0
    expected = 600 * capsule / ((20 * sx - 0.01) * (30 * sy - 0.01))
    assert s.packing == pytest.approx(expected, abs=0.003)
    assert colony_statistics(cells).packing == pytest.approx(expected, abs=0.01)  # the default pixel
    # touching neighbours: end to end along each row, side by side along each column (diagonals are 0.41 µm apart)
    assert s.contacts_per_cell == pytest.approx(2 * (19 * 30 + 20 * 29) / 600)
    # a uniform grid's variance along an axis is s²(n² − 1)/12
    assert s.aspect_ratio == pytest.approx(math.sqrt(sx**2 * (20**2 - 1) / (sy**2 * (30**2 - 1))))
    assert s.xy_radius == pytest.approx(math.sqrt((sx**2 * (20**2 - 1) + sy**2 * (30**2 - 1)) / 12))


def hexagonal_discs(rows, columns):
    x = np.arange(columns)[None, :] + 0.5 * (np.arange(rows)[:, None] % 2)
    y = np.arange(rows)[:, None] * np.sqrt(3) / 2 + 0 * x
    return planar_cells(np.column_stack([x.ravel(), y.ravel()]) * 1.0001, np.zeros(rows * columns), 0.0, 0.5)


def test_hexagonally_packed_discs_lie_between_their_bounding_box_and_the_hexagonal_lattice():
    """Inside, π/(2√3) = 0.9069; the footprint lies within the lattice's bounding box (n + ½ by
    (n − 1)√3/2 + 1 diameters) less its zigzag rim, a share that falls as the lattice grows."""
    packings = []
    for n in (15, 40):
        box = (n + 0.5) * ((n - 1) * np.sqrt(3) / 2 + 1) * 1.0001**2
        packing = colony_statistics(hexagonal_discs(n, n), options=FINE).packing
        assert n * n * np.pi / 4 / box < packing < np.pi / (2 * np.sqrt(3))
        packings.append(packing)
    assert packings[0] < packings[1] - 0.005


def test_a_single_capsule_is_its_own_footprint():
    s = colony_statistics(planar_cells([[0.3, 0.1]], [0.7], 3.0, 0.5), options=FINE)
    assert s.footprint_area == pytest.approx(np.pi * 0.25 + 3.0, rel=0.01)
    assert s.packing == pytest.approx(1.0, abs=0.01)


def test_random_orientations_have_little_order_and_a_short_correlation():
    xy = lattice(40, 40, 2.2, 2.2)
    theta = np.random.default_rng(3).uniform(0, np.pi, len(xy))
    s = colony_statistics(planar_cells(xy, theta, 1.0, 0.5))
    assert s.local_order < 0.5 and s.order < 0.1
    assert s.nematic_length < 2.2  # below 1/e from the nearest neighbours on
    assert s.contacts_per_cell == 0.0  # 2.2 µm apart, 2 µm long at most


def test_a_twisted_field_has_the_correlation_length_of_its_bessel_function():
    """θ = q x: over pairs at distance d in every direction ⟨cos 2q d cos ψ⟩ = J₀(2 q d), which falls
    to 1/e at 2 q d = 1.752."""
    target = 5.0
    z = brentq(lambda v: j0(v) - 1 / math.e, 1.0, 2.4)
    q = z / (2 * target)
    xy = lattice(90, 90, 0.8, 0.8)
    s = colony_statistics(planar_cells(xy, q * xy[:, 0], 0.1, 0.3))
    assert s.nematic_length == pytest.approx(target, rel=0.05)
    # over a disc of radius R, |⟨exp 2iqx⟩| = 2 J₁(2qR)/(2qR) (the disc's Fourier transform)
    assert s.local_order == pytest.approx(2 * j1(2 * q * 3.0) / (2 * q * 3.0), abs=0.015)
    assert colony_statistics(planar_cells(xy, 3 * q * xy[:, 0], 0.1, 0.3)).nematic_length == pytest.approx(
        target / 3, rel=0.08)


def test_a_capped_pair_count_measures_the_same_length():
    xy = lattice(90, 90, 0.8, 0.8)
    theta = 0.17 * xy[:, 0]
    full = colony_statistics(planar_cells(xy, theta, 0.1, 0.3), options=StatisticsOptions(max_pairs=10**8))
    capped = colony_statistics(planar_cells(xy, theta, 0.1, 0.3), options=StatisticsOptions(max_pairs=200_000))
    assert capped.nematic_length == pytest.approx(full.nematic_length, rel=0.03)
    again = colony_statistics(planar_cells(xy, theta, 0.1, 0.3), options=StatisticsOptions(max_pairs=200_000))
    assert again.nematic_length == capped.nematic_length  # seeded


def test_an_aster_is_radial_at_its_edge_and_a_ring_tangential():
    radii = np.arange(3.0, 19.0, 3.2)
    aster = rings([(r, 1.15, True) for r in radii])
    assert colony_statistics(aster).edge_alignment == pytest.approx(1.0)
    wound = rings([(r, 3.2, False) for r in np.arange(2.0, 18.0, 1.1)])
    assert colony_statistics(wound).edge_alignment == pytest.approx(-1.0)


def test_only_the_cells_at_the_edge_count_for_its_alignment():
    inside = [(r, 3.2, False) for r in np.arange(2.0, 12.0, 1.1)]
    outer = inside[-1][0] + 0.5 + 0.1 + 1.5  # radial cells just outside the last tangential ring
    s = colony_statistics(rings([*inside, (outer, 1.15, True)]))
    assert s.edge_alignment == pytest.approx(1.0)
    assert s.edge_cells == int(2 * np.pi * outer / 1.15)
    inner = [(r, 1.15, True) for r in np.arange(3.0, 13.0, 3.2)]
    outside = inner[-1][0] + 1.5 + 0.1 + 0.5
    s = colony_statistics(rings([*inner, (outside, 3.2, False)]))
    assert s.edge_alignment == pytest.approx(-1.0)
    assert s.edge_cells == int(2 * np.pi * outside / 3.2)


def test_the_rim_is_the_outer_ring_with_each_cells_polar_angle():
    """``rim``: the cells the edge alignment averages over (the outer ring of a wound colony,
    none of the inner rings), each centre's polar angle about the centres' mean, and the
    footprint's area (the packing's denominator)."""
    inside = [(r, 3.2, False) for r in np.arange(2.0, 12.0, 1.1)]
    outer = inside[-1][0] + 0.5 + 0.1 + 1.5
    cells = rings([*inside, (outer, 1.15, True)])
    at_rim, polar, area = rim(cells)
    outermost = np.hypot(*cells.centers[:, :2].T) > outer - 0.01
    assert np.array_equal(at_rim, outermost)
    assert np.allclose(np.cos(polar[at_rim]), cells.centers[at_rim, 0] / outer, atol=1e-9)
    assert area == pytest.approx(np.pi * (outer + 1.5) ** 2, rel=0.05)  # the disc out to the radial tips


def test_the_length_distribution():
    lengths = np.linspace(1.0, 3.0, 101)
    cells = planar_cells(lattice(101, 1, 5.0, 1.0), np.zeros(101), lengths, 0.5)
    s = colony_statistics(cells)
    assert (s.length_mean, s.length_median) == pytest.approx((2.0, 2.0))
    assert (s.length_p05, s.length_p25, s.length_p75, s.length_p95) == pytest.approx((1.1, 1.5, 2.5, 2.9))
    assert s.length_sd == pytest.approx(0.02 * math.sqrt((101**2 - 1) / 12))
    assert s.aspect_ratio == math.inf  # a line of cells


def test_a_three_dimensional_stack_has_its_layers_heights_and_vertical_cells():
    """Sites 4 × 4 (3.1 × 1.1 µm apart): a bottom layer along x at z = 0.5, a layer along y at
    z = 1.6 (above the bottom layer's diameter), and 8 vertical cells at z = 4 on the middle two rows."""
    sites = lattice(4, 4, 3.1, 1.1)
    middle = np.abs(sites[:, 1]) < 1.0
    centers = np.concatenate([np.column_stack([sites, np.full(16, 0.5)]), np.column_stack([sites, np.full(16, 1.6)]),
                              np.column_stack([sites[middle], np.full(8, 4.0)])])
    axes = np.concatenate([np.tile([1.0, 0, 0], (16, 1)), np.tile([0, 1.0, 0], (16, 1)), np.tile([0, 0, 1.0], (8, 1))])
    s = colony_statistics(qc.Cells(centers=centers, axes=axes, lengths=2.0, radii=0.5))
    assert s.dimensions == 3 and s.cells == 40
    assert s.bottom_fraction == pytest.approx(16 / 40)
    assert s.bottom_order == pytest.approx(1.0)  # the bottom layer alone: the layer along y is above it
    assert s.vertical_fraction == pytest.approx(8 / 40)
    assert s.median_height == pytest.approx(1.6)
    assert s.height_profile == (0, 16, 0, 16, 0, 0, 0, 0, 8)  # bins of 0.5 µm from z = 0
    assert s.elevation_profile == pytest.approx((0.8, 0, 0, 0, 0, 0.2))
    assert s.elevation_mean == pytest.approx(18.0)
    # mean square radius: 32 cells at every site (x² 12.0125 + y² 1.5125 on average), 8 at y = ±0.55
    assert s.xy_radius == pytest.approx(math.sqrt((32 * 13.525 + 8 * (12.0125 + 0.3025)) / 40))
    assert math.isnan(s.packing) and math.isnan(s.nematic_length) and math.isnan(s.edge_alignment)
    names = [row[0] for row in s.rows()]
    assert "packing" not in names and names[-6:] == [f"elevation_profile[{a}:{a + 15}]" for a in range(0, 90, 15)]
    assert "height_profile[4:4.5]" in names
    assert s.summary().startswith("bottom-layer S 1.000, vertical 0.200, median height 1.60 µm, bottom fraction 0.400")
    flat = colony_statistics(aligned_block(4, 4)[0])
    assert math.isnan(flat.vertical_fraction) and flat.height_profile == ()


def test_unequal_radii_give_each_capsule_its_own_outline():
    cells = planar_cells([[0.0, 0.0], [10.0, 0.0]], np.zeros(2), 0.0, np.array([1.0, 0.5]))
    area, distance = footprint(cells, pixel=0.01)
    assert area == pytest.approx(np.pi * (1.0 + 0.25), rel=0.01)
    assert distance == pytest.approx([1.0, 0.5], abs=0.02)


def test_a_snapshot_a_colony_and_the_cells_give_the_same_statistics(tmp_path):
    cells, _, _ = aligned_block(6, 5)
    colony = qc.Colony.founder(cells, 0.5)
    path = save_colony(tmp_path / "c.npz", colony, 3)
    by_cells = colony_statistics(cells)
    assert colony_statistics(colony) == by_cells
    assert colony_statistics(load_snapshot(path)) == by_cells
    rows = by_cells.rows()
    assert {name for name, *_ in rows} == set(DEFINITIONS) - set(BIOFILM_ONLY)
    assert all(unit == DEFINITIONS[name][0] for name, _, unit, _ in rows)


def test_one_cell():
    s = colony_statistics(planar_cells([[0.0, 0.0]], [0.3]))
    assert s.contacts_per_cell == 0 and s.local_order == pytest.approx(1.0) and math.isnan(s.nematic_length)
    assert math.isnan(s.edge_alignment)  # a cell at the colony's centre has no polar angle


def test_bad_input_is_named():
    with pytest.raises(qc.InvalidArgumentError, match="source: expected a Colony"):
        colony_statistics("colony.npz")
    with pytest.raises(qc.InvalidArgumentError, match="no cells"):
        colony_statistics(planar_cells(np.zeros((0, 2)), np.zeros(0)))
    with pytest.raises(qc.InvalidArgumentError, match="dimensions"):
        colony_statistics(aligned_block(2, 2)[0], dimensions=4)
    with pytest.raises(qc.InvalidArgumentError, match="local_radius"):
        StatisticsOptions(local_radius=-1.0)
    with pytest.raises(qc.InvalidArgumentError, match="max_pairs"):
        StatisticsOptions(max_pairs=0)
    with pytest.raises(qc.InvalidArgumentError, match="options"):
        colony_statistics(aligned_block(2, 2)[0], options={"pixel": 0.1})
    with pytest.raises(qc.InvalidArgumentError, match="options: expected StatisticsOptions"):
        rim(aligned_block(2, 2)[0], {"pixel": 0.1})


def test_crossing_interpolates_from_one_at_zero():
    assert crossing(np.array([1.0, 2.0]), np.array([0.5, 0.0]), 0.25) == pytest.approx(1.5)
    assert crossing(np.array([1.0]), np.array([0.0]), 0.5) == pytest.approx(0.5)
    assert crossing(np.array([1.0]), np.array([0.9]), 0.5) == math.inf
    assert math.isnan(crossing(np.zeros(0), np.zeros(0), 0.5))
    assert isinstance(colony_statistics(aligned_block(2, 2)[0]), ColonyStatistics)
