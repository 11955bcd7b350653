"""Output folders and files (qpcontact.io.outputs): checked before the work, written atomically."""

from __future__ import annotations

import csv
import os
from pathlib import Path

import numpy as np
import pytest

from qpcontact.errors import OutputFolderError
from qpcontact.io.outputs import atomic_write, describe_written, prepare_folder, write_csv, write_text


def test_a_folder_that_cannot_be_written_is_refused_before_any_work(tmp_path):
    blocker = tmp_path / "a-file"
    blocker.write_text("not a folder")
    with pytest.raises(OutputFolderError, match="cannot write there"):
        prepare_folder(blocker / "out")


def unwritable_folder(tmp_path):
    """A folder this process may not write into: one without write permission for a user; for
    root, who writes whatever the permission bits say (CI runs as root), a folder in sysfs, where
    the kernel refuses new entries to everyone."""
    if os.geteuid() != 0:
        folder = tmp_path / "ro"
        folder.mkdir()
        folder.chmod(0o500)
        return folder / "out", lambda: folder.chmod(0o700)
    if not os.path.isdir("/sys/kernel"):
        pytest.fail("no sysfs at /sys: this test needs a folder that root cannot write")
    return Path("/sys/qpcontact-output-test"), lambda: None


def test_a_folder_without_permission_to_write_is_refused_even_as_root(tmp_path):
    """(Skipped as root until issue 19, so CI, which runs as root, never ran it.)"""
    folder, restore = unwritable_folder(tmp_path)
    try:
        with pytest.raises(OutputFolderError, match="cannot write there .*(ermission|not permitted)"):
            prepare_folder(folder)
        assert not folder.exists()
    finally:
        restore()


def test_an_earlier_run_is_refused_and_replaced_only_when_asked(tmp_path):
    (tmp_path / "snapshots").mkdir()
    (tmp_path / "snapshots" / "step_000005.npz").write_text("old")
    (tmp_path / "history.csv").write_text("old")
    (tmp_path / "notes.txt").write_text("mine")
    outputs = ("history.csv", "snapshots/step_*.npz")
    with pytest.raises(OutputFolderError, match="holds the outputs of an earlier run .*--overwrite"):
        prepare_folder(tmp_path, outputs)
    assert (tmp_path / "history.csv").read_text() == "old"
    prepare_folder(tmp_path, outputs, overwrite=True)
    # Nothing of the earlier run stays behind, stale; other files are left alone.
    assert not (tmp_path / "history.csv").exists() and not list((tmp_path / "snapshots").iterdir())
    assert (tmp_path / "notes.txt").read_text() == "mine"


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path):
    path = write_text(tmp_path / "table.md", "old\n")

    def half_then_fail(handle):
        handle.write(b"new, half written")
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        atomic_write(path, half_then_fail)
    assert path.read_text() == "old\n"
    assert [p.name for p in tmp_path.iterdir()] == ["table.md"]
    assert oct(path.stat().st_mode & 0o777) != oct(0o600)  # the usual permissions, not mkstemp's private ones


def test_what_was_written_is_listed_and_grouped(tmp_path):
    files = [tmp_path / "history.csv", *(tmp_path / "snapshots" / f"step_{i:06d}.npz" for i in (10, 20, 30, 40))]
    text = describe_written(files)
    assert text.splitlines()[0] == "wrote:" and f"  {tmp_path / 'history.csv'}" in text
    assert "4 .npz files (step_000010.npz ... step_000040.npz)" in text
    assert describe_written([]) == "wrote no files"


def test_write_csv_formats_floats_and_leaves_missing_values_empty(tmp_path):
    path = tmp_path / "rows.csv"
    rows = [{"a": 1.0 / 3.0, "b": None, "c": True, "extra": "dropped"}, {"a": np.float64(2.5e-7), "c": 3}]
    write_csv(rows, path, ("a", "b", "c"), digits=3)
    with path.open(newline="") as fh:
        read = list(csv.DictReader(fh))
    assert read == [{"a": "0.333", "b": "", "c": "True"}, {"a": "2.5e-07", "b": "", "c": "3"}]
