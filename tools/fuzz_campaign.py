"""Fuzz campaign over every reader and subcommand (see tests/fuzzkit).

    python tools/fuzz_campaign.py --seed 1 --cases 500 [--strategy stacked]
        [--runner subprocess] [--jobs 2]

Builds the valid base inputs, makes ``--cases`` seeded mutants, runs each
subcommand on them and prints the tally per verdict and every failure.
Exit status 1 when any case failed (a hang, exception text, a second line,
an unnamed file, exit 0 with a wrong output, a changed input, a temp file left).
"""

from __future__ import annotations

import argparse
import collections
import os
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MPLBACKEND", "Agg")
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

from fuzzkit.cases import build_base, make_cases
from fuzzkit.run import FAILURES, run_case


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--cases", type=int, default=500)
    ap.add_argument("--runner", choices=["fork", "subprocess"], default="fork")
    ap.add_argument(
        "--strategy",
        choices=["single", "stacked"],
        default="single",
        help="single: one mutation per input (the corpus of make test); stacked: two",
    )
    ap.add_argument("--jobs", type=int, default=1, help="cases run at once")
    ap.add_argument("--timeout", type=float, default=120.0, help="s per case before a hang")
    ap.add_argument("--dir", type=Path, default=None, help="keep the cases here")
    args = ap.parse_args()
    root = args.dir or Path(tempfile.mkdtemp(prefix="omavctl-fuzz-"))
    base = build_base(root / "base")
    cases = make_cases(args.seed, args.cases, base, root / f"seed{args.seed}", args.strategy)
    import omavctl.cli
    import omavctl.evaluate
    import omavctl.planning
    import omavctl.report  # noqa: F401

    start = time.monotonic()

    def one(case):
        return run_case(case, root / f"seed{args.seed}" / f"case{case.name[:5]}", args.runner,
                        args.timeout)  # fmt: skip

    with ThreadPoolExecutor(max_workers=args.jobs) as pool:
        outcomes = list(pool.map(one, cases))
    tally = collections.Counter(o.verdict for o in outcomes)
    failed = [o for o in outcomes if o.verdict in FAILURES]
    for o in failed:
        print(f"FAIL {o.verdict:15s} {o.case.name} [{o.case.mutation}] "
              f"{' '.join(o.case.argv)}\n    {o.detail[:400]}")  # fmt: skip
    print(f"{len(outcomes)} cases in {time.monotonic() - start:.0f} s (seed {args.seed}, "
          f"strategy {args.strategy}, runner {args.runner}) in {root}")  # fmt: skip
    print("verdicts: " + ", ".join(f"{k} {v}" for k, v in sorted(tally.items())))
    exc = sum(1 for o in outcomes if o.verdict == "exception-text")
    wrong = sum(1 for o in outcomes if o.verdict == "exit0-wrong")
    print(f"exception texts {exc}, hangs {tally['hang']}, exit-0-with-wrong-output {wrong}, "
          f"failures in all {len(failed)}")  # fmt: skip
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
