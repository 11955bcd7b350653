"""Motion of capsules over a step: exact rotations of axes, and the position-level move.

- :func:`rotate`: vectors turned by rotation vectors (Rodrigues' formula, exact for any angle);
- :func:`left_jacobian`: how the result of such a rotation moves when the rotation vector
  changes, the exact derivative the position-level step linearizes with;
- :func:`move`: cells at the end of a step with given generalized momenta (``q ⊕ dt·W·p``),
  the one motion map of the position step (:func:`qpcontact.position_step`) and the velocity
  step (:func:`qpcontact.step`).
"""

from __future__ import annotations

import numpy as np

from ..errors import InvalidArgumentError
from .cells import Cells


def rotate(vectors: np.ndarray, rotation: np.ndarray) -> np.ndarray:
    """Rotate each (N, 3) vector by its rotation vector (axis × angle [rad]) with Rodrigues'
    formula, exact for any angle; the results are renormalized to unit length (they are unit up
    to rounding)."""
    angle = np.linalg.norm(rotation, axis=1)
    turning = angle > 0
    out = np.array(vectors, dtype=float, copy=True)
    if turning.any():
        k = rotation[turning] / angle[turning, None]
        v = out[turning]
        cos, sin = np.cos(angle[turning])[:, None], np.sin(angle[turning])[:, None]
        out[turning] = (v * cos + np.cross(k, v) * sin
                        + k * np.einsum("ij,ij->i", k, v)[:, None] * (1.0 - cos))
    return out / np.linalg.norm(out, axis=1)[:, None]


def left_jacobian(rotation: np.ndarray) -> np.ndarray:
    """(N, 3, 3) the left Jacobian ``J(θ)`` of the rotation group at each rotation vector ``θ``:
    turning by ``θ + δθ`` is turning by ``θ``, then by ``J(θ)·δθ`` in the world frame (to first
    order), so a vector ``v = R(θ)v₀`` moves by ``(J(θ)δθ) × v``. ``J = I`` at ``θ = 0`` and
    ``J(θ)θ = θ``; it differs from ``I`` by ``O(|θ|)``, which is why a linearization that turns
    about the moved axes instead converges only linearly in 3D (docs/model-notes.md)::

        J(θ) = I + (1 − cos t)/t² [θ]× + (t − sin t)/t³ [θ]×²,   t = |θ|
    """
    theta = np.asarray(rotation, dtype=float)
    t = np.linalg.norm(theta, axis=1)
    small = t < 1e-4  # the series to second order (its error is below rounding there)
    safe = np.where(small, 1.0, t)
    a = np.where(small, 0.5 - t**2 / 24.0, (1.0 - np.cos(safe)) / safe**2)
    b = np.where(small, 1.0 / 6.0 - t**2 / 120.0, (safe - np.sin(safe)) / safe**3)
    cross = np.zeros((theta.shape[0], 3, 3))
    cross[:, 0, 1], cross[:, 0, 2], cross[:, 1, 2] = -theta[:, 2], theta[:, 1], -theta[:, 0]
    cross -= cross.transpose(0, 2, 1)
    return np.eye(3) + a[:, None, None] * cross + b[:, None, None] * cross @ cross


def turning_vectors(cells: Cells, dt: float, momenta: np.ndarray) -> np.ndarray:
    """(N, 3) the rotation vector of each cell over a step with generalized momenta ``momenta``
    (N, 7): ``dt·ω⊥``, the angular velocity ``I⁻¹L`` of ``cells`` across its axis (a spin about
    the cell's own axis turns nothing)."""
    moving = cells.replace(angular_momenta=momenta[:, 3:6])
    omega = moving.angular_velocities
    omega -= np.einsum("ij,ij->i", omega, cells.axes)[:, None] * cells.axes
    return omega * dt


def move(cells: Cells, dt: float, momenta: np.ndarray | None = None) -> Cells:
    """The cells at the end of a step of overdamped or free motion with generalized momenta
    ``momenta`` (N, 7) ``(p, L, g)``, the cells' own if None: centres by ``dt·p/m``, axes turned
    exactly by :func:`turning_vectors` (a spin about a cell's own axis turns nothing), lengths
    by ``dt·g/G``. Masses and inertia are those of ``cells`` (the start of the step); the
    returned cells carry ``momenta``. The one motion map of both steps: the position step's
    ``q ⊕ dt·W·p`` (:func:`qpcontact.position_step`) and the velocity step's move with the
    post-contact momenta (:func:`qpcontact.step`).

    Raises:
        InvalidArgumentError: a length would become negative (the step is too large for how
            fast contacts compress that cell), or a position, turn or length would not be a
            finite number (a huge ``dt``).
    """
    if momenta is None:
        momenta = cells.generalized_momenta()
    moving = cells.replace(momenta=momenta[:, 0:3], angular_momenta=momenta[:, 3:6], growth_momenta=momenta[:, 6])
    with np.errstate(over="ignore", invalid="ignore"):
        centers = cells.centers + moving.velocities * dt
        turns = turning_vectors(cells, dt, momenta)
        lengths = cells.lengths + moving.growth_rates * dt
    _check_motion(moving, dt, centers, turns, lengths)
    return moving.replace(centers=centers, axes=rotate(cells.axes, turns), lengths=lengths)


def _check_motion(moving: Cells, dt: float, centers: np.ndarray, turns: np.ndarray, lengths: np.ndarray) -> None:
    finite = np.isfinite(centers).all(axis=1) & np.isfinite(turns).all(axis=1) & np.isfinite(lengths)
    if not finite.all():
        i = int(np.flatnonzero(~finite)[0])
        raise InvalidArgumentError(
            f"dt = {dt!r} is too large: cell {i} would move, turn or grow beyond the range of numbers "
            f"(speed {np.linalg.norm(moving.velocities[i]):.3g}, turning rate "
            f"{np.linalg.norm(moving.angular_velocities[i]):.3g}, length rate {moving.growth_rates[i]:.3g}); take a "
            "smaller time step")
    negative = lengths < 0
    if negative.any():
        i = int(np.flatnonzero(negative)[0])
        raise InvalidArgumentError(
            f"dt = {dt!r} is too large: cell {i} would reach length {lengths[i]:.3g} < 0 "
            f"(length rate {moving.growth_rates[i]:.3g}); take a smaller time step")
