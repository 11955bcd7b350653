"""Stiff and extreme cases (qpcontact.studies.catalogue): finiteness, the invariants of model.md, unit
invariance, and clear errors. The 10⁴-rod chain and the 1000-neighbour hub run at reduced size
here (full size in ``qpcontact stability``)."""

from __future__ import annotations

import csv

import numpy as np
import pytest

import qpcontact as q
from qpcontact.resolve import metrics
from qpcontact.studies.catalogue import CATALOGUE, hub, long_chain
from qpcontact.studies.stability import KKT_LIMIT, check, main, prepare
from tests.helpers import interrupt_on_call

#: Reduced sizes of the large cases.
SMALL = {"hub_1000": {"n_neighbours": 60}, "chain_10000": {"n_cells": 200}}
CASES = list(CATALOGUE)


def _resolve(case_name: str, **kwargs) -> tuple[q.Result, object]:
    case = CATALOGUE[case_name]
    cells = case.make(0, **SMALL.get(case_name, {}))
    contacts = case.contacts(cells) if case.contacts else None
    return q.resolve(cells, contacts=contacts, **case.options, **kwargs), cells


@pytest.mark.parametrize("name", CASES)
def test_generators_are_seeded_and_collide(name):
    case = CATALOGUE[name]
    a = case.make(3, **SMALL.get(name, {}))
    b = case.make(3, **SMALL.get(name, {}))
    assert np.array_equal(a.centers, b.centers) and np.array_equal(a.momenta, b.momenta)
    contacts = case.contacts(a) if case.contacts else q.find_contacts(a)
    opts = {k: v for k, v in case.options.items() if k in ("position_correction", "dt")}
    active, rhs = q.colliding(contacts, **opts)
    assert len(active) > 0 and np.all(rhs > 0)


@pytest.mark.parametrize("name", CASES)
def test_invariants_complementarity(name):
    """Finite impulses, no penetration, equal and opposite contact impulses (momentum), energy
    never increases (without position correction), and equality with the plain linear solve
    when every contact is active."""
    result, cells = _resolve(name, solver="clarabel", formulation="complementarity")
    assert result.converged
    assert np.all(np.isfinite(result.impulses)) and np.all(np.isfinite(result.contact_impulses))
    assert result.errors["penetration"] <= KKT_LIMIT
    assert result.errors["momentum_change"] <= KKT_LIMIT
    assert result.errors["angular_momentum_change"] <= KKT_LIMIT
    if not CATALOGUE[name].options.get("position_correction"):
        assert result.errors["energy_change"] <= KKT_LIMIT * abs(cells.kinetic_energy())
    agreement = q.compare_with_linear(result, tolerance=1e-3)
    assert agreement.agrees in (True, None)
    if agreement.all_active:
        assert agreement.distance <= 1e-3


@pytest.mark.parametrize("name", CASES)
def test_linear_solve_is_finite_and_conserves_momentum(name):
    result, cells = _resolve(name, solver="linear", on_failure="return")
    assert np.all(np.isfinite(result.impulses))
    # With position correction Mx = b may have no solution: the plain answer then penetrates and
    # is refused (issue 13, item 6), but it is still a momentum-conserving least-squares answer.
    assert result.converged or "no solution" in result.message
    assert result.errors["momentum_change"] <= 1e-9
    assert result.errors["angular_momentum_change"] <= 1e-9
    if not CATALOGUE[name].options.get("position_correction"):
        # Mx = b is consistent (see test_without_position_correction_mx_equals_b_is_consistent),
        # so the plain solve stops every contact exactly and removes energy.
        assert result.converged and result.errors["penetration"] <= 1e-8
        assert result.errors["energy_change"] <= 1e-9 * abs(cells.kinetic_energy())


@pytest.mark.parametrize("name", ["mass_ratio_1e-08", "growth_inertia_1e-08", "velocity_mixed", "jammed_fcc"])
def test_least_squares_agrees_with_reference(name):
    case = CATALOGUE[name]
    prep = prepare(case, 0, SMALL.get(name))
    result, _ = _resolve(name, solver="osqp", formulation="least_squares")
    measures = check(prep, "least_squares", result.impulses, result.contact_impulses)
    assert measures["failed"] == [], measures


def test_unit_invariance():
    """The same scene in m/kg/s and µm/pg/s: the same dimensionless system and answer, and
    impulses that differ exactly by the unit of momentum."""
    si, _ = _resolve("units_m_kg_s", solver="clarabel")
    micro, _ = _resolve("units_um_pg_s", solver="clarabel")
    assert len(si.contacts) == len(micro.contacts)
    assert np.allclose(si.system.matrix.toarray(), micro.system.matrix.toarray(), rtol=1e-9, atol=1e-12)
    assert np.allclose(si.system.rhs, micro.system.rhs, rtol=1e-9, atol=1e-12)
    assert metrics.distance(si.scaled_solution, micro.scaled_solution) <= 1e-6
    momentum_unit = 1e-15 * 1e-6  # kg·m/s per pg·µm/s
    scale = np.array([momentum_unit] * 3 + [momentum_unit * 1e-6] * 3 + [momentum_unit])
    assert np.allclose(si.impulses, micro.impulses * scale, rtol=1e-5, atol=1e-5 * np.abs(si.impulses).max())


def test_large_cases_at_reduced_size_match_full_size_structure():
    chain = long_chain(0, n_cells=300)
    assert len(q.find_contacts(chain)) == 299  # end to end: one tip contact per neighbour pair
    small_hub = hub(0, n_neighbours=80)
    contacts = q.find_contacts(small_hub)
    assert np.count_nonzero((contacts.cell_a == 0) | (contacts.cell_b == 0)) == 80


def test_without_position_correction_mx_equals_b_is_consistent():
    """The original design notes say least_squares and the plain solve differ for jammed packings, where the
    plain solve leaves contacts penetrating. Without position correction that never happens:
    b = −u = M(−p) (stopping every cell satisfies every contact), so Mx = b is consistent even
    with more contacts than unknowns. Only position correction makes it over-determined."""
    case = CATALOGUE["jammed_disks"]
    cells = case.make(0)
    plain = q.resolve(cells, solver="linear")
    assert plain.system.shape[0] > plain.system.shape[1]  # more contacts than unknowns
    assert plain.errors["penetration"] <= 1e-8 and "least squares" not in plain.status
    ls = q.resolve(cells, solver="osqp", formulation="least_squares")
    assert metrics.distance(ls.scaled_solution, plain.scaled_solution) <= 1e-4
    corrected = q.resolve(cells, solver="linear", on_failure="return", **case.options)
    assert "least squares" in corrected.status and corrected.errors["penetration"] > 1e-5
    assert not corrected.converged  # refused: a penetrating plain answer is not a resolution


def test_reference_solution_of_a_jammed_packing():
    """Regression: reference_solution raised on jammed packings (LSMR cannot reach 1e-12)."""
    result, _ = _resolve("jammed_fcc", solver="clarabel", formulation="least_squares")
    y = q.reference_solution(result.system, "least_squares")
    assert np.all(np.isfinite(y)) and metrics.penetration(result.system, y) <= 1e-8


# Failures raise the documented error. Without scaling, tolerances become absolute in the
# caller's units; these answers passed resolve's checks before the acceptance test also looked
# at least-squares overshoot and at multiplier consistency (docs/stability.md).
@pytest.mark.parametrize("name, solver, formulation, form, words", [
    ("velocity_1e-06", "clarabel", "least_squares", "primal", "overshoots"),
    ("overlap_1e-08", "piqp", "least_squares", "primal", "overshoots"),
    ("units_m_kg_s", "osqp", "complementarity", "primal", "multiplier inconsistency"),
])
def test_unscaled_garbage_is_reported(name, solver, formulation, form, words):
    with pytest.raises(q.SolverFailedError, match=words) as info:
        _resolve(name, solver=solver, formulation=formulation, form=form, scale=False)
    assert info.value.result is not None and not info.value.result.converged
    # The same case with scaling (the default) is solved correctly.
    result, _ = _resolve(name, solver=solver, formulation=formulation, form=form)
    prep = prepare(CATALOGUE[name], 0)
    assert check(prep, formulation, result.impulses, result.contact_impulses)["failed"] == []


def test_failure_returns_unconverged_result_unapplied():
    result, cells = _resolve("velocity_1e-06", solver="clarabel", formulation="complementarity", scale=False,
                             on_failure="return")
    assert not result.converged and result.message
    assert result.cells is not cells and np.array_equal(result.cells.momenta, cells.momenta)


def test_stability_command_writes_tables(tmp_path):
    out = tmp_path / "stab"
    code = main(["--cases", "parallel_0,crossing", "--solvers", "linear,osqp", "--formulations", "complementarity",
                 "--forms", "primal", "--time-limit", "5", "--guard", "60", "--out", str(out)])
    rows = list(csv.DictReader((out / "stability.csv").open()))
    assert code == 0 and len(rows) == 8
    assert {r["outcome"] for r in rows} == {"ok"}
    assert "nan" not in (out / "stability.csv").read_text().lower()
    assert "| parallel_0 |" in (out / "stability.md").read_text()


def test_condition_estimate_is_reported_and_none_when_singular():
    result, _ = _resolve("aspect_10000", solver="osqp", estimate_condition=True)
    assert 1.0 <= result.condition_estimate < 1e3  # long thin rods stay well conditioned after scaling
    near, _ = _resolve("near_duplicate", solver="linear", estimate_condition=True)
    assert near.condition_estimate > 1e12  # two contacts 1e-8 length apart: nearly dependent rows
    dup, _ = _resolve("duplicate_contacts", solver="linear", estimate_condition=True)
    assert dup.converged and dup.condition_estimate is None  # singular Delassus operator: LSMR path


def test_piqp_contact_form_solves_small_cases():
    """Regression: the contact-form Delassus matrix had unsorted CSC indices, which PIQP misreads
    (it reported PIQP_DUAL_INFEASIBLE on a 2 × 2 positive definite bound-constrained QP)."""
    for name in ("parallel_0", "aspect_1", "mass_ratio_1e-08"):
        result, _ = _resolve(name, solver="piqp", formulation="complementarity", form="contact")
        assert result.converged and result.errors["penetration"] <= KKT_LIMIT


def test_stability_command_names_an_unknown_solver(tmp_path, capsys):
    assert main(["--solvers", "nosuch", "--cases", "crossing", "--out", str(tmp_path / "stab")]) == 2
    assert "qpcontact stability: unknown solver 'nosuch'" in capsys.readouterr().err


def test_a_refused_combination_is_counted_as_refused_not_as_an_error(tmp_path):
    """MPRGP does not solve least squares, and says so before solving: that is no failure."""
    out = tmp_path / "stab"
    code = main(["--cases", "crossing", "--solvers", "mprgp", "--forms", "contact,primal", "--scaling", "on",
                 "--repeats", "1", "--out", str(out)])
    rows = list(csv.DictReader((out / "stability.csv").open()))
    assert code == 0
    outcomes = {(r["formulation"], r["form"]): r["outcome"] for r in rows}
    assert outcomes == {("complementarity", "contact"): "ok", ("complementarity", "primal"): "refused",
                        ("least_squares", "contact"): "refused", ("least_squares", "primal"): "refused"}
    text = (out / "stability.md").read_text()
    assert "ok / refused / error / wrong / crash / timeout" in text and "| mprgp LS | 0 / 1 / 0 / 0 / 0 / 0 |" in text


def test_quick_mode_runs_a_few_cases_in_their_default_forms(tmp_path, capsys):
    from qpcontact.studies.stability import QUICK_CASES

    out = tmp_path / "stab"
    assert main(["--quick", "--solvers", "linear,clarabel", "--out", str(out)]) == 0
    rows = list(csv.DictReader((out / "stability.csv").open()))
    assert sorted({r["case"] for r in rows}) == sorted(QUICK_CASES)
    assert {(r["solver"], r["formulation"], r["form"], r["scale"]) for r in rows} == {
        ("linear", "linear", "contact", "True"), ("clarabel", "complementarity", "contact", "True"),
        ("clarabel", "least_squares", "primal", "True")}
    assert f"wrote:\n  {out / 'stability.csv'}\n  {out / 'stability.md'}" in capsys.readouterr().out


def test_ctrl_c_writes_the_runs_that_were_done(tmp_path, monkeypatch):
    """A Ctrl-C lost the whole report."""
    from qpcontact.studies import stability

    interrupt_on_call(monkeypatch, stability, "guarded", 3)
    out = tmp_path / "stab"
    assert main(["--cases", "crossing,parallel_0", "--solvers", "linear,osqp", "--formulations", "complementarity",
                 "--forms", "contact", "--scaling", "on", "--out", str(out)]) == 130
    assert len(list(csv.DictReader((out / "stability.csv").open()))) == 2
    assert "Interrupted (Ctrl-C) after 2 of 4 runs" in (out / "stability.md").read_text()


def test_an_earlier_report_is_replaced_only_when_asked(tmp_path, capsys):
    out = tmp_path / "stab"
    out.mkdir()
    (out / "stability.csv").write_text("committed\n")
    args = ["--cases", "crossing", "--solvers", "linear", "--scaling", "on", "--out", str(out)]
    assert main(args) == 2
    assert "pass --overwrite" in capsys.readouterr().err and (out / "stability.csv").read_text() == "committed\n"
    assert main([*args, "--overwrite"]) == 0 and "crossing" in (out / "stability.csv").read_text()
