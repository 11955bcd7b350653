"""The row nᵀM_r against finite differences of a moving, growing body point (model.md): of the
motion written out here with scipy's rotations, and of the motion the package's own integrator
makes; and the seed's errata shown to be errors by the same finite differences."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import qpcontact as qc
from qpcontact.assembly.system import build_system
from qpcontact.geometry.contacts import Contacts
from qpcontact.geometry.motion import move, rotate


def random_cell(rng):
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    return qc.Cells(
        rng.normal(size=(1, 3)), axis[None], rng.uniform(0.5, 3.0, 1), rng.uniform(0.2, 0.8, 1),
        masses=rng.uniform(0.5, 3.0, 1), growth_inertia=rng.uniform(0.5, 3.0, 1),
        momenta=rng.normal(size=(1, 3)), angular_momenta=rng.normal(size=(1, 3)), growth_momenta=rng.normal(size=1),
    )


def material_point(cell, sigma, e, h):
    """Position at time h of the body point at axial fraction ``sigma`` (−½..½) and radial unit
    offset ``e`` (⊥ axis, or any direction at a tip), moving with the cell's velocities."""
    v, w, ldot = cell.velocities[0], cell.angular_velocities[0], cell.growth_rates[0]
    rot = Rotation.from_rotvec(w * h)
    c = cell.centers[0] + v * h
    a = rot.apply(cell.axes[0])
    length = cell.lengths[0] + ldot * h
    return c + sigma * length * a + cell.radii[0] * rot.apply(e)


def fd_velocity(cell, sigma, e, h=1e-6):
    return (material_point(cell, sigma, e, h) - material_point(cell, sigma, e, -h)) / (2 * h)


def sample_point(rng, cell, on_cap):
    a = cell.axes[0]
    if on_cap:
        sigma = rng.choice([-0.5, 0.5])
        e = rng.normal(size=3)
        e -= min(0.0, np.sign(sigma) * (e @ a)) * a * 2 * np.sign(sigma)  # outward hemisphere
        e /= np.linalg.norm(e)
    else:
        sigma = rng.uniform(-0.5, 0.5)
        e = np.cross(a, rng.normal(size=3))
        e /= np.linalg.norm(e)
    return sigma, e


def system_row(cell, sigma, e, n):
    """nᵀM_r p computed by qpcontact (a contact of the cell with a static body, normal n)."""
    offset = sigma * cell.lengths[0] * cell.axes[0] + cell.radii[0] * e
    contacts = Contacts(np.array([0]), np.array([-1]), n[None], offset[None], np.zeros((1, 3)),
                        np.array([sigma]), np.zeros(1), np.array([-0.1]), np.array([-1.0]), np.array([5]))
    system = build_system(cell, contacts, np.array([1.0]), reduce=False)
    y = system.from_impulses(cell.generalized_momenta())
    return float((system.matrix @ y)[0] * system.velocity_scale)


@pytest.mark.parametrize("seed", range(20))
@pytest.mark.parametrize("on_cap", [False, True])
def test_row_matches_finite_differences(seed, on_cap):
    rng = np.random.default_rng(seed)
    cell = random_cell(rng)
    sigma, e = sample_point(rng, cell, on_cap)
    n = rng.normal(size=3)
    n /= np.linalg.norm(n)
    expected = n @ fd_velocity(cell, sigma, e)
    assert system_row(cell, sigma, e, n) == pytest.approx(expected, rel=1e-7, abs=1e-8)


def test_seed_closed_form_normal_equation_block_is_not_MtM():
    """Erratum 5: each contact adds the rank-one (nᵀM_s)ᵀ(nᵀM_r) to MᵀM; the seed's printed
    diagonal 1/(M₁M₂) for the linear block ignores the normal."""
    rng = np.random.default_rng(11)
    cell = random_cell(rng)
    n = np.array([0.6, 0.8, 0.0])
    contacts = Contacts(np.array([0]), np.array([-1]), n[None], np.array([[0.1, 0.2, 0.3]]), np.zeros((1, 3)),
                        np.array([0.1]), np.zeros(1), np.array([-0.1]), np.array([-1.0]), np.array([5]))
    system = build_system(cell, contacts, np.array([1.0]), reduce=False)
    # Unscale to physical M in the slot basis (translation slots are world x, y, z).
    m_row = system.matrix.toarray()[0] * system.operator_scale * np.sqrt(system.column_inverse_mass)
    mtm = np.outer(m_row, m_row)
    m = cell.masses[0]
    assert mtm[0, 0] == pytest.approx(n[0] ** 2 / m**2)
    assert mtm[2, 2] == 0.0  # n_z = 0: no z-row in MᵀM at all
    assert mtm[0, 0] != pytest.approx(1.0 / m**2)  # the seed's 1/(M₁M₂) with M₁ = M₂ = m


def package_point(cell, sigma, e, h):
    """The body point at time h as the package's own integrator moves it:
    the velocity step's :func:`qpcontact.geometry.motion.move` (centre, axis by the exact rotation, length) and
    :func:`qpcontact.geometry.motion.rotate` for the radial offset, which turns with the body."""
    moved = move(cell, h)
    radial = rotate(e[None], cell.angular_velocities * h)[0]
    return moved.centers[0] + sigma * moved.lengths[0] * moved.axes[0] + cell.radii[0] * radial


@pytest.mark.parametrize("seed", range(10))
@pytest.mark.parametrize("on_cap", [False, True])
def test_row_matches_the_motion_of_the_package_integrator(seed, on_cap):
    """The contact row and the timestep integrator describe the same motion: the row predicts
    the velocity of a body point as move() moves it (central differences, O(h²))."""
    rng = np.random.default_rng(100 + seed)
    cell = random_cell(rng)
    sigma, e = sample_point(rng, cell, on_cap)
    n = rng.normal(size=3)
    n /= np.linalg.norm(n)
    h = 1e-6
    moved = (package_point(cell, sigma, e, h) - package_point(cell, sigma, e, -h)) / (2 * h)
    assert system_row(cell, sigma, e, n) == pytest.approx(n @ moved, rel=1e-7, abs=1e-8)


def test_erratum_1_the_angular_block_is_omega_cross_r():
    """Seed erratum 1: its M_r has +[r]×I⁻¹, i.e. a point velocity r × ω. For a cell that only
    turns, the package's row equals the finite difference of the motion (ω × r), and the
    seed's sign gives the opposite of it."""
    rng = np.random.default_rng(7)
    cell = random_cell(rng).replace(momenta=np.zeros((1, 3)), growth_momenta=[0.0])
    sigma, e = sample_point(rng, cell, False)
    r = sigma * cell.lengths[0] * cell.axes[0] + cell.radii[0] * e
    n = np.cross(cell.angular_velocities[0], r)
    n /= np.linalg.norm(n)  # the direction in which the point moves
    fd = n @ fd_velocity(cell, sigma, e)
    assert fd > 0.1
    assert system_row(cell, sigma, e, n) == pytest.approx(fd, rel=1e-7)
    assert n @ np.cross(r, cell.angular_velocities[0]) == pytest.approx(-fd, rel=1e-7)  # the seed's sign


def test_erratum_2_a_body_point_rides_with_the_full_length_rate():
    """Seed erratum 2: with l the full length, a point at axial coordinate s moves by
    (s/l) l̇ â, not ½ (s/l) l̇ â. For a cell that only grows, the package's row along the axis is
    the finite difference of the motion, which is twice the seed's."""
    rng = np.random.default_rng(3)
    cell = random_cell(rng).replace(momenta=np.zeros((1, 3)), angular_momenta=np.zeros((1, 3)))
    e = np.cross(cell.axes[0], [0.0, 0.0, 1.0])
    e /= np.linalg.norm(e)
    sigma, axis = 0.4, cell.axes[0]
    fd = axis @ fd_velocity(cell, sigma, e)
    assert fd == pytest.approx(sigma * cell.growth_rates[0], rel=1e-8)  # s/l · l̇, from the motion
    assert system_row(cell, sigma, e, axis) == pytest.approx(fd, rel=1e-7)
    assert abs(0.5 * sigma * cell.growth_rates[0] - fd) > 0.1 * abs(fd)  # the seed's factor ½ is off


def test_erratum_3_no_stray_cross_product_after_the_angular_term():
    """Correction 3 of docs/model.md: the original expansion of the velocity change has
    ``−[r]× I⁻¹ΔL × r``, i.e. ``(ω × r) × r`` for ``ω = I⁻¹ΔL``: a vector perpendicular to the
    motion ``ω × r`` of the point (and of units length²/time). For a cell that only turns, the
    package's row equals the finite difference of the motion along the direction the point moves;
    the stray form gives nothing along it."""
    rng = np.random.default_rng(5)
    cell = random_cell(rng).replace(momenta=np.zeros((1, 3)), growth_momenta=[0.0])
    sigma, e = sample_point(rng, cell, False)
    r = sigma * cell.lengths[0] * cell.axes[0] + cell.radii[0] * e
    omega = cell.angular_velocities[0]
    n = np.cross(omega, r)
    n /= np.linalg.norm(n)
    fd = n @ fd_velocity(cell, sigma, e)
    assert fd > 0.1
    assert system_row(cell, sigma, e, n) == pytest.approx(fd, rel=1e-7)
    stray = np.cross(np.cross(omega, r), r)  # −[r]×(I⁻¹ΔL) × r
    assert abs(n @ stray) < 1e-12 * np.linalg.norm(stray)
    assert np.linalg.norm(stray) > 0.1


def test_a_point_on_a_cap_rides_with_the_tip_not_with_its_own_axial_coordinate():
    """docs/model.md, "Corrections to the original derivation": the original growth term
    ``(â·r)/l`` uses the contact point's own axial coordinate; a point on a cap lies beyond the
    tip (``|â·r| > l/2``) and would move faster than it. The caps ride with the tips: the axial
    coordinate is clamped to ``±l/2``. For a cell that only grows, a point on the + cap moves
    along the axis at ``½ l̇`` (finite differences), as the package's row says."""
    rng = np.random.default_rng(9)
    cell = random_cell(rng).replace(momenta=np.zeros((1, 3)), angular_momenta=np.zeros((1, 3)))
    axis = cell.axes[0]
    e = axis + 0.5 * np.cross(axis, [0.0, 0.0, 1.0])  # on the + cap, off the axis
    e /= np.linalg.norm(e)
    r = 0.5 * cell.lengths[0] * axis + cell.radii[0] * e
    fd = axis @ fd_velocity(cell, 0.5, e)
    assert fd == pytest.approx(0.5 * cell.growth_rates[0], rel=1e-8)
    assert system_row(cell, 0.5, e, axis) == pytest.approx(fd, rel=1e-7)
    unclamped = (axis @ r) / cell.lengths[0] * cell.growth_rates[0]
    assert abs(unclamped - fd) > 0.1 * abs(fd)
