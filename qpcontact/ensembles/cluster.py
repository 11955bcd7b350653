"""Dask for the commands (``qpcontact sweep``, and ``compare``/``stability`` with
``--scheduler``/``--workers``): a client on a local cluster or on an existing one, and tasks
that may start child processes.

- :func:`add_cluster_arguments`: ``--scheduler ADDRESS`` (an existing Dask cluster) and
  ``--workers N`` (a :class:`distributed.LocalCluster` of N single-threaded worker processes on
  this machine);
- :func:`open_client`: the :class:`distributed.Client` those flags ask for (a context manager
  that closes the client, and the local cluster it started);
- :func:`run_calls`: ``fn(*args)`` for every ``args``, one after the other here or as Dask tasks
  on a client (``qpcontact compare`` and ``qpcontact stability`` hand their cases to it);
- :func:`call`: the task that runs one call; it may start child processes, which a Dask worker
  process (a daemon) may not do by default: the guarded child of
  :func:`qpcontact.studies.harness.guarded`, which keeps each case's hard time limit, runs
  inside the task as it runs in a local study.

Dask is the optional extra ``qpcontact[sweep]`` (``dask[distributed]``); :func:`require_distributed`
says so in one line when it is missing. Nothing here is imported by ``import qpcontact``; Dask itself only when a client is opened.
A top-level helper like :mod:`qpcontact.io.outputs` (the colony wing's sweep and the studies use it).
"""

from __future__ import annotations

import argparse
import contextlib
import multiprocessing
import os
import signal
import tempfile
import threading
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

from ..cli import positive_int
from ..errors import InvalidArgumentError, NotInstalledError, install_hint

#: How to install Dask for qpcontact.
INSTALL_HINT = install_hint("sweep")
#: Seconds to wait for an existing scheduler to answer.
CONNECT_TIMEOUT = 20.0
#: LocalCluster options: no dashboard, the scheduler's HTTP server on a free port.
NO_DASHBOARD = {"scheduler_kwargs": {"dashboard": False, "dashboard_address": ":0"}}


def require_distributed() -> Any:
    """The ``distributed`` module.

    Raises:
        NotInstalledError: Dask is not installed (naming the extra).
    """
    try:
        import distributed
    except ImportError:
        raise NotInstalledError(f"this needs Dask (dask.distributed): {INSTALL_HINT}") from None
    return distributed


def add_cluster_arguments(parser: argparse.ArgumentParser, *, local_by_default: bool) -> None:
    """``--scheduler ADDRESS`` and ``--workers N``. With ``local_by_default`` (``qpcontact
    sweep``) a local cluster is started when no scheduler is given; otherwise (``compare``,
    ``stability``) Dask is used only when one of the two flags is given."""
    group = parser.add_argument_group("Dask (pip install 'qpcontact[sweep]')")
    group.add_argument("--scheduler", metavar="ADDRESS",
                       help="the address of a running Dask scheduler (tcp://HOST:8786), or its scheduler file (dask "
                            "scheduler --scheduler-file FILE), to run the tasks on; "
                            "--out must then be a folder every worker can write (a shared file system)"
                            + ("" if local_by_default else "; default: no Dask, cases run here one after the other"))
    default = max(1, os.cpu_count() or 1)
    group.add_argument("--workers", type=positive_int, default=None, metavar="N",
                       help=("without --scheduler: start a local Dask cluster of N worker processes, one thread each "
                             f"(default: {default}, the cores here)") if local_by_default else
                            "run the cases on a local Dask cluster of N worker processes, one thread each")


def wants_dask(args: argparse.Namespace) -> bool:
    """Whether the flags of :func:`add_cluster_arguments` ask for Dask (``compare``, ``stability``)."""
    return bool(getattr(args, "scheduler", None) or getattr(args, "workers", None))


@contextlib.contextmanager
def open_client(scheduler: str | None = None, workers: int | None = None) -> Iterator[Any]:
    """A :class:`distributed.Client`: connected to ``scheduler`` (an address, or the path of a
    scheduler file), or to a new local cluster of
    ``workers`` single-threaded worker processes (default: one per core) without a dashboard.
    The client (and the local cluster) are closed when the block ends.

    Raises:
        NotInstalledError: Dask is missing; InvalidArgumentError: the scheduler does not answer (one line each).
    """
    distributed = require_distributed()
    import dask

    if scheduler:
        where = {"scheduler_file": scheduler} if Path(scheduler).is_file() else {"address": scheduler}
        try:
            client = distributed.Client(**where, timeout=CONNECT_TIMEOUT)
        except (OSError, TimeoutError, ValueError) as exc:
            raise InvalidArgumentError(f"--scheduler {scheduler}: cannot connect ({type(exc).__name__}: "
                                       f"{str(exc).splitlines()[0] if str(exc) else 'no answer'})") from None
        with client:
            yield client
        return
    # Worker processes that may start children (the guarded cases; see call()); no dashboard, and
    # the scheduler's HTTP server (health checks) on a free port, not on 8787.
    with dask.config.set({"distributed.worker.daemon": False}), sigint_ignored():
        cluster = distributed.LocalCluster(n_workers=workers or max(1, os.cpu_count() or 1), threads_per_worker=1,
                                           processes=True, dashboard_address=None, **NO_DASHBOARD)
    with cluster, distributed.Client(cluster) as client:
        yield client


@contextlib.contextmanager
def sigint_ignored() -> Iterator[None]:
    """SIGINT ignored while the block runs (in the main thread; elsewhere nothing changes).

    The local cluster's worker processes are started inside it, and an ignored signal stays
    ignored in a child (Python and asyncio then install no handler of their own): a terminal's
    Ctrl-C, which goes to the whole process group, reaches only the sweep's own process, which
    stops the runs through its stop flag, each saving its state. Without it every worker died of
    its own KeyboardInterrupt (about 100 lines of Dask tracebacks, 30 s, and the runs it cut
    short reported as not started; issue 27). The price: a Ctrl-C during the few seconds the
    cluster takes to start is not seen, and a worker that Dask restarts later (after one died) is
    started without it."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


@contextlib.contextmanager
def client_if_asked(args: argparse.Namespace) -> Iterator[Any]:
    """:func:`open_client` if the flags ask for Dask (:func:`wants_dask`), else None."""
    if not wants_dask(args):
        yield None
        return
    with open_client(args.scheduler, args.workers) as client:
        yield client


def check_workers_can_write(client: Any, folder: Path) -> None:
    """Every worker can write into ``folder`` (an absolute path).

    Raises:
        InvalidArgumentError: naming the workers that cannot (the folder is not on a file
            system they share with this machine).
    """
    answers = client.run(_can_write, str(folder))
    wrong = sorted(worker for worker, ok in answers.items() if not ok)
    if wrong:
        raise InvalidArgumentError(f"{folder}: workers {', '.join(wrong)} cannot write there; --out must be on a file "
                                   "system that every worker shares with this machine")


def _can_write(folder: str) -> bool:
    try:
        handle, probe = tempfile.mkstemp(dir=folder, prefix=".qpcontact-worker-test-")
        os.close(handle)
        os.unlink(probe)
    except OSError:
        return False
    return True


@contextlib.contextmanager
def children_allowed() -> Iterator[None]:
    """Let this process start child processes with :mod:`multiprocessing` while the block runs,
    also when it is a daemon (as a Dask worker process started by a nanny is, unless
    ``distributed.worker.daemon`` is false): its children are the short-lived, guarded ones of
    a task, killed by the task itself at their time limit."""
    process = multiprocessing.current_process()
    daemon = process.daemon
    if daemon:
        process.daemon = False
    try:
        yield
    finally:
        if daemon:
            process.daemon = True


def call(fn: Callable[..., Any], args: Sequence[Any], kwargs: Mapping[str, Any]) -> Any:
    """The Dask task of one call: ``fn(*args, **kwargs)`` in a process that may start children
    (:func:`children_allowed`)."""
    with children_allowed():
        return fn(*args, **kwargs)


def run_calls(fn: Callable[..., Any], calls: Iterable[Sequence[Any]], done: Callable[[int, Any], None], *,
              client: Any = None, kwargs: Mapping[str, Any] | None = None) -> None:
    """``fn(*args, **kwargs)`` for every ``args`` of ``calls``; ``done(index, result)`` for each.

    Without a client the calls run here, one after the other, in order. With a Dask client every
    call is a task (:func:`call`), submitted as ``calls`` yields it (so a caller that prepares
    its cases in a generator prepares the next while the workers solve), and ``done`` is called
    as the tasks complete, in any order; arguments that are not plain numbers or strings are
    sent to the cluster once (``Client.scatter``) however many calls share them. A task that
    raises raises here. On ``KeyboardInterrupt`` the tasks not finished are cancelled.
    """
    kwargs = dict(kwargs or {})
    if client is None:
        for index, args in enumerate(calls):
            done(index, fn(*args, **kwargs))
        return
    distributed = require_distributed()
    scattered: dict[int, tuple[Any, Any]] = {}  # id -> (object, its future); the object keeps the id unique

    def remote(value: Any) -> Any:
        if value is None or isinstance(value, (bool, int, float, str)):
            return value
        if id(value) not in scattered:
            scattered[id(value)] = (value, client.scatter(value, hash=False))
        return scattered[id(value)][1]

    remote_kwargs = {name: remote(value) for name, value in kwargs.items()}
    futures: dict[Any, int] = {}
    try:
        for index, args in enumerate(calls):
            future = client.submit(call, fn, [remote(a) for a in args], remote_kwargs, pure=False)
            futures[future] = index
        for future in distributed.as_completed(list(futures)):
            done(futures[future], future.result())
    finally:
        unfinished = [f for f in futures if not f.done()]
        if unfinished:
            client.cancel(unfinished)


def results_in_order(fn: Callable[..., Any], calls: Iterable[Sequence[Any]], *, client: Any = None,
                     kwargs: Mapping[str, Any] | None = None, each: Callable[[], Any] = lambda: None
                     ) -> tuple[list[Any], bool]:
    """:func:`run_calls`, its results in the order of ``calls`` (``each()`` after each one):
    ``(results, interrupted)``; after Ctrl-C, the results of the calls that finished."""
    finished: dict[int, Any] = {}

    def done(index: int, result: Any) -> None:
        finished[index] = result
        each()

    try:
        run_calls(fn, calls, done, client=client, kwargs=kwargs)
        interrupted = False
    except KeyboardInterrupt:
        interrupted = True
    return [finished[index] for index in sorted(finished)], interrupted
