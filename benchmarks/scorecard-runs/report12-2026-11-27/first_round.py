"""First-round diagnosis of kept draws under a variant: python first.py RECORDS DIR..."""
import json, subprocess, sys, os
from pathlib import Path
recs = {}
for f in sys.argv[1].split(","):
    for l in open(f):
        r = json.loads(l); recs[(r["split"], r["index"])] = r
for d in sys.argv[2:]:
    d = Path(d)
    split, idx = d.name.rsplit("-", 1); idx = int(idx)
    r = recs.get((split, idx))
    if r is None or not (d / "m0.npz").exists():
        continue
    held = r["flights"][1]["log"]
    out = Path("/tmp/s20/ev") / os.environ.get("OMAVCTL_VARIANT", "base") / d.name
    out.mkdir(parents=True, exist_ok=True)
    env = dict(os.environ, PYTHONPATH="/tmp/s20:" + os.environ.get("TREE", "/work/main"), OMP_NUM_THREADS="1")
    code = "import sys, variant; from omavctl.cli.app import app; sys.argv=['omavctl']+sys.argv[1:]; app()"
    p = subprocess.run(["/work/main/.venv/bin/python", "-c", code, "evaluate", str(d / held), "--model", str(d / "m0.npz"),
                        "--out", str(out / "ev.json"), "--horizons", "none", "-q"], env=env, capture_output=True, text=True)
    try:
        dg = json.load(open(out / "ev.json"))["diagnosis"]
        ans = [(s["name"], s.get("ambiguous_with")) for s in dg["joint_steps"]]
        print(d.name, "hidden", sorted(r["hidden"]), "| missing", dg["missing"], "learned_claims", dg.get("learned_claims"), "| steps", ans, "| was", r["rounds"][0]["missing"], flush=True)
    except Exception as e:
        print(d.name, "error", p.stderr[-300:], flush=True)
