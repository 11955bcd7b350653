"""qpcontact convergence (issue 32): a tiny study (60 cells, two step sizes, one seed), its tables,
picture and errors against the finest step; a study stopped after its first run keeps it and
continues; the checks before anything starts."""

from __future__ import annotations

import csv
import json
import math

import pytest

from qpcontact import cli
from qpcontact.studies import convergence

ARGS = ["--cells", "60", "--growth-per-step", "0.05,0.1", "--seeds", "1", "--snapshot-every", "20"]


def read_rows(path):
    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


@pytest.fixture(scope="module")
def study(tmp_path_factory):
    out = tmp_path_factory.mktemp("convergence") / "study"
    assert cli.main(["convergence", *ARGS, "--out", str(out)]) == 0
    return out


def test_a_study_reports_each_statistic_against_the_finest_step_with_the_cost_of_each(study, capsys):
    rows = read_rows(study / convergence.TABLE_FILE)
    assert [float(r["growth_per_step"]) for r in rows] == [0.05, 0.1]  # the finest first
    finest, coarse = rows
    assert finest["runs"] == coarse["runs"] == "1"
    for name in convergence.TABLED[2]:
        assert float(finest[f"{name}_error"]) == 0.0
        assert float(coarse[f"{name}_error"]) == pytest.approx(float(coarse[f"{name}_mean"]) -
                                                               float(finest[f"{name}_mean"]), rel=1e-4, abs=1e-5)
    # half the step: about twice the steps and more linearizations
    assert float(finest["steps_mean"]) > 1.6 * float(coarse["steps_mean"])
    assert float(finest["linearizations_mean"]) > float(coarse["linearizations_mean"]) > 0
    runs = read_rows(study / convergence.RUNS_FILE)
    assert {r["name"] for r in runs} == {"growth_per_step-0.05__seed-1", "growth_per_step-0.1__seed-1"}
    for run in runs:
        assert run["status"] == "done" and int(run["cells"]) >= 60 and 0.5 < float(run["packing"]) <= 1.0
        folder = study / "runs" / run["name"]
        history = read_rows(folder / "history.csv")
        assert float(run["run_seconds"]) == pytest.approx(sum(float(h["step_seconds"]) for h in history), rel=1e-5)
        assert int(run["linearizations"]) == sum(int(h["linearizations"]) for h in history)
        stored = json.loads((folder / convergence.STATISTICS_FILE).read_text())
        assert float(run["packing"]) == pytest.approx(stored["packing"], rel=1e-5)
        settings = (folder / "config.toml").read_text()
        assert f"growth_per_step = {run['growth_per_step']}" in settings and "seed = 1" in settings
    assert (study / convergence.PLOT_FILE).stat().st_size > 10_000


def test_a_stopped_study_keeps_its_finished_runs_and_continues(tmp_path, monkeypatch, capsys):
    real = convergence.run_task
    started = []

    def stopped_at_the_second(name, settings, folder):
        started.append(name)
        if len(started) == 2:
            raise KeyboardInterrupt
        return real(name, settings, folder)

    monkeypatch.setattr(convergence, "run_task", stopped_at_the_second)
    out = tmp_path / "study"
    assert cli.main(["convergence", *ARGS, "--out", str(out)]) == 130
    assert "--resume --out" in capsys.readouterr().err
    plan = json.loads((out / convergence.PLAN_FILE).read_text())
    assert [r["status"] for r in plan["runs"]] == ["done", "pending"]  # the cheapest step first
    assert (out / convergence.TABLE_FILE).exists()  # what it reached is written
    monkeypatch.setattr(convergence, "run_task", real)
    assert cli.main(["convergence", "--resume", "--out", str(out)]) == 0
    assert "1 to do" in capsys.readouterr().err
    plan = json.loads((out / convergence.PLAN_FILE).read_text())
    assert [r["status"] for r in plan["runs"]] == ["done", "done"]
    first = out / "runs" / plan["runs"][0]["name"] / "attempts.jsonl"
    assert len(first.read_text().splitlines()) == 1  # not run again
    rows = read_rows(out / convergence.TABLE_FILE)
    assert [r["runs"] for r in rows] == ["1", "1"]


def test_a_three_dimensional_study_reports_the_biofilm(tmp_path, capsys):
    out = tmp_path / "study"
    assert cli.main(["convergence", "--dimensions", "3", "--cells", "12", "--growth-per-step", "0.05,0.1", "--out",
                     str(out)]) == 0
    assert "bottom_fraction" in capsys.readouterr().out
    rows = read_rows(out / convergence.TABLE_FILE)
    assert 0 < float(rows[1]["bottom_fraction_mean"]) <= 1 and float(rows[0]["vertical_fraction_error"]) == 0
    assert math.isnan(float(read_rows(out / convergence.RUNS_FILE)[0]["packing"]))


@pytest.mark.parametrize("argv, message", [
    (["--growth-per-step", "0.05"], "two or more different step sizes"),
    (["--growth-per-step", "0.05,0.05"], "two or more different step sizes"),
    (["--seeds", "1,1"], "each seed once"),
    (["--time-step", "expansion"], "used by the growth time step only"),
    (["--snapshot-every", "0"], "--snapshot-every 0"),
    (["--resume", "--cells", "10"], "drop --cells"),
])
def test_a_bad_study_is_one_line_and_exit_2_before_any_run(tmp_path, capsys, argv, message):
    out = tmp_path / "study"
    assert cli.main(["convergence", *argv, "--out", str(out)]) == 2
    assert message in capsys.readouterr().err
    assert not (out / "runs").exists()


def test_a_study_is_not_replaced_without_overwrite(study, capsys):
    assert cli.main(["convergence", *ARGS, "--out", str(study)]) == 2
    assert "continue it with --resume" in capsys.readouterr().err


def test_a_failed_run_is_reported_by_name_and_the_others_all_the_same(tmp_path, monkeypatch, capsys):
    real = convergence.run_task

    def coarse_fails(name, settings, folder):
        if "0.1" in name:
            return {"name": name, "status": "failed", "error": "TooManyContactsError: 2.4e6 candidate pairs"}
        return real(name, settings, folder)

    monkeypatch.setattr(convergence, "run_task", coarse_fails)
    out = tmp_path / "study"
    assert cli.main(["convergence", *ARGS, "--out", str(out)]) == 1
    assert "growth_per_step-0.1__seed-1: failed: TooManyContactsError" in capsys.readouterr().err
    finest, coarse = read_rows(out / convergence.TABLE_FILE)
    assert (finest["runs"], finest["failed"], coarse["runs"], coarse["failed"]) == ("1", "0", "0", "1")
    assert coarse["packing_mean"] == "nan" and float(finest["packing_mean"]) > 0.5
    statuses = {r["name"]: (r["status"], r["error"]) for r in read_rows(out / convergence.RUNS_FILE)}
    assert statuses["growth_per_step-0.1__seed-1"] == ("failed", "TooManyContactsError: 2.4e6 candidate pairs")


@pytest.mark.parametrize("dimensions, steps", [("2", [0.0125, 0.025, 0.05]), ("3", [0.0015625, 0.003125, 0.00625])])
def test_the_default_steps_are_the_scenes_step_and_two_halvings(dimensions, steps):
    import argparse

    parser = argparse.ArgumentParser()
    convergence.add_arguments(parser)
    _, chosen, _ = convergence.configure(parser.parse_args(["--dimensions", dimensions]))
    assert sorted(chosen) == pytest.approx(steps)
    _, given, _ = convergence.configure(parser.parse_args(["--dimensions", dimensions, "--growth-per-step", "0.1,0.2"]))
    assert sorted(given) == [0.1, 0.2]
