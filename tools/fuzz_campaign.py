"""Fuzz campaign over every reader and subcommand (see tests/fuzzkit).

    python tools/fuzz_campaign.py --seed 1 --cases 500 [--strategy stacked]
        [--runner subprocess] [--keep] [--dir DIR]

Builds the valid base inputs, makes ``--cases`` seeded mutants one after the
other, runs the subcommand that reads each and prints the tally per verdict and
every failure (whose case folder is kept). Exit status 1 when any case failed: a
hang, exception text, more than one line, an unnamed file, an exit status other
than 0 or 2, exit 0 with a wrong output, a changed input, a temp file left.
"""

from __future__ import annotations

import argparse
import collections
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("MPLBACKEND", "Agg")
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

from fuzzkit.cases import build_base, iter_cases
from fuzzkit.run import FAILURES, run_all


def main() -> int:
    ap = argparse.ArgumentParser(description=(__doc__ or "").splitlines()[0])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--cases", type=int, default=500)
    ap.add_argument(
        "--strategy",
        choices=["single", "stacked"],
        default="single",
        help="single: one mutation per input (the corpus of make test); stacked: two",
    )
    ap.add_argument("--runner", choices=["fork", "subprocess"], default="fork")
    ap.add_argument("--timeout", type=float, default=120.0, help="s per case before a hang")
    ap.add_argument("--dir", type=Path, default=None, help="work here (default: a temp dir)")
    ap.add_argument("--keep", action="store_true", help="keep the folders of passing cases")
    args = ap.parse_args()
    root = args.dir or Path(tempfile.mkdtemp(prefix="omavctl-fuzz-"))
    base = build_base(root / "base")
    import omavctl.cli
    import omavctl.diagnose.evaluate
    import omavctl.planning
    import omavctl.report.evaluation  # noqa: F401  (forked children start with everything imported)

    start = time.monotonic()
    cases = iter_cases(args.seed, args.cases, base, root / f"seed{args.seed}", args.strategy)
    outcomes = run_all(cases, args.runner, args.timeout, args.keep)
    tally = collections.Counter(o.verdict for o in outcomes)
    failed = [o for o in outcomes if o.verdict in FAILURES]
    for o in failed:
        print(f"FAIL {o.verdict:15s} {o.case.name} [{o.case.mutation}] {' '.join(o.case.argv)}")
        print(f"    {o.detail[:400]}")
    commands = collections.Counter(o.case.argv[0] for o in outcomes)
    print(
        f"{len(outcomes)} cases in {time.monotonic() - start:.0f} s (seed {args.seed}, "
        f"strategy {args.strategy}, runner {args.runner}) in {root}"
    )
    print("commands: " + ", ".join(f"{k} {v}" for k, v in sorted(commands.items())))
    print("verdicts: " + ", ".join(f"{k} {v}" for k, v in sorted(tally.items())))
    slowest = max(outcomes, key=lambda o: o.seconds)
    print(f"slowest case {slowest.seconds:.1f} s ({slowest.case.name})")
    print(
        f"exception texts {tally['exception-text']}, hangs {tally['hang']}, "
        f"exit-0-with-wrong-output {tally['exit0-wrong']}, failures in all {len(failed)}"
    )
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
