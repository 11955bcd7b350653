"""The fixed-pattern Gram matrix and its factorization (qpcontact/solvers/cholesky.py)."""

import numpy as np
import pytest
import scipy.sparse as sp

from qpcontact.solvers import cholesky
from qpcontact.solvers.cholesky import GramMatrix

#: Both factorizations: CHOLMOD always; PARDISO where pypardiso is installed (CI installs it).
BACKENDS = ["cholmod", pytest.param("pardiso", marks=pytest.mark.skipif(
    cholesky.pypardiso is None, reason="pypardiso not installed (pip install 'qpcontact[pardiso]')"))]


@pytest.fixture(params=BACKENDS)
def backend(request, monkeypatch):
    monkeypatch.setattr(cholesky, "BACKEND", request.param)
    return request.param


def random_rows(seed: int, k: int = 400, n: int = 300) -> sp.csr_matrix:
    """Rows with two blocks of three entries each, like contact rows between two cells."""
    rng = np.random.default_rng(seed)
    cells = rng.integers(0, n // 3, size=(k, 2))
    cells[:, 1] = np.where(cells[:, 1] == cells[:, 0], (cells[:, 0] + 1) % (n // 3), cells[:, 1])
    columns = (3 * cells[:, :, None] + np.arange(3)).reshape(k, 6)
    return sp.csr_matrix((rng.standard_normal(6 * k), (np.repeat(np.arange(k), 6), columns.ravel())), shape=(k, n))


@pytest.mark.parametrize("metis_size", [10**9, 0], ids=["amd", "nested-dissection"])
def test_refill_and_solve_equal_the_sparse_product(monkeypatch, metis_size, backend):
    """The fixed-pattern refill of diag(d) + Aᵀ diag(w) A against scipy's product, for two
    weightings (the second reuses the ordering and the symbolic factorization), with either
    ordering."""
    monkeypatch.setattr(cholesky, "METIS_SIZE", metis_size)
    A = random_rows(1)
    rng = np.random.default_rng(2)
    gram = GramMatrix(A)
    for _ in range(2):
        w, d = rng.uniform(0.1, 2.0, A.shape[0]), rng.uniform(0.1, 2.0, A.shape[1])
        solve = gram.factor(w, d)
        dense = (A.T @ sp.diags(w) @ A).toarray() + np.diag(d)
        stored = gram.lower(w, d).toarray()
        assert np.allclose(stored, np.tril(dense))
        v = rng.standard_normal(A.shape[1])
        assert np.allclose(dense @ solve(v), v)


def test_refresh_takes_new_values_of_the_same_pattern_only(backend):
    A = random_rows(3)
    gram = GramMatrix(A)
    B = A.copy()
    B.data = B.data * 2.0
    assert gram.refresh(B)
    w, d = np.ones(A.shape[0]), np.ones(A.shape[1])
    dense = (B.T @ B).toarray() + np.eye(A.shape[1])
    v = np.arange(A.shape[1], dtype=float)
    assert np.allclose(dense @ gram.factor(w, d)(v), v)
    assert not gram.refresh(random_rows(4))


def test_a_pattern_with_stored_zeros_is_refilled_right_when_they_get_values(backend):
    """The pattern is the structure of A, stored zeros included: ipm reuses the last problem's
    Gram matrix for a matrix of the same structure, and a stored zero there may hold a value
    now. Before, the pattern came from the values (scipy's product drops exact zeros), the
    refill put such products in other entries, and the factorization broke down (a 2-cell step
    after a run of 788 steps: "ipm failed at linearization 0: breakdown")."""
    A = random_rows(5, k=40, n=30)
    zeroed = A.copy()
    zeroed.data[::3] = 0.0  # stored, not removed
    gram = GramMatrix(zeroed)
    assert gram.size == GramMatrix(A).size
    assert gram.refresh(A)
    w, d = np.ones(A.shape[0]), np.ones(A.shape[1])
    dense = (A.T @ A).toarray() + np.eye(A.shape[1])
    stored = gram.lower(w, d).toarray()
    assert np.allclose(stored, np.tril(dense))
    v = np.arange(A.shape[1], dtype=float)
    assert np.allclose(dense @ gram.factor(w, d)(v), v)


def test_a_matrix_that_is_not_positive_definite_is_an_arithmetic_error(backend):
    """(ipm regularizes more on it.) d = −1 with w = 0 makes −I."""
    A = random_rows(6, k=40, n=30)
    gram = GramMatrix(A)
    with pytest.raises(ArithmeticError):
        gram.factor(np.zeros(A.shape[0]), -np.ones(A.shape[1]))


def test_a_constant_matrix_within_the_pattern_is_added_to_every_factorization():
    """GramMatrix.stored: the values of a symmetric matrix in the pattern of AᵀA (none outside
    it), added by factor(..., extra)."""
    import scipy.sparse as sp

    from qpcontact.solvers.cholesky import GramMatrix

    A = sp.csr_matrix(np.array([[1.0, 2.0, 0.0], [0.0, 1.0, 3.0]]))
    gram = GramMatrix(A)
    E = sp.csr_matrix(np.array([[2.0, 1.0, 0.0], [1.0, 2.0, 0.0], [0.0, 0.0, 1.0]]))
    w, d = np.array([1.0, 2.0]), np.ones(3)
    solve = gram.factor(w, d, gram.stored(E))
    matrix = np.diag(d) + A.T.toarray() @ np.diag(w) @ A.toarray() + E.toarray()
    v = np.array([1.0, -2.0, 0.5])
    assert np.allclose(solve(v), np.linalg.solve(matrix, v))
    assert gram.stored(sp.csr_matrix(np.array([[0.0, 0.0, 1.0], [0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]))) is None


def _grown_pair(seed: int) -> tuple[sp.csr_matrix, sp.csr_matrix]:
    """A matrix and the next of its family: its rows with new values, in another order, some of
    them twice, and rows between cells no row joined before (new entries of the pattern)."""
    old = random_rows(seed)
    rng = np.random.default_rng(seed + 100)
    again = old[rng.permutation(old.shape[0])].tocsr()
    again.data = rng.standard_normal(again.nnz)
    new = random_rows(seed + 200, k=20)
    return old, sp.vstack([again, old[:7], new], format="csr")


@pytest.mark.parametrize("metis_size", [10**9, 0], ids=["amd", "nested-dissection"])
def test_a_matrix_grown_from_the_last_of_its_family_is_the_matrix_built_anew(monkeypatch, metis_size, backend):
    monkeypatch.setattr(cholesky, "METIS_SIZE", metis_size)
    old, new = _grown_pair(3)
    last = GramMatrix(old)
    last.factor(np.ones(old.shape[0]), np.ones(old.shape[1]))
    grown, anew = GramMatrix(new, grown_from=last), GramMatrix(new)
    assert grown.inherited and not anew.inherited
    assert grown.size > last.size  # the new rows' entries were added
    rng = np.random.default_rng(4)
    w, d = rng.random(new.shape[0]), 1.0 + rng.random(new.shape[1])
    expected = (sp.diags(d) + new.T @ sp.diags(w) @ new).toarray()
    for matrix in (grown, anew):
        assert np.abs(matrix.lower(w, d).toarray() - np.tril(expected)).max() < 1e-12
    v = rng.standard_normal(new.shape[1])
    assert np.allclose(grown.factor(w, d)(v), np.linalg.solve(expected, v), rtol=1e-9, atol=1e-12)


def _with_plane_rows(matrix: sp.csr_matrix, seed: int) -> sp.csr_matrix:
    """``matrix`` with rows of one block of three entries (a cell against a plane) between its
    rows: rows of different lengths, interleaved."""
    rng = np.random.default_rng(seed)
    k, n = matrix.shape[0] // 4, matrix.shape[1]
    columns = 3 * rng.integers(0, n // 3, size=k)[:, None] + np.arange(3)
    plane = sp.csr_matrix((rng.standard_normal(3 * k), (np.repeat(np.arange(k), 3), columns.ravel())), shape=(k, n))
    rows = sp.vstack([matrix, plane], format="csr")
    return rows[rng.permutation(rows.shape[0])].tocsr()


@pytest.mark.parametrize("metis_size", [10**9, 0], ids=["amd", "nested-dissection"])
def test_rows_of_different_lengths_refill_and_grow_right(monkeypatch, metis_size, backend):
    """Rows of a cell against a plane (3 entries) among contact rows (6): the refill, a refresh
    and a matrix grown from the last all equal the sparse product."""
    monkeypatch.setattr(cholesky, "METIS_SIZE", metis_size)
    old, new = _grown_pair(11)
    old, new = _with_plane_rows(old, 12), _with_plane_rows(new, 13)
    last = GramMatrix(old)
    last.factor(np.ones(old.shape[0]), np.ones(old.shape[1]))
    grown = GramMatrix(new, grown_from=last)
    assert grown.inherited
    rng = np.random.default_rng(14)
    refreshed = new.copy()
    refreshed.data = rng.standard_normal(refreshed.nnz)
    for matrix, values in ((grown, new), (grown, refreshed)):
        assert matrix.refresh(values)
        w, d = rng.random(new.shape[0]), 1.0 + rng.random(new.shape[1])
        expected = (sp.diags(d) + values.T @ sp.diags(w) @ values).toarray()
        assert np.abs(matrix.lower(w, d).toarray() - np.tril(expected)).max() < 1e-12
        v = rng.standard_normal(new.shape[1])
        assert np.allclose(matrix.factor(w, d)(v), np.linalg.solve(expected, v), rtol=1e-9, atol=1e-12)


def test_a_grown_matrix_with_no_new_entries_keeps_the_last_analysis(backend):
    old = random_rows(5)
    last = GramMatrix(old)
    last.factor(np.ones(old.shape[0]), np.ones(old.shape[1]))
    again = old.copy()
    again.data = np.random.default_rng(6).standard_normal(again.nnz)
    grown = GramMatrix(sp.vstack([again, old[:3]], format="csr"), grown_from=last)
    assert grown.size == last.size and grown._symbolic is not None and last._symbolic is None
    w, d = np.ones(old.shape[0] + 3), np.ones(old.shape[1])
    matrix = sp.vstack([again, old[:3]], format="csr")
    expected = (sp.diags(d) + matrix.T @ matrix).toarray()
    assert np.allclose(grown.factor(w, d)(np.ones(old.shape[1])), np.linalg.solve(expected, np.ones(old.shape[1])))


def test_a_matrix_of_other_columns_or_mostly_new_rows_is_built_anew():
    old = random_rows(7)
    last = GramMatrix(old)
    assert not GramMatrix(random_rows(8, n=303), grown_from=last).inherited  # other unknowns
    assert not GramMatrix(random_rows(9), grown_from=last).inherited  # other rows altogether
    empty = GramMatrix(sp.csr_matrix((20, 300)))  # rows with no entries: no products to keep
    rows = sp.vstack([sp.csr_matrix((20, 300)), random_rows(10, k=1)], format="csr")
    grown = GramMatrix(rows, grown_from=empty)
    assert not grown.inherited
    expected = (sp.identity(300) + rows.T @ rows).toarray()
    assert np.allclose(grown.lower(np.ones(21), np.ones(300)).toarray(), np.tril(expected))
