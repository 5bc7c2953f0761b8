"""Write the demo's numbers into docs/getting-started.md from the demo's own outputs.

The page quotes the demo (`make demo`, outputs in examples/build/): the first
verdict and the fit command it prints, how much the error falls with the named
effect added and why an axis got worse, how much better the planned flight is
than the task. Those spans sit between ``<!-- demo:KEY -->`` and ``<!-- /demo -->``
markers; this tool computes every KEY from the demo's files (eval.json,
eval-drag.json, plan.json), writes them to docs/demo-numbers.json and puts them in
the page. tests/test_docs.py checks that the page holds exactly those values,
without running the demo; run this after anything that changes the demo's output:

    make demo && python tools/demo_numbers.py          # or --check: exit 1 if stale
"""

from __future__ import annotations

import argparse
import json
import re
import shlex
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
BUILD = ROOT / "examples" / "build"
DOC = ROOT / "docs" / "getting-started.md"
NUMBERS = ROOT / "docs" / "demo-numbers.json"
MARKER = re.compile(r"<!-- demo:([a-z_]+) -->(.*?)<!-- /demo -->", re.DOTALL)
AXES = ("x", "y", "z")


def _as_typed_in_the_doc(command: str) -> str:
    """A demo command (run in examples/, outputs in build/) as the page types it: from
    the repository's top, the demo's logs in examples/build/, new outputs and the models
    the page fits in build/first/ (and the separating plan's task, which the verdict
    writes beside the model); commands joined by ``&&`` each so."""
    if " && " in command:
        return " && ".join(_as_typed_in_the_doc(c) for c in command.split(" && "))
    words = shlex.split(command)
    out = []
    for prev, word in zip(["", *words], words, strict=False):
        if word.startswith("build/"):
            rest = word.removeprefix("build/")
            mine = prev in ("--out", "--model", "--task")
            word = f"build/first/{rest}" if mine else f"examples/build/{rest}"
        out.append(word)
    return shlex.join(out)


def _pct(v: float, digits: int = 0) -> str:
    return f"{100 * v:+.{digits}f} %".replace("-", "−")


def numbers(build: Path) -> dict[str, str]:
    """Every quoted value, from the demo's files in ``build``."""
    sys.path.insert(0, str(ROOT))
    from omavctl.diagnose.change import change_lines, scores_of_files
    from omavctl.diagnose.verdict import verdict

    first = json.loads((build / "eval.json").read_text())
    after = json.loads((build / "eval-drag.json").read_text())
    plan = json.loads((build / "plan.json").read_text())
    head = verdict(first)[0]
    command = _as_typed_in_the_doc(str(head.command))
    text = head.text  # the plan command in it as typed in the page too
    if sep := first["diagnosis"].get("separate_command"):
        text = text.replace(sep, _as_typed_in_the_doc(sep))
    top = first["diagnosis"]["missing_effects"][0]
    r0, r1 = first["metrics"]["model"]["rmse"], after["metrics"]["model"]["rmse"]
    change = {a: r1[a] / r0[a] - 1.0 for a in AXES}
    fall = 1.0 - sum(r1.values()) / sum(r0.values())
    scores = scores_of_files([(first, "eval.json"), (after, "eval-drag.json")])
    worse = [ln.text for ln in change_lines(scores)[1:]]
    best = plan["best_cost"] / plan["task_cost"] - 1.0
    return {
        "verdict": f"\n```text\n{text}\n  {head.add_words.lower()}: {command}\n```\n",
        "loop": (
            f"\n```sh\n{command}\n"
            "omavctl evaluate examples/build/flight-02.bag --model "
            f"{shlex.split(command)[shlex.split(command).index('--out') + 1]} "
            "--out build/first/eval-drag.json\n"
            "omavctl report build/first/eval.json build/first/eval-drag.json "
            "--out build/first/report.html\n```\n"
        ),
        "plan": (
            "\n```sh\nomavctl plan --task examples/build/fig8.csv --model "
            f"{shlex.split(command)[shlex.split(command).index('--out') + 1]} \\\n"
            "    --candidates 20 --sims 4 --scores build/first/scores.csv "
            "--out build/first/next.csv\n```\n"
        ),
        "top_explained": f"{100 * top['explained_variance']:.0f} %",
        "change_rounded": ", ".join(f"{a} {_pct(change[a])}" for a in AXES),
        "change": ", ".join(f"{a} {_pct(change[a], 1)}" for a in AXES),
        "fall": f"{100 * fall:.0f} %",
        "worse": " ".join(worse) if worse else "no axis got worse on the demo.",
        "plan_cem": f"{abs(100 * best):.1f} % {'better' if best < 0 else 'worse'}",
    }


def render(doc: str, values: Mapping[str, Any]) -> str:
    """``doc`` with every marked span replaced by its value (KeyError for an unknown KEY)."""
    return MARKER.sub(lambda m: f"<!-- demo:{m[1]} -->{values[m[1]]}<!-- /demo -->", doc)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--build", type=Path, default=BUILD, help="the demo's outputs")
    ap.add_argument("--check", action="store_true", help="exit 1 if the page is stale")
    args = ap.parse_args(argv)
    values = numbers(args.build)
    doc = DOC.read_text()
    text = render(doc, values)
    if args.check:
        if text != doc:
            print(f"{DOC} is stale: run python tools/demo_numbers.py", file=sys.stderr)
            return 1
        return 0
    NUMBERS.write_text(json.dumps(values, indent=1, sort_keys=True) + "\n")
    DOC.write_text(text)
    print(f"wrote {DOC} and {NUMBERS}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
