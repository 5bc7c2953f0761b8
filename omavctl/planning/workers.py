"""Worker processes for ``plan``: forked, one BLAS thread each, progress through shared memory.

:func:`run_tasks` runs ``fn(i, report)`` for tasks ``i = 0 .. n-1`` either in this
process (``jobs == 1``) or in ``jobs`` forked worker processes, and returns the
results in task order. The state a task needs (the model, the simulations) is
whatever ``fn`` closes over: the workers are forked, so they inherit it without
copying or pickling; only the results travel back through pipes.

``report(fraction)`` lets a task say how far it is; the parent shows the mean over
the tasks on ``progress`` while it waits (the workers write into a shared array,
so the progress bar moves with ``--jobs`` as without).

How the work is split must not change any result: callers split it into pieces
whose arithmetic does not depend on the split (``plan`` gives the same bytes for
every ``--jobs``; ``tests/test_plan_fast.py``).
"""

from __future__ import annotations

import math
import multiprocessing
import os
import signal
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from omavctl.planning.rollout import Progress

__all__ = ["available_cores", "run_tasks"]

Task = Callable[[int, Callable[[float], None]], Any]

_STATE: dict[str, Any] = {}


def available_cores(cpu_max: str = "/sys/fs/cgroup/cpu.max") -> int:
    """Cores this process may use, at least 1: its CPU affinity, and no more than a
    container's CPU quota (cgroup v2 ``cpu.max``, e.g. ``200000 100000`` = 2 cores),
    which the affinity does not show."""
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cores = os.cpu_count() or 1
    try:
        quota, period = Path(cpu_max).read_text().split()[:2]
        if quota != "max":
            cores = min(cores, math.ceil(int(quota) / int(period)))
    except (OSError, ValueError):
        pass
    return max(1, cores)


def _worker_init(parent: int) -> None:
    """Worker initialiser. The parent handles Ctrl-C and SIGTERM (and cleans up its
    outputs); a worker inherits the parent's handlers through fork, which would raise
    in it when the pool ends it, so it takes the defaults (SIGINT ignored). A worker
    whose parent died (kill -9) ends itself within half a second instead of waiting
    for tasks forever."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)

    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(0.5)
        os._exit(1)

    threading.Thread(target=watch, daemon=True).start()


def _call(i: int) -> Any:
    """Worker body: task i with one BLAS thread, reporting into the shared array."""
    from threadpoolctl import threadpool_limits

    fn: Task = _STATE["fn"]
    shared = _STATE["shared"]

    def report(fraction: float) -> None:
        shared[i] = fraction

    with threadpool_limits(1):
        out = fn(i, report)
    shared[i] = 1.0
    return out


def run_tasks(
    fn: Task, count: int, jobs: int, progress: Progress | None = None, label: str = ""
) -> list[Any]:
    """[fn(0, report), ..., fn(count - 1, report)], in ``min(jobs, count)`` processes."""
    done = [0.0] * count

    def show() -> None:
        if progress is not None and count:
            progress(label, sum(done) / count)

    if jobs <= 1 or count <= 1:
        out = []
        for i in range(count):

            def report(fraction: float, i: int = i) -> None:
                done[i] = fraction
                show()

            out.append(fn(i, report))
            report(1.0)
        return out
    ctx = multiprocessing.get_context("fork")
    shared = ctx.RawArray("d", count)
    _STATE.update(fn=fn, shared=shared)
    pool = ctx.Pool(min(jobs, count), initializer=_worker_init, initargs=(os.getpid(),))
    try:
        pending = pool.map_async(_call, range(count), chunksize=1)
        while not pending.ready():
            pending.wait(0.2)
            done[:] = shared[:]
            show()
        results = pending.get()
    except BaseException:  # an error, Ctrl-C or SIGTERM: end the workers now
        pool.terminate()
        pool.join()
        raise
    finally:
        _STATE.clear()
    pool.close()  # the workers finish on their own
    pool.join()
    done[:] = [1.0] * count
    show()
    return list(results)
