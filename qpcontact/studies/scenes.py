"""Reproducible scenes, and the one scene registry of the studies.

:data:`SCENES` maps a name to a :class:`Scene`; ``scene.make(seed=..., **size)`` builds it
(:func:`make_scene`). This module registers the colony snapshots and hand-made cases below;
:mod:`qpcontact.studies.catalogue` registers the stiff and extreme cases of the stability report
(importing :mod:`qpcontact.studies` imports both, so the registry is always complete).

Every generator here takes a cell count ``n_cells`` (ignored where the case fixes it) and a
``seed`` and returns a :class:`~qpcontact.Cells` whose momenta make pairs collide. Units: µm, pg,
minutes.

Colony snapshots (vectorized; 10⁵ cells take a few seconds):

- :func:`colony_2d`: a monolayer in the xy-plane, as E. coli grows under a coverslip. Cells sit
  in locally aligned *orientation domains* (Voronoi cells of a jittered grid of seeds, one
  director per domain, a degree or so of jitter per cell). Inside a domain cells lie in staggered
  rows, packed so that neighbours overlap by a few per cent of the diameter; where two domains
  meet, cells that would overlap too deeply are removed (the defects at domain walls).
- :func:`colony_3d`: a dome-shaped biofilm on a substrate (the plane z = 0): stacked aligned
  layers, each with its own domains, trimmed to nested paraboloids. Cells of adjacent layers cross
  at the angle between their domains. The substrate itself is not a contact here (this package
  has no plane contacts in ``find_contacts``); the bottom layer rests on it and never moves into it.

Momenta: each cell grows (finite growth inertia ``G``, growth momentum ``g = G·rate·l``, which
pushes the tips of end-to-end neighbours into each other) and has small random linear and
angular momenta (which make about half of the side-by-side contacts approach). Masses are
proportional to volume (density ``DENSITY``).

Hand-made cases: :func:`two_rods`, :func:`rod_chain`, :func:`rod_across_many`,
:func:`jammed_packing` (more contacts than unknowns).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.spatial import cKDTree

from ..errors import InvalidArgumentError
from ..geometry import Cells, Contacts, capsule_mass, find_contacts, inertia_times

#: Cell radius [µm] (E. coli).
RADIUS = 0.5
#: Cell lengths (cylinder part, without caps) are drawn uniformly from this range [µm].
LENGTH_RANGE = (2.0, 4.0)
#: Mass density [pg/µm³], so a cell weighs about 1 pg.
DENSITY = 1.1
#: Relative growth rate [1/min] (doubling in about 30 minutes).
GROWTH_RATE = np.log(2.0) / 30.0
#: Largest overlap kept between neighbours, as a fraction of the diameter.
MAX_OVERLAP = 0.10


# ------------------------------------------------------------------------------------------
# The registry
# ------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Scene:
    """One registered scene.

    Attributes:
        name: unique name.
        family: the family it belongs to (``hand-made``, ``colony``, and the catalogue's
            families: ``mass_ratio``, ``geometry``, ...).
        description: one line: what the scene is (and what makes it hard).
        make: ``make(seed=..., **size) -> Cells``, deterministic for a seed; ``size`` is the
            generator's size keyword (``n_cells``, ``n_neighbours``, ...), if it has one.
        contacts: ``contacts(cells) -> Contacts`` to hand to :func:`qpcontact.resolve`, or None
            (resolve finds them).
        options: further keywords for :func:`qpcontact.resolve` (e.g. position correction).
        large: a full-size scene that tests build smaller.
    """

    name: str
    family: str
    description: str
    make: Callable[..., Cells]
    contacts: Callable[[Cells], Contacts] | None = None
    options: dict[str, Any] = field(default_factory=dict)
    large: bool = False


#: name -> Scene, in registration order.
SCENES: dict[str, Scene] = {}


def register_scene(scene: Scene) -> Scene:
    """Add a scene to :data:`SCENES`. Returns it.

    Raises:
        ValueError: the name is taken.
    """
    if scene.name in SCENES:
        raise ValueError(f"scene {scene.name!r} is already registered")
    SCENES[scene.name] = scene
    return scene


def make_scene(name: str, n_cells: int | None = None, seed: int = 0, **size: Any) -> Cells:
    """The scene ``name`` from :data:`SCENES` (``n_cells=None`` and no ``size``: the generator's
    default size)."""
    if name not in SCENES:
        raise InvalidArgumentError(f"unknown scene {name!r}; known: {sorted(SCENES)}")
    if n_cells is not None:
        size["n_cells"] = n_cells
    return SCENES[name].make(seed=seed, **size)


# ------------------------------------------------------------------------------------------
# Cells with momenta
# ------------------------------------------------------------------------------------------
def moving_cells(
    rng: np.random.Generator,
    centers: np.ndarray,
    axes: np.ndarray,
    lengths: np.ndarray,
    *,
    radius: float = RADIUS,
    growth_rate: float = GROWTH_RATE,
    growth_inertia: float = 1.0,
    random_speed: float = 0.5,
    planar: bool = False,
) -> Cells:
    """Cells with growth and random momenta (see the module docstring).

    Args:
        rng: random generator.
        centers, axes, lengths: geometry (N, 3), (N, 3), (N,).
        radius: cell radius [µm].
        growth_rate: relative growth rate ``l̇/l`` [1/min].
        growth_inertia: ``G`` as a multiple of the cell mass (finite: growth is an unknown).
        random_speed: standard deviation of each random velocity component, as a multiple of the
            mean tip speed ``rate·l/2`` (angular: the same speed at the tips).
        planar: keep velocities in the xy-plane and rotation about z.
    """
    n = centers.shape[0]
    radii = np.full(n, radius)
    masses = capsule_mass(lengths, radii, DENSITY)
    tip_speed = growth_rate * float(np.mean(lengths)) / 2.0 if n else 0.0
    sigma_v = random_speed * tip_speed
    velocity = rng.normal(0.0, sigma_v, (n, 3))
    omega = rng.normal(0.0, 1.0, (n, 3)) * (sigma_v / np.maximum(lengths / 2.0 + radius, radius))[:, None]
    if planar:
        velocity[:, 2] = 0.0
        omega[:, :2] = 0.0
    g_inertia = growth_inertia * masses
    return Cells(
        centers=centers,
        axes=axes,
        lengths=lengths,
        radii=radii,
        masses=masses,
        growth_inertia=g_inertia,
        momenta=masses[:, None] * velocity,
        angular_momenta=inertia_times(axes, lengths, radii, masses, omega),
        growth_momenta=g_inertia * growth_rate * lengths,
        normalize_axes=True,
    )


# ------------------------------------------------------------------------------------------
# Colony snapshots
# ------------------------------------------------------------------------------------------
def aligned_layer(
    rng: np.random.Generator,
    colony_radius: float,
    *,
    radius: float = RADIUS,
    domain_size: float = 20.0,
    side_overlap: float = 0.04,
    angle_jitter_deg: float = 1.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Candidate cells of one aligned monolayer covering a disc (before the overlap pruning).

    Each domain lays a patch of staggered rows in its own rotated frame (vectorized over
    domains); a cell is kept when its centre is in its own domain's Voronoi cell and the disc.

    Returns:
        (centres (M, 2), angles (M,) [rad], lengths (M,)).
    """
    diameter = 2.0 * radius
    mean_len = float(np.mean(LENGTH_RANGE))
    # Domain seeds on a jittered square grid covering the disc.
    ticks = np.arange(-colony_radius - domain_size, colony_radius + domain_size + 1e-9, domain_size)
    gx, gy = np.meshgrid(ticks, ticks, indexing="ij")
    seeds = np.column_stack([gx.ravel(), gy.ravel()]) + rng.uniform(-0.35, 0.35, (gx.size, 2)) * domain_size
    seeds = seeds[np.linalg.norm(seeds, axis=1) <= colony_radius + 1.5 * domain_size]
    n_dom = seeds.shape[0]
    theta = rng.uniform(0.0, np.pi, n_dom)

    # A patch of rows around each seed, large enough to cover its Voronoi cell.
    half = 1.3 * domain_size
    row_pitch = diameter * (1.0 - side_overlap)
    n_rows = int(np.ceil(2 * half / row_pitch)) + 1
    n_per_row = int(np.ceil(2 * half / (mean_len + diameter))) + 3
    shape = (n_dom, n_rows, n_per_row)
    lengths = rng.uniform(*LENGTH_RANGE, shape)
    end_overlap = rng.uniform(0.01, MAX_OVERLAP * 0.9, shape) * diameter
    pitch = 0.5 * (lengths + np.roll(lengths, 1, axis=2)) + diameter - end_overlap
    pitch[:, :, 0] = 0.5 * lengths[:, :, 0]
    u = np.cumsum(pitch, axis=2) - half - rng.uniform(0.0, mean_len + diameter, (n_dom, n_rows, 1))
    v = np.broadcast_to((np.arange(n_rows) * row_pitch - half)[None, :, None], shape)
    c, s = np.cos(theta)[:, None, None], np.sin(theta)[:, None, None]
    x = seeds[:, 0, None, None] + c * u - s * v
    y = seeds[:, 1, None, None] + s * u + c * v
    owner = np.broadcast_to(np.arange(n_dom)[:, None, None], shape)
    centres = np.column_stack([x.ravel(), y.ravel()])
    _, nearest = cKDTree(seeds).query(centres)
    keep = (nearest == owner.ravel()) & (np.linalg.norm(centres, axis=1) <= colony_radius)
    angles = (np.broadcast_to(theta[:, None, None], shape).ravel()[keep]
              + np.deg2rad(angle_jitter_deg) * rng.standard_normal(int(keep.sum())))
    return centres[keep], angles, lengths.ravel()[keep]


def prune_deep_overlaps(centers: np.ndarray, axes: np.ndarray, lengths: np.ndarray, *,
                        radius: float = RADIUS, max_overlap: float = MAX_OVERLAP,
                        settled: np.ndarray | None = None) -> np.ndarray:
    """Indices of cells to keep so that no two overlap by more than ``max_overlap`` of the
    diameter. Contacts are found once; then, round by round, of every remaining too-deep pair one
    cell is removed: an unsettled one before a ``settled`` one, then the one with more such pairs,
    then the higher index. Removing cells only removes pairs, so the contact list stays valid
    (a loop over rounds, not over cells). Settled cells must not overlap each other too deeply."""
    probe = Cells(centers=centers, axes=axes, lengths=lengths, radii=radius)
    contacts = find_contacts(probe)
    deep = contacts.separation < -max_overlap * 2.0 * radius
    a, b = contacts.cell_a[deep], contacts.cell_b[deep]
    alive = np.ones(centers.shape[0], dtype=bool)
    rank = np.zeros(centers.shape[0]) if settled is None else settled.astype(float) * 1e9
    while True:
        live = alive[a] & alive[b]
        if not live.any():
            return np.flatnonzero(alive)
        a, b = a[live], b[live]
        count = np.bincount(np.concatenate([a, b]), minlength=alive.size) - rank
        alive[np.where((count[a] > count[b]) | ((count[a] == count[b]) & (a > b)), a, b)] = False


def _axis_points(centres: np.ndarray, axes: np.ndarray, lengths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centre and both tips of each axis segment: (3M, 3) points and (3M,) owner indices."""
    half = 0.5 * lengths[:, None] * axes
    points = np.concatenate([centres, centres - half, centres + half])
    return points, np.tile(np.arange(len(lengths)), 3)


def packed_layer(rng: np.random.Generator, colony_radius: float, *, domain_size: float,
                 fill_passes: int = 3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """An aligned layer with its domain walls pruned, then the gaps the pruning left filled by
    cells from further layers of smaller domains (which yield to the cells already placed).

    A fill candidate with an axis point (centre or tip) closer than the allowed distance to an
    axis point of a placed cell overlaps too deeply and is dropped before the exact check; the
    exact check then runs only on the candidates left and the placed cells near them.

    Returns:
        (centres (M, 3) with z = 0, axes (M, 3), lengths (M,)).
    """
    closest = 2.0 * RADIUS * (1.0 - MAX_OVERLAP)
    reach = float(LENGTH_RANGE[1]) + 2.0 * RADIUS
    c2, ang, lengths = aligned_layer(rng, colony_radius, domain_size=domain_size)
    centres = np.column_stack([c2, np.zeros(len(ang))])
    axes = np.column_stack([np.cos(ang), np.sin(ang), np.zeros(len(ang))])
    keep = prune_deep_overlaps(centres, axes, lengths)
    centres, axes, lengths = centres[keep], axes[keep], lengths[keep]
    for k in range(1, fill_passes + 1):  # a few passes, each vectorized
        c2, ang, new_len = aligned_layer(rng, colony_radius, domain_size=domain_size / (1 + k))
        new_c = np.column_stack([c2, np.zeros(len(ang))])
        new_ax = np.column_stack([np.cos(ang), np.sin(ang), np.zeros(len(ang))])
        placed_pts, placed_owner = _axis_points(centres, axes, lengths)
        new_pts, new_owner = _axis_points(new_c, new_ax, new_len)
        dist, _ = cKDTree(placed_pts).query(new_pts, distance_upper_bound=closest)
        clash = np.zeros(len(new_len), dtype=bool)
        clash[new_owner[dist < closest]] = True
        new_c, new_ax, new_len = new_c[~clash], new_ax[~clash], new_len[~clash]
        if not len(new_len):
            continue
        dist, _ = cKDTree(_axis_points(new_c, new_ax, new_len)[0]).query(placed_pts, distance_upper_bound=reach)
        near = np.unique(placed_owner[dist < reach])
        sub_c = np.vstack([centres[near], new_c])
        sub_ax = np.vstack([axes[near], new_ax])
        sub_len = np.concatenate([lengths[near], new_len])
        settled = np.arange(len(sub_len)) < near.size
        keep = prune_deep_overlaps(sub_c, sub_ax, sub_len, settled=settled)
        added = keep[keep >= near.size] - near.size
        centres = np.vstack([centres, new_c[added]])
        axes = np.vstack([axes, new_ax[added]])
        lengths = np.concatenate([lengths, new_len[added]])
    return centres, axes, lengths


def _area_per_cell(radius: float) -> float:
    diameter = 2.0 * radius
    return (float(np.mean(LENGTH_RANGE)) + diameter) * diameter


def _check_count(n_cells: int, least: int = 1) -> int:
    if int(n_cells) != n_cells or n_cells < least:
        raise InvalidArgumentError(f"n_cells: must be an integer >= {least}, got {n_cells!r}")
    return int(n_cells)


def colony_2d(n_cells: int = 1000, seed: int = 0, *, domain_size: float = 20.0, growth_inertia: float = 1.0,
              random_speed: float = 0.5) -> Cells:
    """A monolayer colony of ``n_cells`` rods in the xy-plane (centres, axes, momenta with z = 0).

    Args:
        n_cells: number of cells.
        seed: random seed (same seed, same scene).
        domain_size: spacing of the orientation domains [µm].
        growth_inertia: ``G`` as a multiple of the cell mass.
        random_speed: random velocities relative to the mean tip speed of growth.
    """
    n_cells = _check_count(n_cells)
    rng = np.random.default_rng(seed)
    colony_radius = np.sqrt(n_cells * _area_per_cell(RADIUS) / np.pi) * 1.1 + 3.0
    while True:  # enlarge the disc until it holds enough cells (nearly always the first time)
        centres, axes, lengths = packed_layer(rng, colony_radius, domain_size=domain_size)
        if lengths.size >= n_cells:
            break
        colony_radius *= 1.15
    kept = np.argsort(np.linalg.norm(centres, axis=1), kind="stable")[:n_cells]
    return moving_cells(rng, centres[kept], axes[kept], lengths[kept], growth_inertia=growth_inertia,
                        random_speed=random_speed, planar=True)


def colony_3d(n_cells: int = 1000, seed: int = 0, *, aspect: float = 0.35, domain_size: float = 20.0,
              tilt_deg: float = 1.0, growth_inertia: float = 1.0, random_speed: float = 0.5) -> Cells:
    """A dome-shaped biofilm of ``n_cells`` rods on the substrate z = 0.

    Aligned layers (each with its own orientation domains, see :func:`packed_layer`) are stacked
    4 % of a diameter less than a diameter apart and trimmed to the paraboloid dome ``z ≤ H(1 − r²/R²)`` with ``H = aspect·R``;
    the ``n_cells`` cells deepest inside the dome are kept. Axes tilt out of their layer by about
    ``tilt_deg``. The bottom layer lies on the substrate (``z = ρ``) and does not move into it.
    """
    n_cells = _check_count(n_cells)
    rng = np.random.default_rng(seed)
    diameter = 2.0 * RADIUS
    layer_pitch = diameter * (1.0 - 0.04)
    volume_per_cell = _area_per_cell(RADIUS) * layer_pitch
    base_radius = (2.0 * n_cells * volume_per_cell / (np.pi * aspect)) ** (1.0 / 3.0) * 1.05 + 2.0
    while True:  # enlarge the dome until it holds enough cells (nearly always the first time)
        height = aspect * base_radius
        parts = []
        for k in range(int(np.floor((height - RADIUS) / layer_pitch)) + 1):  # a few layers, each vectorized
            z = RADIUS + k * layer_pitch
            layer_radius = base_radius * np.sqrt(max(0.0, 1.0 - z / height))
            if layer_radius < 1.0:
                break
            c, ax, lens = packed_layer(rng, layer_radius, domain_size=domain_size)
            c[:, 2] = z
            parts.append((c, ax, lens))
        centres = np.vstack([p[0] for p in parts])
        axes = np.vstack([p[1] for p in parts])
        lengths = np.concatenate([p[2] for p in parts])
        # Tilt out of the layer, bounded so that a tip rises or sinks by at most 3 % of the
        # diameter: layers overlap by 4 % + 2·3 % at most, within MAX_OVERLAP, so stacking the
        # pruned layers needs no further pruning.
        bound = np.arcsin(np.minimum(1.0, 0.03 * diameter / (0.5 * np.maximum(lengths, 1e-9))))
        tilt = np.clip(np.deg2rad(tilt_deg) * rng.standard_normal(len(lengths)), -bound, bound)
        tilt[centres[:, 2] <= RADIUS + 1e-9] = 0.0  # the bottom layer lies flat on the substrate
        axes = np.column_stack([axes[:, :2] * np.cos(tilt)[:, None], np.sin(tilt)])
        depth = np.sum(centres[:, :2] ** 2, axis=1) / base_radius**2 + centres[:, 2] / height
        if lengths.size >= n_cells:
            break
        base_radius *= 1.1
    kept = np.argsort(depth, kind="stable")[:n_cells]
    cells = moving_cells(rng, centres[kept], axes[kept], lengths[kept], growth_inertia=growth_inertia,
                         random_speed=random_speed)
    on_substrate = cells.centers[:, 2] <= RADIUS + 1e-9
    momenta = cells.momenta.copy()
    momenta[on_substrate, 2] = np.abs(momenta[on_substrate, 2])
    return cells.replace(momenta=momenta)


# ------------------------------------------------------------------------------------------
# Hand-made cases
# ------------------------------------------------------------------------------------------
def two_rods(n_cells: int = 2, seed: int = 0) -> Cells:
    """Two growing rods in the plane meeting at an angle (T-junction with a small overlap),
    driven into each other. ``n_cells`` is ignored (always 2)."""
    rng = np.random.default_rng(seed)
    angle = rng.uniform(0.3, 1.2)
    lengths = np.array([3.0, 2.5])
    axes = np.array([[1.0, 0.0, 0.0], [np.cos(angle), np.sin(angle), 0.0]])
    # Rod b's tip touches rod a's side with a 5 % overlap.
    tip_b = np.array([0.4, 2 * RADIUS * 0.95, 0.0])
    centers = np.array([[0.0, 0.0, 0.0], tip_b + 0.5 * lengths[1] * axes[1]])
    cells = moving_cells(rng, centers, axes, lengths, random_speed=0.0, planar=True)
    speed = GROWTH_RATE * 3.0
    momenta = cells.masses[:, None] * np.array([[0.0, speed, 0.0], [0.0, -speed, 0.0]])
    return cells.replace(momenta=momenta)


def rod_chain(n_cells: int = 10, seed: int = 0) -> Cells:
    """``n_cells`` growing rods end to end along x, each tip overlapping the next by 1–10 % of
    the diameter, with small random sideways motion: every end contact is pushed together."""
    n_cells = _check_count(n_cells, 2)
    rng = np.random.default_rng(seed)
    lengths = rng.uniform(*LENGTH_RANGE, n_cells)
    overlap = rng.uniform(0.01, 0.1, n_cells) * 2 * RADIUS
    pitch = 0.5 * (lengths + np.roll(lengths, 1)) + 2 * RADIUS - overlap
    pitch[0] = 0.0
    x = np.cumsum(pitch)
    centers = np.column_stack([x - x.mean(), np.zeros(n_cells), np.zeros(n_cells)])
    axes = np.tile([1.0, 0.0, 0.0], (n_cells, 1))
    return moving_cells(rng, centers, axes, lengths, random_speed=0.2, planar=True)


def rod_across_many(n_cells: int = 9, seed: int = 0) -> Cells:
    """One long rod (3D) lying across ``n_cells − 1`` parallel rods beneath it, pressed down
    onto them; the rods below are spaced so they do not touch each other."""
    n_cells = _check_count(n_cells, 2)
    rng = np.random.default_rng(seed)
    n_below = n_cells - 1
    spacing = 2 * RADIUS * 1.2
    x = (np.arange(n_below) - (n_below - 1) / 2) * spacing
    below = np.column_stack([x, rng.uniform(-0.5, 0.5, n_below), np.zeros(n_below)])
    top_len = n_below * spacing + 1.0
    z_top = 2 * RADIUS * 0.95 + rng.uniform(-0.02, 0.02)
    centers = np.vstack([below, [[0.0, 0.0, z_top]]])
    axes = np.vstack([np.tile([0.0, 1.0, 0.0], (n_below, 1)), [[1.0, 0.0, 0.0]]])
    lengths = np.concatenate([rng.uniform(*LENGTH_RANGE, n_below), [top_len]])
    cells = moving_cells(rng, centers, axes, lengths, random_speed=0.2)
    momenta = cells.momenta.copy()
    momenta[-1, 2] = -cells.masses[-1] * GROWTH_RATE * 2.0  # the long rod comes down
    return cells.replace(momenta=momenta)


def jammed_packing(n_cells: int = 61, seed: int = 0) -> Cells:
    """A hexagonal packing of spheres (l = 0, non-growing) inside a ring of fixed spheres,
    compressed towards the centre: each mobile sphere has 2 unknowns (planar) but about 3
    contacts, so ``M x = b`` has more rows than unknowns. The mobile spheres are jittered by 2 %
    of the radius so that overlaps are uneven: with position correction ``b`` then has a part no
    velocity field produces and ``M x = b`` has no solution (with plain ``b = −u`` it always has
    one, see docs/model-notes.md)."""
    n_cells = _check_count(n_cells, 7)
    rng = np.random.default_rng(seed)
    pitch = 2 * RADIUS * 0.95
    # Hexagonal rings needed for n_cells (1 + 3r(r + 1) >= n), plus one ring for the wall.
    rings = int(np.ceil((-3 + np.sqrt(9 + 12 * (n_cells - 1))) / 6)) + 1
    grid_i, grid_j = np.meshgrid(np.arange(-rings, rings + 1), np.arange(-rings, rings + 1), indexing="ij")
    i, j = grid_i.ravel(), grid_j.ravel()
    hex_dist = np.maximum(np.abs(i), np.maximum(np.abs(j), np.abs(i + j)))
    inside_rings = hex_dist <= rings
    i, j, hex_dist = i[inside_rings], j[inside_rings], hex_dist[inside_rings]
    pos = np.column_stack([pitch * (i + 0.5 * j), pitch * (np.sqrt(3) / 2) * j, np.zeros(i.size)])
    order = np.lexsort((np.arctan2(pos[:, 1], pos[:, 0]), np.linalg.norm(pos, axis=1)))
    inside = order[:n_cells]
    # The wall: every site of the last ring and the unfilled sites of the ring before it, so
    # it touches the outermost mobile spheres.
    wall = order[np.isin(order, np.flatnonzero(hex_dist >= rings - 1)) & ~np.isin(order, inside)]
    mobile = pos[inside] + np.column_stack([rng.normal(0.0, 0.02 * RADIUS, (n_cells, 2)), np.zeros(n_cells)])
    centers = np.vstack([mobile, pos[wall]])
    n_all = centers.shape[0]
    axes = np.tile([1.0, 0.0, 0.0], (n_all, 1))
    masses = np.concatenate([capsule_mass(np.zeros(n_cells), np.full(n_cells, RADIUS), DENSITY),
                             np.full(n_all - n_cells, np.inf)])
    velocity = -0.05 * centers + rng.normal(0.0, 0.01, (n_all, 3))
    velocity[:, 2] = 0.0
    velocity[n_cells:] = 0.0
    momenta = np.where(np.isfinite(masses), masses, 0.0)[:, None] * velocity
    return Cells(centers=centers, axes=axes, lengths=0.0, radii=RADIUS, masses=masses, momenta=momenta)


for _generator, _family in ((two_rods, "hand-made"), (rod_chain, "hand-made"), (rod_across_many, "hand-made"),
                           (jammed_packing, "hand-made"), (colony_2d, "colony"), (colony_3d, "colony")):
    register_scene(Scene(_generator.__name__, _family, (_generator.__doc__ or "").split("\n\n")[0].replace("\n", " "),
                         _generator))
