"""Randomised scorecard of the whole loop (docs/scorecard.md; ``make scorecard``).

Each draw hides none, one or two registry effects at random sizes in the truth
plant, flies a fit flight and a held-out flight on two different trajectory
families (controller timing, log formats, noise level and seeds drawn too), and
runs the user's loop through the real CLI: ``fit`` with defaults, ``evaluate``
on the held-out flight, the ``fit_command`` the verdict prints, ``evaluate``
again, two rounds. One JSON line per draw; the tables (every rate with its
Wilson 95 % interval, overall and by the hidden effect's size over the claim
floor) are rebuilt from those lines.

    python benchmarks/scorecard.py run --split tune|report|tune2|report2..report28 [--draws N]
        [--start I] [--jobs J] [--workdir DIR] [--out FILE.jsonl]
        [--simulator 'CMD {reference} {truth} {out} {seed}']
    python benchmarks/scorecard.py analyse FILE.jsonl... [--markdown OUT.md] [--apparent A.json]

The split (benchmarks/scorecard_draws.py, SPLITS): ``tune`` draws (seeds from 0,
families figure-8, multi-sine wobble, chirp) may be looked at to change the
tool; ``report`` draws (seeds from 1 000 000, every one flying the held-back
random-steps family) are only reported. ``tune2`` and ``report2`` to ``report28`` are
version 2 (benchmarks/scorecard_v2.py: sizes as multiples of the claim floor, planned
flights); each later report split has other seeds than the one before, whose records
were read to find causes. ``run`` skips draws already in the output file, so an interrupted run
resumes.
"""

from __future__ import annotations

import argparse
import json
import sys
import threading
from collections import Counter
from collections.abc import Sequence
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks import scorecard_score as sc
from benchmarks.scorecard_draws import SPLITS, draw_spec, run_draw
from benchmarks.scorecard_v2 import simulator_argv

DEFAULT_DRAWS = {
    "tune": 12,
    "report": 18,
    "tune2": 12,
    "report2": 48,
    "report3": 48,
    "report4": 48,
    "report5": 48,
    "report6": 48,
    "report7": 48,
    "report8": 48,
    "report9": 48,
    "report10": 48,
    "report11": 48,
    "report12": 48,
    "report13": 48,
    "report14": 48,
    "report15": 48,
    "report16": 48,
    "report17": 48,
    "report18": 48,
    "report19": 48,
    "report20": 48,
    "report21": 48,
    "report22": 48,
    "report23": 48,
    "report24": 48,
    "report25": 48,
    "report26": 48,
    "report27": 48,
    "report28": 48,
}


def _done(out: Path) -> set[tuple[str, int]]:
    if not out.exists():
        return set()
    return {(r["split"], r["index"]) for r in read_records([out])}


def read_records(paths: Sequence[Path]) -> list[dict[str, Any]]:
    """Every record of the JSON lines files, in order (the last of a repeated draw wins)."""
    by_key: dict[tuple[str, int], dict[str, Any]] = {}
    for p in paths:
        for line in p.read_text().splitlines():
            if line.strip():
                r = json.loads(line)
                by_key[(r["split"], r["index"])] = r
    return list(by_key.values())


def run(
    split: str,
    draws: int,
    start: int,
    jobs: int,
    workdir: Path,
    out: Path,
    simulator: str | None = None,
) -> None:
    """Run draws ``start .. start+draws-1`` of ``split``, appending records to ``out``;
    ``simulator``: a command template that flies the flights (docs/scorecard.md)."""
    from omavctl.physics.effects import SIMULATED_EFFECTS as EFFECTS

    done = _done(out)
    todo = [i for i in range(start, start + draws) if (split, i) not in done]
    out.parent.mkdir(parents=True, exist_ok=True)
    lock = threading.Lock()

    def one(i: int) -> None:
        rec = run_draw(draw_spec(split, i, sorted(EFFECTS)), workdir, simulator)
        with lock, out.open("a") as f:
            f.write(json.dumps(rec, allow_nan=False) + "\n")
        what = rec["error"] or ", ".join(rec["rounds"][0]["missing"]) or "nothing missing"
        hidden = sorted(rec["hidden"]) or "none"
        print(
            f"{split} {i}: {rec['seconds']:.0f} s, hidden {hidden}: {what}",
            file=sys.stderr,
            flush=True,
        )

    with ThreadPoolExecutor(max_workers=max(1, jobs)) as pool:
        list(pool.map(one, todo))


def above_floor(records: Sequence[dict[str, Any]]) -> int:
    """Draws that ran, hide an effect and have it at or above 1x the claim floor on the
    held-out flight (the population issue 26's goals are stated for)."""
    return sum(1 for r in records if not r["error"] and r["hidden"] and sc.size_ratio(r) >= 1.0)


def run_until(
    split: str,
    until: int,
    most: int,
    start: int,
    jobs: int,
    workdir: Path,
    out: Path,
    simulator: str | None = None,
) -> int:
    """Run draws from ``start`` in index order, ``jobs`` at a time, until ``out`` holds
    ``until`` draws of ``split`` at or above the floor or ``most`` draws were run; the
    index after the last draw run. The stopping rule reads only the hidden effects'
    sizes, never an outcome, so it does not bias the rates."""
    i = start
    while i < start + most:
        done = [r for r in read_records([out]) if r["split"] == split] if out.exists() else []
        if above_floor(done) >= until:
            break
        n = min(max(1, jobs), start + most - i)
        run(split, n, i, jobs, workdir, out, simulator)
        i += n
    return i


def _rate(k: int, n: int) -> str:
    if n == 0:
        return "–"
    lo, hi = sc.wilson(k, n)
    return f"{k}/{n} = {100 * k / n:.0f} % [{100 * lo:.0f}, {100 * hi:.0f}]"


def _apparent_of(r: dict[str, Any], apparent: dict[str, Any] | None) -> dict[str, Any] | None:
    """The record's entry in the apparent truths (None: none given)."""
    return None if apparent is None else apparent[f"{r['split']}:{r['index']}"]


def table(records: Sequence[dict[str, Any]], apparent: dict[str, Any] | None = None) -> list[str]:
    """The markdown table: every metric overall and by size bin, Wilson 95 % intervals;
    with ``apparent`` (benchmarks/scorecard_truth.py) the rows against the apparent
    truth too."""
    ok = [r for r in records if not r["error"]]
    judged = [(r, sc.judge(r, _apparent_of(r, apparent))) for r in ok]
    bins = ["none", *(b[0] for b in sc.SIZE_BINS)]
    head = ["metric", "goal", "all", "hidden >= 1x floor", *bins]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    above = [j for r, j in judged if r["hidden"] and sc.size_ratio(r) >= 1.0]
    # the strict first-answer row only for records that carry learned claims (since
    # 2026-11-26): older records' tables are unchanged
    learned = any("learned_claims" in rd for r in ok for rd in r["rounds"])
    for label, key, goal in sc.METRICS:
        if key == "first_right_strict" and not learned:
            continue
        if key in sc.APPARENT_KEYS and apparent is None:
            continue
        cells = [label, goal, _rate(*sc.tally([j for _, j in judged], key))]
        cells.append(_rate(*sc.tally(above, key)))
        for b in bins:
            cells.append(_rate(*sc.tally([j for r, j in judged if sc.size_bin(r) == b], key)))
        lines.append("| " + " | ".join(cells) + " |")
    counts = Counter(sc.size_bin(r) for r in ok)
    lines.append("")
    lines.append(
        "Draws: "
        + ", ".join(f"{b} {counts.get(b, 0)}" for b in bins)
        + f"; failed to run: {len(records) - len(ok)}."
    )
    return lines


def by_effect(records: Sequence[dict[str, Any]]) -> list[str]:
    """First answer and error fall per hidden effect (a two-effect draw counts for both)."""
    rows: dict[str, list[dict[str, Any]]] = {}
    for r in records:
        if not r["error"]:
            for name in r["hidden"] or ["none"]:
                rows.setdefault(name, []).append(sc.judge(r))
    lines = [
        "| hidden effect | draws | first answer right | error falls >= 50 % | ends invented |",
        "|---|---|---|---|---|",
    ]
    for name in sorted(rows):
        js = rows[name]
        cells = [_rate(*sc.tally(js, k)) for k in ("first_right", "fall", "invented")]
        lines.append(f"| {name} | {len(js)} | " + " | ".join(cells) + " |")
    return lines


def _draw_label(r: dict[str, Any]) -> str:
    hidden = (
        ", ".join(
            f"{n} ({r['sizes'][n] / r['rounds'][0]['claim_floor']:.1f}x)"
            if r.get("sizes") and r["rounds"][0]["claim_floor"]
            else n
            for n in sorted(r["hidden"])
        )
        or "none"
    )
    fams = " → ".join(f"{f['family']} ({f['format']})" for f in r["flights"])
    return f"{r['split']} {r['index']}: {hidden}; {fams}; {r['timing']}"


def _uncovered(
    r: dict[str, Any], checks: list[Any], truth: str, groups: dict[str, list[str]]
) -> None:
    """The parameter checks whose interval misses their ``truth`` (its label), under
    "<truth> outside the 95 % interval"."""
    for c in checks:
        if not c.covered:
            ci = (
                "no interval"
                if c.interval is None
                else f"[{c.interval[0]:.4g}, {c.interval[1]:.4g}]"
            )
            groups.setdefault(f"{truth} outside the 95 % interval", []).append(
                f"{_draw_label(r)}: {c.effect}.{c.name} {c.estimate:.4g} {ci} for {c.truth:.4g}"
            )


def _apparent_failures(
    r: dict[str, Any], app: dict[str, Any], groups: dict[str, list[str]]
) -> None:
    """The record's parameters outside their interval against the apparent truth, and
    a none draw's first claims that are no default imperfection's look-alike."""
    _uncovered(r, sc.param_checks(r, app), "apparent truth", groups)
    if not r["hidden"]:
        bad = [n for n in sc.claimed(r["rounds"][0]) if not sc.lookalike(r, app, n)]
        if bad:
            groups.setdefault("none draw: a claim that is no default's look-alike", []).append(
                f"{_draw_label(r)}: {', '.join(bad)}"
            )


def failures(
    records: Sequence[dict[str, Any]], apparent: dict[str, Any] | None = None
) -> list[str]:
    """One line per failed judgement, grouped by metric (with ``apparent``, the
    apparent truth's too)."""
    groups: dict[str, list[str]] = {}
    for r in records:
        if r["error"]:
            groups.setdefault("step failed", []).append(f"{_draw_label(r)}: {r['error']}")
            continue
        j = sc.judge(r)
        first = r["rounds"][0]
        said = ", ".join(first["missing"]) or "nothing missing"
        if not j["first_right"]:
            verdict = (first.get("verdict") or [""])[0][:240]
            groups.setdefault("first answer wrong", []).append(
                f"{_draw_label(r)}: said {said} (verdict: “{verdict}”)"
            )
        if j["fall"] is False:
            groups.setdefault("physics-only error fell < 50 %", []).append(
                f"{_draw_label(r)}: fell {100 * sc.physics_fall(r):.0f} % over "
                f"{len(r['rounds']) - 1} round(s); first said {said}"
            )
        if j["invented"]:
            groups.setdefault("ends with an effect the vehicle lacks", []).append(
                f"{_draw_label(r)}: {', '.join(sc.invented(sc.final_names(r), r['hidden']))}"
            )
        if j["worse"]:
            last = r["rounds"][-1]
            ratios = ", ".join(
                f"{a} {last['rmse_model'][a] / last['rmse_physics'][a]:.2f}x"
                for a in sc.worse_axes(last)
            )
            groups.setdefault("model worse than physics-only", []).append(
                f"{_draw_label(r)}: {ratios}"
            )
        _uncovered(r, sc.param_checks(r), "truth", groups)
        app = _apparent_of(r, apparent)
        if app is not None:
            _apparent_failures(r, app, groups)
        last = r["rounds"][-1]
        low = {a: c for a, c in last["coverage"].items() if c < sc.COVER_MIN}
        if low:
            groups.setdefault("2-sigma coverage < 0.85", []).append(
                f"{_draw_label(r)}: " + ", ".join(f"{a} {c:.2f}" for a, c in low.items())
            )
    out = []
    for g, items in groups.items():
        out += [f"**{g}** ({len(items)})", ""] + [f"- {x}" for x in items] + [""]
    return out


def cost(records: Sequence[dict[str, Any]]) -> str:
    secs = [r["seconds"] for r in records]
    if not secs:
        return "no draws"
    mean = sum(secs) / len(secs)
    return (
        f"{len(secs)} draws, {mean:.0f} s per draw on average (wall, one job), "
        f"{sum(secs) / 60:.0f} min of job time in all"
    )


def analyse(
    paths: Sequence[Path], markdown: Path | None, apparent_path: Path | None = None
) -> None:
    """Print (and optionally write) the tables per split and the failures; with
    ``apparent_path`` (benchmarks/scorecard_truth.py's JSON) the apparent truth's rows."""
    records = read_records(paths)
    apparent = None if apparent_path is None else json.loads(apparent_path.read_text())
    lines: list[str] = []
    for split in SPLITS:
        recs = [r for r in records if r["split"] == split]
        if recs:
            lines += [f"### {split} split", "", *table(recs, apparent), "", *by_effect(recs), ""]
            lines += [f"Cost: {cost(recs)}.", ""]
    lines += ["### Failures by metric", "", *failures(records, apparent)]
    text = "\n".join(lines) + "\n"
    print(text)
    if markdown is not None:
        markdown.write_text(text)


def main(argv: Sequence[str] | None = None) -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    sub = ap.add_subparsers(dest="mode", required=True)
    r = sub.add_parser("run", help="run draws, appending JSON lines")
    r.add_argument("--split", choices=sorted(SPLITS), required=True)
    r.add_argument(
        "--draws", type=int, default=None, help=f"draws to run (default {DEFAULT_DRAWS})"
    )
    r.add_argument("--start", type=int, default=0, help="first draw index")
    r.add_argument("--jobs", type=int, default=2)
    r.add_argument("--workdir", type=Path, default=Path("build/scorecard"))
    r.add_argument(
        "--out", type=Path, default=None, help="JSON lines (default WORKDIR/SPLIT.jsonl)"
    )
    r.add_argument(
        "--simulator",
        default=None,
        metavar="'CMD {reference} {truth} {out} {seed}'",
        help="fly the flights with this command instead of omavctl simulate (run in the "
        "draw's directory; it must write a log omavctl reads at {out})",
    )
    r.add_argument(
        "--until-above",
        type=int,
        default=None,
        metavar="N",
        help="run draws in index order until the output holds N hidden-effect draws at or "
        "above 1x the claim floor (--draws is then the most to run)",
    )
    a = sub.add_parser("analyse", help="rebuild the tables from JSON lines")
    a.add_argument("records", type=Path, nargs="+")
    a.add_argument("--markdown", type=Path, default=None)
    a.add_argument(
        "--apparent",
        type=Path,
        default=None,
        help="the records' apparent truth (benchmarks/scorecard_truth.py): adds its rows",
    )
    args = ap.parse_args(argv)
    if args.mode == "run":
        draws = DEFAULT_DRAWS[args.split] if args.draws is None else args.draws
        out = args.out or args.workdir / f"{args.split}.jsonl"
        if args.simulator is not None:
            try:
                simulator_argv(args.simulator, "ref.csv", "truth.yaml", "log", 0)
            except ValueError as exc:
                print(f"error: {exc}", file=sys.stderr)
                sys.exit(2)
        workdir = args.workdir.resolve()
        if args.until_above is None:
            run(args.split, draws, args.start, args.jobs, workdir, out, args.simulator)
            return
        end = run_until(
            args.split, args.until_above, draws, args.start, args.jobs, workdir, out, args.simulator
        )
        count = above_floor([r for r in read_records([out]) if r["split"] == args.split])
        print(f"{args.split}: {count} draws at or above the floor after index {end - 1}")
    else:
        analyse(args.records, args.markdown, args.apparent)


if __name__ == "__main__":
    main()
