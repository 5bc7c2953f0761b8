"""What a new user reads in the verdict refers only to what they can see, and every
effect it names comes with the command that adds or tests it."""

from __future__ import annotations

import copy
from typing import Any

from omavctl.diagnose.verdict import verdict
from omavctl.report.summary import render_evaluation


def _nothing_missing() -> dict[str, Any]:
    """An evaluation tree where no registered effect is missing."""
    return {
        "models": [{"name": "m.npz", "effects": {}}],
        "metrics": {"model": {"rmse": {"x": 0.1, "y": 0.2, "z": 0.1}}},
        "diagnosis": {
            "method": {"min_explained_variance": 0.15, "measurement_noise_std": 0.03},
            "missing": [],
            "missing_effects": [],
            "fit_command": None,
            "unexplained": [
                {"kind": "feature correlation", "axis": "y", "feature": "wz", "correlation": -0.47},
                {
                    "kind": "spectral peak",
                    "axis": "x",
                    "frequency_hz": 1.25,
                    "power_ratio": 30.0,
                    "power_share": 0.22,
                },
                {
                    "kind": "feature correlation",
                    "axis": "z",
                    "feature": "roll",
                    "correlation": 0.31,
                },
            ],
        },
    }


def _terminal(tree: dict[str, Any]) -> str:
    import io

    from rich.console import Console

    con = Console(width=400, record=True, file=io.StringIO())
    render_evaluation(con, tree, {})
    return con.export_text()


def test_the_terminal_verdict_shows_the_structure_it_refers_to():
    """The verdict said "(see Diagnosis)" in a terminal that has no Diagnosis: it says
    what the structure is instead."""
    tree = _nothing_missing()
    text = verdict(tree)[0].text
    assert "see Diagnosis" not in text
    assert text.endswith(
        "Some structure remains that no registered effect explains: the y error "
        "correlates with wz (r = -0.47); the x error has a spectral peak at 1.2 Hz, 22 % "
        "of its power; 1 more in the evaluation JSON (diagnosis.unexplained)."
    )
    shown = _terminal(tree)
    assert "correlates with wz (r = -0.47)" in shown and "Diagnosis" not in shown
    clean = copy.deepcopy(tree)
    clean["diagnosis"]["unexplained"] = []
    assert "structure" not in verdict(clean)[0].text
