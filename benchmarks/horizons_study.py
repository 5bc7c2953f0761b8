"""Open-loop prediction over horizons on simulated hidden-effect draws and the real log.

Per draw, as a user would (the examples' workflow): a figure-8 flight through a
truth plant with the default actuator imperfections and one hidden effect
(``examples/truth-drag.yaml``'s, or another), ``fit --effects
rotor_interference``, a held-out flight of another figure-8, ``evaluate`` (which
names the missing effect), ``fit`` again with the named effect, then one
``evaluate`` of both models on the held-out flight. Printed (and with
``--markdown FILE`` written as Markdown): the horizon table of the four
predictors, whether the full model's 0.5 s body-rate error stays within 1.05x
physics + effects on every axis, the band's coverage at every horizon, whether
adding the named effect lowers the 0.5 s error where it lowers the one-step
error, and the draws where the GP helps at one step and hurts at 0.5 s. Then
the shared real log (px4tools octocopter: fit on 6.5-15 s, evaluate on 15 s-).

    python benchmarks/horizons_study.py [--draws drag,com_offset,...] [--workdir DIR]
        [--markdown FILE] [--no-real]
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path
from typing import Any

from omavctl.diagnose.evalio import write_evaluation
from omavctl.diagnose.evaluate import evaluate
from omavctl.diagnose.horizon_findings import SIGNIFICANT, paired_se
from omavctl.learn.fit import fit_model
from omavctl.learn.model_file import save_model
from omavctl.logs import write_log
from omavctl.report.evaluation import write_report
from omavctl.sim.plant import simulate
from omavctl.sim.tasks import fig8
from omavctl.sim.truth import load_truth, truth_from_tree
from omavctl.vehicle import default_vehicle, load_vehicle

ROOT = Path(__file__).resolve().parents[1]
#: the shared real flight, relative to the repository (as benchmarks/generalise.py)
REAL = ROOT.parent / "shared/data/real/px4tools_octocopter/01_07_59.csv"
#: draw -> (truth YAML under examples/ or a truth tree, fit seed, flight seeds)
DRAWS: dict[str, Any] = {
    "drag": "truth-drag.yaml",
    "com_offset": {"seed": 2, "effects": {"com_offset": {"r": [0.02, -0.015, 0.0]}}},
    "motor_lag": {"seed": 3, "effects": {"motor_lag": {"T_m": 0.05}}},
    "drag_strong": {"seed": 4, "effects": {"rotational_drag": {"D": [0.1, 0.08, 0.05]}}},
    "clean": {"seed": 5, "effects": {}},  # no hidden effect: only the actuator imperfections
}
AXES = ("x", "y", "z")
KINDS = ("naive", "nominal", "effects", "model")


def _truth(draw: str, vehicle):
    spec = DRAWS[draw]
    if isinstance(spec, str):
        return load_truth(ROOT / "examples" / spec, vehicle)
    return truth_from_tree(spec, vehicle)


def draw_flights(draw: str, work: Path) -> tuple[Any, Path, Path, Path]:
    """A draw's vehicle, directory and its fit and held-out logs (figure-8s, seeds 1
    and 2), flown into ``work/draw`` unless an earlier run left them there (same
    draws, same seeds)."""
    vehicle = default_vehicle()
    d = work / draw
    d.mkdir(parents=True, exist_ok=True)
    fit_log, held = d / "flight-01.csv", d / "flight-02.csv"
    if not held.exists():
        truth = _truth(draw, vehicle)
        ref = fig8(roll_deg=26, pitch_deg=26, period=8, duration=20)
        write_log(fit_log, simulate(ref, vehicle, truth, seed=1).log)
        other = fig8(roll_deg=20, pitch_deg=30, period=6, duration=20)
        write_log(held, simulate(other, vehicle, truth, seed=2).log)
    return vehicle, d, fit_log, held


def run_draw(draw: str, work: Path) -> dict[str, Any]:
    """One draw: fit, evaluate, fit with the named effect, evaluate both models."""
    vehicle, d, fit_log, held = draw_flights(draw, work)
    base = d / "gp.npz"
    if not base.exists():
        save_model(base, fit_model([fit_log], vehicle, effects=("rotor_interference",)).model)
    first = evaluate([base], [held], horizons=())
    missing = list(first.tree["diagnosis"]["missing"])
    named = missing[:1]
    out: dict[str, Any] = {"draw": draw, "named": named[0] if named else None, "missing": missing}
    models = [base]
    if named:
        added = d / f"gp-{named[0]}.npz"
        effects = ("rotor_interference", named[0])
        if not added.exists():
            save_model(added, fit_model([fit_log], vehicle, effects=effects).model)
        models.append(added)
    result = evaluate(models, [held])
    write_evaluation(work / f"{draw}.eval.json", result)
    out["tree"] = result.tree
    return out


def run_real(work: Path) -> dict[str, Any]:
    """The px4tools octocopter: fit on 6.5-15 s, evaluate on 15 s to the end."""
    vehicle = load_vehicle(ROOT / "examples" / "px4tools-octocopter.yaml")
    model = work / "px4tools-gp.npz"
    if not model.exists():
        save_model(model, fit_model([REAL], vehicle, time_window=(6.5, 15.0)).model)
    result = evaluate([model], [REAL], time_window=(15.0, None))
    write_evaluation(work / "px4tools.eval.json", result)
    return {"draw": "px4tools octocopter (real)", "named": None, "tree": result.tree}


def _fmt(v: float | None) -> str:
    return "n/a" if v is None else f"{v:.3g}"


def table_lines(result: dict[str, Any]) -> list[str]:
    """The horizon table of one evaluation (model 0 and, when present, model 1)."""
    h = result["tree"]["horizons"]
    secs = [f"{s:g} s" for s in h["seconds"]]
    lines = [
        "| predictor | " + " | ".join(f"{s} rate x/y/z" for s in secs) + " | 0.5 s attitude "
        "| sum over 0.5 s | 2σ coverage |",
        "|---|" + "---|" * (len(secs) + 3),
    ]
    for p in h["predictors"]:
        rows = h["table"][p["key"]]
        name = p["key"].replace("_1", " (with the named effect)")
        if p["model"] == 0 and len(h["predictors"]) > 4:
            name += " (rotor_interference only)"
        cells = ["/".join(_fmt(r["rate_error"][a]) for a in AXES) for r in rows]
        cov = "/".join(f"{100 * r['coverage']['all']:.0f} %" for r in rows if r["coverage"])
        lines.append(
            f"| {name} | " + " | ".join(cells) + f" | {_fmt(rows[-1]['attitude_error'])} "
            f"| {_fmt(rows[-1]['rate_error_sum'])} | {cov or ''} |"
        )
    return lines


def _added_lines(result: dict[str, Any], kind: str, what: str) -> list[str]:
    """Per axis: adding the named effect, the one-step RMSE and the 0.5 s error (with
    the paired standard error over chunks of start times) before and after; whether
    they agree (a 0.5 s change within 2 standard errors is no change)."""
    tree, h = result["tree"], result["tree"]["horizons"]
    one = [tree["metrics_by_model"][k][kind]["rmse"] for k in (0, 1)]
    rows = [h["table"][k][-1] for k in (kind, f"{kind}_1")]
    lines = []
    for a in AXES:
        d1 = one[1][a] - one[0][a]
        d50 = rows[1]["rate_error"][a] - rows[0]["rate_error"][a]
        se = paired_se(rows[0], rows[1], a)
        within = se is not None and abs(d50) <= SIGNIFICANT * se
        verdict = (
            "within its standard error"
            if within
            else "agree"
            if (d1 < 0) == (d50 < 0)
            else "DISAGREE"
        )
        se_text = "" if se is None else f" ({d50:+.2g} ± {se:.2g}, {verdict})"
        lines.append(
            f"adding {result['named']} ({what}), {a}: one-step RMSE {one[0][a]:.3g} -> "
            f"{one[1][a]:.3g} rad/s², 0.5 s error {rows[0]['rate_error'][a]:.3g} -> "
            f"{rows[1]['rate_error'][a]:.3g} rad/s{se_text}"
        )
    return lines


def checks(result: dict[str, Any]) -> list[str]:
    """The must-show checks of one draw, one line each."""
    tree = result["tree"]
    h = tree["horizons"]
    j = 1 if "model_1" in h["table"] else 0
    sfx = "_1" if j else ""
    full, eff = h["table"][f"model{sfx}"], h["table"][f"effects{sfx}"]
    ratio = {a: full[-1]["rate_error"][a] / eff[-1]["rate_error"][a] for a in AXES}
    ok = all(r <= 1.05 for r in ratio.values())
    cov = [r["coverage"]["all"] for r in full]
    cov_axes = [min(r["coverage"][a] for a in AXES) for r in full]
    lines = [
        "full model / physics + effects at 0.5 s: "
        + ", ".join(f"{a} {ratio[a]:.2f}" for a in AXES)
        + (" (within 1.05)" if ok else " (ABOVE 1.05)"),
        "2σ coverage per horizon (all axes; worst axis): "
        + ", ".join(
            f"{100 * c:.0f} % ({100 * w:.0f} %)" for c, w in zip(cov, cov_axes, strict=True)
        )
        + (" (>= 85 %)" if min(cov) >= 0.85 else " (BELOW 85 %)"),
        "one-step coverage of the acceleration band: "
        + ", ".join(
            f"{a} {100 * tree['metrics_by_model'][j]['model']['coverage_2sigma'][a]:.0f} %"
            for a in AXES
        ),
    ]
    if j:
        for kind, what in (("model", "full model"), ("effects", "physics + effects")):
            lines += _added_lines(result, kind, what)
    left = [f["message"] for f in h["findings"] if f["code"] == "gp_left_out"]
    lines += [f"rollouts leave the GP mean out: {m}" for m in left] or [
        "the rollouts keep the GP mean on every axis (fit's check on held-out rollouts)"
    ]
    hurts = [f["message"] for f in h["findings"] if f["code"] == "gp_hurts_long"]
    lines += [f"GP helps at one step, hurts at 0.5 s: {m}" for m in hurts] or [
        "the GP does not help at one step and hurt at 0.5 s on any axis (beyond 2 SE)"
    ]
    added = [f["message"] for f in h["findings"] if f["code"] == "effect_added_hurts_long"]
    if j:
        lines += [f"the added effect helps at one step, hurts at 0.5 s: {m}" for m in added] or [
            "the added effect does not help at 0.01 s and hurt at 0.5 s on any axis (beyond 2 SE)"
        ]
    noise = h.get("rate_noise") or []
    for n in noise:
        if n.get("recorded"):
            lines.append(
                "gyro noise from the recorded samples: "
                + "/".join(f"{n[a]:.2g}" for a in AXES)
                + " rad/s (the grid's estimate "
                + "/".join(f"{n['grid'][a]:.2g}" for a in AXES)
                + ")"
            )
    return lines


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--draws", default=",".join(DRAWS))
    ap.add_argument("--workdir", type=Path, default=None)
    ap.add_argument("--markdown", type=Path, default=None)
    ap.add_argument("--no-real", action="store_true")
    args = ap.parse_args()
    work = args.workdir or Path(tempfile.mkdtemp(prefix="horizons-"))
    out: list[str] = []
    results = [run_draw(d, work) for d in args.draws.split(",") if d]
    if not args.no_real and REAL.exists():
        results.append(run_real(work))
    for r in results:
        out += [f"### {r['draw']}", ""]
        if r["named"]:
            names = ", ".join(f"`{m}`" for m in r["missing"])
            out += [f"evaluate named {names} missing; the second model adds `{r['named']}`.", ""]
        out += table_lines(r) + [""] + [f"- {line}" for line in checks(r)] + [""]
    evals = [work / f"{d}.eval.json" for d in args.draws.split(",") if d]
    if not args.no_real and REAL.exists():
        evals.append(work / "px4tools.eval.json")
    if len(evals) > 1:  # the report sets the draws side by side and names where the GP hurts
        write_report(evals, work / "draws-report.md")
        report = (work / "draws-report.md").read_text()
        part = report[report.index("The files side by side") :]
        out += ["### The report over the draws and the real log (section 6, end)", ""]
        out.append(part.split("## 7.")[0])
    text = "\n".join(out)
    print(text)
    if args.markdown:
        args.markdown.write_text(text + "\n")


if __name__ == "__main__":
    main()
