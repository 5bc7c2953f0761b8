"""Do the diagnosis and ``fit --effects`` estimate one effect on one log alike? (issue 26)

Issue 26 asks that "the diagnosis's and ``fit --effects``'s estimates of one effect on
one log differ by < 2 combined standard errors". The diagnosis quotes, for every effect
its first evaluation claims, the estimate the printed ``fit --effects`` command would
make (``diagnosis.claim_estimates``, and a learned claim's ``estimate``), but on the
evaluated (held-out) flight, while the printed command fits the fit flight. This runs
that command on the held-out log itself, with the same options, on the kept draw
directories of a scorecard run (``WORKDIR/SPLIT-NNNN``, ``m0.eval.json``), and compares
each parameter component: |a - b| / sqrt(se_a^2 + se_b^2), with the statistical standard
errors (the rotors' spread's systematic part, the same on both, left out: the stricter
reading). The diagnosis makes its second stage at 100 k-medoids points, ``fit`` at 200.

    python benchmarks/scorecard_agree.py RECORDS.jsonl [--workdir DIR] [--out FILE.json]
"""

from __future__ import annotations

import argparse
import json
import math
import shlex
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks.scorecard import read_records
from benchmarks.scorecard_draws import StepFailed, omavctl
from benchmarks.scorecard_score import wilson

#: combined standard errors under which the two estimates agree (issue 26)
APART = 2.0


def _claims(diag: Mapping[str, Any]) -> dict[str, Mapping[str, Any]]:
    """Each claimed effect's estimate on the evaluated flight (missing and learned)."""
    out = {n: e for n, e in (diag.get("claim_estimates") or {}).items() if n in diag["missing"]}
    for step in diag.get("learned_steps") or []:
        for name in diag.get("learned_claims") or []:
            if step.get("name") == name and isinstance(step.get("estimate"), Mapping):
                out.setdefault(name, step["estimate"])
    return out


def _options(command: str) -> list[str]:
    """The printed fit command's options after its log and ``--effects``/``--out``."""
    argv = shlex.split(command)[3:]  # omavctl fit LOG
    keep, skip = [], False
    for a in argv:
        if skip:
            skip = False
        elif a in ("--effects", "--out"):
            skip = True
        else:
            keep.append(a)
    return keep


def compare(here: Mapping[str, Any], fitted: Mapping[str, Any]) -> list[dict[str, Any]]:
    """Per component of every parameter both give with a finite standard error."""
    rows = []
    for param, values in fitted.get("values", {}).items():
        ours, se_ours = here.get(param), here.get(f"{param}_stderr")
        se_fit = fitted.get("stderr", {}).get(param)
        if not (isinstance(ours, list) and isinstance(se_ours, list) and se_fit):
            continue
        for i, (a, sa, b, sb) in enumerate(zip(ours, se_ours, values, se_fit, strict=False)):
            if None in (a, sa, b, sb) or not all(math.isfinite(float(x)) for x in (sa, sb)):
                continue
            se = math.hypot(float(sa), float(sb))
            if se <= 0:
                continue
            apart = abs(float(a) - float(b)) / se
            rows.append({"param": param, "i": i, "diagnosis": a, "diagnosis_se": sa,
                         "fit": b, "fit_se": sb, "apart": apart})  # fmt: skip
    return rows


def agree_draw(record: Mapping[str, Any], workdir: Path) -> dict[str, Any] | None:
    """The draw's claims compared with ``fit --effects`` on its held-out log; None
    without a claim or a kept first evaluation."""
    d = workdir / f"{record['split']}-{record['index']:04d}"
    ev = d / "m0.eval.json"
    if not ev.exists():
        return None
    diag = json.loads(ev.read_text())["diagnosis"]
    claims = _claims(diag)
    command = diag.get("fit_command")
    if not claims or not isinstance(command, str):
        return None
    held = record["flights"][1]["log"]
    argv = ["fit", held, "--effects", ",".join(claims), "--out", "agree.npz", *_options(command)]
    try:
        res = omavctl(argv, d, [])
    except StepFailed as exc:
        return {"index": record["index"], "error": str(exc)}
    rows = []
    for name, here in claims.items():
        fitted = (res.get("effects") or {}).get(name)
        if isinstance(fitted, Mapping):
            rows += [{"effect": name, **r} for r in compare(here, fitted)]
    return {"index": record["index"], "effects": list(claims), "rows": rows}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("records", type=Path)
    ap.add_argument("--workdir", type=Path, default=None)
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    workdir = (args.workdir or args.records.parent).resolve()
    results = []
    for rec in read_records([args.records]):
        if rec.get("error"):
            continue
        res = agree_draw(rec, workdir)
        if res is None:
            continue
        results.append(res)
        worst = max((r["apart"] for r in res.get("rows", [])), default=float("nan"))
        print(f"{rec['split']} {rec['index']}: {res.get('effects')} worst {worst:.2f}", flush=True)
    rows = [r for res in results for r in res.get("rows", [])]
    ok = sum(r["apart"] < APART for r in rows)
    lo, hi = wilson(ok, len(rows))
    print(f"components within {APART:g} combined standard errors: {ok}/{len(rows)} "
          f"[{100 * lo:.0f}, {100 * hi:.0f}] over {len(results)} draws")  # fmt: skip
    for r in (r for res in results for r in res.get("rows", []) if r["apart"] >= APART):
        what = f"{r['effect']}.{r['param']}[{r['i']}]"
        print(
            f"  apart {r['apart']:.2f}: {what} {r['diagnosis']:.4g} ± {r['diagnosis_se']:.2g}"
            f" vs {r['fit']:.4g} ± {r['fit_se']:.2g}"
        )
    if args.out:
        args.out.write_text(json.dumps(results, indent=1, allow_nan=False))


if __name__ == "__main__":
    main()
