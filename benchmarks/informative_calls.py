"""How ``benchmarks/informative.py`` runs its steps: in worker processes that stay up.

Until session 14 every step of a draw was a child process ``python -m omavctl ...
--json`` (about 45 per draw), and every held-out error a full ``evaluate``. The
profile of one draw (docs/informative.md, "The cost of a draw") found most of its
CPU time in what the benchmark never reads: ``evaluate``'s diagnosis and open-loop
horizons (about 80 % of each evaluation, and 20 evaluations a draw) and the start-up
of each child process (importing NumPy, SciPy, scikit-learn and omavctl, about 2 s of
CPU each). So:

- :func:`omavctl` runs the command line a user would type (``simulate``, ``fit``,
  ``plan``, ``task``) through the typer application itself, in a worker process
  that stays up, and returns its ``--json`` object: the same code and arguments as
  the child process had;
- :func:`heldout` gives what the benchmark reads of ``evaluate --json``: the first
  model's RMSE per axis (``models[0].rmse``) and the tracking (``tracking``), from
  the library's :func:`omavctl.diagnose.evaluate.evaluate` without the diagnosis
  and the horizons, which change neither (the metrics come before them).

The workers are spawned (not forked) with one BLAS thread each, as the child
processes were (``OMP_NUM_THREADS=1``, ``OPENBLAS_NUM_THREADS=1``): the same numbers,
byte for byte on the draw measured in docs/informative.md. :func:`start` sets how
many run at once (``--workers``); tasks wait for a free worker.
"""

from __future__ import annotations

import io
import json
import multiprocessing
import os
import threading
import time
from concurrent.futures import Future, ProcessPoolExecutor
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path
from typing import Any

__all__ = ["cost", "heldout", "omavctl", "start", "stop"]

#: the environment of a worker: one BLAS thread, as the child processes had
_ONE_THREAD = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
_POOL: dict[str, ProcessPoolExecutor] = {}
_LIMITS: list[Any] = []  # in a worker: its BLAS limit, kept alive
#: step kind -> [calls, CPU seconds in the worker, wall seconds in the worker]
_COST: dict[str, list[float]] = {}
_LOCK = threading.Lock()


def start(workers: int) -> None:
    """Start ``workers`` worker processes (spawned, one BLAS thread each)."""
    stop()
    saved = {k: os.environ.get(k) for k in _ONE_THREAD}
    os.environ.update(_ONE_THREAD)  # a spawned worker reads them when it loads NumPy
    try:
        ctx = multiprocessing.get_context("spawn")
        _POOL["pool"] = ProcessPoolExecutor(workers, mp_context=ctx, initializer=_init)
        for f in [_POOL["pool"].submit(_ready) for _ in range(workers)]:
            f.result()  # every worker has started (with the environment above)
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def stop() -> None:
    """End the worker processes (if any)."""
    pool = _POOL.pop("pool", None)
    if pool is not None:
        pool.shutdown(wait=True)


def _submit(fn: Any, *args: Any) -> Future:
    if "pool" not in _POOL:
        start(1)
    return _POOL["pool"].submit(_timed, fn, *args)


def _timed(fn: Any, *args: Any) -> tuple[Any, float, float]:
    """Worker body: ``fn(*args)``, the CPU and wall seconds it took."""
    cpu, wall = time.process_time(), time.perf_counter()
    out = fn(*args)
    return out, time.process_time() - cpu, time.perf_counter() - wall


def _result(kind: str, future: Future) -> Any:
    """The result of a step, its cost added to :func:`cost`."""
    out, cpu, wall = future.result()
    with _LOCK:
        row = _COST.setdefault(kind, [0, 0.0, 0.0])
        row[0], row[1], row[2] = row[0] + 1, row[1] + cpu, row[2] + wall
    return out


def cost() -> dict[str, list[float]]:
    """Steps run so far: kind (``simulate``, ``simulate --model``, ``fit``, ``plan``,
    ``task``, ``evaluate``) -> [calls, CPU s, wall s], as the workers measured them."""
    with _LOCK:
        return {k: list(v) for k, v in _COST.items()}


def _init() -> None:
    """Worker initialiser: one BLAS thread (also for a BLAS already loaded)."""
    from threadpoolctl import threadpool_limits

    _LIMITS.append(threadpool_limits(limits=1))
    import omavctl.cli  # noqa: F401  (imported once per worker, not once per step)


def _ready() -> int:
    return os.getpid()


def _run(args: list[str]) -> tuple[int, str, str]:
    """Worker body: ``omavctl ARGS --json -q`` by the typer application; exit status,
    stdout and stderr."""
    import typer
    from typer.exceptions import TyperException

    from omavctl.cli import app

    out, err = io.StringIO(), io.StringIO()
    with redirect_stdout(out), redirect_stderr(err):
        try:
            code = app(args=[*args, "--json", "-q"], prog_name="omavctl", standalone_mode=False)
        except (TyperException, typer.Exit) as exc:
            code = exc.exit_code
    return (code if isinstance(code, int) else 0), out.getvalue(), err.getvalue()


def omavctl(*args: str) -> dict:
    """Run ``omavctl ARGS --json -q`` in a worker; its JSON object."""
    kind = "simulate --model" if args[0] == "simulate" and "--model" in args else args[0]
    code, out, err = _result(kind, _submit(_run, list(args)))
    if code != 0:
        raise RuntimeError(f"omavctl {' '.join(args)} failed ({code}):\n{out}\n{err}")
    return json.loads(out)


def _heldout(model: str, log: str) -> dict[str, Any]:
    """Worker body of :func:`heldout`."""
    import warnings

    from omavctl.diagnose.evaluate import evaluate

    with warnings.catch_warnings():  # as the command line runs it (omavctl.guard)
        warnings.simplefilter("ignore")
        tree = evaluate([model], [log], horizons=(), with_diagnosis=False).tree
    return {"rmse": tree["metrics"]["model"]["rmse"], "tracking": tree["tracking"]}


def heldout(model: Path, log: Path) -> dict[str, Any]:
    """``evaluate``'s RMSE per axis of ``model`` on ``log`` (``rmse``, rad/s^2, as
    ``models[0].rmse`` of ``evaluate --json``) and its ``tracking`` (None when the
    log holds no desired acceleration)."""
    return _result("evaluate", _submit(_heldout, str(model), str(log)))
