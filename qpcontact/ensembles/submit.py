"""A sweep's runs on Dask: submitted as tasks (:func:`qpcontact.ensembles.tasks.run_task`),
recorded in ``sweep.json`` as each finishes, with a progress bar of runs done / running /
failed (:func:`execute`), and stopped cleanly on Ctrl-C (:func:`stop`: the runs not started are
cancelled, the running ones save their state at their next step). The client and the cluster
are :mod:`qpcontact.ensembles.cluster`'s.
"""

from __future__ import annotations

import os
import sys
import time
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

from .tasks import EVENT_TOPIC, STOP_FILE, attempts_of, run_task

if TYPE_CHECKING:
    from .sweep import Sweep

__all__ = ["STOP_WAIT", "execute", "record", "stop", "with_unsubscribe"]

#: Seconds a stopping sweep waits for its running runs to save their state.
STOP_WAIT = 30.0


def execute(sweep: Sweep, client: Any, runs: list[dict[str, Any]], *, progress: bool = True) -> bool:
    """Submit ``runs`` to the client, record each as it finishes (``sweep.json``), with a progress
    bar of runs done / running / failed. Returns False if interrupted (Ctrl-C: the runs not
    finished are cancelled and stay pending)."""
    from tqdm import tqdm

    running: set[str] = set()

    def on_event(event: tuple[float, Mapping[str, Any]]) -> None:
        message = event[1]
        (running.add if message.get("event") == "started" else running.discard)(message.get("run", ""))

    client.subscribe_topic(EVENT_TOPIC, on_event)
    # A task writes its start to its folder before its first step, where the stop can see it even
    # when the "started" event has not reached this client yet (issue 19: a run stopped within a
    # second of its start was taken for one not started and cancelled, which cannot stop it).
    starts_before = {run["name"]: len(attempts_of(sweep.folder(run))) for run in runs}

    def started(run: Mapping[str, Any]) -> bool:
        return run["name"] in running or len(attempts_of(sweep.folder(run))) > starts_before[run["name"]]

    pending = {client.submit(run_task, run["name"], run["settings"], str(sweep.folder(run)),
                             key=f"sweep-{run['name']}-{os.urandom(4).hex()}", pure=False): run for run in runs}
    bar = tqdm(total=len(sweep.runs), initial=len(sweep.runs) - len(runs), unit="run", desc="sweep",
               disable=not progress, file=sys.stderr, dynamic_ncols=True)
    for run in runs:  # a run being redone is pending until it finishes again
        run.update(status="pending", error="")
    shown: dict[str, int] = {}

    def collect() -> bool:
        """Record the runs finished since the last call; whether there were any."""
        finished = [future for future in pending if future.done()]
        for future in finished:
            run = pending.pop(future)
            running.discard(run["name"])
            if record(sweep, run, future):
                sweep.save()
                bar.update()
        return bool(finished)

    try:
        while pending:
            finished = collect()
            counts = sweep.counts()
            postfix = {"done": counts["done"], "running": len(running & {r["name"] for r in pending.values()}),
                       "failed": counts["failed"]}
            if postfix != shown:
                bar.set_postfix(postfix)
                shown = postfix
            if not finished:
                time.sleep(0.2)
    except KeyboardInterrupt:
        stop(sweep, client, pending, collect, started)
        return False
    finally:
        bar.close()
        with_unsubscribe(client)
        sweep.save()
    return True


def record(sweep: Sweep, run: dict[str, Any], future: Any) -> bool:
    """Record the finished task of ``run``: done or failed (True), or pending again (False: the
    run stopped with the sweep, or the scheduler lost its task)."""
    if future.status == "finished" and future.result()["status"] == "stopped":
        run.update(status="pending", error=future.result()["error"])
        return False
    if future.status == "finished":
        sweep.record(run, future.result())
    elif future.status == "error":
        exc = future.exception()
        sweep.record(run, {"status": "failed", "error": f"{type(exc).__name__}: {exc}"})
    else:  # cancelled: the scheduler lost it
        run.update(status="pending", error=f"task {future.status} (the scheduler lost it); resume the sweep")
        return False
    return True


def stop(sweep: Sweep, client: Any, pending: dict[Any, Any], collect: Callable[[], bool],
         started: Callable[[Mapping[str, Any]], bool]) -> None:
    """Stop a sweep: the runs not started are cancelled; the running ones see the stop flag and
    save their state at their next step (waited for up to :data:`STOP_WAIT` seconds; a second
    Ctrl-C does not wait). The flag stays until the sweep's client is closed (:func:`run_command`):
    a task that starts all the same (a cancellation racing its start) stops at once; the next
    sweep in the folder removes a flag left behind."""
    flag = sweep.out / STOP_FILE
    flag.touch()
    try:
        waiting = [future for future, run in pending.items() if not started(run)]
        client.cancel(waiting)
        for future in waiting:  # not started: they stay pending
            pending.pop(future)
        deadline = time.monotonic() + STOP_WAIT
        while pending and time.monotonic() < deadline:
            collect()
            time.sleep(0.1)
    finally:
        client.cancel(list(pending))


def with_unsubscribe(client: Any) -> None:
    try:
        client.unsubscribe_topic(EVENT_TOPIC)
    except Exception:  # noqa: BLE001 - a client that lost its scheduler
        pass
