"""Run fuzz cases and judge them.

Two runners: ``fork`` (the parent imports omavctl once, each case runs
``omavctl.cli.main`` in a forked child with its own stdout/stderr files: fast,
real exit status, real stderr) and ``subprocess`` (the installed ``omavctl``
console script, as a user runs it). Both stop a case after ``timeout`` s (a hang).

The oracle (:func:`judge`): inputs byte-for-byte unchanged and no temporary
files left, always; a non-zero exit must be 2 with exactly one line
``error: ...`` naming the mutated file or option and no exception text; exit 0
must leave finite, schema-valid outputs (and is wrong when the input was
invalid by construction).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import re
import shutil
import subprocess
import sys
import time
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .cases import Case

#: Text that betrays a leaked library exception or warning.
EXCEPTION_TEXT = re.compile(
    r"Traceback|\b[A-Z][a-z]\w*(Error|Exception|Warning)\b|invalid magic|NoneType|codec can't|"
    r"could not broadcast|out of bounds|math domain|unsupported operand|object is not|"
    r"not subscriptable|internal error|has no attribute|unexpected keyword|position \d+:",
)


@dataclass
class Outcome:
    case: Case
    code: int | None  # None: hang (killed after the timeout)
    stdout: str
    stderr: str
    seconds: float
    verdict: str  # "refused", "ok", or a failure class
    detail: str = ""


def _digest(path: Path) -> str:
    if path.is_dir():
        return "|".join(_digest(p) for p in sorted(path.rglob("*")) if p.is_file())
    return hashlib.sha256(path.read_bytes()).hexdigest() if path.exists() else "-"


def _child(argv: list[str], work: str) -> None:
    """Body of a forked case: own stdout/stderr files, the real entry point, exit status."""
    code = 1
    try:
        os.chdir(work)
        for fd, name in ((1, ".stdout"), (2, ".stderr")):
            f = os.open(name, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
            os.dup2(f, fd)
            os.close(f)
        # the parent's sys.stdout/stderr may be a capture (pytest): use the fds
        sys.stdout = open(1, "w", closefd=False)
        sys.stderr = open(2, "w", closefd=False)
        import warnings

        warnings.resetwarnings()
        warnings.showwarning = warnings._showwarning_orig  # type: ignore[attr-defined]
        sys.argv = ["omavctl", *argv]
        from omavctl.cli import main

        try:
            main()
            code = 0
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    except BaseException:
        import traceback

        traceback.print_exc()
        code = 99
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)


_CONTEXT: Any = None


def _context() -> Any:
    """A forkserver: a clean process that imported omavctl once and forks each case.
    (Forking the test process itself would copy library thread pools, e.g. the
    k-medoids one, that deadlock in the child.)"""
    global _CONTEXT
    if _CONTEXT is None:
        import multiprocessing

        ctx = multiprocessing.get_context("forkserver")
        ctx.set_forkserver_preload(
            ["omavctl.cli", "omavctl.diagnose.evaluate", "omavctl.report.evaluation"]
        )
        _CONTEXT = ctx
    return _CONTEXT


def _run_fork(argv: list[str], work: Path, timeout: float) -> tuple[int | None, str, str]:
    out, err = work / ".stdout", work / ".stderr"
    proc = _context().Process(target=_child, args=(argv, str(work)))
    proc.start()
    proc.join(timeout)
    if proc.is_alive():
        proc.kill()
        proc.join()
        code = None
    else:
        code = proc.exitcode
    text = [p.read_text(errors="replace") if p.exists() else "" for p in (out, err)]
    for p in (out, err):
        p.unlink(missing_ok=True)
    return code, text[0], text[1]


def _run_subprocess(argv: list[str], work: Path, timeout: float) -> tuple[int | None, str, str]:
    exe = Path(sys.executable).with_name("omavctl")
    try:
        proc = subprocess.run(
            [str(exe), *argv], cwd=work, capture_output=True, text=True, timeout=timeout
        )
    except subprocess.TimeoutExpired as exc:
        return None, str(exc.stdout or ""), str(exc.stderr or "")
    return proc.returncode, proc.stdout, proc.stderr


# ----------------------------------------------------------------- output checks
def _finite_json(text: str) -> object:
    def bad(name: str) -> object:
        raise ValueError(f"{name} in JSON")

    return json.loads(text, parse_constant=bad)


def check_output(path: Path, kind: str) -> str | None:
    """None when ``path`` is a finite, schema-valid output of ``kind``, else why not."""
    from omavctl.base.errors import OmavctlError

    if not path.exists():
        return "output missing"
    try:
        if kind == "model":
            from omavctl.learn.model_file import load_model

            m = load_model(path)
            mean, var = m.gp_predict(m.inputs[:5], noise=True)
            if not (np.all(np.isfinite(mean)) and var is not None and np.all(np.isfinite(var))):
                return "model predicts non-finite values"
        elif kind == "eval":
            from omavctl.report.load import load_for_report

            _finite_json(path.read_text())
            _, series = load_for_report(path)
            if not all(np.all(np.isfinite(v)) for v in series.values() if v.dtype.kind == "f"):
                return "series not finite"
        elif kind == "trajectory":
            from omavctl.sim.trajectory import read_trajectory

            read_trajectory(path)
        elif kind == "scores":
            rows = [r.split(",") for r in path.read_text().splitlines()]
            numeric = [
                j
                for j, name in enumerate(rows[0])
                if name[:2] in ("f_", "A_") or name in ("cost", "tracking", "generation")
            ]
            for row in rows[1:]:
                for j in numeric:
                    if row[j] and not math.isfinite(float(row[j])):
                        return f"scores cell {row[j]}"
        elif kind == "log":
            from omavctl.logs import read_raw

            raw = read_raw(path)
            for role, s in raw.series.items():
                if not np.all(np.isfinite(s.values)):
                    return f"log role {role} not finite"
        elif kind == "report":
            text = path.read_text()
            text = re.sub(r"data:image/png;base64,[A-Za-z0-9+/=]+", "", text)
            if re.search(r"\b(nan|inf)\b", text, re.IGNORECASE):
                return "report shows nan/inf"
    except (OmavctlError, ValueError) as err:
        return f"invalid {kind}: {err}"
    return None


def judge(case: Case, work: Path, code: int | None, stdout: str, stderr: str) -> tuple[str, str]:
    """(verdict, detail) of one run; see the module docstring."""
    if code is None:
        return "hang", ""
    leftovers = [p.name for p in work.iterdir() if p.name.startswith(".") and p.name[1:2] != "."]
    if leftovers:
        return "temp-file-left", ", ".join(leftovers)
    text = stderr.strip() if "--json" in case.argv else (stdout + stderr).strip()
    if code != 0 and "--json" in case.argv and stdout.strip():
        # a failed --json run prints its error as one JSON object, the same line
        try:
            obj = json.loads(stdout)
        except ValueError:
            return "not-one-line", f"stdout on failure is not JSON: {stdout[:200]}"
        if (
            stdout.strip().count("\n")
            or obj.get("exit_code") != code
            or (f"error: {obj.get('error')}" != text)
        ):
            return "not-one-line", f"stdout on failure: {stdout[:200]}"
    if code != 0:
        lines = text.splitlines()
        if code != 2:
            return "exit-status", f"{code}: {text[-300:]}"
        if len(lines) != 1 or not lines[0].startswith("error: "):
            return "not-one-line", text[-500:]
        line = lines[0]
        name = Path(case.target).name
        named = case.target in line or name in line
        if case.target.startswith("--"):  # an option: named, or the value it gave
            named = named or case.target.strip("-").replace("-", " ") in line
        if not named:
            return "file-not-named", line
        if EXCEPTION_TEXT.search(line.replace(case.target, "").replace(name, "")):
            return "exception-text", line
        return "refused", line
    if EXCEPTION_TEXT.search(stderr) and "Traceback" in stderr:
        return "exception-text", stderr[-300:]
    if re.search(r"Warning", stderr):
        return "warning-printed", stderr[-300:]
    if case.must_fail:
        return "exit0-wrong", f"accepted {case.mutation}"
    if "--json" in case.argv:
        lines = stdout.strip().splitlines()
        try:
            if len(lines) != 1 or not isinstance(_finite_json(lines[0]), dict):
                return "exit0-wrong", f"--json printed {len(lines)} lines"
        except ValueError as err:
            return "exit0-wrong", f"--json output is not strict JSON: {err}"
    for out, kind in case.outputs.items():
        problem = check_output(work / out, kind)
        if problem:
            return "exit0-wrong", f"{out}: {problem}"
    return "ok", ""


def run_case(case: Case, work: Path, runner: str = "fork", timeout: float = 60.0) -> Outcome:
    before = {p: _digest(work / p) for p in case.inputs}
    start = time.monotonic()
    run = _run_fork if runner == "fork" else _run_subprocess
    code, stdout, stderr = run(case.argv, work, timeout)
    seconds = time.monotonic() - start
    verdict, detail = judge(case, work, code, stdout, stderr)
    changed = [p for p, d in before.items() if _digest(work / p) != d]
    if changed and verdict in ("ok", "refused"):
        verdict, detail = "input-changed", ", ".join(changed)
    return Outcome(case, code, stdout, stderr, seconds, verdict, detail)


FAILURES = (
    "hang",
    "exit-status",
    "not-one-line",
    "file-not-named",
    "exception-text",
    "warning-printed",
    "exit0-wrong",
    "input-changed",
    "temp-file-left",
)


def run_all(
    cases: Iterable[tuple[Case, Path]],
    runner: str = "fork",
    timeout: float = 60.0,
    keep: bool = False,
) -> list[Outcome]:
    """Run every case; the folders of cases that passed are removed unless ``keep``."""
    outcomes = []
    for case, work in cases:
        outcome = run_case(case, work, runner, timeout)
        outcomes.append(outcome)
        if not keep and outcome.verdict not in FAILURES:
            shutil.rmtree(work, ignore_errors=True)
    return outcomes
