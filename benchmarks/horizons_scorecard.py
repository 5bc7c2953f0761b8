"""Issue 28's must-show over the scorecard's random draws: open-loop horizons, post hoc.

    python benchmarks/horizons_scorecard.py RECORDS.jsonl[,...] ROOT[,...] [--replay LABEL]
        [--jobs N] [--out ROWS.jsonl] [--markdown FILE]

RECORDS: scorecard records (``benchmarks/scorecard.py run --out``, or a replay's
``scorecard_replay.py replay`` output); ROOT: the work directories that hold their
draws (``ROOT/<split>-<index>``, the first that has it; with ``--replay LABEL`` the
replay's models in ``ROOT/<split>-<index>/replay-<LABEL><index % 2>``). Each draw's
loop is taken as it ran: its first model (``fit`` with defaults) and its last (after
the rounds of the verdict's commands), both fitted on the draw's fit flight, are
evaluated together on its held-out flight (another trajectory family, seed, log format
and often control rate) with the default horizons 0.01, 0.1 and 0.5 s at stride 1
(``evaluate``'s table). The loop ran with ``--horizons none``, so nothing here chose a model.

Printed (and with ``--markdown`` written) with binomial 95 % intervals:

- the last model's full-model 0.5 s body-rate error over physics + effects', per
  axis-flight: within 1.05x, and above it beyond 2 paired standard errors;
- the last model's 2-sigma predictive band coverage at each horizon: pooled over the
  axes per flight, and per axis-flight; the first model's beside it;
- adding the loop's effects (first model -> last): on each axis where physics +
  effects' one-step RMSE falls, whether its 0.5 s error falls too (or moves within 2
  paired standard errors), and the same for the full model;
- the draws where ``evaluate`` finds the GP helping at one step and hurting at 0.5 s
  (``gp_hurts_long``) or the added effect doing so (``effect_added_hurts_long``).

Results: docs/horizons.md (session 32).
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Iterable
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from omavctl.diagnose.horizon_band import MIN_COVERAGE as COVER
from omavctl.diagnose.horizon_findings import SIGNIFICANT as SIG
from omavctl.diagnose.horizon_findings import TOLERANCE as RATIO

AXES = ("x", "y", "z")


def _models(record: dict[str, Any]) -> list[str]:
    """The loop's model files in the order they were fitted (first: ``m0.npz``)."""
    out = ["m0.npz"]
    for fit in record["fits"][1:]:
        words = fit["command"].split()
        out.append(words[words.index("--out") + 1])
    return out


def draw_dir(record: dict[str, Any], roots: list[str], replay: str | None) -> Path:
    """Where a record's models and logs are (the first root that has the draw)."""
    name = f"{record['split']}-{record['index']:04d}"
    d = next((Path(r) / name for r in roots if (Path(r) / name).is_dir()), Path(roots[0]) / name)
    return d / f"replay-{replay}{record['index'] % 2}" if replay else d


def _compact(tree: dict[str, Any], names: list[str]) -> dict[str, Any]:
    """What the summary needs of one evaluation tree: the horizon table's entries, the
    one-step RMSE and coverage per model, the horizon findings."""
    h = tree["horizons"]
    keep = ("rate_error", "rate_error_chunks", "coverage")
    table = {k: [{f: r.get(f) for f in keep} for r in rows] for k, rows in h["table"].items()}
    one = [
        {kind: {"rmse": m[kind]["rmse"]} for kind in ("nominal", "effects", "model") if kind in m}
        | {"coverage_2sigma": m["model"].get("coverage_2sigma")}
        for m in tree["metrics_by_model"]
    ]
    return {
        "models": names,
        "seconds": h["seconds"],
        "windows": h["windows"],
        "table": table,
        "one_step": one,
        "findings": [{"code": f["code"], "message": f["message"]} for f in h["findings"]],
    }


def run_one(job: tuple[dict[str, Any], list[str], str | None]) -> dict[str, Any]:
    """Evaluate one draw's first and last models on its held-out flight."""
    from threadpoolctl import threadpool_limits

    from omavctl.diagnose.evaluate import evaluate

    record, roots, replay = job
    d = draw_dir(record, roots, replay)
    names = _models(record)
    models = [names[0]] if len(names) == 1 else [names[0], names[-1]]
    row: dict[str, Any] = {
        "draw": f"{record['split']}-{record['index']:04d}",
        "hidden": sorted(record["hidden"]),
        "fit": record["flights"][0]["family"],
        "held": record["flights"][1]["family"],
        "timing": record.get("timing"),
    }
    try:
        with threadpool_limits(1):
            result = evaluate(
                [d / m for m in models], [d / record["flights"][1]["log"]], with_diagnosis=False
            )
    except Exception as exc:  # a benchmark row records what failed
        return row | {"error": f"{type(exc).__name__}: {exc}"}
    return row | _compact(result.tree, models)


def _wilson(k: int, n: int) -> str:
    from benchmarks.scorecard_score import wilson

    if n == 0:
        return "0/0"
    lo, hi = wilson(k, n)
    return f"{k}/{n} = {100 * k / n:.0f} % [{100 * lo:.0f}, {100 * hi:.0f}]"


def _sfx(row: dict[str, Any]) -> str:
    return "_1" if "model_1" in row["table"] else ""


def ratio_lines(rows: list[dict[str, Any]]) -> list[str]:
    """The last model's full / physics + effects at the longest horizon."""
    from omavctl.diagnose.horizon_findings import paired_se

    n = ok = beyond = 0
    worst: list[str] = []
    for r in rows:
        s = _sfx(r)
        full, eff = r["table"][f"model{s}"][-1], r["table"][f"effects{s}"][-1]
        for a in AXES:
            n += 1
            q = full["rate_error"][a] / eff["rate_error"][a]
            se = paired_se(eff, full, a)
            rise = full["rate_error"][a] - eff["rate_error"][a]
            ok += q <= RATIO
            if q > RATIO:
                sig = se is None or rise > SIG * se
                beyond += sig
                worst.append(
                    f"{r['draw']} ({r['fit']} -> {r['held']}) {a} {q:.2f}"
                    + ("" if se is None else f" (+{rise:.2g} ± {se:.2g} rad/s)")
                )
    return [
        f"- full model within {RATIO}x physics + effects at 0.5 s, axis-flights: " + _wilson(ok, n),
        f"- above {RATIO}x beyond {SIG:g} paired standard errors: {beyond}/{n}",
        *(f"  - {w}" for w in worst),
    ]


def coverage_lines(rows: list[dict[str, Any]], which: str) -> list[str]:
    """The band's 2-sigma coverage per horizon: pooled per flight, and per axis-flight."""
    out = []
    secs = rows[0]["seconds"]
    for i, sec in enumerate(secs):
        pooled = per_axis = n = 0
        low: list[str] = []
        for r in rows:
            key = f"model{_sfx(r)}" if which == "last" else "model"
            cov = r["table"][key][i]["coverage"]
            n += 1
            pooled += cov["all"] >= COVER
            for a in AXES:
                per_axis += cov[a] >= COVER
                if cov[a] < COVER:
                    low.append(f"{r['draw']} {r['held']} {a} {100 * cov[a]:.0f} %")
        out.append(
            f"- {which} model, {sec:g} s: pooled ≥ {COVER:.0%} on {_wilson(pooled, n)} of "
            f"flights; per axis {_wilson(per_axis, 3 * n)}"
            + (f"; under: {', '.join(low)}" if low else "")
        )
    return out


def added_lines(rows: list[dict[str, Any]]) -> list[str]:
    """First model -> last: where one-step RMSE falls, does the 0.5 s error fall?"""
    from omavctl.diagnose.horizon_findings import paired_se

    out = []
    for kind, what in (("effects", "physics + effects"), ("model", "full model")):
        counts = {"agree": 0, "within 2 SE": 0, "disagree": 0}
        bad: list[str] = []
        for r in (r for r in rows if _sfx(r)):
            a0, a1 = r["table"][kind][-1], r["table"][f"{kind}_1"][-1]
            for a in AXES:
                d1 = r["one_step"][1][kind]["rmse"][a] - r["one_step"][0][kind]["rmse"][a]
                if d1 >= 0:
                    continue
                d50 = a1["rate_error"][a] - a0["rate_error"][a]
                se = paired_se(a0, a1, a)
                key = (
                    "agree"
                    if d50 < 0
                    else "within 2 SE"
                    if se is not None and d50 <= SIG * se
                    else "disagree"
                )
                counts[key] += 1
                if key == "disagree":
                    bad.append(
                        f"{r['draw']} ({r['fit']} -> {r['held']}) {a}: one-step "
                        f"{d1:+.2g} rad/s², 0.5 s {d50:+.2g}"
                        + ("" if se is None else f" ± {se:.2g}")
                        + " rad/s"
                    )
        total = sum(counts.values())
        out.append(
            f"- {what}: of {total} axis-flights where the loop's effects lower the one-step "
            f"RMSE, the 0.5 s error falls on {counts['agree']}, moves within 2 SE on "
            f"{counts['within 2 SE']}, rises beyond 2 SE on {counts['disagree']}"
        )
        out += [f"  - {b}" for b in bad]
    return out


def finding_lines(rows: list[dict[str, Any]]) -> list[str]:
    out = []
    for code in ("gp_hurts_long", "effect_added_hurts_long", "band_narrow", "hold_beats_models"):
        hits = [r for r in rows if any(f["code"] == code for f in r["findings"])]
        out.append(f"- `{code}`: {len(hits)}/{len(rows)} draws")
        for r in hits:
            msgs = [f["message"] for f in r["findings"] if f["code"] == code]
            out.append(f"  - {r['draw']} ({r['fit']} -> {r['held']}): {msgs[0]}")
    return out


def summary(rows: list[dict[str, Any]]) -> list[str]:
    ok = [r for r in rows if "error" not in r]
    failed = [f"{r['draw']}: {r['error']}" for r in rows if "error" in r]
    lines = [
        f"{len(ok)} draws evaluated ({sum(1 for r in ok if _sfx(r))} with effects added by "
        f"the loop); failed: {len(failed)}",
        *(f"  - {f}" for f in failed),
        "",
    ]
    if not ok:
        return lines
    return [
        *lines,
        *ratio_lines(ok),
        "",
        *coverage_lines(ok, "last"),
        *coverage_lines(ok, "first"),
        "",
        *added_lines(ok),
        "",
        *finding_lines(ok),
    ]


def _records(paths: Iterable[str]) -> list[dict[str, Any]]:
    out = []
    for path in paths:
        for line in Path(path).read_text().splitlines():
            r = json.loads(line)
            if not r.get("error"):
                out.append(r)
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("records", help="scorecard record files, comma-separated")
    ap.add_argument("roots", help="work directories of the draws, comma-separated")
    ap.add_argument("--replay", default=None, help="replay label (models in replay-LABEL<p>)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", type=Path, default=None, help="rows (JSONL); reused if present")
    ap.add_argument("--markdown", type=Path, default=None)
    args = ap.parse_args(argv)
    records = _records(args.records.split(","))
    done: dict[str, dict[str, Any]] = {}
    if args.out and args.out.exists():
        done = {r["draw"]: r for r in map(json.loads, args.out.read_text().splitlines())}
    todo = [
        (r, args.roots.split(","), args.replay)
        for r in records
        if f"{r['split']}-{r['index']:04d}" not in done
    ]
    with ProcessPoolExecutor(args.jobs) as pool:
        for row in pool.map(run_one, todo):
            done[row["draw"]] = row
            print(f"{row['draw']}: {row.get('error', 'ok')}", file=sys.stderr, flush=True)
            if args.out:
                with args.out.open("a") as f:
                    f.write(json.dumps(row) + "\n")
    rows = [done[k] for k in sorted(done)]
    text = "\n".join(summary(rows))
    print(text)
    if args.markdown:
        args.markdown.write_text(text + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
