"""The independent blocks of a contact system: connected components of the contact graph.

Two contacts are coupled when they share an unknown (a column of ``B̃``); a component's rows
and columns form a problem of their own. :func:`qpcontact.solvers.registry.solve_by_blocks`
hands each block (components merged into blocks of about :data:`BLOCK_ROWS` contacts) to a
blockwise solver separately.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

#: Blocks handed to a solver have about this many contacts (see :func:`independent_blocks`).
BLOCK_ROWS = 2000


def independent_blocks(matrix: sp.spmatrix, min_rows: int = 0) -> list[tuple[np.ndarray, np.ndarray]]:
    """The independent subproblems of ``B̃ ỹ ≥ b̃``: connected components of the contact graph
    (rows and columns linked by the non-zeros of ``B̃``), as ``(rows, columns)`` index arrays in
    increasing order. Consecutive components are merged into blocks of about ``min_rows`` rows
    (the components starting in the same window of ``min_rows`` rows; a component is never cut):
    fewer, larger solver calls, since each call has a fixed cost. Blocks without rows (columns
    with no non-zero, whose answer is 0) are left out."""
    matrix = sp.csr_matrix(matrix)
    k, n = matrix.shape
    pattern = sp.csr_matrix((np.ones(matrix.nnz, dtype=np.int8), matrix.indices, matrix.indptr), shape=(k, n))
    n_comp, label = connected_components(sp.bmat([[None, pattern], [pattern.T, None]], format="csr"), directed=False)
    sizes = np.bincount(label[:k], minlength=n_comp)
    block = np.unique((np.cumsum(sizes) - sizes) // max(min_rows, 1), return_inverse=True)[1][label]
    row_block, col_block = block[:k], block[k:]
    n_blocks = int(block.max()) + 1
    rows = np.split(np.argsort(row_block, kind="stable"), np.cumsum(np.bincount(row_block, minlength=n_blocks))[:-1])
    cols = np.split(np.argsort(col_block, kind="stable"), np.cumsum(np.bincount(col_block, minlength=n_blocks))[:-1])
    return [(r, c) for r, c in zip(rows, cols, strict=True) if r.size]
