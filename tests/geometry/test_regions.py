"""Detection shared by region among processes (qpcontact.geometry.regions): the pairs the
regions find, put together, are the pairs one search finds."""

from __future__ import annotations

import numpy as np
import pytest

from qpcontact.geometry.contacts import candidate_pairs, evaluate_contacts, select_contacts
from qpcontact.geometry.regions import ONE, Split, counted, halo_width, region_pairs
from qpcontact.simulation import Settings, run_colony


@pytest.fixture(scope="module")
def colonies():
    """A grown 2D colony and a 3D biofilm (a few hundred cells each)."""
    return [run_colony(Settings().updated({"cells": 300, "dimensions": d}), progress=False).colony.cells
            for d in (2, 3)]


def _contacts(cells, pairs, margin):
    a, b, kind = select_contacts(cells, pairs, margin, always_closest=True)
    return set(zip(a.tolist(), b.tolist(), kind.tolist(), strict=True))


def _keys(cells, pairs):
    return set((pairs[:, 0].astype(np.int64) * cells.n + pairs[:, 1]).tolist())


def _within(cells, pairs, margin, slack):
    """The keys of the pairs whose capsules are within ``margin + slack_i + slack_j``."""
    pairs = np.unique(pairs, axis=0)
    closest = evaluate_contacts(cells, pairs[:, 0], pairs[:, 1], np.zeros(len(pairs), dtype=np.intp))
    near = closest.separation <= margin + slack[pairs[:, 0]] + slack[pairs[:, 1]]
    return _keys(cells, pairs[near])


@pytest.mark.parametrize("parts", [2, 3, 5])
@pytest.mark.parametrize("margin", [0.0, 0.5])
def test_the_regions_find_each_pair_once_and_every_contact_one_search_finds(colonies, parts, margin):
    for cells in colonies:
        rng = np.random.default_rng(parts)
        slack = rng.uniform(0.0, 0.3, cells.n)
        slack[rng.integers(cells.n)] = 2.0  # one cell that may move far
        for given in (None, slack):
            found = np.concatenate([region_pairs(cells, margin, given, rank, parts) for rank in range(parts)])
            keys = found[:, 0].astype(np.int64) * cells.n + found[:, 1]
            assert np.unique(keys).size == keys.size  # each pair by one region only
            assert np.all(found[:, 0] < found[:, 1])
            one = candidate_pairs(cells, margin, given)
            if given is None:
                assert _contacts(cells, found, margin) == _contacts(cells, one, margin)
            else:  # both hold every pair within margin + slack_i + slack_j (the promise of slack)
                needed = _within(cells, np.concatenate([found, one]), margin, given)
                assert needed <= _keys(cells, found) and needed <= _keys(cells, one)


def test_a_halo_covers_the_farthest_candidates():
    cells = run_colony(Settings().updated({"cells": 50}), progress=False).colony.cells
    assert halo_width(cells, 0.5) == pytest.approx(float(cells.lengths.max() + 2 * cells.radii.max()) + 0.5)
    assert halo_width(cells, 0.5, np.full(cells.n, 0.25)) == pytest.approx(halo_width(cells, 0.5) + 0.5)


def test_one_process_shares_nothing():
    assert ONE.share(10) == slice(0, 10) and ONE.gather("x") == ["x"]


class _Two:
    """Rank ``rank`` of two processes, whose other process contributes ``other``."""

    def __init__(self, rank, other):
        self.rank, self.other = rank, other

    def Get_size(self):
        return 2

    def Get_rank(self):
        return self.rank

    def allgather(self, value):
        return [value, self.other] if self.rank == 0 else [self.other, value]


def test_two_processes_put_their_pairs_together_as_one_search_sorts_them(colonies):
    cells = colonies[0]
    theirs = region_pairs(cells, 0.5, None, 1, 2)
    together = Split(_Two(0, theirs)).candidate_pairs(cells, 0.5)
    keys = together[:, 0].astype(np.int64) * cells.n + together[:, 1]
    assert np.all(np.diff(keys) > 0)
    assert _contacts(cells, together, 0.5) == _contacts(cells, candidate_pairs(cells, 0.5), 0.5)
    assert Split(_Two(1, None)).share(10) == slice(5, 10)


def test_a_counted_block_adds_one_and_its_cpu_seconds_even_when_it_raises():
    """What the MPI benchmarks' counts rest on: each block adds one to ``key + "s"`` and its CPU
    seconds (not wall seconds: a sleep costs none) to ``key + "_cpu"``, also when it raises."""
    import time

    table = {"solves": 0.0, "solve_cpu": 0.0}
    with counted(table, "solve"):
        np.linalg.eigvalsh(np.random.default_rng(0).random((300, 300)))  # some CPU work
        time.sleep(0.2)
    assert table["solves"] == 1 and 0.0 < table["solve_cpu"] < 0.2
    with pytest.raises(ValueError), counted(table, "solve"):
        raise ValueError("inside")
    assert table["solves"] == 2
