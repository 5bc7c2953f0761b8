"""Replay the scorecard's diagnosis steps on kept draws (docs/scorecard.md, "Replays").

A scorecard draw (benchmarks/scorecard.py) costs minutes: two simulated flights,
three fits, three evaluations. A change to the diagnosis does not change the
flights nor the first fit, so this replays only what it can change, on the
draw directories ``scorecard.py run`` keeps (``WORKDIR/SPLIT-NNNN``): evaluate
the kept first model ``m0.npz`` on the kept held-out log, run the ``fit_command``
the verdict prints, evaluate again, two rounds (as
:func:`benchmarks.scorecard_draws.loop`), and score the result with
:mod:`benchmarks.scorecard_score`. Fits are cached in the draw directory by
their arguments and the omavctl sources (fitting does not depend on the diagnosis,
but a change to the fit's code, as session 19's intervals, is another fit), so a
second replay of the same code runs only the evaluations. Evaluations skip the
open-loop horizon table (``--horizons none``), which no score reads.

    python benchmarks/scorecard_replay.py draw --draws 16 --workdir build/sc   # run once
    python benchmarks/scorecard_replay.py replay build/sc/tune.jsonl --label after
    python benchmarks/scorecard_replay.py compare build/sc/tune.jsonl \\
        build/sc/tune.before.jsonl build/sc/tune.after.jsonl

``draw`` runs tune draws (or ``--split own``: seeds from 2 000 000 with the held-back
``steps`` family on one side, as the report draws have, to look for causes) with
``scorecard.py``'s runner (one job by default).
``replay`` writes ``<records>.<label>.jsonl`` beside the records (the original
record with its ``rounds`` and ``fits`` replaced) and prints the tables;
``compare`` prints the per-draw before/after lines and the table of each.
Report draws may be replayed only to report, never to tune (docs/scorecard.md).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import shlex
import shutil
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from benchmarks import scorecard_score as sc
from benchmarks.scorecard import by_effect, failures, read_records, table
from benchmarks.scorecard_draws import (
    ROOT,
    ROUNDS,
    SPLITS,
    StepFailed,
    fit_argv,
    next_command,
    omavctl,
    round_record,
)

#: Draws of one's own (not the report split): the held-back ``steps`` family on one
#: side as the report draws, other seeds; for finding causes, never for the report.
OWN_SPLIT = {
    "own": {"seed_base": 2_000_000, "families": ("fig8", "wobble", "chirp"), "held_back": "steps"},
    # version 2's design (sizes as multiples of the claim floor, planned flights), the
    # held-back family on one side as report2/report3 fly it; other seeds than both
    "own2": {
        "seed_base": 2_000_000,
        "families": ("fig8", "wobble", "chirp", "planned"),
        "held_back": "steps",
        "version": 2,
    },
    # issue 26 "steps" (session 14): a steps fit flight judged on a figure-8 or a planned
    # flight, lags, delays and a drag hidden (or nothing); seeds of no other split
    "own-steps": {
        "seed_base": 9_100_000,
        "families": ("fig8", "planned"),
        "held_back": "steps",
        "held_back_fits": True,
        "effects": ("command_delay", "motor_lag", "servo_lag", "rotational_drag"),
        "version": 2,
    },
    # issue 26 "steps7" (session 15): report7's design (every effect, the steps family
    # on either side, version 2), declared before any draw was flown; fresh seeds
    "own-steps7": {
        "seed_base": 9_300_000,
        "families": ("fig8", "wobble", "chirp", "planned"),
        "held_back": "steps",
        "version": 2,
    },
    # issue 26 "pair" (session 15): timing effects in pairs and beside a non-timing one,
    # every trajectory family; only the draws that hide two effects, at least one a lag or
    # delay, are flown (/tmp script's rule, declared before any was looked at); the same
    # seed base as own-steps7 (both declared in parallel), another effect pool: other draws
    "own-timing": {
        "seed_base": 9_300_000,
        "families": ("fig8", "wobble", "chirp", "planned"),
        "held_back": "steps",
        "effects": (
            "command_delay",
            "motor_lag",
            "servo_lag",
            "rotational_drag",
            "inertia_error",
            "com_offset",
        ),
        "version": 2,
    },
    # issue 26 "delaylag" (session 16): the timing effects alone, singles and pairs, the
    # steps family on one side, every other family on the other; only the draws that hide
    # at least one effect are flown, in index order (a scratch loop's rule, declared here
    # before any draw was flown); seeds of no other split
    "own-timing2": {
        "seed_base": 9_400_000,
        "families": ("fig8", "wobble", "chirp", "planned"),
        "held_back": "steps",
        "effects": ("command_delay", "motor_lag", "servo_lag"),
        "version": 2,
    },
    # issue 26 "smooth" (session 16): report7/8's design (every effect, the steps family
    # on either side, version 2), declared before any draw was flown; fresh seeds
    "own-steps8": {
        "seed_base": 9_500_000,
        "families": ("fig8", "wobble", "chirp", "planned"),
        "held_back": "steps",
        "version": 2,
    },
    # issue 26 "band" (session 17): the report design (every effect, the steps family on
    # either side, version 2), declared before any draw was flown; the band inside the fit
    # inputs is reported on own-band, anything tuned only on own-band-tune; fresh seeds
    "own-band": {
        "seed_base": 9_700_000,
        "families": ("fig8", "wobble", "chirp", "planned"),
        "held_back": "steps",
        "version": 2,
    },
    "own-band-tune": {
        "seed_base": 9_710_000,
        "families": ("fig8", "wobble", "chirp", "planned"),
        "held_back": "steps",
        "version": 2,
    },
    # issue 26 "drag" (session 19): report10's weakest effect (rotational_drag, first
    # answer right 3/8 at or above the floor) and its look-alike com_offset, the steps
    # family on either side, version 2; declared before any draw was flown; fresh seeds
    "own-drag": {
        "seed_base": 9_800_000,
        "families": ("fig8", "wobble", "chirp", "planned"),
        "held_back": "steps",
        "effects": ("com_offset", "rotational_drag"),
        "version": 2,
    },
    # issue 26 "inertia" (session 20): report11's inventions and misses around
    # inertia_error (beside a large drag or motor lag; held back by the guard) and the
    # rotors' interference it looks like; the steps family on either side, version 2;
    # declared before any draw was flown; fresh seeds
    "own-inertia": {
        "seed_base": 9_810_000,
        "families": ("fig8", "wobble", "chirp", "planned"),
        "held_back": "steps",
        "effects": ("inertia_error", "rotational_drag", "motor_lag", "rotor_interference"),
        "version": 2,
    },
    # issue 26 "invent" (session 21): the report design (every effect, the steps family on
    # either side, version 2), to find draws that end with an effect the vehicle lacks
    # or none draws with a claim (report12: 2/57 and 1/11, not read to tune); declared
    # before any draw was flown; fresh seeds
    "own-invent": {
        "seed_base": 9_820_000,
        "families": ("fig8", "wobble", "chirp", "planned"),
        "held_back": "steps",
        "version": 2,
    },
    # issue 26 "fig8" (session 22): report13's commonest wrong first answer (a steps fit
    # flight judged on a figure-8: the defaults' look-alikes named, the hidden effect
    # not; draws 1, 28, 32, 40 of report13), every effect, the steps flight always the fit
    # flight and the figure-8 the held-out one; declared before any draw was flown
    "own-fig8": {
        "seed_base": 9_830_000,
        "families": ("fig8",),
        "held_back": "steps",
        "held_back_fits": True,
        "version": 2,
    },
}
SPLITS.update(OWN_SPLIT)

REPLAY_DIR = "replay"
CACHE_DIR = "fitcache"


#: Python that imports what a ``fit`` run loads of omavctl (the CLI, and the two
#: modules it imports when it writes its JSON and notes) and prints their files
_FIT_LOADS = (
    "import sys, omavctl.cli.app, omavctl.report.summary, omavctl.diagnose.estimate_text\n"
    "print('\\n'.join(m.__file__ for n, m in list(sys.modules.items())"
    " if n.startswith('omavctl') and getattr(m, '__file__', None)))"
)


def _fit_sources() -> set[Path]:
    """The omavctl source files a ``fit`` run loads, from ROOT (a subprocess)."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = subprocess.run(
        [sys.executable, "-c", _FIT_LOADS], env=env, capture_output=True, text=True, check=True
    )
    return {Path(line).resolve() for line in out.stdout.split()}


def _code_hash() -> str:
    """Hash of the omavctl sources a fit can run (ROOT/omavctl/**/*.py and its data, but
    the diagnosis's and the report's modules a fit run does not load): a fit cached by
    one version of that code is not another's, and a change to ``evaluate``'s
    diagnosis alone (omavctl/diagnose/timing_*.py, say) reuses the fits."""
    if not _CODE:
        h = hashlib.sha256()
        loads = _fit_sources()
        for path in sorted((ROOT / "omavctl").rglob("*")):
            rel = path.relative_to(ROOT)
            if rel.parts[1:2] in (("diagnose",), ("report",)) and path.resolve() not in loads:
                continue
            if path.suffix in (".py", ".yaml") and "__pycache__" not in path.parts:
                h.update(str(path.relative_to(ROOT)).encode() + b"\0" + path.read_bytes())
        _CODE.append(h.hexdigest()[:16])
    return _CODE[0]


_CODE: list[str] = []


def _fit_key(argv: Sequence[str]) -> str:
    """Cache key of a fit: its arguments without ``--out`` (effects sorted) and the
    code that runs it (:func:`_code_hash`)."""
    words = [_code_hash(), *argv]
    if "--out" in words:
        i = words.index("--out")
        del words[i : i + 2]
    if "--effects" in words:
        i = words.index("--effects")
        words[i + 1] = ",".join(sorted(words[i + 1].split(",")))
    return hashlib.sha256("\0".join(words).encode()).hexdigest()[:16]


def cached_fit(argv: list[str], d: Path, cwd: Path, log: list[dict[str, Any]]) -> dict[str, Any]:
    """Run ``omavctl fit ARGV`` in ``cwd`` unless the draw's cache holds it; the
    fit's ``--json`` object. The model lands at its ``--out`` either way."""
    cache = d / CACHE_DIR
    cache.mkdir(exist_ok=True)
    key = _fit_key(argv)
    out = cwd / argv[argv.index("--out") + 1]
    model, summary = cache / f"{key}.npz", cache / f"{key}.json"
    if model.exists() and summary.exists():
        shutil.copyfile(model, out)
        log.append({"command": shlex.join(["omavctl", *argv]), "seconds": 0.0, "cached": True})
        data: dict[str, Any] = json.loads(summary.read_text())
        return data
    result = omavctl(argv, cwd, log)
    shutil.copyfile(out, model)
    summary.write_text(json.dumps(result, allow_nan=False))
    return result


def _evaluate(model: str, cwd: Path, held: str, log: list[dict[str, Any]]) -> dict[str, Any]:
    ev = Path(model).stem + ".eval.json"
    args = ["evaluate", held, "--model", model, "--out", ev, "--horizons", "none"]
    return round_record(omavctl(args, cwd, log), cwd / ev)


def replay_draw(
    record: dict[str, Any], workdir: Path, label: str = "", refit_first: bool = False
) -> dict[str, Any]:
    """The draw's diagnosis steps again, in ``DRAW/replay-LABEL`` (logs and ``m0.npz``
    linked from the draw): the record with new ``rounds``, ``fits``, ``commands``.
    ``refit_first``: fit the first model again with this code (cached like the others)
    instead of linking the draw's: for a change to what a fit stores for the diagnosis
    (the effects' regressors at the training points)."""
    d = workdir / f"{record['split']}-{record['index']:04d}"
    r = d / f"{REPLAY_DIR}-{label}" if label else d / REPLAY_DIR
    if r.exists():
        shutil.rmtree(r)
    r.mkdir()
    fit_log, held = (f["log"] for f in record["flights"])
    for name in (fit_log, held) if refit_first else (fit_log, held, "m0.npz"):
        (r / name).symlink_to(d / name)
    log: list[dict[str, Any]] = []
    out = {**record, "commands": log, "error": None}
    start = time.perf_counter()
    try:
        if refit_first:
            cached_fit(["fit", fit_log, "--out", "m0.npz"], d, r, log)
        rounds = [_evaluate("m0.npz", r, held, log)]
        fits = [record["fits"][0]]
        for _ in range(ROUNDS):
            cmd = next_command(rounds[-1])
            if not cmd:
                break
            argv, model = fit_argv(cmd)
            res = cached_fit(argv, d, r, log)
            fits.append({"command": cmd, "effects": res.get("effects") or {}})
            rounds.append(_evaluate(model, r, held, log))
        out["rounds"], out["fits"] = rounds, fits
    except StepFailed as exc:
        out["error"] = str(exc)
    out["seconds"] = round(time.perf_counter() - start, 1)
    return out


def _tables(records: Sequence[dict[str, Any]]) -> list[str]:
    return [*table(records), "", *by_effect(records), ""]


def replay(
    records_path: Path,
    label: str,
    workdir: Path | None,
    only: set[int] | None,
    refit_first: bool = False,
) -> Path:
    """Replay every kept draw of ``records_path``; writes ``<stem>.<label>.jsonl``."""
    workdir = (workdir or records_path.parent).resolve()
    target = records_path.with_suffix(f".{label}.jsonl")
    records = [r for r in read_records([records_path]) if not r["error"]]
    if only is not None:
        records = [r for r in records if r["index"] in only]
    done = read_records([target]) if target.exists() else []
    keep = {(r["split"], r["index"]) for r in records}
    kept = [r for r in done if (r["split"], r["index"]) not in keep]
    target.write_text("".join(json.dumps(r, allow_nan=False) + "\n" for r in kept))
    for rec in records:
        new = replay_draw(rec, workdir, label, refit_first)
        with target.open("a") as f:
            f.write(json.dumps(new, allow_nan=False) + "\n")
        print(_line(new), file=sys.stderr, flush=True)
    print("\n".join(_tables(read_records([target]))))
    return target


def _line(r: dict[str, Any]) -> str:
    """One draw in one line: hidden (size over the floor), what each round claimed,
    the fall, and the judgements."""
    if r["error"]:
        return f"{r['split']} {r['index']}: error {r['error']}"
    j = sc.judge(r)
    hidden = ", ".join(
        f"{n} ({v / r['rounds'][0]['claim_floor']:.1f}x)"
        for n, v in sorted((r.get("sizes") or {}).items())
    )
    said = " | ".join(
        "+".join(
            [
                n + ("~" + "~".join(c["ambiguous_with"]) if c.get("ambiguous_with") else "")
                for n in rd["missing"]
                for c in rd["candidates"]
                if c["name"] == n
            ]
            + [f"L:{n}" for n in rd.get("learned_claims") or []]  # learned by the GP, claimed
        )
        or "-"
        for rd in r["rounds"]
    )
    fams = "→".join(f["family"] for f in r["flights"])
    fall = 100 * sc.physics_fall(r)
    marks = (
        f"right={int(j['first_right'])} strict={int(j['first_right_strict'])} "
        f"fall={fall:.0f}% invented={int(j['invented'])} worse={int(j['worse'])}"
    )
    return f"{r['split']} {r['index']} [{hidden or 'none'}; {fams}; {r['timing']}]: {said}; {marks}"


def compare(paths: Sequence[Path]) -> None:
    """Per draw, one line per file; then each file's table."""
    sets = [{(r["split"], r["index"]): r for r in read_records([p])} for p in paths]
    for key in sorted(set().union(*sets)):
        for p, s in zip(paths, sets, strict=True):
            if key in s:
                print(f"{p.name:>28}  {_line(s[key])}")
        print()
    for p, s in zip(paths, sets, strict=True):
        print(f"### {p.name}\n")
        print("\n".join(_tables(list(s.values()))))
        print("\n".join(failures(list(s.values()))))


def draw_large(draws: int, start: int, factor: float, workdir: Path) -> None:
    """Own draws with hidden effects only, each ``factor`` x its drawn size (most
    scorecard draws sit under the claim floor on the held-out flight): records in
    ``WORKDIR/own-large.jsonl``, directories ``own-large-NNNN``."""
    import numpy as np

    from benchmarks.scorecard_draws import draw_spec, hidden_parameters, run_draw
    from omavctl.physics.effects import EFFECTS

    out = workdir / "own-large.jsonl"
    done = {r["index"] for r in read_records([out])} if out.exists() else set()
    for i in range(start, start + draws):
        spec = draw_spec("own", i, sorted(EFFECTS))
        if not spec["hidden"] or i in done:
            continue
        rng = np.random.default_rng([2_000_000 + i, 0x1A7])
        spec["split"] = "own-large"
        spec["scales"] = {n: factor * v for n, v in spec["scales"].items()}
        spec["hidden"] = {n: hidden_parameters(n, v, rng) for n, v in spec["scales"].items()}
        spec["truth"]["effects"] = spec["hidden"]
        rec = run_draw(spec, workdir)
        with out.open("a") as f:
            f.write(json.dumps(rec, allow_nan=False) + "\n")
        print(_line(rec), file=sys.stderr, flush=True)


def main(argv: Sequence[str] | None = None) -> None:
    ap = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    sub = ap.add_subparsers(dest="mode", required=True)
    dr = sub.add_parser("draw", help="run draws once, keeping their directories")
    dr.add_argument("--split", choices=["tune", *OWN_SPLIT], default="tune")
    dr.add_argument("--draws", type=int, default=16)
    dr.add_argument("--start", type=int, default=0)
    dr.add_argument("--jobs", type=int, default=1)
    dr.add_argument("--workdir", type=Path, default=Path("build/scorecard-replay"))
    lg = sub.add_parser("large", help="own draws, hidden effects only, sizes x FACTOR")
    lg.add_argument("--draws", type=int, default=6)
    lg.add_argument("--start", type=int, default=0)
    lg.add_argument("--factor", type=float, default=3.0)
    lg.add_argument("--workdir", type=Path, default=Path("build/scorecard-replay"))
    rp = sub.add_parser("replay", help="replay the diagnosis steps of kept draws")
    rp.add_argument("records", type=Path)
    rp.add_argument("--label", default="replay")
    rp.add_argument("--workdir", type=Path, default=None, help="default: the records' folder")
    rp.add_argument("--only", type=int, nargs="*", default=None, help="draw indices")
    rp.add_argument(
        "--refit-first",
        action="store_true",
        help="fit the first model again with this code (a change to what fits store)",
    )
    cp = sub.add_parser("compare", help="per-draw lines and tables of several record files")
    cp.add_argument("records", type=Path, nargs="+")
    args = ap.parse_args(argv)
    if args.mode == "draw":
        from benchmarks.scorecard import run

        wd = args.workdir.resolve()
        run(args.split, args.draws, args.start, args.jobs, wd, wd / f"{args.split}.jsonl")
    elif args.mode == "large":
        draw_large(args.draws, args.start, args.factor, args.workdir.resolve())
    elif args.mode == "replay":
        only = set(args.only) if args.only is not None else None
        replay(args.records, args.label, args.workdir, only, args.refit_first)
    else:
        compare(args.records)


if __name__ == "__main__":
    main()
