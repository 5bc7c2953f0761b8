"""Fuzz suite (issue #18): seeded mutants of every input kind through every subcommand.

Each case mutates one input (a log in each format, vehicle/truth YAML, task CSV,
model, evaluation JSON or series), an option value or an output path, runs the
command in a forked process (real exit status and stderr) and asserts: a
non-zero exit is status 2 with exactly one ``error:`` line naming the file (or
option) and no exception text; exit 0 leaves finite, schema-valid outputs (and
never happens for an input invalid by construction); inputs are unchanged and
no temporary file is left. ``make test`` runs 80 cases; ``make fuzz`` thousands
(tools/fuzz_campaign.py); OMAVCTL_FUZZ_CASES / OMAVCTL_FUZZ_SEED override here.
"""

from __future__ import annotations

import collections
import os

import pytest

try:  # tests/ as a package or as a rootdir on sys.path
    from .fuzzkit.cases import build_base, iter_cases
    from .fuzzkit.run import FAILURES, Outcome, run_all
except ImportError:
    from fuzzkit.cases import build_base, iter_cases
    from fuzzkit.run import FAILURES, Outcome, run_all

CASES = int(os.environ.get("OMAVCTL_FUZZ_CASES", "80"))
SEED = int(os.environ.get("OMAVCTL_FUZZ_SEED", "2026"))


@pytest.fixture(scope="module")
def outcomes(tmp_path_factory: pytest.TempPathFactory) -> list[Outcome]:
    root = tmp_path_factory.mktemp("fuzz")
    base = build_base(root / "base")
    import omavctl.diagnose.evaluate
    import omavctl.planning
    import omavctl.report.evaluation  # noqa: F401

    return run_all(iter_cases(SEED, CASES, base, root / "cases"), "fork", 60.0)


def test_every_case_is_a_clean_refusal_or_a_valid_output(outcomes: list[Outcome]) -> None:
    failed = [o for o in outcomes if o.verdict in FAILURES]
    report = "\n".join(
        f"{o.verdict} {o.case.name} [{o.case.mutation}] {' '.join(o.case.argv)}: {o.detail[:300]}"
        for o in failed
    )
    assert not failed, f"{len(failed)} of {len(outcomes)} cases failed:\n{report}"


def test_the_corpus_covers_every_command_and_input(outcomes: list[Outcome]) -> None:
    commands = collections.Counter(o.case.argv[0] for o in outcomes)
    kinds = collections.Counter(o.case.name.split("-")[1] for o in outcomes)
    assert set(commands) >= {"inspect", "fit", "evaluate", "simulate", "plan", "report", "task"}
    assert set(kinds) >= {"log", "vehicle", "truth", "task", "model", "eval", "series", "output"}
    verdicts = collections.Counter(o.verdict for o in outcomes)
    assert verdicts["refused"] > CASES // 2 and verdicts["ok"] > 0, verdicts
