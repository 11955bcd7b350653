"""A sparse Cholesky factorization of ``diag(d) + Aᵀ diag(w) A`` for a fixed pattern of ``A``.

The interior-point solver (:mod:`qpcontact.solvers.ipm`) factorizes such a matrix once per
iteration, with new weights ``w`` and ``d`` each time and the same ``A``. So everything that
depends only on the pattern is done once (:class:`GramMatrix`): every product ``A_ki A_kj``
(``i ≥ j``, same row ``k``) is listed with the place of entry ``(i, j)`` in the lower triangle,
so a refill is one ``np.bincount``; the fill-reducing ordering and CHOLMOD's symbolic analysis
are computed once; each iteration only refills the values and runs the numeric factorization.

Two factorizations (:data:`BACKEND`):

- ``"cholmod"`` (always there): CHOLMOD's supernodal Cholesky, bundled with cvxopt (dense BLAS
  kernels on the supernodes: 5× the simplicial LDLᵀ of qdldl on a grown colony of 10⁴ cells,
  docs/performance.md), ordered by METIS's nested dissection (through pymetis) when pymetis is
  installed, else by CHOLMOD's own AMD: on grown colonies nested dissection makes the factor 25 %
  cheaper in 2D and 3D (docs/model-notes.md, "A step that scales"). cvxopt's CHOLMOD is built
  without METIS, hence pymetis; its BLAS is the wheel's OpenBLAS, built without threads, so it uses one core.
- ``"pardiso"`` (``pip install 'qpcontact[pardiso]'``: pypardiso and Intel's MKL, about 1 GB):
  MKL's PARDISO, its own nested dissection and a threaded supernodal Cholesky on every core.
  Used when installed. Whether it pays depends on the CPU: on an Intel Xeon with 2 cores its
  factorizations were 2–4.5× CHOLMOD's speed, on this project's AMD EPYC with 2 cores 1.2–1.5×,
  and a whole step 0.97–1.27× (docs/performance.md, "Both cores at the accurate defaults").
"""

from __future__ import annotations

import contextlib
import importlib
import os
from collections.abc import Callable
from typing import Any

import cvxopt
import numpy as np
import scipy.sparse as sp
from cvxopt import cholmod


def _optional(name: str) -> Any:
    """The module, or None where it is not installed."""
    try:
        return importlib.import_module(name)
    except ImportError:  # pragma: no cover - depends on the installation
        return None


#: Optional: without it, the ordering is CHOLMOD's AMD.
pymetis: Any = _optional("pymetis")
#: Optional (qpcontact[pardiso]): the threaded factorization.
pypardiso: Any = _optional("pypardiso")
#: What keeps numpy's threads out of the factorization's way (:func:`quiet_numpy`).
threadpoolctl: Any = _optional("threadpoolctl")
_CONTROLLER: list[Any] = []

#: The factorization of :class:`GramMatrix` (module docstring): ``"pardiso"`` when pypardiso is
#: installed, else ``"cholmod"``. Module attribute, read when a matrix is made.
BACKEND = "pardiso" if pypardiso is not None else "cholmod"


#: Below this many unknowns the ordering is CHOLMOD's (AMD): nested dissection pays only for
#: large matrices, and METIS is not free (0.1–0.2 s at 10⁴ cells).
METIS_SIZE = 2000


def ordering_name() -> str:
    """``"metis"`` when pymetis is installed (nested dissection for large matrices), else ``"amd"``."""
    return "metis" if pymetis is not None else "amd"


def quiet_numpy() -> contextlib.AbstractContextManager[Any]:
    """numpy's own OpenBLAS threads limited to one while the interior point runs, on every path:
    its vector work is memory-bound (dot products and matrix-vector products of the iterate), and
    OpenBLAS's threads spin for a while after each call, taking the cores that PARDISO's threads
    need, or, with the serial CHOLMOD, the core of another job on a busy machine (one step of a
    grown 2D colony of 10⁴ cells with PARDISO: 12–13 s against 19–21 s, 2026-12-02; with
    CHOLMOD on a loaded machine 1.2 s of an 8.9 s step went to one dot product)."""
    if threadpoolctl is None:  # pragma: no cover - a dependency; kept optional for odd installs
        return contextlib.nullcontext()
    if not _CONTROLLER:
        _CONTROLLER.append(threadpoolctl.ThreadpoolController())
    return _CONTROLLER[0].select(internal_api="openblas").limit(limits=1)


def column_groups(matrix: sp.csr_matrix) -> tuple[np.ndarray, sp.csr_matrix]:
    """The columns of the K × n ``matrix`` that appear in exactly the same rows (the unknowns of
    one cell, which every contact of that cell touches) as one group each: ``(group, graph)``,
    each column's group (n,) and the groups' adjacency (groups sharing a row), without its
    diagonal: the graph of the cells, which orderings and partitions work on.

    Groups are found by a random signature of their rows (two columns with different rows share
    one with probability ~1e-16 per pair; they would only be ordered or placed together)."""
    k, n = matrix.shape
    csc = matrix.tocsc()
    rows_of = sp.csc_matrix((np.ones(csc.nnz), csc.indices, csc.indptr), shape=(k, n))
    _, group = np.unique(np.random.default_rng(0).random(k) @ rows_of, return_inverse=True)
    members = sp.csr_matrix((np.ones(n), (np.arange(n), group)), shape=(n, int(group.max()) + 1))
    touches = abs(matrix) @ members  # rows × groups
    touches.data[:] = 1.0
    graph = (touches.T @ touches).tocsr()
    graph.setdiag(0)
    graph.eliminate_zeros()
    return group, graph


def _nested_dissection(matrix: sp.csr_matrix) -> np.ndarray | None:
    """A fill-reducing permutation of the columns of ``Aᵀ A`` for the K × n ``matrix`` ``A``
    (METIS's nested dissection), or None (then CHOLMOD orders with AMD).

    Columns that appear in exactly the same rows (the unknowns of one cell, which every contact
    of that cell touches) are one vertex of the graph METIS orders, and stay together in the
    permutation: a graph of the cells instead of their unknowns, 5–20× faster to order, and as
    good a factor (on grown colonies of 10⁴ cells in 2D and 2,000 in 3D)."""
    n = matrix.shape[1]
    if pymetis is None or n < METIS_SIZE:
        return None
    group, graph = column_groups(matrix)
    order, _ = pymetis.nested_dissection(adjacency=pymetis.CSRAdjacency(graph.indptr, graph.indices))
    rank = np.empty(len(order), dtype=np.int64)
    rank[np.asarray(order)] = np.arange(len(order))
    return np.lexsort((np.arange(n), rank[group])).astype(np.int64)


def _row_pairs(indptr: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The pairs ``(i ≥ j)`` of stored entries of each row of a CSR matrix, row by row (each
    row's in the order of ``np.tril_indices``): ``(first, second, start)``, positions in its data,
    and where each row's pairs start (K + 1). Generated for all rows with the same number of
    entries at once (a few distinct counts: a loop over counts, not over rows)."""
    counts = np.diff(indptr)
    start = np.concatenate([[0], np.cumsum(counts * (counts + 1) // 2)]).astype(np.int64)
    index = indptr.dtype  # positions in the data: scipy's index type, int32 below 2³¹ entries
    first, second = np.empty(start[-1], dtype=index), np.empty(start[-1], dtype=index)
    for m in np.unique(counts[counts > 0]):
        of = np.flatnonzero(counts == m)
        i, j = (k.astype(index) for k in np.tril_indices(int(m)))
        data_start = indptr[of][:, None]
        if of.size == counts.size:  # every row alike (a scene without planes): already row by row
            first[:], second[:] = (data_start + i).ravel(), (data_start + j).ravel()
        else:
            place = (start[of][:, None] + np.arange(i.size)).ravel()
            first[place], second[place] = (data_start + i).ravel(), (data_start + j).ravel()
    return first, second, start


def _row_signatures(structure: sp.csr_matrix) -> np.ndarray:
    """(K,) a number per row of ``structure`` (a matrix's pattern, ones where it stores entries)
    that only rows with the same columns share (a sum of random weights of its columns, fixed by
    the number of columns: two rows with different columns share one with a probability of about
    10⁻¹⁶)."""
    return structure @ (np.random.default_rng(structure.shape[1]).random(structure.shape[1]) + 1.0)


#: A matrix is grown from the last one of its family (:class:`GramMatrix`, ``grown_from``) only when
#: at most this fraction of its rows have columns no row of the last one had; else it is built anew.
GROWN_NEW_ROWS = 0.1


def _pattern(csr: sp.csr_matrix, structure: sp.csr_matrix, first: np.ndarray,
             second: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The keys ``column·n + row`` of the lower triangle of ``I + AᵀA`` (sorted: CSC order) for
    ``A = csr`` (``structure``: its pattern, ones where it stores entries), and the entry of each
    product ``(first, second)`` of :func:`_row_pairs`.

    From the structure, not the values: a product of stored zeros is dropped by scipy's matmul,
    and a refresh (:meth:`GramMatrix.refresh`) may fill them (a planar step's Jacobian has zeros
    where the next step's has values). Each product's entry by a binary search of its key (columns
    sorted within a row of A: the first of a pair is the larger column, the row of the lower
    triangle)."""
    n = csr.shape[1]
    pattern = sp.tril(structure.T @ structure + sp.identity(n, format="csc"), format="csc")
    pattern.sort_indices()
    keys = np.repeat(np.arange(n, dtype=np.int64), np.diff(pattern.indptr)) * n + pattern.indices
    return keys, np.searchsorted(keys, csr.indices[second].astype(np.int64) * n + csr.indices[first])


def _grown(old: GramMatrix, csr: sp.csr_matrix, signatures: np.ndarray, first: np.ndarray, second: np.ndarray,
           start: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """The pattern's keys and each product's entry for ``csr`` grown from the matrix of ``old``
    (:class:`GramMatrix`, ``grown_from``; ``signatures``: :func:`_row_signatures` of ``csr``;
    ``first, second, start``: :func:`_row_pairs`), or None where it cannot be (another number of
    columns, more than :data:`GROWN_NEW_ROWS` of its rows with columns no row of ``old`` had).

    A row with the columns of a row of ``old`` has its products at that row's entries; the
    products of the other rows are looked up, and the entries they need that ``old`` lacks are
    added to the pattern (old entries keep their order, shifted past the added ones)."""
    n, counts = csr.shape[1], np.diff(csr.indptr)
    if old.shape[0] != n or old._scatter.nnz == 0:  # nothing to keep from a matrix with no products
        return None
    order = np.argsort(old._signatures, kind="stable")
    at = np.minimum(np.searchsorted(old._signatures[order], signatures), max(order.size - 1, 0))
    match = order[at] if order.size else np.zeros(signatures.size, dtype=np.int64)
    found = (old._signatures[match] == signatures) & (old._counts[match] == counts) if order.size else \
        np.zeros(signatures.size, dtype=bool)
    if np.count_nonzero(~found) > GROWN_NEW_ROWS * max(signatures.size, 1):
        return None
    pairs = np.diff(start)
    fresh = np.repeat(~found, pairs)
    fresh_keys = csr.indices[second[fresh]].astype(np.int64) * n + csr.indices[first[fresh]]
    wanted = np.unique(fresh_keys)  # few (the new rows'): the old keys are sorted already
    at = np.minimum(np.searchsorted(old._keys, wanted), old._keys.size - 1)
    added = wanted[old._keys[at] != wanted]
    keys = old._keys if added.size == 0 else np.insert(old._keys, np.searchsorted(old._keys, added), added)
    # A known row's products lie in old's scatter at its row's place, in the same order.
    source = np.arange(start[-1], dtype=np.int64)
    source += np.repeat(np.where(found, old._scatter.indptr[match] - start[:-1], 0), pairs)
    source[fresh] = 0
    position = old._scatter.indices[source].astype(np.int64)
    if added.size:  # each old entry moves past the added ones before it
        position += np.cumsum(np.bincount(np.searchsorted(old._keys, added), minlength=old.size + 1))[position]
    position[fresh] = np.searchsorted(keys, fresh_keys)
    return keys, position


class GramMatrix:
    """``diag(d) + Aᵀ diag(w) A`` (n × n, for a K × n sparse ``A``) with the pattern of ``A``
    fixed, refilled for each ``w ≥ 0``, ``d > 0`` and factorized (module docstring).

    The refill is one sparse product ``P w``: ``P`` (entries of the lower triangle × rows of
    ``A``) holds each product ``A_ki A_kj`` at the place of entry ``(i, j)`` and row ``k``, so
    the values come out in one pass with no temporaries (a weighted ``np.bincount`` over the
    products took 10 ms a refill on a grown 2D colony of 5,000 cells, the product 2 ms;
    2026-12-04).

    ``grown_from``: the matrix of the last problem of the same family (the linearizations of one
    position step: the same unknowns, the contacts of the last and a few more): its ordering is
    kept, and so are its entries and the place of each product of a row with the same columns, so
    only the products of new rows are looked up and only the entries they add are inserted (a
    new pattern costs a symbolic analysis, not a nested dissection and a search of every product:
    0.1 s a linearization of a grown 2D colony of 5,000 cells, docs/model-notes.md). Built anew
    where it cannot be grown (:func:`_grown`).

    Memory: about 20 bytes per product; a 2D colony has about 36 products per contact row, a 3D
    one about 78."""

    def __init__(self, matrix: sp.spmatrix, grown_from: GramMatrix | None = None) -> None:
        csr = sp.csr_matrix(matrix)
        csr.sum_duplicates()
        csr.sort_indices()
        k, n = csr.shape
        first, second, start = _row_pairs(csr.indptr)
        structure = sp.csr_matrix((np.ones(csr.nnz), csr.indices, csr.indptr), shape=csr.shape)
        self._signatures, self._counts = _row_signatures(structure), np.diff(csr.indptr)
        grown = None if grown_from is None else _grown(grown_from, csr, self._signatures, first, second, start)
        #: The ordering was computed for another matrix of the family (:meth:`refresh`).
        self.inherited = grown is not None
        keys, position = _pattern(csr, structure, first, second) if grown is None else grown
        column_of_entry, row_of_entry = keys // n, keys % n
        indptr = np.concatenate([[0], np.cumsum(np.bincount(column_of_entry, minlength=n))])
        self.diagonal_position = np.searchsorted(keys, np.arange(n, dtype=np.int64) * (n + 1))
        self._keys = keys
        self.size = keys.size
        self.shape = (n, n)
        # P: one row per entry, one column per row of A, in CSC: each row's products, one after the
        # other, each at its entry (a row adds to an entry at most once: no duplicates). Stored by
        # row of A, P needs no sorting, a matrix grown from this one finds the entries of its rows
        # here (its indices), and its product is faster than by entry (the entries one row adds to
        # lie together; docs/performance.md, "The normal matrix set up three times faster").
        index = np.int32 if max(self.size, position.size) < 2**31 else np.int64  # 4 bytes a product
        self._first, self._second = first, second
        self._scatter = sp.csc_matrix((csr.data[first] * csr.data[second], position.astype(index), start.astype(index)),
                                      shape=(self.size, k))
        self._indptr, self._indices = csr.indptr.copy(), csr.indices.copy()
        self._lower_pattern = (indptr, row_of_entry)
        self.backend = BACKEND
        self._matrix: Any = None
        self._symbolic: Any = None
        if grown_from is not None and keys is grown_from._keys and grown_from.backend == self.backend:
            # The same pattern: its matrix and analysis are this one's (the last is not used again).
            self._matrix, self._symbolic = grown_from._matrix, grown_from._symbolic
            grown_from._matrix = grown_from._symbolic = None
        if self.backend == "pardiso":
            # The lower triangle in CSC is the upper triangle in CSR, which PARDISO takes.
            self._pattern = (indptr.astype(np.int32), row_of_entry.astype(np.int32))
        else:
            self._rows = cvxopt.matrix(row_of_entry, tc="i")
            self._cols = cvxopt.matrix(column_of_entry, tc="i")
            self._permutation = (getattr(grown_from, "_permutation", None) if grown is not None
                                 else _nested_dissection(csr))

    def refresh(self, matrix: sp.spmatrix) -> bool:
        """Take the values of ``matrix`` if it has the pattern this was built for (then the
        ordering and the symbolic factorization are reused). Returns whether it did."""
        csr = sp.csr_matrix(matrix)
        if csr.shape[1] != self.shape[0] or not (np.array_equal(csr.indptr, self._indptr)
                                                 and np.array_equal(csr.indices, self._indices)):
            return False
        self._scatter.data = csr.data[self._first] * csr.data[self._second]
        return True

    def stored(self, symmetric: sp.spmatrix) -> np.ndarray | None:
        """The values of a symmetric n × n matrix in the stored order (:meth:`values`'s), to be
        added to every refill (``extra`` of :meth:`factor`); None when its pattern is not within
        this one's."""
        lower = sp.tril(sp.csc_matrix(symmetric), format="csc")
        lower.sum_duplicates()
        keys = np.repeat(np.arange(self.shape[0], dtype=np.int64), np.diff(lower.indptr)) * self.shape[0] + lower.indices
        position = np.minimum(np.searchsorted(self._keys, keys), self._keys.size - 1)
        if not np.array_equal(self._keys[position], keys):
            return None
        out = np.zeros(self.size)
        np.add.at(out, position, lower.data)
        return out

    def values(self, w: np.ndarray, d: np.ndarray) -> np.ndarray:
        """The stored (lower-triangle, CSC-ordered) values for these weights (rows of ``A`` past
        the end of ``w`` weigh 0)."""
        rows = self._scatter.shape[1]
        data = self._scatter @ (w if w.size == rows else np.concatenate([w, np.zeros(rows - w.size)]))
        data[self.diagonal_position] += d
        return data

    def lower(self, w: np.ndarray, d: np.ndarray) -> sp.csc_matrix:
        """The lower triangle of ``diag(d) + Aᵀ diag(w) A`` as a sparse matrix (what is factorized)."""
        indptr, indices = self._lower_pattern
        return sp.csc_matrix((self.values(w, d), indices, indptr), shape=self.shape)

    def factor(self, w: np.ndarray, d: np.ndarray, extra: np.ndarray | None = None) -> Callable[[np.ndarray], np.ndarray]:
        """Factorize for these weights; returns a function ``v ↦ (diag(d) + Aᵀ diag(w) A + E)⁻¹ v``,
        ``E`` the matrix whose stored values are ``extra`` (:meth:`stored`; None: 0).

        Raises:
            ArithmeticError: the matrix is not numerically positive definite (CHOLMOD's error, or
                PARDISO's).
        """
        values = self.values(w, d)
        if extra is not None:
            values += extra
        if self.backend == "pardiso":
            return self._factor_pardiso(values)
        data = cvxopt.matrix(values)
        if self._matrix is None:
            self._matrix = cvxopt.spmatrix(data, self._rows, self._cols, self.shape)
            saved = dict(cholmod.options)
            cholmod.options["supernodal"] = 2  # supernodal: dense BLAS kernels
            try:
                if self._permutation is None:
                    self._symbolic = cholmod.symbolic(self._matrix, uplo="L")
                else:
                    self._symbolic = cholmod.symbolic(self._matrix, uplo="L",
                                                      p=cvxopt.matrix(self._permutation.tolist(), tc="i"))
            finally:
                cholmod.options.clear()
                cholmod.options.update(saved)
        else:
            self._matrix.V = data
        cholmod.numeric(self._matrix, self._symbolic)
        factor = self._symbolic

        def solve(v: np.ndarray) -> np.ndarray:
            x = cvxopt.matrix(np.asarray(v, dtype=float))
            cholmod.solve(factor, x)
            return np.asarray(x).ravel()

        return solve

    def _factor_pardiso(self, data: np.ndarray) -> Callable[[np.ndarray], np.ndarray]:
        """PARDISO (real symmetric positive definite): the analysis once, then the numeric
        factorization; returns the solve."""
        indptr, indices = self._pattern
        upper = sp.csr_matrix((data, indices, indptr), shape=self.shape)
        if self._symbolic is None:
            self._symbolic = pypardiso.PyPardisoSolver(mtype=2)
            # Its own parameters: nested dissection (METIS), and conditional numerical
            # reproducibility for the threads MKL uses: without it, the threads' order changes the
            # last bits from run to run (3·10⁻¹³), and a resumed run would not follow the
            # uninterrupted one bit for bit. (Not slower: measured on grown colonies.)
            self._symbolic.iparm[0], self._symbolic.iparm[1] = 1, 2
            self._symbolic.iparm[33] = int(self._symbolic.libmkl.MKL_Get_Max_Threads())
            # pypardiso looks for MKL's library by walking sys.prefix on every new solver (0.3 s)
            # unless it is told where it is: tell it, once found.
            os.environ.setdefault("PYPARDISO_MKL_RT", self._symbolic.libmkl._name)
            self._call(11, upper, np.zeros(self.shape[0]))
        self._call(22, upper, np.zeros(self.shape[0]))
        return lambda v: self._call(33, upper, np.asarray(v, dtype=float))

    def _call(self, phase: int, upper: sp.csr_matrix, v: np.ndarray) -> np.ndarray:
        self._symbolic.set_phase(phase)
        try:
            return self._symbolic._call_pardiso(upper, v)
        except pypardiso.pardiso_wrapper.PyPardisoError as exc:  # -4: a zero pivot, not positive definite
            raise ArithmeticError(f"PARDISO: {exc}") from None

    def __del__(self) -> None:
        if getattr(self, "backend", None) == "pardiso" and self._symbolic is not None:
            try:
                self._symbolic.free_memory(everything=True)
            except Exception:  # pragma: no cover - at interpreter exit
                pass
