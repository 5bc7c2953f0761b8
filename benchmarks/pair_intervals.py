"""Do fit's 95 % intervals hold the truth for effects fitted together? (docs/intervals.md,
"Effects fitted in pairs").

Run, once per tree (``PYTHONPATH`` says which ``omavctl`` fits):

    python benchmarks/pair_intervals.py fit RECORDS.jsonl --logs DIR --apparent A.json \
        --out ROWS.jsonl
    python benchmarks/pair_intervals.py summary BEFORE.jsonl AFTER.jsonl

``fit``: for every scorecard record with a hidden effect, its fit flight's log
(``DIR/<split>-<index:04d>/<log>``) is fitted as ``fit --effects`` fits it (the first
pass, the GP hyperparameters, the timing searches and the linear effects jointly with
the GP; 200 points, seed 0) with the hidden set, and with ``com_offset`` beside it as
the loop adds it. Each hidden parameter component is scored by
``benchmarks/scorecard_score.param_checks`` against the hidden value and, with
``--apparent`` (``benchmarks/scorecard_truth.py RECORDS --out A.json``, the fitted sets
``hidden + com_offset``), the apparent truth. About 10-40 s a fit on a busy 2-core
machine. ``summary``: coverage, narrow-and-within and median half-width of both row
files (the apparent truth where there is one), overall, for single effects and for
effects fitted in pairs, and the components whose interval changed.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np


def fit_rows(record: dict[str, Any], log: Path, apparent: dict[str, Any] | None) -> list[dict]:
    """The scored components of the record's hidden set and hidden + com_offset fits."""
    from benchmarks.scorecard_score import param_checks
    from omavctl.learn.effect_fit import merged_estimates
    from omavctl.learn.fit_steps import (
        first_pass,
        fit_options,
        gp_hyperparameters,
        joint_step,
        training_set,
    )
    from omavctl.learn.flights import read_samples
    from omavctl.vehicle import default_vehicle

    vehicle = default_vehicle()
    hidden = list(record["hidden"])
    rows = []
    for names in [hidden] + ([[*hidden, "com_offset"]] if "com_offset" not in hidden else []):
        opts = fit_options(
            [log], vehicle, names, 200, None, (11, 2), "wrench+rate+dtorque", 0, 2, None
        )
        original, _ = read_samples([log], vehicle, opts.sg, None, 200, lambda *a: None)
        res = first_pass(original, opts.names)
        train = training_set(opts, res)
        gp = gp_hyperparameters(opts, original, res, train)
        eff, _ = joint_step(opts, res, train, gp)
        est = merged_estimates(opts.names, eff.estimates, res.found)
        scored = dict(record, fits=[{"effects": {n: e.to_json() for n, e in est.items()}}])
        for kind, app in (("hidden", None), ("apparent", apparent)):
            if kind == "apparent" and app is None:
                continue
            for c in param_checks(scored, app):
                rows.append(
                    {
                        "key": f"{record['split']}:{record['index']}",
                        "set": "+".join(names),
                        "kind": kind,
                        "effect": c.effect,
                        "param": c.name,
                        "truth": c.truth,
                        "est": c.estimate,
                        "ci": c.interval,
                        "covered": c.covered,
                        "narrow": c.narrow,
                        "within": c.within_tol,
                    }
                )
    return rows


def _load(path: Path) -> dict[tuple[str, ...], dict]:
    """Rows by (record, set, effect, parameter): the apparent truth's where there is one."""
    rows = [json.loads(line) for line in path.read_text().splitlines() if line]
    apparent = {r["key"] for r in rows if r["kind"] == "apparent"}
    keep = [r for r in rows if r["kind"] == ("apparent" if r["key"] in apparent else "hidden")]
    return {(r["key"], r["set"], r["effect"], r["param"]): r for r in keep}


def _line(rows: list[dict], label: str) -> str:
    covered = sum(r["covered"] for r in rows)
    narrow = [r for r in rows if r["narrow"]]
    half = [abs(r["ci"][1] - r["ci"][0]) / 2 / abs(r["est"]) for r in rows if r["ci"] and r["est"]]
    median = 100 * float(np.median(half)) if half else float("nan")
    return (
        f"{label:24s} inside {covered}/{len(rows)}; narrow within "
        f"{sum(r['within'] for r in narrow)}/{len(narrow)}; median half-width {median:.1f} %"
    )


def summary(before: Path, after: Path) -> None:
    """Print both files' rates and the components whose interval changed."""
    a, b = _load(before), _load(after)
    for name, rows in ((before.name, a), (after.name, b)):
        print(name)
        every = list(rows.values())
        print("  " + _line(every, "all"))
        print("  " + _line([r for r in every if "+" not in r["set"]], "single effects"))
        print("  " + _line([r for r in every if "+" in r["set"]], "fitted together"))
    for key in sorted(a.keys() & b.keys()):
        x, y = a[key], b[key]
        if x["covered"] != y["covered"] or x["ci"] != y["ci"]:
            print(
                f"  {key}: truth {x['truth']:.4g}: {x['est']:.4g} {x['ci']}"
                f" -> {y['est']:.4g} {y['ci']}"
            )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="command", required=True)
    f = sub.add_parser("fit")
    f.add_argument("records", type=Path)
    f.add_argument("--logs", type=Path, required=True)
    f.add_argument("--apparent", type=Path)
    f.add_argument("--out", type=Path, required=True)
    s = sub.add_parser("summary")
    s.add_argument("before", type=Path)
    s.add_argument("after", type=Path)
    args = ap.parse_args()
    if args.command == "summary":
        summary(args.before, args.after)
        return
    apparent = json.loads(args.apparent.read_text()) if args.apparent else {}
    with args.out.open("w") as out:
        for line in args.records.read_text().splitlines():
            record = json.loads(line)
            if record.get("error") or not record["hidden"]:
                continue
            flight = next(x for x in record["flights"] if x["role"] == "fit")
            log = args.logs / f"{record['split']}-{record['index']:04d}" / flight["log"]
            app = apparent.get(f"{record['split']}:{record['index']}")
            for row in fit_rows(record, log, app):
                out.write(json.dumps(row, allow_nan=False) + "\n")
            out.flush()
            print(record["split"], record["index"], flush=True)


if __name__ == "__main__":
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
    main()
