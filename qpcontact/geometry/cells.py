"""Cells: N capsules stored as a structure of arrays.

A cell is a capsule (spherocylinder): a cylinder of length ``l`` and radius ``ρ`` along the unit
axis ``â``, capped by two hemispheres, centred at ``c``. Units are the caller's own, as long as
they are consistent (e.g. µm, pg, s or m, kg, s); qpcontact never assumes a unit system.

Generalized momentum of a cell (7 numbers): linear momentum ``p`` (3), angular momentum ``L``
(3) and growth momentum ``g`` (1). Velocities: ``v = p/m``, ``ω = I⁻¹L``, ``l̇ = g/G``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike

from ..checks import flag, real_array
from ..errors import InvalidCellsError

#: Largest deviation of ``|â|`` from 1 that is accepted (and then renormalized to the last bit).
AXIS_UNIT_TOLERANCE = 1e-6
#: Axes and normals with |z| below this count as lying in the xy-plane; centres whose heights
#: differ by less than this times the largest radius count as one layer.
PLANAR_TOLERANCE = 1e-12


def _array(name: str, value: Any, n: int, tail: tuple[int, ...]) -> np.ndarray:
    """``value`` as a float array of shape ``(n, *tail)``; scalars (and ``tail`` vectors)
    broadcast. Strings, complex values and ragged nesting are refused."""
    arr = real_array(name, value, InvalidCellsError)
    shape = (n, *tail)
    if arr.shape == shape:
        return arr.copy()
    if arr.ndim <= len(tail) and arr.shape == tail[len(tail) - arr.ndim :]:
        return np.broadcast_to(arr, shape).copy()
    raise InvalidCellsError(f"{name}: expected shape {shape} (or a broadcastable scalar), got {arr.shape}")


def _check(name: str, arr: np.ndarray, *, allow_inf: bool = False) -> None:
    bad = np.isnan(arr) if allow_inf else ~np.isfinite(arr)
    if bad.any():
        index = int(np.argwhere(bad)[0][0])
        what = "NaN" if allow_inf else "NaN or inf"
        raise InvalidCellsError(f"{name}: {what} at cell {index} ({int(bad.any(axis=tuple(range(1, arr.ndim))).sum())} cells)")


def _positive(name: str, arr: np.ndarray) -> None:
    bad = ~(arr > 0)
    if bad.any():
        index = int(np.flatnonzero(bad)[0])
        raise InvalidCellsError(f"{name}: must be > 0, got {arr[index]!r} at cell {index}")


def _unit_axes(axes: np.ndarray, normalize: bool) -> None:
    """Divide the (N, 3) axes by their lengths in place; refuse a zero axis, and one not of unit
    length unless ``normalize``. |a| of axes like 1e200 overflows (and the axis became zero after
    the division), of axes like 1e-200 underflows: such axes are divided by their largest
    component first (only those: dividing a unit axis again would change its last bits)."""
    largest = np.max(np.abs(axes), axis=1)
    with np.errstate(over="ignore", under="ignore"):
        norms = np.linalg.norm(axes, axis=1)
    extreme = (largest > 0) & ~((norms > 1e-150) & (norms < 1e150))
    if extreme.any():
        axes[extreme] /= largest[extreme, None]
        norms[extreme] = np.linalg.norm(axes[extreme], axis=1) * largest[extreme]
    zero = ~(largest > 0)
    if zero.any():
        raise InvalidCellsError(f"axes: zero axis at cell {int(np.flatnonzero(zero)[0])}")
    off = np.abs(norms - 1.0) > AXIS_UNIT_TOLERANCE
    if off.any() and not normalize:
        index = int(np.flatnonzero(off)[0])
        raise InvalidCellsError(
            f"axes: not unit length at cell {index} (|a| = {norms[index]:.6g}); "
            "pass normalize_axes=True to normalize them"
        )
    norms[extreme] /= largest[extreme]
    axes /= norms[:, None]


def perpendicular_basis(axes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors e₁, e₂ with (â, e₁, e₂) right-handed orthonormal. For â in the xy-plane,
    e₂ = −ẑ, so a planar scene keeps only e₂."""
    ref = np.zeros_like(axes)
    near_z = np.abs(axes[:, 2]) > 0.9
    ref[~near_z, 2] = 1.0
    ref[near_z, 0] = 1.0
    e1 = np.cross(axes, ref)
    e1 /= np.linalg.norm(e1, axis=1)[:, None]
    return e1, np.cross(axes, e1)


@dataclass(frozen=True, eq=False)
class Cells:
    """N capsule cells as arrays (structure of arrays). Arrays are validated and copied on
    construction; scalars broadcast to every cell.

    Attributes:
        centers: (N, 3) centre positions [length].
        axes: (N, 3) unit axis directions. Axes within ``AXIS_UNIT_TOLERANCE`` of unit length
            are renormalized; others are rejected unless ``normalize_axes=True`` is given to
            the constructor, and zero axes are always rejected.
        lengths: (N,) cylinder length ``l`` (not counting the caps), ``>= 0``; 0 is a sphere
            [length].
        radii: (N,) radius ``ρ > 0`` [length].
        masses: (N,) mass ``m > 0`` [mass]; ``inf`` marks a fixed cell: it neither moves, turns
            nor changes length (its growth inertia counts as infinite too).
        growth_inertia: (N,) growth inertia ``G > 0`` [mass]; ``inf`` marks a cell whose length
            contacts cannot change (a non-growing cell).
        momenta: (N, 3) linear momentum ``p`` [mass·length/time].
        angular_momenta: (N, 3) angular momentum ``L`` [mass·length²/time].
        growth_momenta: (N,) growth momentum ``g = G·l̇`` [mass·length/time].
    """

    centers: np.ndarray
    axes: np.ndarray
    lengths: np.ndarray
    radii: np.ndarray
    masses: Any = 1.0
    growth_inertia: Any = np.inf
    momenta: Any = 0.0
    angular_momenta: Any = 0.0
    growth_momenta: Any = 0.0
    normalize_axes: dataclasses.InitVar[bool] = False

    if TYPE_CHECKING:  # the constructor takes array-likes (scalars broadcast); the attributes are arrays
        def __init__(self, centers: ArrayLike, axes: ArrayLike, lengths: ArrayLike, radii: ArrayLike,
                     masses: ArrayLike = 1.0, growth_inertia: ArrayLike = np.inf, momenta: ArrayLike = 0.0,
                     angular_momenta: ArrayLike = 0.0, growth_momenta: ArrayLike = 0.0,
                     normalize_axes: bool = False) -> None: ...

    def __post_init__(self, normalize_axes: bool) -> None:
        normalize_axes = flag("normalize_axes", normalize_axes, error=InvalidCellsError)
        centers = real_array("centers", self.centers, InvalidCellsError)
        if centers.ndim != 2 or centers.shape[1] != 3:
            raise InvalidCellsError(f"centers: expected shape (N, 3), got {np.shape(centers)}")
        n = centers.shape[0]
        arrays = {
            "centers": _array("centers", self.centers, n, (3,)),
            "axes": _array("axes", self.axes, n, (3,)),
            "lengths": _array("lengths", self.lengths, n, ()),
            "radii": _array("radii", self.radii, n, ()),
            "masses": _array("masses", self.masses, n, ()),
            "growth_inertia": _array("growth_inertia", self.growth_inertia, n, ()),
            "momenta": _array("momenta", self.momenta, n, (3,)),
            "angular_momenta": _array("angular_momenta", self.angular_momenta, n, (3,)),
            "growth_momenta": _array("growth_momenta", self.growth_momenta, n, ()),
        }
        for name in ("centers", "axes", "lengths", "radii", "momenta", "angular_momenta", "growth_momenta"):
            _check(name, arrays[name])
        for name in ("masses", "growth_inertia"):
            _check(name, arrays[name], allow_inf=True)
        _positive("radii", arrays["radii"])
        _positive("masses", arrays["masses"])
        _positive("growth_inertia", arrays["growth_inertia"])
        negative = arrays["lengths"] < 0
        if negative.any():
            index = int(np.flatnonzero(negative)[0])
            raise InvalidCellsError(f"lengths: must be >= 0, got {arrays['lengths'][index]!r} at cell {index}")
        _unit_axes(arrays["axes"], normalize_axes)
        # Arrays are private copies (the caller's inputs are never aliased); they stay writeable
        # so that libraries needing writable buffers accept them.
        for name, arr in arrays.items():
            object.__setattr__(self, name, arr)
        self._check_inverses()

    def _check_inverses(self) -> None:
        """Inverse masses and inertias must be numbers: radii of 1e-170 (ρ² underflows to 0) or
        masses of 1e-320 gave infinite inverse inertias and NaN velocities."""
        movable = np.isfinite(self.masses)
        with np.errstate(divide="ignore", over="ignore", under="ignore", invalid="ignore"):
            inverses = (("1/m", self.inverse_masses), ("1/I∥ = 2/(mρ²)", self.inverse_inertia_parallel),
                        ("1/I⊥ = 12/(m(3ρ² + l²))", self.inverse_inertia_perpendicular))
        for what, inverse in inverses:
            bad = movable & ~(np.isfinite(inverse) & (inverse > 0))
            if bad.any():
                i = int(np.flatnonzero(bad)[0])
                raise InvalidCellsError(f"masses, radii, lengths: {what} is not a finite positive number at cell {i} "
                                        f"(m = {self.masses[i]!r}, ρ = {self.radii[i]!r}, l = {self.lengths[i]!r}); "
                                        "rescale the units")

    # ----------------------------------------------------------------------------------------
    @property
    def n(self) -> int:
        """Number of cells."""
        return self.centers.shape[0]

    def __len__(self) -> int:
        return self.n

    def is_monolayer(self) -> bool:
        """All centres at one height z, every axis in the xy-plane, and the motion in it (no
        momentum along z, no angular momentum about an in-plane axis), to
        :data:`PLANAR_TOLERANCE`: a scene that the planar reduction can solve, and whose
        contacts must keep their normals in the plane."""
        if self.n == 0:
            return True

        def flat(values: np.ndarray, columns: Any) -> bool:
            return bool(np.all(np.abs(values[:, columns]) <= PLANAR_TOLERANCE * float(np.max(np.abs(values)))))

        spread = float(np.ptp(self.centers[:, 2]))
        return (spread <= PLANAR_TOLERANCE * float(np.max(self.radii)) and flat(self.axes, 2)
                and flat(self.momenta, 2) and flat(self.angular_momenta, slice(0, 2)))

    def copy(self) -> Cells:
        """The same cells, bit for bit, in arrays of their own (no validation again: a new
        construction would renormalize the axes, changing their last bits)."""
        out = object.__new__(type(self))
        for name, value in vars(self).items():
            object.__setattr__(out, name, value.copy() if isinstance(value, np.ndarray) else value)
        return out

    def replace(self, **changes: Any) -> Cells:
        """A new, validated Cells with some arrays replaced (``dataclasses.replace``)."""
        return dataclasses.replace(self, **changes)

    def subset(self, index: Any) -> Cells:
        """The cells selected by ``index`` (boolean mask or integer indices), in that order."""
        return Cells(**{f.name: getattr(self, f.name)[index] for f in dataclasses.fields(self)})

    @property
    def inverse_masses(self) -> np.ndarray:
        """(N,) ``1/m`` [1/mass]; 0 for fixed cells."""
        return 1.0 / self.masses

    @property
    def inverse_growth_inertia(self) -> np.ndarray:
        """(N,) ``1/G`` [1/mass]; 0 for non-growing and for fixed cells."""
        return np.where(np.isfinite(self.masses), 1.0 / self.growth_inertia, 0.0)

    @property
    def inverse_inertia_parallel(self) -> np.ndarray:
        """(N,) ``1/I∥ = 2/(mρ²)`` about the cell's own axis [1/(mass·length²)]."""
        return 2.0 / (self.masses * self.radii**2)

    @property
    def inverse_inertia_perpendicular(self) -> np.ndarray:
        """(N,) ``1/I⊥ = 12/(m(3ρ² + l²))`` about any axis normal to â [1/(mass·length²)]."""
        return 12.0 / (self.masses * (3.0 * self.radii**2 + self.lengths**2))

    def apply_inverse_inertia(self, vectors: np.ndarray) -> np.ndarray:
        """``I⁻¹ w`` for one (N, 3) vector per cell, using the axisymmetric form
        ``I⁻¹ = (1/I∥) ââᵀ + (1/I⊥)(Id − ââᵀ)`` (no rotation matrices)."""
        along = np.einsum("ij,ij->i", self.axes, vectors)[:, None] * self.axes
        return (
            self.inverse_inertia_parallel[:, None] * along
            + self.inverse_inertia_perpendicular[:, None] * (vectors - along)
        )

    @property
    def velocities(self) -> np.ndarray:
        """(N, 3) linear velocity ``v = p/m`` [length/time]."""
        return self.inverse_masses[:, None] * self.momenta

    @property
    def angular_velocities(self) -> np.ndarray:
        """(N, 3) angular velocity ``ω = I⁻¹L`` [1/time]."""
        return self.apply_inverse_inertia(self.angular_momenta)

    @property
    def growth_rates(self) -> np.ndarray:
        """(N,) length rate ``l̇ = g/G`` [length/time]."""
        return self.inverse_growth_inertia * self.growth_momenta

    def kinetic_energy(self) -> float:
        """Total kinetic energy ``½ Σ (p²/m + L·I⁻¹L + g²/G)`` [mass·length²/time²]."""
        return 0.5 * float(
            np.einsum("ij,ij->", self.momenta, self.velocities)
            + np.einsum("ij,ij->", self.angular_momenta, self.angular_velocities)
            + np.dot(self.growth_momenta, self.growth_rates)
        )

    def generalized_momenta(self) -> np.ndarray:
        """(N, 7) stacked ``(p, L, g)`` in the column order of ``Result.impulses``."""
        return np.hstack([self.momenta, self.angular_momenta, self.growth_momenta[:, None]])

    def with_impulses(self, impulses: np.ndarray) -> Cells:
        """A new Cells whose momenta are these plus the (N, 7) impulses ``(Δp, ΔL, Δg)``."""
        impulses = np.asarray(impulses, dtype=float)
        if impulses.shape != (self.n, 7):
            raise InvalidCellsError(f"impulses: expected shape ({self.n}, 7), got {impulses.shape}")
        return self.replace(
            momenta=self.momenta + impulses[:, 0:3],
            angular_momenta=self.angular_momenta + impulses[:, 3:6],
            growth_momenta=self.growth_momenta + impulses[:, 6],
        )

    def point_velocities(self, cell: np.ndarray, offsets: np.ndarray, stretch: np.ndarray) -> np.ndarray:
        """Velocity of body points (model.md): ``v + ω × r + (s/l) l̇ â``.

        Args:
            cell: (K,) cell index of each point.
            offsets: (K, 3) offset ``r`` of the point from the cell centre [length].
            stretch: (K,) ``s/l`` in ``[-½, ½]``: how the point rides with growth (the caps ride
                with the tips).
        """
        return (
            self.velocities[cell]
            + np.cross(self.angular_velocities[cell], offsets)
            + (stretch * self.growth_rates[cell])[:, None] * self.axes[cell]
        )
