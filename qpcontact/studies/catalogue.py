"""A catalogue of stiff and extreme scenes: named, seeded generators for the stability report.

Each entry of :data:`CATALOGUE` is a :class:`~qpcontact.studies.scenes.Scene`, registered in the
one scene registry (:data:`qpcontact.studies.scenes.SCENES`): ``case.make(seed=...) -> Cells``
builds the scene (deterministic for a seed; every generator is vectorized over cells),
``case.contacts(cells)`` gives the contacts to hand to :func:`qpcontact.resolve` (``None``: let
resolve find them) and ``case.options`` the other resolve keywords the case needs (e.g. position
correction for the overlap cases, where the overlap depth is what drives ``b``).

Families (``case.family``): mass ratio, aspect ratio, growth inertia, parallel/crossing/
coincident geometry, overlap depth, relative velocity, units, one cell touched by many, long
chains, jammed packings (more contacts than degrees of freedom), duplicate contacts.

Sizes: generators take a size keyword (``n_cells``, ``n_neighbours``, ``n_pairs``) so tests
can build the 10⁴-rod chain or the 1000-neighbour hub at a reduced size; the catalogue entries
are full size.

Every scene is built so that its contacts collide (overlap and approach), otherwise there would
be nothing to solve.
"""

from __future__ import annotations

from functools import partial

import numpy as np

from ..geometry import Cells, Contacts, capsule_volume, concatenate, evaluate_contacts, find_contacts
from ..geometry.contacts import A_PLUS_END, B_MINUS_END
from .scenes import Scene, register_scene

#: Default radius and length of a rod [length units of the scene].
RADIUS, LENGTH = 0.5, 2.0
#: Default overlap of touching cells, as a fraction of the sum of radii.
OVERLAP = 1e-3
#: Position jitter of the jammed packings (fraction of the pitch): uneven overlaps, so that
#: position correction asks for more than the contacts can deliver (Mx = b inconsistent).
JITTER = 3e-4
#: Resolve options of the jammed packings. Without position correction ``b = −u = M(−p)`` is
#: always in the range of M (stopping every cell satisfies every contact), so even a jammed
#: packing has a consistent Mx = b; the overlap term is what makes it over-determined.
JAMMED_OPTIONS = {"position_correction": 0.5, "dt": 1e-3}


# ------------------------------------------------------------------------------------------
# Helpers
# ------------------------------------------------------------------------------------------
def _rotate_z(vectors: np.ndarray, angle: np.ndarray | float) -> np.ndarray:
    """Rotate (N, 3) vectors by ``angle`` [rad] about z."""
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([c * vectors[:, 0] - s * vectors[:, 1], s * vectors[:, 0] + c * vectors[:, 1], vectors[:, 2]], axis=1)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _cells(centers, axes, lengths, radii, masses, velocities, *, growth_inertia=np.inf, growth_rates=0.0) -> Cells:
    """Cells moving with the given velocities (momenta = m·v; fixed cells get zero momentum)."""
    centers = np.asarray(centers, dtype=float)
    n = centers.shape[0]
    masses = np.broadcast_to(np.asarray(masses, dtype=float), (n,))
    finite = np.isfinite(masses)
    momenta = np.where(finite[:, None], np.broadcast_to(velocities, (n, 3)) * np.where(finite, masses, 0.0)[:, None], 0.0)
    g_inertia = np.broadcast_to(np.asarray(growth_inertia, dtype=float), (n,))
    growth = np.where(np.isfinite(g_inertia), np.where(np.isfinite(g_inertia), g_inertia, 0.0) * growth_rates, 0.0)
    return Cells(centers, axes, lengths, radii, masses, g_inertia, momenta, 0.0, growth)


def _compressed(centers: np.ndarray, speed: float, rng: np.random.Generator, noise: float = 0.1) -> np.ndarray:
    """Velocities pointing at the centroid (|v| ∝ distance, max ``speed``) with relative noise."""
    to_centre = centers.mean(axis=0) - centers
    scale = max(float(np.max(np.linalg.norm(to_centre, axis=1))), 1e-300)
    v = speed * to_centre / scale
    return v + noise * speed * rng.standard_normal(v.shape) * (np.linalg.norm(v, axis=1, keepdims=True) / speed)


# ------------------------------------------------------------------------------------------
# Generators. Each takes ``seed`` first and returns Cells; the other keywords are the case's
# parameter (set by the catalogue) and its size.
# ------------------------------------------------------------------------------------------
def mass_sandwich(seed: int, *, ratio: float) -> Cells:
    """Three crossing rods stacked in z: the middle one has mass ``ratio``, the outer two mass
    1; the outer ones move towards the middle one. Axes get small seeded tilts."""
    rng = np.random.default_rng(seed)
    gap = 2 * RADIUS * (1 - OVERLAP)
    centers = np.array([[0.0, 0.0, -gap], [0.0, 0.0, 0.0], [0.0, 0.0, gap]]) + 0.05 * rng.standard_normal((3, 3)) * [1, 1, 0]
    angles = np.array([0.0, np.pi / 2, 0.3]) + 0.05 * rng.standard_normal(3)
    axes = _rotate_z(np.tile([1.0, 0.0, 0.0], (3, 1)), angles)
    velocities = np.array([[0, 0, 1.0], [0, 0, 0], [0, 0, -1.0]]) + 0.1 * rng.standard_normal((3, 3))
    return _cells(centers, axes, LENGTH, RADIUS, np.array([1.0, ratio, 1.0]), velocities)


def crossing_star(seed: int, *, aspect: float, n_neighbours: int = 6) -> Cells:
    """A rod of aspect ratio ``l/ρ = aspect`` along x touched by ``n_neighbours`` rods of the same shape
    crossing it from above and below at seeded positions along its length (all moving towards
    it). For ``aspect = 0`` (spheres), the neighbours sit around the centre sphere instead."""
    rng = np.random.default_rng(seed)
    n = n_neighbours
    length = aspect * RADIUS
    gap = 2 * RADIUS * (1 - OVERLAP)
    side = np.where(np.arange(n) % 2 == 0, 1.0, -1.0)
    if length > 0:
        x = rng.uniform(-0.5, 0.5, n) * length
        centers = np.column_stack([x, rng.uniform(-0.2, 0.2, n) * length, side * gap])
        axes = _rotate_z(np.tile([0.0, 1.0, 0.0], (n, 1)), rng.uniform(-0.5, 0.5, n))
    else:
        directions = _unit(rng.standard_normal((n, 3)))
        centers = gap * directions
        axes = _unit(rng.standard_normal((n, 3)))
    centers = np.vstack([np.zeros(3), centers])
    axes = np.vstack([[1.0, 0.0, 0.0], axes])
    velocities = np.zeros((n + 1, 3))
    # Rods come at the centre rod along z; spheres along their direction to the centre.
    velocities[1:] = np.column_stack([np.zeros((n, 2)), -side]) if length > 0 else -_unit(centers[1:])
    return _cells(centers, axes, length, RADIUS, 1.0, velocities)


def growing_chain(seed: int, *, growth_inertia: float, n_cells: int = 5) -> Cells:
    """``n_cells`` rods end to end along x (small seeded tilts) that push on each other by growing
    (length rate 1; for infinite G the cells do not grow and are compressed instead)."""
    rng = np.random.default_rng(seed)
    n = n_cells
    pitch = LENGTH + 2 * RADIUS * (1 - OVERLAP)
    centers = np.column_stack([pitch * np.arange(n), 1e-3 * rng.standard_normal((n, 2))])
    axes = _unit(np.column_stack([np.ones(n), 1e-3 * rng.standard_normal((n, 2))]))
    grows = np.isfinite(growth_inertia)
    velocities = np.zeros((n, 3)) if grows else _compressed(centers, 1.0, rng)
    return _cells(centers, axes, LENGTH, RADIUS, 1.0, velocities, growth_inertia=growth_inertia,
                  growth_rates=1.0 if grows else 0.0)


def angled_pair(seed: int, *, angle: float, planar: bool = True) -> Cells:
    """Two rods side by side, the second turned by ``angle`` [rad] about z (``angle = 0``:
    exactly parallel), approaching along y; ``planar=False`` lifts the scene out of the plane."""
    rng = np.random.default_rng(seed)
    gap = 2 * RADIUS * (1 - OVERLAP)
    centers = np.array([[0.0, gap, 0.0], [0.3 * rng.uniform(-1, 1), 0.0, 0.0]])
    axes = _rotate_z(np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]]), np.array([0.0, angle]))
    velocities = np.array([[0.0, -1.0, 0.0], [0.0, 1.0, 0.0]])
    cells = _cells(centers, axes, LENGTH, RADIUS, 1.0, velocities)
    if not planar:
        tilt = _unit(np.array([0.0, 1.0, 1.0]))
        # Rotate the whole scene by 45° about x (positions, axes, momenta).
        rot = np.array([[1.0, 0.0, 0.0], [0.0, tilt[1], -tilt[2]], [0.0, tilt[2], tilt[1]]])
        cells = cells.replace(centers=cells.centers @ rot.T, axes=cells.axes @ rot.T, momenta=cells.momenta @ rot.T)
    return cells


def crossing_axes(seed: int) -> Cells:
    """Two rods whose axes intersect (δ = 0: full overlap, the normal is undefined and falls back
    to â × b̂), moving apart along â × b̂ the wrong way (approaching)."""
    rng = np.random.default_rng(seed)
    angle = rng.uniform(0.3, 1.2)
    axes = _rotate_z(np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]]), np.array([0.0, angle]))
    centers = np.array([[0.0, 0.0, 0.0], [0.2 * LENGTH * np.cos(angle), 0.2 * LENGTH * np.sin(angle), 0.0]])
    normal = np.cross(axes[0], axes[1])
    normal /= np.linalg.norm(normal)
    return _cells(centers, axes, LENGTH, RADIUS, 1.0, np.array([-normal, normal]))


def coincident(seed: int) -> Cells:
    """Two identical rods with the same centre and axis (the closest points, the normal and the
    contact interval are all undefined); they get equal and opposite velocities along the
    fallback normal."""
    rng = np.random.default_rng(seed)
    axis = _unit(rng.standard_normal(3))
    cells = Cells(np.zeros((2, 3)), np.tile(axis, (2, 1)), LENGTH, RADIUS)
    found = find_contacts(cells)
    normal = found.normal[0] if len(found) else np.array([1.0, 0.0, 0.0])
    return _cells(cells.centers, cells.axes, LENGTH, RADIUS, 1.0, np.array([-normal, normal]))


def overlap_pair(seed: int, *, overlap: float) -> Cells:
    """Two crossing rods (seeded angle) at rest whose capsules overlap by ``overlap`` times the
    diameter (1 = a full diameter: the axes intersect). Needs position correction: ``b`` comes
    from the overlap alone."""
    rng = np.random.default_rng(seed)
    angle = rng.uniform(0.3, 1.4)
    axes = _rotate_z(np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]]), np.array([0.0, angle]))
    z = 2 * RADIUS * (1 - overlap)
    centers = np.array([[0.0, 0.0, z], [0.0, 0.0, 0.0]])
    return _cells(centers, axes, LENGTH, RADIUS, 1.0, np.zeros((2, 3)))


def mixed_overlaps(seed: int, *, n_pairs: int = 15) -> Cells:
    """A row of ``n_pairs`` sphere pairs at rest whose overlaps range log-uniformly from 1e-14 to 1 of
    the diameter in one scene (``b`` spans 14 decades)."""
    rng = np.random.default_rng(seed)
    n = n_pairs
    overlaps = np.logspace(-14, 0, n)
    rng.shuffle(overlaps)
    x = 10.0 * np.arange(n)
    direction = _unit(rng.standard_normal((n, 3)))
    centers = np.concatenate([np.column_stack([x, np.zeros((n, 2))]),
                              np.column_stack([x, np.zeros((n, 2))]) + (2 * RADIUS * (1 - overlaps))[:, None] * direction])
    return _cells(centers, np.tile([1.0, 0.0, 0.0], (2 * n, 1)), 0.0, RADIUS, 1.0, np.zeros((2 * n, 3)))


def velocity_pair(seed: int, *, speed: float) -> Cells:
    """The crossing pair of :func:`overlap_pair` (overlap 1e-3 of the diameter) approaching at
    relative speed ``speed`` [length/time]."""
    cells = overlap_pair(seed, overlap=OVERLAP)
    return cells.replace(momenta=np.array([[0.0, 0.0, -0.5 * speed], [0.0, 0.0, 0.5 * speed]]))


def mixed_velocities(seed: int, *, n_cells: int = 25) -> Cells:
    """A seeded cluster of rods whose approach speeds range log-uniformly from 1e-12 to 1e12 in
    one scene."""
    rng = np.random.default_rng(seed)
    cells = random_cluster(seed, n_cells=n_cells)
    speeds = 10.0 ** rng.uniform(-12, 12, n_cells)
    v = _unit(cells.centers.mean(axis=0) - cells.centers) * speeds[:, None]
    return cells.replace(momenta=v * cells.masses[:, None])


def random_cluster(seed: int, *, n_cells: int = 25, scale_length: float = 1.0, scale_mass: float = 1.0,
                   scale_time: float = 1.0) -> Cells:
    """A seeded 3D heap of ``n_cells`` rods (lengths 1–3, radius 0.5, density 1) squeezed towards its
    centroid, in units where a length is ``scale_length``, a mass ``scale_mass`` and a time
    ``scale_time`` (so the same scene can be written in m/kg/s and µm/pg/s)."""
    rng = np.random.default_rng(seed)
    n = n_cells
    side = 1.6 * n ** (1 / 3)
    centers = rng.uniform(0, side, (n, 3))
    axes = _unit(rng.standard_normal((n, 3)))
    lengths = rng.uniform(1.0, 3.0, n)
    masses = capsule_volume(lengths, RADIUS)  # density 1
    velocities = _compressed(centers, 1.0, rng)
    growth = rng.uniform(0.0, 0.5, n)
    cells = _cells(centers, axes, lengths, RADIUS, masses, velocities, growth_inertia=masses, growth_rates=growth)
    v_unit = scale_length / scale_time
    return Cells(cells.centers * scale_length, cells.axes, cells.lengths * scale_length, cells.radii * scale_length,
                 cells.masses * scale_mass, cells.growth_inertia * scale_mass, cells.momenta * scale_mass * v_unit,
                 cells.angular_momenta * scale_mass * scale_length * v_unit, cells.growth_momenta * scale_mass * v_unit)


def hub(seed: int, *, n_neighbours: int = 1000) -> Cells:
    """One big sphere touched by ``n_neighbours`` rods standing radially on it (tip contacts, a
    Fibonacci lattice of directions, seeded jitter), all moving inwards; masses by volume."""
    rng = np.random.default_rng(seed)
    n = n_neighbours
    big = RADIUS * np.sqrt(n / 1.2)  # surface area per neighbour ≈ 4.2 (2ρ)²
    k = np.arange(n) + 0.5
    phi = np.arccos(1 - 2 * k / n)
    theta = np.pi * (1 + 5**0.5) * k + 0.02 * rng.standard_normal(n)
    directions = np.column_stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)])
    axes = _unit(directions + 0.01 * rng.standard_normal((n, 3)))
    centers = (big + RADIUS * (1 - 2 * OVERLAP) + 0.5 * LENGTH) * directions
    centers = np.vstack([np.zeros(3), centers])
    axes = np.vstack([[1.0, 0.0, 0.0], axes])
    lengths = np.concatenate([[0.0], np.full(n, LENGTH)])
    radii = np.concatenate([[big], np.full(n, RADIUS)])
    masses = capsule_volume(lengths, radii)
    velocities = -directions * rng.uniform(0.5, 1.0, (n, 1))
    return _cells(centers, axes, lengths, radii, masses, np.vstack([np.zeros(3), velocities]))


def long_chain(seed: int, *, n_cells: int = 10_000) -> Cells:
    """``n_cells`` growing rods end to end along x (seeded tilts and lateral jitter), G = m."""
    rng = np.random.default_rng(seed)
    n = n_cells
    pitch = LENGTH + 2 * RADIUS * (1 - OVERLAP)
    centers = np.column_stack([pitch * np.arange(n), 1e-3 * rng.standard_normal(n), np.zeros(n)])
    axes = _unit(np.column_stack([np.ones(n), 1e-3 * rng.standard_normal(n), np.zeros(n)]))
    velocities = 0.05 * rng.standard_normal((n, 3)) * [1, 1, 0]
    return _cells(centers, axes, LENGTH, RADIUS, 1.0, velocities, growth_inertia=1.0, growth_rates=rng.uniform(0.5, 1.0, n))


def hexagonal_disks(seed: int, *, side: int = 12) -> Cells:
    """A planar hexagonal packing of ``side²`` spheres (2 unknowns each, about 3 contacts each),
    slightly overlapping and squeezed towards the centre: more contacts than unknowns."""
    rng = np.random.default_rng(seed)
    i, j = np.meshgrid(np.arange(side), np.arange(side), indexing="ij")
    pitch = 2 * RADIUS * (1 - OVERLAP)
    x = pitch * (i + 0.5 * (j % 2))
    y = pitch * np.sqrt(3) / 2 * j
    centers = np.column_stack([x.ravel(), y.ravel(), np.zeros(side * side)])
    centers[:, :2] += JITTER * pitch * rng.standard_normal((side * side, 2))
    velocities = _compressed(centers, 1.0, rng) * [1, 1, 0]
    return _cells(centers, np.tile([1.0, 0.0, 0.0], (side * side, 1)), 0.0, RADIUS, 1.0, velocities)


def fcc_spheres(seed: int, *, side: int = 5) -> Cells:
    """A face-centred cubic packing of spheres (3 unknowns, up to 6 contacts each), slightly
    overlapping and squeezed towards the centre."""
    rng = np.random.default_rng(seed)
    g = np.stack(np.meshgrid(*[np.arange(side)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    g = g[g.sum(axis=1) % 2 == 0]
    pitch = 2 * RADIUS * (1 - OVERLAP) / np.sqrt(2)
    centers = pitch * g.astype(float) + JITTER * pitch * rng.standard_normal(g.shape)
    velocities = _compressed(centers, 1.0, rng)
    return _cells(centers, np.tile([1.0, 0.0, 0.0], (len(g), 1)), 0.0, RADIUS, 1.0, velocities)


def rod_bundle(seed: int, *, side: int = 6) -> Cells:
    """A hexagonal bundle of parallel rods along z (5 unknowns each; two contacts per
    neighbour, up to 6 contacts per rod), squeezed sideways."""
    rng = np.random.default_rng(seed)
    i, j = np.meshgrid(np.arange(side), np.arange(side), indexing="ij")
    pitch = 2 * RADIUS * (1 - OVERLAP)
    x = pitch * (i + 0.5 * (j % 2))
    y = pitch * np.sqrt(3) / 2 * j
    n = side * side
    centers = np.column_stack([x.ravel(), y.ravel(), 0.01 * rng.standard_normal(n)])
    centers[:, :2] += JITTER * pitch * rng.standard_normal((n, 2))
    velocities = _compressed(centers, 1.0, rng) * [1, 1, 0]
    return _cells(centers, np.tile([0.0, 0.0, 1.0], (n, 1)), LENGTH, RADIUS, 1.0, velocities)


def squeezed_between_fixed(seed: int) -> Cells:
    """The scene of :func:`mass_sandwich` with the outer rods fixed (infinite mass) and the
    middle one moving: mass ratio ∞."""
    cells = mass_sandwich(seed, ratio=1.0)
    velocities = np.array([[0.0, 0.0, 0.0], [0.3, 0.1, 1.0], [0.0, 0.0, 0.0]])
    return _cells(cells.centers, cells.axes, LENGTH, RADIUS, np.array([np.inf, 1.0, np.inf]), velocities)


def near_duplicate(seed: int, *, interval: float = 1e-8) -> Cells:
    """Two parallel rods whose side-by-side interval is only ``interval`` times their length,
    so their two end contacts nearly coincide (two almost identical rows of M)."""
    rng = np.random.default_rng(seed)
    gap = 2 * RADIUS * (1 - OVERLAP)
    shift = LENGTH * (1 - interval)
    centers = np.array([[0.0, 0.0, 0.0], [shift, gap, 0.0]]) + [0.0, 0.0, 0.0]
    axes = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    velocities = np.array([[0.0, 1.0, 0.0], [0.0, -1.0, 0.0]]) + 0.1 * rng.standard_normal((2, 3)) * [1, 0, 0]
    return _cells(centers, axes, LENGTH, RADIUS, 1.0, velocities)


def overlap_end_contacts(cells: Cells) -> Contacts:
    """The two contacts at the ends of the overlap of the two rods of :func:`near_duplicate` (b's
    −end, a's +end), both kept: :func:`~qpcontact.geometry.select_contacts` would drop one of
    them as a near duplicate, and this case is there to show what solvers make of such rows."""
    return evaluate_contacts(cells, np.array([0, 0]), np.array([1, 1]), np.array([B_MINUS_END, A_PLUS_END]))


def duplicated_contacts(cells: Cells) -> Contacts:
    """Every contact of the scene twice (redundant rows of M: a singular Delassus operator)."""
    found = find_contacts(cells)
    return concatenate([found, found])


# ------------------------------------------------------------------------------------------
# The catalogue
# ------------------------------------------------------------------------------------------
def _catalogue() -> list[Scene]:
    cases: list[Scene] = []
    add = cases.append
    for ratio in (1e-8, 1e-4, 1e4, 1e8):
        add(Scene(f"mass_ratio_{ratio:g}", "mass_ratio",
                 f"a rod of mass {ratio:g} pressed between two rods of mass 1", partial(mass_sandwich, ratio=ratio)))
    add(Scene("mass_ratio_inf", "mass_ratio", "a rod pressed between two fixed (infinite-mass) rods",
             squeezed_between_fixed))
    for aspect in (0.0, 1e-8, 1.0, 1e2, 1e4):
        add(Scene(f"aspect_{aspect:g}", "aspect_ratio",
                 f"a rod with l/ρ = {aspect:g} crossed by 6 rods of the same shape" + (" (spheres)" if aspect == 0 else ""),
                 partial(crossing_star, aspect=aspect)))
    for g in (1e-8, 1.0, 1e8, np.inf):
        add(Scene(f"growth_inertia_{g:g}", "growth_inertia",
                 f"5 rods end to end pushing by growth, G = {g:g}" + (" (not growing, compressed)" if np.isinf(g) else ""),
                 partial(growing_chain, growth_inertia=g)))
    for angle in (1e-3, 1e-6, 1e-12, 0.0):
        add(Scene(f"parallel_{angle:g}", "geometry", f"two side-by-side rods at {angle:g} rad (planar)",
                 partial(angled_pair, angle=angle)))
    add(Scene("parallel_1e-12_3d", "geometry", "two side-by-side rods at 1e-12 rad, out of the plane",
             partial(angled_pair, angle=1e-12, planar=False)))
    add(Scene("crossing", "geometry", "two rods whose axes intersect (δ = 0)", crossing_axes))
    add(Scene("coincident", "geometry", "two identical rods with the same centre and axis", coincident))
    for overlap in (1e-14, 1e-8, 1e-3, 0.5, 1.0):
        add(Scene(f"overlap_{overlap:g}", "overlap", f"two crossing rods at rest overlapping by {overlap:g} diameter",
                 partial(overlap_pair, overlap=overlap), options={"position_correction": 1.0, "dt": 1.0}))
    add(Scene("overlap_mixed", "overlap", "15 sphere pairs at rest, overlaps 1e-14..1 diameter in one scene",
             mixed_overlaps, options={"position_correction": 1.0, "dt": 1.0}))
    for speed in (1e-12, 1e-6, 1e6, 1e12):
        add(Scene(f"velocity_{speed:g}", "velocity", f"two crossing rods approaching at {speed:g}",
                 partial(velocity_pair, speed=speed)))
    add(Scene("velocity_mixed", "velocity", "25 rods, approach speeds 1e-12..1e12 in one scene", mixed_velocities))
    add(Scene("units_m_kg_s", "units", "25 rods (ρ = 0.5 µm, density 1 pg/µm³) in m, kg, s",
             partial(random_cluster, scale_length=1e-6, scale_mass=1e-15)))
    add(Scene("units_um_pg_s", "units", "the same 25 rods in µm, pg, s", random_cluster))
    add(Scene("hub_1000", "hub", "a big sphere touched by 1000 radial rods", hub, large=True))
    add(Scene("chain_10000", "chain", "10⁴ growing rods end to end", long_chain, large=True))
    add(Scene("jammed_disks", "jammed", "144 disks in a hexagonal packing (planar): 381 contacts, 288 unknowns",
             hexagonal_disks, options=JAMMED_OPTIONS))
    add(Scene("jammed_fcc", "jammed", "63 spheres in an fcc packing: 240 contacts, 189 unknowns", fcc_spheres, options=JAMMED_OPTIONS))
    add(Scene("jammed_rod_bundle", "jammed", "36 parallel rods in a hexagonal bundle: 170 contacts, 180 unknowns, rank-deficient",
             rod_bundle, options=JAMMED_OPTIONS))
    add(Scene("duplicate_contacts", "duplicate", "a 25-rod heap with every contact listed twice",
             random_cluster, contacts=duplicated_contacts))
    add(Scene("near_duplicate", "duplicate", "two parallel rods whose two end contacts are 1e-8 length apart",
             near_duplicate, contacts=overlap_end_contacts))
    return cases


#: name -> Scene, in report order (each also registered in :data:`qpcontact.studies.scenes.SCENES`).
CATALOGUE: dict[str, Scene] = {case.name: register_scene(case) for case in _catalogue()}
