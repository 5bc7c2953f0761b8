"""Fuzz cases: a base set of valid inputs, and seeded cases that mutate one (or,
with the ``stacked`` strategy, several) of them and run the subcommand that reads it.

A :class:`Case` knows its command line, the file it mutated (the error line
must name it), the outputs to check when the command succeeds, and whether
the mutated input is invalid by construction (then success is wrong).
"""

from __future__ import annotations

import json
import random
import shutil
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from . import mutate as mu
from .formats import write_betaflight_csv, write_cfusdlog, write_gzip_csv

#: Cheap settings that keep each run short.
FIT = ["--points", "15", "--restarts", "0", "-q"]
PLAN = [
    "--candidates",
    "4",
    "--amplitude",
    "0.2",
    "--sims",
    "2",
    "--test-points",
    "30",
    "--points",
    "5",
    "-q",
]
LOG_KINDS = ("log.csv", "log.bag", "log.mcap", "log_dir", "log.csv.gz", "cflog", "bf.csv")
CSV_REQUIRED = {
    "t",
    *(f"body_rate_{a}" for a in "xyz"),
    *(f"attitude_{a}" for a in ("roll", "pitch", "yaw")),
    *(f"force_command_{a}" for a in "xyz"),
    *(f"torque_command_{a}" for a in "xyz"),
}
MODEL_CRITICAL = {
    "schema",
    "features",
    "input_names",
    "train_inputs",
    "train_targets",
    "input_mean",
    "input_scale",
    "target_mean",
    "signal_variance",
    "length_scales",
    "noise_variance",
    "vehicle",
}
VEHICLE_CRITICAL = ("mass", "inertia", "gravity", "geometry", "rotor", "controller", "servo")


@dataclass
class Case:
    """One fuzz case."""

    name: str
    argv: list[str]
    target: str  # the mutated input (or the option) the error line must name
    mutation: str
    must_fail: bool
    outputs: dict[str, str] = field(default_factory=dict)  # path -> kind to validate
    inputs: list[str] = field(default_factory=list)


# ----------------------------------------------------------------- base inputs
def build_base(base: Path) -> Path:
    """Write the valid inputs every case starts from (about 10 s)."""
    from omavctl.cli import app
    from omavctl.diagnose.evalio import write_evaluation
    from omavctl.diagnose.evaluate import evaluate
    from omavctl.logs import write_log
    from omavctl.sim.plant import simulate
    from omavctl.sim.tasks import fig8
    from omavctl.sim.trajectory import write_trajectory
    from omavctl.sim.truth import truth_from_tree
    from omavctl.vehicle import default_vehicle

    base.mkdir(parents=True, exist_ok=True)
    if (base / "done").exists():
        return base
    veh = default_vehicle()
    write_trajectory(base / "task.csv", fig8(20, 20, 3.0, 4.0, 100.0, 1.0, 1.0))
    short = fig8(20, 20, 3.0, 6.0, 100.0, 1.0, 1.0)
    truth = {"seed": 1, "effects": {"rotational_drag": {"D": [0.02, 0.02, 0.04]}}}
    result = simulate(short, veh, truth_from_tree(truth, veh), seed=1)
    for name in LOG_KINDS[:4]:
        write_log(base / name, result.log, topics=veh.topics)
    write_gzip_csv(base / "log.csv", base / "log.csv.gz")
    write_cfusdlog(result.log, base / "cflog")
    write_betaflight_csv(result.log, base / "bf.csv")
    (base / "vehicle.yaml").write_text(yaml.safe_dump(veh.tree))
    (base / "truth.yaml").write_text(yaml.safe_dump(truth))
    from typer.testing import CliRunner

    res = CliRunner().invoke(
        app, ["fit", str(base / "log.csv"), "--out", str(base / "m.npz"), *FIT]
    )
    assert res.exit_code == 0, res.output
    write_evaluation(base / "eval.json", evaluate([base / "m.npz"], [base / "log.mcap"]))
    (base / "done").write_text("ok")
    return base


# ----------------------------------------------------------------- commands
def _consumers(kind: str) -> list[Callable[[dict[str, str]], tuple[list[str], dict[str, str]]]]:
    """Commands reading an input of ``kind``; each maps input paths -> (argv, outputs)."""

    def inspect(p: dict[str, str]) -> tuple[list[str], dict[str, str]]:
        return ["inspect", p["log"], *(["--vehicle", p["vehicle"]] if "vehicle" in p else [])], {}

    def fit(p: dict[str, str]) -> tuple[list[str], dict[str, str]]:
        argv = ["fit", p["log"], "--out", "out.npz", *FIT]
        argv += ["--vehicle", p["vehicle"]] if "vehicle" in p else []
        argv += ["--prior", p["prior"]] if "prior" in p else []
        return argv, {"out.npz": "model"}

    def evaluate(p: dict[str, str]) -> tuple[list[str], dict[str, str]]:
        return ["evaluate", p["log"], "--model", p["model"], "--out", "out.json", "-q"], {
            "out.json": "eval"
        }

    def simulate(p: dict[str, str]) -> tuple[list[str], dict[str, str]]:
        out = p.get("sim_out", "sim.csv")
        argv = ["simulate", "-r", p["task"], "--out", out, "-q"]
        for opt in ("truth", "vehicle", "model"):
            argv += [f"--{opt}", p[opt]] if opt in p else []
        return argv, {out: "log"}

    def plan(p: dict[str, str]) -> tuple[list[str], dict[str, str]]:
        argv = ["plan", "--task", p["task"], "--model", p["model"], "--out", "plan.csv"]
        argv += ["--scores", "scores.csv", *PLAN]
        argv += ["--vehicle", p["vehicle"]] if "vehicle" in p else []
        return argv, {"plan.csv": "trajectory", "scores.csv": "scores"}

    def report(p: dict[str, str]) -> tuple[list[str], dict[str, str]]:
        out = p.get("report_out", "report.md")
        return ["report", p["eval"], "--out", out, "-q"], {out: "report"}

    return {
        "log": [inspect, fit, evaluate],
        "vehicle": [inspect, fit, simulate, plan],
        "truth": [simulate],
        "task": [simulate, plan],
        "model": [evaluate, plan, simulate, fit],
        "eval": [report],
        "legacy": [report],
        "series": [report],
    }[kind]


def _defaults(kind: str, cmd: str) -> dict[str, str]:
    """Valid inputs a command needs besides the mutated one."""
    p = {"log": "log.csv", "model": "m.npz", "task": "task.csv", "eval": "eval.json"}
    if kind == "model" and cmd == "fit":
        p["prior"] = "m.npz"
    return p


# ----------------------------------------------------------------- mutating one input
def _mutate_file(rng: random.Random, kind: str, src: Path, dst: Path) -> tuple[str, bool]:
    """Write a mutant of ``src`` to ``dst``; (description, invalid by construction)."""
    data = src.read_bytes()
    if kind == "log" and src.suffix == ".csv" and rng.random() < 0.7:
        if rng.random() < 0.6:
            new, desc, bad = mu.csv_cell(rng, data, CSV_REQUIRED)
        else:
            new, desc, bad = mu.csv_structure(rng, data)
    elif kind == "task" and rng.random() < 0.8:
        if rng.random() < 0.6:
            new, desc, bad = mu.csv_cell(rng, data)
        else:
            new, desc, bad = mu.csv_structure(rng, data)
    elif kind in ("vehicle", "truth"):
        crit: Callable[[tuple[Any, ...]], bool] = (
            (lambda path: path[0] in VEHICLE_CRITICAL)
            if kind == "vehicle"
            else (lambda path: path[0] != "seed")
        )
        new, desc, bad = mu.yaml_mutation(rng, data, crit)
    elif kind == "eval":
        new, desc, bad = mu.json_mutation(rng, data, lambda path: path[:1] == ("metrics",))
    elif kind == "legacy":  # written before run ids: checked field by field
        tree = json.loads(data)
        del tree["series"]["sha256"], tree["series"]["run_id"]
        new, desc, bad = mu.json_mutation(
            rng, json.dumps(tree).encode(), lambda path: path[:2] == ("metrics", "model")
        )
    elif kind in ("model", "series") and rng.random() < 0.6:
        critical = (lambda k: k in MODEL_CRITICAL) if kind == "model" else (lambda k: k != "x")
        new, desc, bad = mu.npz_mutation(rng, data, critical)
    else:
        new, desc, bad = rng.choice(mu.BYTE_MUTATORS)(rng, data)
        if kind == "log" and src.suffix == ".csv":
            bad = bad or new[:200].count(b",") < 5
    dst.write_bytes(new)
    return desc, bad


def _mutate_ros2(rng: random.Random, src: Path, dst: Path) -> tuple[str, bool]:
    shutil.copytree(src, dst)
    if rng.random() < 0.5:
        meta = dst / "metadata.yaml"
        roll = rng.random()
        if roll < 0.3:
            meta.write_text("")
            return "empty metadata.yaml", True
        new, desc, bad = mu.yaml_mutation(rng, meta.read_bytes(), lambda path: False)
        meta.write_bytes(new)
        return f"metadata.yaml {desc}", False
    storage = next(p for p in dst.iterdir() if p.name != "metadata.yaml")
    new, desc, bad = rng.choice(mu.BYTE_MUTATORS)(rng, storage.read_bytes())
    storage.write_bytes(new)
    return f"{storage.name} {desc}", bad and "empt" in desc


KINDS = ("log", "log", "log", "vehicle", "truth", "task", "model", "model", "eval", "legacy",
         "series")  # fmt: skip


def make_case(rng: random.Random, index: int, base: Path, work: Path) -> Case:
    """Case ``index``: copy the base inputs into ``work``, mutate one, pick a command."""
    kind = rng.choice(KINDS)
    cmd = rng.choice(_consumers(kind))
    paths = _defaults(kind, cmd.__name__)
    for name in ("task.csv", "m.npz", "eval.json", "eval.series.npz", "log.csv"):
        shutil.copy2(base / name, work / name)
    if kind == "log":
        src = base / rng.choice(LOG_KINDS)
        if rng.random() < 0.1:  # a log under another format's name
            target = f"bad{rng.choice(['.mcap', '.bag', '.csv'])}"
            dst = work / target
            dst.write_bytes((base / rng.choice(["log.bag", "log.mcap", "log.csv"])).read_bytes())
            desc, bad = f"{src.name} renamed {target}", False
        elif src.is_dir():
            target = "bad_dir"
            desc, bad = _mutate_ros2(rng, src, work / target)
        else:
            target = f"bad{''.join(src.suffixes)}"  # bad.csv.gz, bad (a Crazyflie log)
            desc, bad = _mutate_file(rng, kind, src, work / target)
        paths["log"] = target
    elif kind == "series":
        target = "eval.series.npz"
        desc, bad = _mutate_file(rng, kind, base / target, work / target)
        # a changed array breaks the content hash the JSON records
        bad = bad or (desc.startswith("member") and "kept" not in desc and "no change" not in desc)
        paths["eval"] = "eval.json"
    else:
        src = {"vehicle": "vehicle.yaml", "truth": "truth.yaml", "task": "task.csv"}.get(
            kind, {"model": "m.npz", "eval": "eval.json", "legacy": "eval.json"}.get(kind, "")
        )
        target = f"bad_{src}"
        desc, bad = _mutate_file(rng, kind, base / src, work / target)
        if kind in ("eval", "legacy"):
            shutil.copy2(base / "eval.series.npz", work / "bad_eval.series.npz")
        paths["eval" if kind == "legacy" else kind] = target
        if kind == "model" and cmd.__name__ == "fit":
            paths["prior"] = target
    if cmd.__name__ == "simulate":
        paths["sim_out"] = rng.choice(["sim.csv", "sim.bag", "sim.mcap", "sim_dir"])
    if cmd.__name__ == "report" and rng.random() < 0.15:
        paths["report_out"] = "report.html"
    if cmd.__name__ == "inspect":  # lenient by design: bad cells and rows become notes
        bad = bad and kind != "log"
    argv, outputs = cmd(paths)
    inputs = [v for k, v in paths.items() if k not in ("sim_out", "report_out")]
    return Case(f"{index:05d}-{kind}-{cmd.__name__}", argv, target, desc, bad, outputs, inputs)


# ----------------------------------------------------------------- option cases
OPTION_CASES: list[tuple[list[str], str, list[str]]] = [
    (["task", "fig8", "--out", "t.csv", "-q"], "--duration", ["nan", "inf", "-1", "0", "1e300"]),
    (["task", "fig8", "--out", "t.csv", "-q"], "--rate", ["nan", "0", "-5", "1e-300", "1e300"]),
    (["task", "pitch", "--out", "t.csv", "-q"], "--amplitude", ["nan", "90", "1e300", "-inf"]),
    (["task", "circle", "--out", "t.csv", "-q"], "--radius", ["nan", "-1", "1e300", "0"]),
    (["task", "yaw", "--out", "t.csv", "-q"], "--period", ["nan", "0", "-1", "1e-300"]),
    (["task", "heave", "--out", "t.csv", "-q"], "--height", ["nan", "inf", "-1e300"]),
    (["task", "wobble", "--out", "t.csv", "-q"], "--bandwidth", ["nan", "0", "-1", "1e300"]),
    (["task", "chirp", "--out", "t.csv", "-q"], "--f-end", ["nan", "0", "-1", "1e300"]),
    (["task", "steps", "--out", "t.csv", "-q"], "--hold", ["nan", "0", "-1", "1e300"]),
    (["task", "steps", "--out", "t.csv", "-q"], "--ramp", ["nan", "inf", "-1"]),
    (["plan", "--task", "task.csv", "--model", "m.npz", "--out", "p.csv", *PLAN], "--amplitude",
     ["nan", "inf", "-1", "0", "1e300"]),
    (["plan", "--task", "task.csv", "--model", "m.npz", "--out", "p.csv", *PLAN], "--max-freq",
     ["nan", "inf", "0", "1e300"]),
    (["plan", "--task", "task.csv", "--model", "m.npz", "--out", "p.csv", *PLAN], "--epsilon",
     ["nan", "inf", "0", "-1", "1e300", "1e-300"]),
    (["simulate", "-r", "task.csv", "--out", "s.csv", "-q"], "--physics-rate",
     ["nan", "inf", "0", "999", "1e300"]),
    (["fit", "log.csv", "--out", "f.npz", *FIT], "--sg-window", ["0", "-1", "4", "100001"]),
    (["fit", "log.csv", "--out", "f.npz", *FIT], "--time-window",
     ["nan:1", "a:b", "5:1", "1e300:", ":-1", "inf:"]),
    (["evaluate", "log.csv", "--model", "m.npz", "--out", "e.json", "-q"], "--time-window",
     ["nan:", "3:2", "100:200", ":0"]),
]  # fmt: skip

OPTION_OUTPUTS = {
    "t.csv": "trajectory",
    "p.csv": "trajectory",
    "s.csv": "log",
    "f.npz": "model",
    "e.json": "eval",
}


def option_case(rng: random.Random, index: int, base: Path, work: Path) -> Case:
    argv, option, values = rng.choice(OPTION_CASES)
    value = rng.choice(values)
    for name in ("task.csv", "m.npz", "log.csv"):
        shutil.copy2(base / name, work / name)
    bad = value in ("nan", "inf", "-inf", "-1e300", "1e300") and option != "--height"
    outputs = {a: OPTION_OUTPUTS[a] for a in argv if a in OPTION_OUTPUTS}
    return Case(
        f"{index:05d}-option{option}",
        [*argv, option, value],
        option,
        f"{option} {value}",
        bad and option not in ("--time-window",),
        outputs,
        [a for a in argv if a in ("task.csv", "m.npz", "log.csv")],
    )


def output_case(rng: random.Random, index: int, base: Path, work: Path) -> Case:
    """An output that is an input (also through another path), or a directory."""
    for name in ("task.csv", "m.npz", "log.csv", "eval.json", "eval.series.npz"):
        shutil.copy2(base / name, work / name)
    (work / "sub").mkdir()
    choices = [
        (["fit", "log.csv", *FIT, "--out"], "log.csv"),
        (["fit", "log.csv", *FIT, "--out"], "./sub/../log.csv"),
        (["evaluate", "log.csv", "--model", "m.npz", "-q", "--out"], "m.npz"),
        (["evaluate", "log.csv", "--model", "m.npz", "-q", "--out"], "log.csv"),
        (["plan", "--task", "task.csv", "--model", "m.npz", *PLAN, "--out"], "task.csv"),
        (["plan", "--task", "task.csv", "--model", "m.npz", *PLAN, "--out"], "m.npz"),
        (["plan", "--task", "task.csv", "--model", "m.npz", "--scores", "y.csv", *PLAN, "--out"],
         "y.csv"),
        (["simulate", "-r", "task.csv", "-q", "--out"], "task.csv"),
        (["simulate", "-r", "task.csv", "--model", "m.npz", "-q", "--out"], "m.npz"),
        (["report", "eval.json", "-q", "--out"], "eval.json"),
        (["report", "eval.json", "-q", "--out"], "eval.series.npz"),
        (["fit", "log.csv", *FIT, "--out"], "sub"),
        (["task", "fig8", "-q", "--out"], "sub"),
        (["report", "eval.json", "-q", "--out"], "sub/x.pdf"),
    ]  # fmt: skip
    argv, out = rng.choice(choices)
    inputs = [a for a in argv if a in ("task.csv", "m.npz", "log.csv", "eval.json")]
    if "report" in argv:
        inputs.append("eval.series.npz")
    return Case(f"{index:05d}-output", [*argv, out], out, f"--out {out}", True, {}, inputs)


def _stack(rng: random.Random, case: Case, work: Path) -> Case:
    """Mutate the case's mutated file once more (``stacked`` strategy)."""
    path = work / case.target
    kind = case.name.split("-")[1]
    if not path.is_file() or kind not in ("log", "vehicle", "truth", "task", "model", "eval"):
        return case
    try:
        desc, bad = _mutate_file(rng, kind, path, path)
    except Exception:  # the first mutation left nothing to parse: mutate the bytes
        new, desc, bad = rng.choice(mu.BYTE_MUTATORS)(rng, path.read_bytes())
        path.write_bytes(new)
        # an empty YAML is an empty mapping: no overrides, a valid vehicle or truth
        bad = bad and kind != "log" and not (kind in ("vehicle", "truth") and not new)
    case.mutation = f"{case.mutation}; then {desc}"
    case.must_fail = bad and case.argv[0] != "inspect"  # the last mutation decides
    return case


def iter_cases(
    seed: int, count: int, base: Path, root: Path, strategy: str = "single"
) -> Iterator[tuple[Case, Path]]:
    """``count`` cases from ``seed`` with their folders, each made when it is reached:
    75 % input mutations, 15 % options, 10 % outputs.

    ``strategy`` ``"single"`` mutates one input once (the corpus of ``make test``);
    ``"stacked"`` mutates it again on top (a different population of inputs).
    """
    rng = random.Random(seed)
    for i in range(count):
        work = root / f"case{i:05d}"
        work.mkdir(parents=True)
        roll = rng.random()
        maker = make_case if roll < 0.75 else option_case if roll < 0.9 else output_case
        case = maker(rng, i, base, work)
        if strategy == "stacked" and maker is make_case:
            case = _stack(rng, case, work)
        if rng.random() < 0.2:  # scripting: one JSON object on stdout, errors on stderr
            case.argv.append("--json")
        yield case, work
