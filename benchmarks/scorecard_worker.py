"""One process that runs a draw's ``omavctl`` commands (scorecard version 2).

Each CLI call of a draw used to start a fresh Python that imported numpy, scipy,
scikit-learn and omavctl again: about 3 s of a ``fit`` or ``evaluate`` on an idle
core, more under load, ten times per draw. A worker imports them once per draw and
runs every command through the CLI's own entry point (:func:`omavctl.guard.run_app`,
the same argument parsing, error handling and exit codes), in the draw's directory,
with its stdout and stderr captured. One worker per draw (never shared between
draws), so a draw's record does not depend on which draws ran before it.

Protocol: one JSON request per line on stdin (``{"args": [...], "cwd": DIR}``), one
JSON reply per line (``{"code": N, "stdout": TEXT, "stderr": TEXT}``) on the file
descriptor that was stdout when the worker started; anything else the commands
write to file descriptor 1 goes to stderr.
"""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
from contextlib import redirect_stderr, redirect_stdout
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent


def serve() -> None:
    """The worker's loop (``python benchmarks/scorecard_worker.py``)."""
    reply = os.fdopen(os.dup(1), "w")
    os.dup2(2, 1)
    sys.path.insert(0, str(ROOT))
    from omavctl.cli import app
    from omavctl.guard import run_app

    for line in sys.stdin:
        req = json.loads(line)
        os.chdir(req["cwd"])
        out, err = io.StringIO(), io.StringIO()
        sys.argv = ["omavctl", *req["args"]]
        code: Any = 0
        with redirect_stdout(out), redirect_stderr(err):
            try:
                run_app(app, "omavctl")
            except SystemExit as exc:
                code = exc.code
        if not isinstance(code, int):
            code = 0 if code is None else 1
        reply.write(json.dumps({"code": code, "stdout": out.getvalue(), "stderr": err.getvalue()}))
        reply.write("\n")
        reply.flush()


class Worker:
    """A worker process for one draw (a context manager); :meth:`call` runs a command."""

    def __init__(self) -> None:
        env = {
            **os.environ,
            "PYTHONPATH": str(ROOT),
            "OMP_NUM_THREADS": "1",
            "OPENBLAS_NUM_THREADS": "1",
        }
        self.proc = subprocess.Popen(
            [sys.executable, str(Path(__file__).resolve())],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            env=env,
            text=True,
        )

    def call(self, args: list[str], cwd: Path) -> tuple[int, str, str]:
        """(exit code, stdout, stderr) of ``omavctl ARGS`` run in ``cwd``."""
        assert self.proc.stdin is not None and self.proc.stdout is not None
        self.proc.stdin.write(json.dumps({"args": args, "cwd": str(cwd)}) + "\n")
        self.proc.stdin.flush()
        line = self.proc.stdout.readline()
        if not line:
            return 1, "", "the scorecard worker died"
        r = json.loads(line)
        return int(r["code"]), str(r["stdout"]), str(r["stderr"])

    def close(self) -> None:
        if self.proc.stdin is not None:
            self.proc.stdin.close()
        try:
            self.proc.wait(timeout=60)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()

    def __enter__(self) -> Worker:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


if __name__ == "__main__":
    serve()
