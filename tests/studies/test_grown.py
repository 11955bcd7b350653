"""The grown-colony benchmark (qpcontact bench-grown): it grows colonies with each step kind, times
one step of the grown states, reads the peer's log, and writes its table."""

import json

from qpcontact import cli
from qpcontact.studies import grown


def test_bench_grown_writes_its_tables(tmp_path):
    out, cache = tmp_path / "out", tmp_path / "cache"
    code = cli.main(["bench-grown", "--sizes", "8,16", "--velocity-cells", "8", "--repeats", "1", "--out", str(out),
                     "--cache-dir", str(cache)])
    assert code == 0
    data = json.loads((out / "grown.json").read_text())
    growth = {(r["dimensions"], r["step"]): r for r in data["growth"]}
    position, velocity = growth[(2, "position")], growth[(2, "velocity")]
    assert set(position["reached"]) == {"8", "16"} and set(velocity["reached"]) == {"8"}
    assert position["max_overlap"] <= 0.01 + 1e-9 and position["peak_bytes"] > 0
    assert (cache / "2d-16.npz").exists()
    labels = {(r["cells"] >= 16, r["label"]) for r in data["steps"]}
    assert (True, "position, ipm") in labels and (True, "velocity, clarabel 1e-6") in labels
    assert all("error" not in r for r in data["steps"])
    text = (out / "grown.md").read_text()
    assert "Time to grow" in text and "One step of a grown colony" in text
    assert (out / "grown.png").stat().st_size > 1000
    # the same folder again is refused unless --overwrite
    assert cli.main(["bench-grown", "--sizes", "8", "--out", str(out), "--cache-dir", str(cache), "--reuse"]) == 2


def test_bench_grown_can_time_the_growth_alone(tmp_path):
    out, cache = tmp_path / "out", tmp_path / "cache"
    assert cli.main(["bench-grown", "--sizes", "8", "--steps", "position", "--no-step-table", "--out", str(out),
                     "--cache-dir", str(cache)]) == 0
    data = json.loads((out / "grown.json").read_text())
    assert [r["step"] for r in data["growth"]] == ["position"] and data["steps"] == []
    assert "Time to grow" in (out / "grown.md").read_text()


def test_peer_times_read_the_cellmodeller_log(tmp_path):
    log = tmp_path / "log.json"
    rows = [dict(step=i + 1, n=2 ** (i // 3), t_sim=0.5) for i in range(30)]
    rows[15]["max_overlap"] = 0.12
    log.write_text(json.dumps(dict(args={}, log=rows)))
    peer = grown.peer_times(log, [8, 64])
    assert peer["reached"][8]["seconds"] == 0.5 * 10 and peer["reached"][8]["step"] == 10
    assert peer["reached"][64]["max_overlap"] == 0.12


def test_a_growth_run_at_its_time_limit_stops_and_reports_what_it_reached(tmp_path):
    """A colony short of its target at the time limit is stopped cleanly (as by SIGTERM) and the
    sizes it reached are kept (before, the child was killed and the whole record lost)."""
    record = grown.run_growth(2, "position", [2, 10**6], 10**6, tmp_path, timeout=3.0)
    assert "error" not in record or record.get("reached"), record
    assert record["stopped"] == "time limit 3 s"
    assert "2" in {str(k) for k in record["reached"]} and 2 <= record["cells"] < 10**6
    assert (tmp_path / "2d-2.npz").exists()
    assert "run stopped at the time limit 3 s" in grown.markdown([record], [], None, [2, 10**6],
                                                              dict(date="d", machine="m", command="c"))
