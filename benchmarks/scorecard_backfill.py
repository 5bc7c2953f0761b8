"""Add each round's ``claim_estimates`` to scorecard records flown before they were kept.

    python benchmarks/scorecard_backfill.py RECORDS.jsonl ROOT OUT.jsonl

Since session 34 ``scorecard_draws.round_record`` keeps the claims' estimates as the
printed fit command makes them on the held-out flight (the evaluation's
``diagnosis.claim_estimates``, and the learned claims' estimates), which
``scorecard_score.lookalike`` judges a none draw's look-alike by when the verdict does
not quote it (a claim named after "Also:", or claimed as learned). Older
records lack them; their draws' evaluation files (``ROOT/<split>-<index>/``: round 0's
``m0.eval.json``, round k's the ``.eval.json`` of the model the k-th fit wrote) hold
them. Records whose files are gone are copied unchanged.
"""

from __future__ import annotations

import json
import shlex
import sys
from pathlib import Path
from typing import Any

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parent))

from scorecard_draws import claim_estimates


def _eval_files(record: dict[str, Any], folder: Path) -> list[Path]:
    """The evaluation file of each round: the model each round evaluated."""
    models = ["m0.npz"]
    for fit in record.get("fits", [])[1:]:
        words = shlex.split(str(fit.get("command", "")))
        if "--out" in words:
            models.append(words[words.index("--out") + 1])
    return [folder / (Path(m).stem + ".eval.json") for m in models]


def backfill(record: dict[str, Any], root: Path) -> dict[str, Any]:
    """``record`` with ``claim_estimates`` in every round whose evaluation file is there."""
    folder = root / f"{record['split']}-{record['index']:04d}"
    for rnd, path in zip(record.get("rounds", []), _eval_files(record, folder), strict=False):
        if "claim_estimates" not in rnd and path.is_file():
            diag = json.loads(path.read_text()).get("diagnosis") or {}
            rnd["claim_estimates"] = claim_estimates(diag)
    return record


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if len(args) != 3:
        print(__doc__.strip().splitlines()[2].strip(), file=sys.stderr)
        return 2
    records, root, out = Path(args[0]), Path(args[1]), Path(args[2])
    rows = [backfill(json.loads(ln), root) for ln in records.read_text().splitlines() if ln]
    out.write_text("".join(json.dumps(r) + "\n" for r in rows))
    done = sum(all("claim_estimates" in r for r in row.get("rounds", [])) for row in rows)
    print(f"{done} of {len(rows)} records have every round's claim_estimates; wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
