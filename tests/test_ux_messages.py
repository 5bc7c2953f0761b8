"""What a new user reads must be something they can act on: every ``--option`` a
message of ``plan`` suggests is an option of the command that takes it."""

from __future__ import annotations

import ast
import re
from pathlib import Path
from types import SimpleNamespace

import pytest
import typer.main
from typer.testing import CliRunner

from omavctl.cli import app
from omavctl.sim.tasks import fig8, yaw

ROOT = Path(__file__).resolve().parent.parent
OPTION = re.compile(r"(?<![\w-])--[a-z][a-z0-9-]*")
#: Options of another command that a plan message names on purpose (the model's fit).
OTHER_COMMANDS = {"--features": "fit"}


def _options(command: str) -> set[str]:
    group = typer.main.get_command(app)
    cmd = group.commands[command]  # type: ignore[attr-defined]
    return {o for p in cmd.params for o in (*p.opts, *p.secondary_opts) if o.startswith("--")}


def _string_literals(path: Path) -> list[str]:
    """Every string constant of a module (f-strings' constant parts included), but the
    docstrings."""
    tree = ast.parse(path.read_text())
    docs = {
        id(node.body[0].value)
        for node in ast.walk(tree)
        if isinstance(node, ast.Module | ast.FunctionDef | ast.ClassDef | ast.AsyncFunctionDef)
        and node.body
        and isinstance(node.body[0], ast.Expr)
        and isinstance(node.body[0].value, ast.Constant)
    }
    return [
        n.value
        for n in ast.walk(tree)
        if isinstance(n, ast.Constant) and isinstance(n.value, str) and id(n) not in docs
    ]


def _plan_sources() -> list[Path]:
    return [
        *sorted((ROOT / "omavctl" / "planning").glob("*.py")),
        ROOT / "omavctl" / "cli" / "plan.py",
        ROOT / "omavctl" / "report" / "plan.py",
    ]


@pytest.mark.parametrize("path", _plan_sources(), ids=lambda p: p.name)
def test_every_option_a_plan_message_names_exists(path):
    plan_options = _options("plan")
    named = {o for text in _string_literals(path) for o in OPTION.findall(text)}
    for option in sorted(named):
        command = OTHER_COMMANDS.get(option, "plan")
        assert option in _options(command), f"{path.name} suggests {option}: not an option"
    assert plan_options  # the scan compares against something


def test_the_envelope_warnings_suggest_real_options_that_work(tmp_path):
    """A plan that tilts, turns yaw and rotates far beyond the task warns of all
    three; each option the warnings suggest is a plan option, and the tilt limit the
    tilt warning suggests is accepted by plan and refused outside its range."""
    from omavctl.planning.envelope import envelope_warnings

    task = fig8(roll_deg=26, pitch_deg=26, duration=8.0, ramp=1.0)
    wild = yaw(300, 0.5, duration=8.0)  # yaw through 600 deg at several rad/s
    steep = fig8(roll_deg=70, pitch_deg=20, duration=8.0, ramp=1.0)
    warnings = [
        *envelope_warnings(SimpleNamespace(best=0, task=task, best_trajectory=lambda: wild)),
        *envelope_warnings(SimpleNamespace(best=0, task=task, best_trajectory=lambda: steep)),
    ]
    assert len(warnings) == 3, warnings
    suggested = {o for w in warnings for o in OPTION.findall(w)}
    assert suggested == {"--amplitude", "--max-freq", "--max-tilt"}
    assert suggested <= _options("plan")
    tilt = next(w for w in warnings if "tilts to" in w)
    assert "--max-tilt 52 " in tilt
    result = CliRunner().invoke(
        app,
        ["plan", "--task", "t.csv", "--model", "m.npz", "--out", "o.csv", "--max-tilt", "95"],
    )
    assert result.exit_code == 2
    assert "--max-tilt must be in (0, 90] deg, got 95" in result.output


def _all_options() -> set[str]:
    out: set[str] = set()

    def walk(cmd) -> None:
        for p in getattr(cmd, "params", []):
            out.update(o for o in (*p.opts, *p.secondary_opts) if o.startswith("--"))
        for sub in getattr(cmd, "commands", {}).values():
            walk(sub)

    walk(typer.main.get_command(app))
    return out


def test_every_option_any_message_names_is_an_option_of_some_command():
    """Outside plan too: no message of omavctl suggests an option no command has."""
    known = _all_options()
    assert {"--effects", "--max-tilt", "--time-window", "--json"} <= known
    unknown = sorted(
        f"{path.relative_to(ROOT)}: {option}"
        for path in sorted((ROOT / "omavctl").rglob("*.py"))
        for text in _string_literals(path)
        for option in OPTION.findall(text)
        if option not in known
    )
    assert unknown == []
