"""ipm-petsc: the interior point of :mod:`.ipm` over MPI processes, on PETSc's distributed objects.

Under ``mpiexec -n P``, every process holds the same problem (the colony's state is replicated,
docs/distributed.md; in the position step each process assembles only its own rows of it); this
solver splits it: each process owns the unknowns of some cells and some contact rows (the position
step's slabs, given as ``owners``; or, in a direct call, the cells, the groups of columns of ``B̃``
with the same rows, :func:`~qpcontact.solvers.cholesky.column_groups`, partitioned by METIS into P
connected regions of the contact graph, each row with its first cell), and the iterations of
:func:`qpcontact.solvers.ipm.iterate_rows` run on those parts:

- the products with ``B̃`` and ``B̃ᵀ`` are PETSc's (an MPIAIJ matrix; the halo of unknowns that
  a process's rows read from its neighbours is PETSc's scatter);
- the normal matrix ``diag(d) + B̃ᵀ diag(w) B̃`` is PETSc's ``MatTransposeMatMult`` of the
  row-scaled ``B̃`` (its pattern once per problem, its values each iteration), factorized by
  MUMPS (Cholesky, its symbolic analysis once per problem);
- the step lengths, the complementarity and the error are reductions over the processes
  (:class:`_Reductions`: a reduction to process 0 then a broadcast, so that every process takes
  the same branch with the same bits).

The answer is gathered to every process, so that what follows (the acceptance checks, the
motion of the cells) is the same everywhere. In one process the same code runs with P = 1 (the
factorization is MUMPS's instead of CHOLMOD's). Only the normal equations in the unknowns are
distributed: a tolerance below :data:`~qpcontact.solvers.ipm.UNKNOWNS_ACCURACY`, which needs the
contact space's, is refused.

Registered as ``"ipm-petsc"`` when petsc4py and mpi4py can be imported
(``scripts/install-mpi``, docs/distributed.md).
"""

from __future__ import annotations

import ctypes
import importlib.util
import itertools
import os
import time
from collections.abc import Callable, Mapping
from typing import Any

import numpy as np
import scipy.sparse as sp

from ..errors import InvalidArgumentError, NotInstalledError, SolverFailedError
from ..geometry.regions import counted
from . import cholesky
from .ipm import MAX_ITERATIONS, UNKNOWNS_ACCURACY, Reductions, bounds_of, iterate_rows, make_rows
from .registry import IterativeSolution, Problem, SolverOutput, SolverSpec, check_options, register


def installed() -> bool:
    """petsc4py and mpi4py can be imported."""
    return all(importlib.util.find_spec(name) is not None for name in ("petsc4py", "mpi4py"))


#: What to install where petsc4py or mpi4py is missing (one line, as the solver's install hint).
INSTALL_HINT = "needs petsc4py and mpi4py: scripts/install-mpi VENV (docs/distributed.md)"


#: Debian's MUMPS built with PT-Scotch (``libmumps-ptscotch-5.5``, which ``scripts/install-mpi``
#: installs): where ``PETSC_OPTIONS`` asks for MUMPS's analysis on every process
#: (``-mat_mumps_icntl_28 2``, with ``-mat_mumps_icntl_29 1`` for PT-Scotch), it is loaded ahead of
#: the MUMPS PETSc links to (the same functions, the same version), since Debian's plain MUMPS has
#: neither PT-Scotch nor ParMETIS and refuses it (INFOG(1) = −38). Otherwise PETSc's own MUMPS
#: runs, untouched. Not asked for by default: on 2 processes PT-Scotch's ordering made 12 % more
#: flops than the sequential AMF, and the step 5 % slower (docs/distributed.md).
PTSCOTCH_MUMPS = ("libptscotch-7.0.so", "libptscotcherr-7.0.so", "libmumps_common_ptscotch-5.5.so",
                  "libpord_ptscotch-5.5.so", "libdmumps_ptscotch-5.5.so")
_STATE: dict[str, Any] = {}


def _asks_parallel_analysis() -> bool:
    """``PETSC_OPTIONS`` sets ``-mat_mumps_icntl_28 2`` (MUMPS's analysis on every process)."""
    words = os.environ.get("PETSC_OPTIONS", "").split()
    return any(word == "-mat_mumps_icntl_28" and value == "2" for word, value in itertools.pairwise(words))


def _load_parallel_analysis() -> bool:
    """Load :data:`PTSCOTCH_MUMPS` into the global scope, before PETSc is loaded, where asked for
    (:func:`_asks_parallel_analysis`) and installed; whether it was."""
    if not _asks_parallel_analysis():
        return False
    try:
        for name in PTSCOTCH_MUMPS:
            ctypes.CDLL(name, mode=ctypes.RTLD_GLOBAL)
    except OSError:
        return False
    return True


def parallel_analysis() -> bool:
    """Whether the MUMPS with PT-Scotch was loaded (:data:`PTSCOTCH_MUMPS`: asked for, and
    installed), so that PETSc's option ``-mat_mumps_icntl_28 2`` works."""
    petsc()
    return bool(_STATE["parallel_analysis"])


def petsc() -> Any:
    """petsc4py's ``PETSc`` module (MPI initialized on first use; MUMPS with PT-Scotch loaded
    first where asked for and installed: :data:`PTSCOTCH_MUMPS`).

    Raises:
        NotInstalledError: petsc4py or mpi4py is missing (naming what to install).
    """
    if not installed():
        raise NotInstalledError(f"the distributed stack {INSTALL_HINT}")
    if "parallel_analysis" not in _STATE:
        _STATE["parallel_analysis"] = _load_parallel_analysis()
    from petsc4py import PETSc

    return PETSc


def world() -> Any:
    """The MPI communicator of the processes a distributed step runs on (mpi4py's
    ``COMM_WORLD``, PETSc's world).

    Raises:
        NotInstalledError: petsc4py or mpi4py is missing (naming what to install).
    """
    return petsc().COMM_WORLD.tompi4py()


#: What this process's distributed solves did since the counters were last reset
#: (:func:`reset_counters`), the counts a model of many processes is built from
#: (``benchmarks/mpi_model.py``); CPU seconds are ``time.process_time``, waiting in MPI included:
#:
#: - ``factor_cpu``: the factorizations (MUMPS's analysis and numeric factorization);
#:   ``first_factor_cpu`` the first of each problem (its analysis and one numeric factorization),
#:   ``problems`` and ``factorizations`` their numbers;
#: - ``factor_flops``: MUMPS's floating-point operations of elimination on this process (RINFO(3),
#:   summed); ``factor_entries`` the entries of its last factor on this process (INFO(9));
#:   ``entry_solves`` the factor entries on this process, once for each triangular solve (which
#:   reads each entry twice, forward and back); ``factor_memory_mb`` its largest working
#:   memory on this process (INFO(16));
#: - ``solves`` and ``solve_cpu``: MUMPS's triangular solves; ``normal_cpu`` the refills of the
#:   normal matrix (PETSc's product of the row-scaled ``B̃`` with itself), one a factorization;
#: - ``products`` and ``product_cpu``: the products with ``B̃`` and ``B̃ᵀ``; ``halo_bytes`` the
#:   bytes of unknowns this process sent to its neighbours for them (the halo of PETSc's scatter,
#:   counted from the columns its rows read from other processes: each product sends as many as
#:   it receives, on average);
#: - ``collectives`` and ``collective_cpu``: the solver's own reductions and gathers (the step
#:   lengths, the error, the answer); ``gathered_bytes`` what this process sent of the answer;
#: - ``owned_iterations``: the rows and unknowns this process owns, summed over the interior-point
#:   iterations (its share of the vector work).
COUNTERS: dict[str, float] = {}


def reset_counters() -> None:
    """Set :data:`COUNTERS` to zero."""
    COUNTERS.update({key: 0.0 for key in (
        "factor_cpu", "first_factor_cpu", "problems", "factorizations", "normal_cpu", "factor_flops", "factor_entries",
        "entry_solves", "factor_memory_mb", "solves", "solve_cpu", "products", "product_cpu", "halo_bytes",
        "collectives", "collective_cpu", "gathered_bytes", "owned_iterations", "parallel_analysis")})


reset_counters()


class _Reductions(Reductions):
    """Reductions over the processes of ``comm``: to process 0, then broadcast (an all-reduce
    may give processes results that differ in the last bit, and their branches would part)."""

    def __init__(self, comm: Any) -> None:
        from mpi4py import MPI

        self.comm, self._ops = comm, {"total": MPI.SUM, "least": MPI.MIN, "most": MPI.MAX}

    def _all(self, value: float, op: str) -> float:
        with counted(COUNTERS, "collective"):
            return float(self.comm.bcast(self.comm.reduce(float(value), op=self._ops[op], root=0), root=0))

    def total(self, value: float) -> float:
        return self._all(value, "total")

    def least(self, value: float) -> float:
        return self._all(value, "least")

    def most(self, value: float) -> float:
        return self._all(value, "most")


class Partition:
    """Which process owns which columns (unknowns) and rows (contacts) of a (K, n) ``B̃``, and the
    order that puts each process's part in one block (PETSc's distributed objects own ranges).

    Given ``column_owner`` and ``row_owner`` (the position step's: the slabs of
    :func:`~qpcontact.geometry.regions.slab_owners`, computed alike by every process), those.
    Otherwise columns go by cells (:func:`~qpcontact.solvers.cholesky.column_groups`), cells by
    METIS's k-way partition of the cells' contact graph (computed by process 0, broadcast: a
    direct call of :func:`distributed_interior_point`), and a row goes with the owner of its
    first column.

    Attributes:
        column_order: (n,) the columns in the order of the processes' blocks.
        row_order: (K,) the rows likewise.
        column_counts, row_counts: (P,) the size of each process's block.
    """

    def __init__(self, matrix: sp.csr_matrix, comm: Any, column_owner: np.ndarray | None = None,
                 row_owner: np.ndarray | None = None) -> None:
        size = comm.Get_size()
        k, n = matrix.shape
        if column_owner is not None and row_owner is not None:
            owner, row_owner = np.asarray(column_owner, dtype=np.int64), np.asarray(row_owner, dtype=np.int64)
            if owner.shape != (n,) or row_owner.shape != (k,) or np.any((owner < 0) | (owner >= size)) \
                    or np.any((row_owner < 0) | (row_owner >= size)):
                raise InvalidArgumentError(f"owners: expected ({n},) and ({k},) process numbers below {size}, got "
                                           f"shapes {owner.shape} and {row_owner.shape}")
        else:
            owner = np.zeros(n, dtype=np.int64)
            if size > 1:
                owner = comm.bcast(_owners(matrix, size) if comm.Get_rank() == 0 else None, root=0)
            first = matrix.indices[matrix.indptr[:-1]] if k else np.zeros(0, dtype=np.int64)
            row_owner = owner[first]
        self.column_order = np.argsort(owner, kind="stable")
        self.row_order = np.argsort(row_owner, kind="stable")
        self.column_counts = np.bincount(owner, minlength=size)
        self.row_counts = np.bincount(row_owner, minlength=size)

    def columns(self, rank: int) -> np.ndarray:
        """The columns process ``rank`` owns, in its block's order."""
        start = int(self.column_counts[:rank].sum())
        return self.column_order[start:start + self.column_counts[rank]]

    def rows(self, rank: int) -> np.ndarray:
        """The rows process ``rank`` owns, in its block's order."""
        start = int(self.row_counts[:rank].sum())
        return self.row_order[start:start + self.row_counts[rank]]


def _owners(matrix: sp.csr_matrix, parts: int) -> np.ndarray:
    """(n,) the process of each column: METIS's k-way partition of the cells (contiguous blocks
    of cells where METIS is missing or the graph too small)."""
    group, graph = cholesky.column_groups(matrix)
    groups = graph.shape[0]
    if cholesky.pymetis is not None and groups > parts:
        _, membership = cholesky.pymetis.part_graph(
            parts, adjacency=cholesky.pymetis.CSRAdjacency(graph.indptr, graph.indices))
        part = np.asarray(membership, dtype=np.int64)
    else:
        part = np.arange(groups, dtype=np.int64) * parts // max(groups, 1)
    return part[group]


class _Operator:
    """``B̃`` (or ``B̃ᵀ``) on the parts of vectors a process owns: ``@`` as :class:`~.ipm._Rows`
    uses it, by PETSc's distributed product (which brings the halo of unknowns)."""

    def __init__(self, matrix: Any, transpose: bool, halo: int = 0) -> None:
        self.matrix, self.transpose, self.halo = matrix, transpose, halo
        right, left = matrix.createVecs()
        self._in, self._out = (left, right) if transpose else (right, left)
        self.shape = (self._out.getLocalSize(), self._in.getLocalSize())

    def __matmul__(self, x: np.ndarray) -> np.ndarray:
        COUNTERS["halo_bytes"] += 8 * self.halo
        with counted(COUNTERS, "product"):
            self._in.array[:] = x
            (self.matrix.multTranspose if self.transpose else self.matrix.mult)(self._in, self._out)
            return self._out.array.copy()


#: MUMPS's ICNTL(14) unless the user sets it (PETSc's option ``-mat_mumps_icntl_14``).
WORKSPACE_PERCENT = 60


class DistributedGram:
    """``diag(d) + B̃ᵀ diag(w) B̃`` over the processes, refilled for each ``w ≥ 0`` and ``d > 0``
    and factorized by MUMPS (Cholesky): :meth:`factor` is that of
    :class:`~qpcontact.solvers.cholesky.GramMatrix`, on the parts each process owns."""

    def __init__(self, matrix: Any) -> None:
        PETSc = petsc()
        self._B = matrix
        self._scaled = matrix.duplicate(copy=True)
        self._normal: Any = None
        self._weights, self._diagonal = matrix.createVecs()[::-1]
        self._ksp = PETSc.KSP().create(comm=matrix.getComm())
        self._ksp.setType(PETSc.KSP.Type.PREONLY)
        pc = self._ksp.getPC()
        pc.setType(PETSc.PC.Type.CHOLESKY)
        pc.setFactorSolverType(PETSc.Mat.SolverType.MUMPS)
        options = PETSc.Options()
        if not options.hasName("mat_mumps_icntl_14"):
            # MUMPS's workspace beyond its estimate, in percent (its default 20 ran short,
            # INFOG(1) = -9, on 4 processes owning slabs of a 400-cell colony, 2026-12-05).
            options.setValue("mat_mumps_icntl_14", WORKSPACE_PERCENT)
        self._x, self._b = self._diagonal.duplicate(), self._diagonal.duplicate()

    def factor(self, w: np.ndarray, d: np.ndarray, extra: np.ndarray | None = None) -> Callable[[np.ndarray], np.ndarray]:
        """Factorize for these weights (this process's rows of ``w``, columns of ``d``); returns
        the solve on this process's part. ``extra`` (an objective's curvature) must be None: a
        distributed step is first order.

        Raises:
            ArithmeticError: MUMPS found the matrix numerically singular.
            SolverFailedError: MUMPS failed otherwise (its error code and what may help).
        """
        if extra is not None:
            raise InvalidArgumentError("curvature: the distributed interior point takes none (a first-order step)")
        PETSc = petsc()
        cpu = time.process_time()
        self._B.copy(self._scaled, structure=PETSc.Mat.Structure.SAME_NONZERO_PATTERN)
        self._weights.array[:] = np.sqrt(w)
        self._scaled.diagonalScale(L=self._weights)
        first = self._normal is None
        self._normal = self._scaled.transposeMatMult(self._scaled, result=self._normal)
        self._diagonal.array[:] = d
        self._normal.setDiagonal(self._diagonal, addv=PETSc.InsertMode.ADD_VALUES)
        COUNTERS["normal_cpu"] += time.process_time() - cpu
        # MUMPS's Cholesky without pivoting (its positive definite mode) needs the option on the
        # assembled matrix; once is enough: PETSc reads it when it makes the factor, at the first
        # set-up of each problem (MatGetFactor for MUMPS), and later refills keep that factor.
        if first:
            self._normal.setOption(PETSc.Mat.Option.SPD, True)
        self._ksp.setOperators(self._normal)
        cpu = time.process_time()
        self._ksp.setUp()
        spent = time.process_time() - cpu
        COUNTERS["factor_cpu"] += spent
        COUNTERS["factorizations"] += 1
        if first:
            COUNTERS["first_factor_cpu"] += spent
            COUNTERS["problems"] += 1
        factor = self._ksp.getPC().getFactorMatrix()
        status = factor.getMumpsInfog(1)  # the same on every process
        if status >= 0:
            COUNTERS["factor_flops"] += float(factor.getMumpsRinfo(3))
            entries = float(factor.getMumpsInfo(9))  # negative: millions
            COUNTERS["factor_entries"] = entries if entries >= 0 else -1e6 * entries
            COUNTERS["factor_memory_mb"] = max(COUNTERS["factor_memory_mb"], float(factor.getMumpsInfo(16)))
            COUNTERS["parallel_analysis"] = float(factor.getMumpsInfog(32) == 2)  # 1: on every process
        if status == -10:  # numerically singular: the interior point regularizes more
            raise ArithmeticError("MUMPS: the matrix is numerically singular (INFOG(1) = -10)")
        if status < 0:
            hint = " (workspace too small: PETSC_OPTIONS='-mat_mumps_icntl_14 100')" if status in (-8, -9) else ""
            if status == -38:
                hint = (" (a parallel analysis, ICNTL(28) = 2, that this MUMPS was built without ParMETIS/PT-SCOTCH "
                        "for; on Debian: apt-get install libmumps-ptscotch-5.5, which scripts/install-mpi installs)")
            raise SolverFailedError(f"MUMPS failed with INFOG(1) = {status}{hint}; its user guide lists the codes")

        entries = COUNTERS["factor_entries"]

        def solve(v: np.ndarray) -> np.ndarray:
            COUNTERS["entry_solves"] += entries
            with counted(COUNTERS, "solve"):
                self._b.array[:] = v
                self._ksp.solve(self._b, self._x)
                return self._x.array.copy()

        return solve

    def destroy(self) -> None:
        """Free PETSc's objects (collective)."""
        for obj in (self._ksp, self._normal, self._scaled, self._weights, self._diagonal, self._x, self._b):
            if obj is not None:
                obj.destroy()


def _gather(part: np.ndarray, order: np.ndarray, counts: np.ndarray, comm: Any) -> np.ndarray:
    """The whole vector, on every process, from each process's ``part`` of the block order ``order``."""
    whole = np.empty(int(counts.sum()))
    with counted(COUNTERS, "collective"):
        comm.Allgatherv(np.ascontiguousarray(part, dtype=float), [whole, counts])
    out = np.empty_like(whole)
    out[order] = whole
    return out


def distributed_interior_point(matrix: sp.spmatrix, rhs: np.ndarray, lower: np.ndarray | None = None,
                               upper: np.ndarray | None = None, *, tolerance: float = 1e-4,
                               max_iterations: int | None = None, time_limit: float | None = None,
                               comm: Any = None, owners: tuple[np.ndarray, np.ndarray] | None = None
                               ) -> IterativeSolution:
    """:func:`qpcontact.solvers.ipm.interior_point` over the processes of ``comm`` (default
    :func:`world`): every process passes the same problem and gets the same answer (module
    docstring). ``owners``: ``(column_owner, row_owner)``, the process of each unknown and each
    row (:class:`Partition`); then a process reads only its own rows of ``matrix`` and
    ``rhs`` (the others may be left empty: the position step assembles only its own).

    Raises:
        InvalidArgumentError: a tolerance below :data:`~qpcontact.solvers.ipm.UNKNOWNS_ACCURACY`
            (only the normal equations in the unknowns are distributed), or bad bounds.
    """
    check_options(tolerance, max_iterations, time_limit)
    if tolerance < UNKNOWNS_ACCURACY:
        raise InvalidArgumentError(f"ipm-petsc: tolerance {tolerance:g} is below {UNKNOWNS_ACCURACY:g}, which only "
                                   "the one-process ipm reaches (in the contact impulses)")
    start = time.perf_counter()
    comm = world() if comm is None else comm
    B = sp.csr_matrix(matrix)
    if not B.has_sorted_indices:
        B = B.sorted_indices()  # a copy: the caller's matrix stays as it was
    k, n = B.shape
    lo, hi = bounds_of(lower, upper, n)
    partition = Partition(B, comm, *(owners or (None, None)))
    mine, my_rows = partition.columns(comm.Get_rank()), partition.rows(comm.Get_rank())
    mat, halo = _distributed_matrix(B, partition, my_rows, comm)
    reduce = _Reductions(comm)
    normal = DistributedGram(mat)
    try:
        rows = make_rows(_Operator(mat, False, halo), _Operator(mat, True, halo), np.asarray(rhs, dtype=float)[my_rows],
                         lo[mine], hi[mine], reduce)
        if rows is None:
            return IterativeSolution(np.zeros(n), np.zeros(k), 0, False, "infeasible", np.inf,
                                     time.perf_counter() - start)
        with cholesky.quiet_numpy():
            part = iterate_rows(rows, normal, lo[mine], hi[mine], start=start, tolerance=tolerance,
                                max_iterations=max_iterations or MAX_ITERATIONS, time_limit=time_limit,
                                initial=None, warm_shift=1e-2, space="unknowns")
    finally:
        normal.destroy()
        mat.destroy()
    assert part.lam is not None
    COUNTERS["owned_iterations"] += float(mine.size + my_rows.size) * part.iterations
    y = _gather(part.y, partition.column_order, partition.column_counts, comm)
    lam = _gather(part.lam, partition.row_order, partition.row_counts, comm)
    if comm.Get_size() > 1:
        COUNTERS["gathered_bytes"] += 8.0 * (part.y.size + part.lam.size)
    return IterativeSolution(y, lam, part.iterations, part.converged, part.status, part.residual,
                             time.perf_counter() - start)


def _distributed_matrix(B: sp.csr_matrix, partition: Partition, rows: np.ndarray, comm: Any) -> tuple[Any, int]:
    """``B̃`` as PETSc's MPIAIJ matrix: this process's ``rows``, the columns renumbered in the
    order of the processes' blocks (collective); and how many columns of other processes its rows
    read (the halo of a product)."""
    PETSc = petsc()
    k, n = B.shape
    place = np.empty(n, dtype=np.int64)
    place[partition.column_order] = np.arange(n)
    local = B[rows]
    local = sp.csr_matrix((local.data, place[local.indices], local.indptr), shape=local.shape)
    local.sort_indices()
    owned = int(partition.column_counts[comm.Get_rank()])
    first = int(partition.column_counts[:comm.Get_rank()].sum())
    read = np.unique(local.indices)
    halo = int(np.count_nonzero((read < first) | (read >= first + owned)))
    mat = PETSc.Mat().createAIJ(size=((rows.size, k), (owned, n)),
                                csr=(local.indptr.astype(PETSc.IntType), local.indices.astype(PETSc.IntType),
                                     local.data), comm=_petsc_comm(comm))
    mat.assemble()
    return mat, halo


def _petsc_comm(comm: Any) -> Any:
    """PETSc's communicator over the processes of the mpi4py communicator ``comm``."""
    return petsc().Comm(comm)


def _solve(problem: Problem, formulation: str, form: str, *, tolerance: float, time_limit: float | None,
           settings: Mapping[str, Any], initial: np.ndarray | None) -> SolverOutput:
    out = distributed_interior_point(problem.matrix, problem.rhs, problem.lower, problem.upper, tolerance=tolerance,
                                     time_limit=time_limit, max_iterations=settings.get("max_iterations"),
                                     comm=settings.get("comm"), owners=settings.get("owners"))
    return out.output()


register(SolverSpec(
    "ipm-petsc", formulations=("complementarity",), forms=("contact",), warm_start=False, time_limit=True,
    solve=_solve, available=installed,
    description="the built-in interior point over MPI processes (PETSc, MUMPS); takes bounds on ỹ",
    settings=("max_iterations", "comm", "owners"), blockwise=False, bounds=("contact",),
    install_hint=f"{INSTALL_HINT}; a run saved by several processes continues in one with --position-solver ipm",
))
