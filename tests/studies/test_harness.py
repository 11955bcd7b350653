"""The study harness shared by the comparison and the stability report."""

from __future__ import annotations

import math
import operator
import os
import time

from qpcontact.resolve import metrics
from qpcontact.studies import CATALOGUE, harness, make_scene
from qpcontact.studies.compare import SceneCase


def test_guarded_reports_ok_timeout_crash_and_error():
    assert harness.guarded(dict, ([("x", 1)],), 10) == ("ok", {"x": 1})
    start = time.perf_counter()
    assert harness.guarded(time.sleep, (30,), 0.5) == ("timeout", None)
    assert time.perf_counter() - start < 10
    assert harness.guarded(os._exit, (3,), 10) == ("crashed", 3)
    status, text = harness.guarded(operator.truediv, (1, 0), 10)
    assert status == "error" and text.startswith("ZeroDivisionError: division by zero") and "Traceback" in text


def test_guarded_children_start_from_a_forkserver(monkeypatch):
    """Forking a process that has run Clarabel can deadlock: the guard must never fork it."""
    import multiprocessing

    contexts = []
    real = multiprocessing.get_context

    def spy(method=None):
        contexts.append(method)
        return real(method)

    monkeypatch.setattr(multiprocessing, "get_context", spy)
    assert harness.guarded(abs, (-2,), 10) == ("ok", 2)
    assert contexts == ["forkserver"]


def test_prepare_gives_references_that_meet_their_own_optimality_conditions():
    case = SceneCase("rod_chain", "hand-made", "rod_chain", 12)
    prepared = harness.prepare(case, make_scene("rod_chain", 12), refine=True)
    system = prepared.system
    assert system is not None and set(prepared.references) == {"linear", "least_squares", "complementarity"}
    assert prepared.reference_residual <= 1e-10 and prepared.condition is None
    for name, y in prepared.references.items():
        assert prepared.reference_penetration[name] == metrics.penetration(system, y)
    # A chain pushed together end to end: every contact pushes, so all three answers coincide.
    assert prepared.all_active
    for y in prepared.references.values():
        assert metrics.distance(y, prepared.references["linear"]) < 1e-8


def test_prepare_of_a_scene_with_nothing_to_solve():
    case = CATALOGUE["crossing"]
    cells = case.make(seed=0)
    resting = cells.replace(momenta=-cells.momenta * 0.0, centers=cells.centers + [[0.0, 0.0, 10.0], [0.0, 0.0, 0.0]])
    prepared = harness.prepare(case, resting, condition=True)
    assert prepared.system is None and prepared.references == {} and prepared.condition is None
    assert math.isnan(prepared.reference_residual)
