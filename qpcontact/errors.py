"""Exceptions raised by qpcontact.

Every error a user can trigger derives from :class:`QPContactError`, and also from the builtin


class that fits it (``ValueError`` for bad input, ``ImportError`` for a missing backend,
``RuntimeError`` for a solver that did not deliver), so ``except ValueError`` keeps working.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any


class QPContactError(Exception):
    """Base class of every error raised by qpcontact."""


class InvalidCellsError(QPContactError, ValueError):
    """The cell arrays are malformed: wrong shape, NaN/inf where not allowed, non-positive radius
    or mass, zero or non-unit axis, negative length."""


class TooManyContactsError(InvalidCellsError):
    """The scene has more candidate contact pairs than
    :data:`qpcontact.geometry.contacts.MAX_PAIRS_PER_CELL` per cell (coincident or deeply
    interpenetrating cells, where the pairs grow like N²); raised before they are allocated."""


class InvalidArgumentError(QPContactError, ValueError):
    """An argument other than the cells is out of range (tolerance, margin, time step, ...)."""


class UnknownSolverError(QPContactError, ValueError):
    """No solver of that name is registered (:func:`qpcontact.solvers.get_solver`)."""


class NotInstalledError(QPContactError, ImportError):
    """An optional part is asked for whose package is not installed (PETSc, pandas, Dask, meshio,
    ...). The message is one line that names what to install (the extra of ``pip install``, or
    ``scripts/install-mpi``); the commands and the examples print it and exit with status 2."""


class SolverNotInstalledError(NotInstalledError):
    """The solver is registered (e.g. a known qpsolvers backend), but its Python package is not
    installed."""


class SolverFailedError(QPContactError, RuntimeError):
    """The solver raised, did not converge, or returned an answer that fails the checks.

    ``result`` holds the unconverged :class:`qpcontact.Result` when one could be built (its
    ``converged`` flag is False); it is never applied to the cells.
    """

    def __init__(self, message: str, result: Any = None):
        super().__init__(message)
        self.result = result


class StepFailedError(SolverFailedError):
    """A position-level colony step did not reach its overlap tolerance within its iteration cap,
    or one of its solves failed.

    ``result`` holds the unconverged :class:`qpcontact.timestep.PositionStepResult` (``converged``
    is False); the caller still holds the cells of the start of the step, which stand.
    """


class InvalidSnapshotError(InvalidArgumentError):
    """A colony snapshot cannot be read: missing, truncated or corrupted, not a qpcontact
    snapshot, of a newer format version, or holding inconsistent values (wrong shapes or types,
    non-finite time, ...). The message names the file and what is wrong."""


class OutputFolderError(QPContactError, OSError):
    """An output folder cannot be used: it cannot be written, or it holds the files of another
    run (pass ``overwrite=True``, ``--overwrite`` on the command line, to replace them)."""


class ModelHookError(QPContactError, RuntimeError):
    """A colony run's model hook (:mod:`qpcontact.colony.hooks`) raised, or returned something it
    cannot use; the hook's own exception, if any, is the ``__cause__``."""


class RefusedPickleError(InvalidSnapshotError):
    """A pickle was refused: it asks for a class or function that the state it should hold does
    not have, which is then neither built nor called (loading a pickle can run any code its
    author put in it; :func:`qpcontact.io.cellmodeller.load_pickle` builds only what a
    CellModeller state holds). The message names what it asked for."""


class PullingImpulseWarning(UserWarning):
    """The plain linear solve (``solver="linear"``, :func:`qpcontact.solvers.solve_min_norm`)
    returned contact impulses that pull (``λ_k < 0``): every contact of its all-active system is
    held at ``Mx = b``, including those a real contact would let go. Its answer is then no
    physical resolution, only the all-active solve; it is a check of a QP answer only where every
    contact pushes (:func:`qpcontact.compare_with_linear`). The result says so too
    (``Result.pulling``)."""


def install_hint(extra: str) -> str:
    """How to install qpcontact's extra ``extra``, in words that work where this qpcontact came
    from: ``pip install 'qpcontact[extra]'`` (an index install), and where the package sits in a
    source checkout (its ``pyproject.toml`` beside it) also ``pip install -e 'CHECKOUT[extra]'``,
    since the index form would fetch another qpcontact."""
    checkout = Path(__file__).resolve().parents[1]
    index = f"pip install 'qpcontact[{extra}]'"
    if (checkout / "pyproject.toml").is_file():
        return f"{index} (from this source checkout: pip install -e '{checkout}[{extra}]')"
    return index
