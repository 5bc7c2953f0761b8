"""Terminal summaries and ``--json`` objects of ``evaluate`` (verdict first), ``fit``
and ``inspect``.

Several models are shown side by side: one column group per model, RMSE of
the nominal model, nominal + effects and each model per axis, the fraction of
samples within 2 sigma, then the verdict (and the before/after lines when
there are several models).
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from omavctl.diagnose.change import verdict_of_models
from omavctl.diagnose.verdict import AXES, coverage_of
from omavctl.report.horizons import horizons_json, render_horizons

__all__ = ["evaluation_json", "fit_json", "inspect_json", "nominal_note", "render_evaluation"]


def _g(v: Any, digits: int = 4) -> str:
    ok = isinstance(v, int | float) and not isinstance(v, bool)
    return f"{v:.{digits}g}" if ok else "n/a"


def _by_model(tree: Mapping[str, Any]) -> list[Mapping[str, Any]]:
    by_model = tree.get("metrics_by_model")
    if isinstance(by_model, list) and by_model:
        return by_model
    return [tree.get("metrics") or {}]


def render_evaluation(con: Any, tree: Mapping[str, Any], files: Mapping[str, Path]) -> None:
    """Print the evaluation: verdict, models side by side, tracking, files written."""
    from rich.table import Table
    from rich.text import Text

    models = tree.get("models") or []
    by_model = _by_model(tree)
    lines = verdict_of_models(tree)
    con.print(Text("verdict", style="bold"))
    for line in lines:
        con.print(Text(f"  {line.text}"))
        if line.command:
            con.print(Text(f"    {line.add_words.lower()}: {line.command}"))
    table = Table(title="RMSE of the angular acceleration, rad/s^2", title_justify="left")
    table.add_column("prediction")
    for axis in AXES:
        table.add_column(axis, justify="right")
    table.add_column("within 2σ x/y/z", justify="right")
    table.add_column("NLPD x/y/z, nats", justify="right")
    table.add_column("effects")
    zero = by_model[0].get("zero") or {}
    if zero:  # evaluations written before it lack the row
        table.add_row("zero (no acceleration)", *(_g(zero.get("rmse", {}).get(a)) for a in AXES))
    nominal = by_model[0].get("nominal") or {}
    table.add_row("nominal", *(_g(nominal.get("rmse", {}).get(a)) for a in AXES), "", "", "")
    for j, metrics in enumerate(by_model):
        name = str(models[j].get("name", f"model {j + 1}")) if j < len(models) else f"model {j}"
        effects = ", ".join((models[j].get("effects") or {}) if j < len(models) else {})
        eff = metrics.get("effects") or {}
        table.add_row(
            Text(f"{name}: nominal + effects"),
            *(_g(eff.get("rmse", {}).get(a)) for a in AXES),
            "",
            "",
            Text(effects or "none"),
        )
        model = metrics.get("model") or {}
        cov = coverage_of(model)
        table.add_row(
            Text(f"{name}: model"),
            *(_g(model.get("rmse", {}).get(a)) for a in AXES),
            "/".join(f"{100 * cov[a]:.0f}%" if a in cov else "n/a" for a in AXES),
            "/".join(_g((model.get("nlpd") or {}).get(a), 2) for a in AXES),
            Text(effects or "none"),
        )
    con.print(table)
    if note := nominal_note(zero.get("rmse") or {}, nominal.get("rmse") or {}):
        con.print(Text(f"  {note}"))
    tracking = tree.get("tracking")
    if isinstance(tracking, Mapping):
        con.print(
            "tracking, mean |a* - w_dot| of the flight (its own controller, whatever model), "
            "rad/s^2: " + ", ".join(f"{a} {_g(tracking[a], 3)}" for a in AXES)
        )
    render_horizons(con, tree)
    for what, path in files.items():
        con.print(Text(f"wrote {path} ({what})"))


def nominal_note(zero: Mapping[str, Any], nominal: Mapping[str, Any]) -> str | None:
    """'nominal is worse than predicting no acceleration on x (0.919 against 0.362 ...)'
    when the nominal physics' RMSE is over 1.1x the zero predictor's on an axis (two new
    users read 'nominal 0.92' under 'zero 0.36' without a word); None otherwise."""
    worse = [
        (a, n, z)
        for a in AXES
        if isinstance(n := nominal.get(a), int | float)
        and isinstance(z := zero.get(a), int | float) and z > 0 and n > 1.1 * z
    ]  # fmt: skip
    if not worse:
        return None
    said = ", ".join(f"{a} ({_g(n)} against {_g(z)} rad/s^2)" for a, n, z in worse)
    return (
        f"nominal is worse than predicting no acceleration on {said}: the physics without "
        "the model's effects is far off there, and the effects and the GP carry the model "
        "(an effect kept out of the nominal physics does this, as the omav's "
        "rotor_interference; so does a command gain, sign or frame that is off)"
    )


def evaluation_json(tree: Mapping[str, Any], files: Mapping[str, Path]) -> dict[str, Any]:
    """The ``--json`` object of ``evaluate``: files written and the key figures."""
    models = tree.get("models") or []
    out_models = []
    for j, metrics in enumerate(_by_model(tree)):
        m = models[j] if j < len(models) else {}
        model = metrics.get("model") or {}
        out_models.append(
            {
                "path": m.get("path"),
                "effects": list((m.get("effects") or {}).keys()),
                "rmse": model.get("rmse"),
                "rmse_effects": (metrics.get("effects") or {}).get("rmse"),
                "coverage_2sigma": coverage_of(model),
            }
        )
    diag = tree.get("diagnosis") or {}
    lines = verdict_of_models(tree)
    return {
        "command": "evaluate",
        "files": {k: str(v) for k, v in files.items()},
        "rmse_nominal": (tree.get("metrics") or {}).get("nominal", {}).get("rmse"),
        "models": out_models,
        "tracking": tree.get("tracking"),
        "missing": list(diag.get("missing") or []),
        # effects the GP learned that the held-out flight confirms, claimed (with the fit
        # command) when nothing is missing
        "learned_claims": list(diag.get("learned_claims") or []),
        "fit_command": diag.get("fit_command"),
        # the fit command of every effect the diagnosis names (missing, held back, learned)
        "effect_commands": dict(diag.get("effect_commands") or {}),
        "flags": list(tree.get("flags") or []),
        "horizons": horizons_json(tree),
        "verdict": [
            {"key": line.key, "text": line.text, "command": line.command, "test": line.test}
            for line in lines
        ],
    }


def fit_json(summary: Any, out: Path) -> dict[str, Any]:
    """The --json object of fit: the model written, data used, effects, GP per axis."""
    return {
        "command": "fit",
        "files": {"model": str(out)},
        "samples": summary.samples,
        "points": summary.points,
        "points_new": summary.points_new,
        "points_prior": summary.points_prior,
        "features": summary.features,
        "logs": [
            {"path": str(lg.path), "samples": lg.samples, "used": lg.used} for lg in summary.logs
        ],
        "effects": {
            name: {
                "values": {k: v for k, v in est.values.items()},
                "stderr": {k: v for k, v in est.stderr.items()},
                "ci95": est.interval95(),
                "pinned": est.pinned(),
                "stderr_method": est.stderr_method,
                **(
                    {
                        "systematic": dict(est.systematic),
                        "ci95_statistical": est.interval95(systematic=False),
                    }
                    if est.systematic is not None
                    else {}
                ),
            }
            for name, est in summary.effects.items()
        },
        "axes": {
            axis: {
                "signal_std": a.signal_std,
                "noise_std": a.noise_std,
                "training_r2": a.r2,
                "training_rmse": a.rmse,
                "rms_without_model": a.rmse_nominal,
                # blocked cross-validation (docs/fit.md): whether the GP stays on, its
                # held-out errors and coverage, the factors its band was given
                "gp_on": a.gp_on,
                "held_out_rmse_gp": a.cv_rmse_gp,
                "held_out_rmse_physics": a.cv_rmse_physics,
                # before the std was widened by std_factor (after it: 95 % by design)
                "held_out_coverage_2sigma_before_widening": a.cv_coverage,
                "std_factor": a.std_factor,
                "beyond_scale": a.beyond_scale,
                # the band inside the fit inputs: band_scale (1 + band_slope rho)
                "band_scale": a.band_scale,
                "band_slope": a.band_slope,
            }
            for axis, a in zip("xyz", summary.axes, strict=True)
        },
        "notes": list(summary.notes),
    }


def inspect_json(ins: Any) -> dict[str, Any]:
    """The --json object of inspect."""
    return {
        "command": "inspect",
        "path": str(ins.path),
        "format": ins.format,
        "duration": ins.duration,
        "t0": ins.t0,
        "topics": [
            {
                "name": t.name,
                "type": t.msgtype,
                "count": t.count,
                "rate_hz": t.rate,
                "gaps": len(t.gaps),
                "duplicates": t.duplicates,
                "out_of_order": t.out_of_order,
            }
            for t in ins.topics
        ],
        "roles_found": ins.roles_found,
        "roles_missing": ins.roles_missing,
        "required_missing": ins.required_missing,
        "column_ranges": {k: list(v) for k, v in ins.column_ranges.items()},
        "suggested_columns": ins.suggested_columns,
        # the whole suggested vehicle snippet (preset, frame, command units with the
        # columns): a script that built its YAML from the columns alone fitted a PX4 log
        # in the wrong frame and units, silently (a new user)
        "suggestion_yaml": ins.suggestion,
        "column_units": dict(ins.column_units),
        "column_rates": dict(ins.column_rates),
        "header_values": dict(ins.header_values),
        "notes": list(ins.notes),
    }
