"""Each error measure of model.md on a case whose answer is known by hand.

The case: two spheres (radius ½, masses 1 and 3) meeting head-on along x at speeds +1 and −1,
overlapping by 5 %. One contact, normal −x̂ (from b to a), approach speed u = −2, so b = 2. The
inelastic answer is the common velocity ``(m_a − m_b)/(m_a + m_b) = −½`` for both, with contact
impulse ``λ = 2/(1/m_a + 1/m_b) = 1.5``. Scaled: with a single contact ``Ã = B̃B̃ᵀ = 1`` and ``b̃ = 1``.
"""

import numpy as np
import pytest

from qpcontact import Cells, build_system, colliding, find_contacts
from qpcontact.resolve import metrics
from qpcontact.solvers.linear import solve_min_norm

M_A, M_B = 1.0, 3.0


@pytest.fixture
def head_on():
    cells = Cells(
        centers=[[0.0, 0.0, 0.0], [0.95, 0.0, 0.0]], axes=[1.0, 0.0, 0.0], lengths=0.0, radii=0.5,
        masses=[M_A, M_B], momenta=[[M_A * 1.0, 0.0, 0.0], [M_B * -1.0, 0.0, 0.0]],
    )
    active, b = colliding(find_contacts(cells))
    system = build_system(cells, active, b)
    exact = solve_min_norm(system.matrix, system.rhs, tolerance=1e-14)
    return cells, system, exact.y, exact.lam


def test_the_case_is_what_the_docstring_says(head_on):
    cells, system, y, lam = head_on
    assert system.shape == (1, 4)  # planar spheres: x, y translation each
    np.testing.assert_allclose(system.b, [2.0])
    np.testing.assert_allclose(system.rhs, [1.0])
    np.testing.assert_allclose((system.matrix @ system.matrix.T).toarray(), [[1.0]])
    np.testing.assert_allclose(system.to_contact_impulses(lam), [1.5])
    after = cells.with_impulses(system.to_impulses(y))
    np.testing.assert_allclose(after.velocities[:, 0], [-0.5, -0.5], atol=1e-12)


def test_penetration(head_on):
    _, system, y, _ = head_on
    assert metrics.penetration(system, y) == pytest.approx(0.0, abs=1e-14)
    assert metrics.penetration(system, np.zeros_like(y)) == pytest.approx(1.0)  # nothing done: full approach
    assert metrics.penetration(system, 0.25 * y) == pytest.approx(0.75)  # a quarter of the impulse
    assert metrics.penetration(system, 2.0 * y) == 0.0  # bouncing apart does not penetrate


def test_complementarity_residual(head_on):
    _, system, y, lam = head_on
    assert metrics.complementarity_residual(system, y, lam) == pytest.approx(0.0, abs=1e-14)
    # Nothing done: slack −b̃ = −1 at λ = 0 → |min(0, −1)| = 1.
    assert metrics.complementarity_residual(system, np.zeros_like(y), np.zeros(1)) == pytest.approx(1.0)
    # A pulling impulse with the right velocities: |min(−0.3, 0)| = 0.3.
    assert metrics.complementarity_residual(system, y, np.array([-0.3])) == pytest.approx(0.3)
    # Twice the impulse: slack B̃(2ỹ) − b̃ = 1 and λ̃ = 2 → min = 1.
    assert metrics.complementarity_residual(system, 2 * y, 2 * lam) == pytest.approx(1.0)


def test_duality_gap(head_on):
    _, system, y, lam = head_on
    assert metrics.duality_gap(system, y, lam) == pytest.approx(0.0, abs=1e-14)
    # ỹ = 2ỹ*, λ̃ = 2: gap |2·1| over ‖2ỹ*‖² = 4 → ½.
    assert metrics.duality_gap(system, 2 * y, 2 * lam) == pytest.approx(0.5)


def test_distance(head_on):
    _, _, y, _ = head_on
    assert metrics.distance(y, y) == 0.0
    assert metrics.distance(2 * y, y) == pytest.approx(1.0)
    assert metrics.distance(np.zeros_like(y), y) == pytest.approx(1.0)
    e = np.zeros_like(y)
    e[0] = 1e-3
    assert metrics.distance(y + e, y) == pytest.approx(1e-3 / np.linalg.norm(y))


def test_objective_gap(head_on):
    _, system, y, _ = head_on
    # complementarity: f = ½‖ỹ‖², ‖ỹ*‖² = Ã = 1, so f(ỹ*) = ½, f(2ỹ*) = 2; normalized by ½‖b̃‖² = ½.
    assert metrics.objective_gap(system, "complementarity", y, y) == 0.0
    assert metrics.objective_gap(system, "complementarity", 2 * y, y) == pytest.approx(3.0)
    # least_squares: f = ½‖B̃ỹ − b̃‖² = 0 at ỹ*, ½ at 0 → gap 1.
    assert metrics.objective_gap(system, "least_squares", np.zeros_like(y), y) == pytest.approx(1.0)


def test_physics_of_the_exact_answer(head_on):
    cells, system, y, lam = head_on
    out = metrics.physics(cells, system, system.to_impulses(y), system.to_contact_impulses(lam))
    assert out["momentum_change"] == pytest.approx(0.0, abs=1e-14)
    assert out["angular_momentum_change"] == pytest.approx(0.0, abs=1e-14)
    # Perfectly inelastic: KE before 2, after 4·(−½)²/2 = ½ → ΔKE = −3/2; relative to the
    # impulse energy ½λ²(1/m_a + 1/m_b) = 3/2 → −1.
    assert out["energy_change"] == pytest.approx(-1.5)
    assert out["energy_change_relative"] == pytest.approx(-1.0)


def test_physics_sees_momentum_that_is_not_equal_and_opposite(head_on):
    cells, system, _, _ = head_on
    impulses = np.zeros((2, 7))
    impulses[0, 0] = -3.0  # only cell a is pushed: net momentum −3 for Σ|λ| = 3 → 1
    out = metrics.physics(cells, system, impulses, np.array([3.0]))
    assert out["momentum_change"] == pytest.approx(1.0)
    # ΔKE of a alone: (−2)²/2 − 1/2 = 3/2 > 0: the check reports energy created.
    assert out["energy_change"] == pytest.approx(1.5)
    assert out["energy_change_relative"] > 0


def test_minimum_euclidean_norm_answer_breaks_momentum(head_on):
    """model.md: the minimum Euclidean-norm solution (CG on raw impulses) is not physical when
    masses differ; measured with the metrics (the W-norm answer conserves momentum)."""
    from qpcontact.solvers.baselines import conjugate_gradient

    cells, system, y, _ = head_on
    euclid = conjugate_gradient(system.matrix, system.rhs, tolerance=1e-12, metric="euclidean",
                                column_inverse_mass=system.column_inverse_mass)
    assert euclid.converged
    assert metrics.penetration(system, euclid.y) == pytest.approx(0.0, abs=1e-12)  # still stops the approach
    out = metrics.physics(cells, system, system.to_impulses(euclid.y), None)
    assert out["momentum_change"] > 0.1
    assert metrics.distance(euclid.y, y) > 0.1
