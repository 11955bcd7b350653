"""Output files: checked before a command starts, written atomically, listed when it ends.

Every command that writes files (``qpcontact simulate``, ``compare``, ``stability``, ``bench``,
``demo --out``) writes into one folder (``--out``, by default ``./<command>-out/``) and

1. checks it at the start (:func:`prepare_folder`): the folder is created and must be writable,
   and files of an earlier run are replaced only when asked (``overwrite=True``,
   ``--overwrite``), so that no run silently overwrites another and nothing is lost at the end
   of a long run because the folder cannot be written;
2. writes files that must never be seen half-written (snapshots, configurations, tables)
   through a temporary file in the same folder and a rename (:func:`atomic_write`): a process
   killed while writing leaves the old file or the new one, never a truncated one;
3. prints what it wrote (:func:`describe_written`).

Tables go to CSV through :func:`write_csv` (one row per run, floats to fixed significant digits).

Standard library only; what the io wing, the run loop, ensembles and the studies write goes through it.
"""

from __future__ import annotations

import contextlib
import csv
import os
import tempfile
from collections.abc import Callable, Iterable, Iterator, Sequence
from pathlib import Path
from typing import IO, Any

from ..errors import OutputFolderError

_UMASK = os.umask(0)
os.umask(_UMASK)


def prepare_folder(folder: str | Path, outputs: Sequence[str] = (), *, overwrite: bool = False) -> Path:
    """Create ``folder`` if needed and check that it can be written, before any work is done.

    Args:
        folder: the output folder.
        outputs: the files the command writes there, relative to the folder (glob patterns
            allowed, e.g. ``"snapshots/step_*.npz"``). Any of them already present means the
            folder holds an earlier run.
        overwrite: replace an earlier run: the files matching ``outputs`` are deleted now (so
            that none of them stays behind, stale, next to the new ones). Other files in the
            folder are left alone.

    Returns:
        The folder, as a :class:`~pathlib.Path`.

    Raises:
        OutputFolderError: the folder cannot be created or written, or it holds an earlier
            run's files and ``overwrite`` is False.
    """
    folder = Path(folder)
    try:
        folder.mkdir(parents=True, exist_ok=True)
        handle, probe = tempfile.mkstemp(dir=folder, prefix=".qpcontact-write-test-")
        os.close(handle)
        os.unlink(probe)
    except OSError as exc:
        raise OutputFolderError(f"{folder}: cannot write there ({exc.strerror or exc})") from exc
    found = earlier_outputs(folder, outputs)
    if found and not overwrite:
        shown = ", ".join(str(p.relative_to(folder)) for p in found[:3]) + (", ..." if len(found) > 3 else "")
        raise OutputFolderError(f"{folder} holds the outputs of an earlier run ({shown}); pass --overwrite to "
                                "replace them, or choose another output folder")
    for path in found:
        try:
            path.unlink()
        except OSError as exc:
            raise OutputFolderError(f"{path}: cannot remove it ({exc.strerror or exc})") from exc
    return folder


def earlier_outputs(folder: Path, outputs: Iterable[str]) -> list[Path]:
    """The files in ``folder`` that match ``outputs`` (glob patterns), sorted."""
    return sorted({path for pattern in outputs for path in folder.glob(pattern) if path.is_file()})


@contextlib.contextmanager
def replacing(path: str | Path) -> Iterator[Path]:
    """A temporary path in the folder of ``path`` (parent folders are created), renamed to
    ``path`` when the block ends without an error, removed otherwise (``path`` is then left as
    it was). For writers that take a file name (e.g. meshio)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(handle)
    try:
        yield Path(temporary)
        os.chmod(temporary, 0o666 & ~_UMASK)  # mkstemp makes it private; outputs get the usual permissions
        os.replace(temporary, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(temporary)
        raise


def atomic_write(path: str | Path, write: Callable[[IO[Any]], object], *, text: bool = False) -> Path:
    """Write ``path`` through a temporary file in the same folder, then rename it into place
    (:func:`replacing`).

    ``write(handle)`` writes the content to an open file (binary, or UTF-8 text with
    ``text=True``). The temporary file is flushed and synced before the rename; if anything
    fails (or the process is interrupted) it is removed and ``path`` is left as it was. Returns
    ``path``.
    """
    with replacing(path) as temporary:
        with open(temporary, "w", encoding="utf-8", newline="") if text else open(temporary, "wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
    return Path(path)


def write_text(path: str | Path, content: str) -> Path:
    """:func:`atomic_write` of a text file (UTF-8)."""
    return atomic_write(path, lambda fh: fh.write(content), text=True)


def describe_written(paths: Iterable[str | Path], *, group_above: int = 3) -> str:
    """What a command wrote, one line per file, for printing at its end. More than
    ``group_above`` files of one kind (same folder and suffix) are summarized in one line."""
    groups: dict[tuple[Path, str], list[Path]] = {}
    for path in map(Path, paths):
        groups.setdefault((path.parent, path.suffix), []).append(path)
    lines = []
    for (parent, suffix), members in groups.items():
        if len(members) > group_above:
            names = sorted(p.name for p in members)
            lines.append(f"  {parent}/ : {len(members)} {suffix or 'other'} files ({names[0]} ... {names[-1]})")
        else:
            lines += [f"  {p}" for p in members]
    return "wrote:\n" + "\n".join(lines) if lines else "wrote no files"


def write_csv(rows: Iterable[dict[str, Any]], path: Path, columns: Sequence[str], digits: int) -> None:
    """The rows as CSV with these columns (missing values and None empty, floats to ``digits``
    significant digits, everything else as ``str``)."""
    def text(value: Any) -> str:
        if value is None:
            return ""
        if isinstance(value, float):
            return f"{value:.{digits}g}"
        return str(value)

    with Path(path).open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(columns), extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            writer.writerow({k: text(row.get(k)) for k in columns})
