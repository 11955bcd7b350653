"""The colony measurements that run as modules (python -m qpcontact.studies.…), at toy size."""

from __future__ import annotations

import csv

from qpcontact.studies import colony_10k, colony_benchmark


def test_colony_benchmark_writes_its_table_data_and_picture(tmp_path):
    code = colony_benchmark.main(["--cells", "6", "--repeats", "1", "--configs", "linear,clarabel 1e-6",
                                  "--out", str(tmp_path)])
    assert code == 0
    rows = list(csv.DictReader((tmp_path / "data" / "colony_benchmark.csv").open()))
    assert [r["config"] for r in rows] == ["linear", "clarabel 1e-6"]
    assert all(int(r["cells"]) >= 6 and not r["error"] for r in rows)
    assert "| linear |" in (tmp_path / "data" / "colony_benchmark.md").read_text()
    assert (tmp_path / "img" / "colony_error_time.png").stat().st_size > 1000


def test_colony_10k_steps_a_packed_colony_with_each_solver(tmp_path):
    assert colony_10k.main(["colony_2d:40", "--steps", "2", "--solvers", "osqp@1e-4,mprgp@1e-6",
                            "--out", str(tmp_path)]) == 0
    rows = [line for line in (tmp_path / "colony_10k.md").read_text().splitlines()
            if line.startswith("| scenes.colony_2d(40)")]
    assert [row.split("|")[2].strip() for row in rows] == ["osqp", "mprgp"]
    assert all(row.split("|")[-2].strip() == "" for row in rows)  # no failure noted
