"""First answers of report12's kept first models with the tool before the session (e17f08f)
against the records (76a0e41): the same rule as scorecard_score.first_answer_right."""
import json, sys, copy
sys.path.insert(0, "/work/main")
from pathlib import Path
from benchmarks import scorecard_score as sc
recs = [json.loads(l) for l in open("/work/main/benchmarks/scorecard-runs/report12-2026-11-27/report12.jsonl")]
n = same = 0
rows = []
tot = {"before": 0, "after": 0, "n": 0}
for r in recs:
    if r.get("error") or not r.get("rounds"):
        continue
    p = Path(f"/tmp/s20/ev/r12-before/report12-{r['index']:04d}/ev.json")
    if not p.exists():
        continue
    d = json.load(open(p))["diagnosis"]
    before = copy.deepcopy(r)
    before["rounds"] = [{"missing": d["missing"], "learned_claims": d.get("learned_claims") or [],
                         "candidates": [{"name": e["name"], "ambiguous_with": e.get("ambiguous_with") or []} for e in d.get("missing_effects") or []]}]
    a, b = sc.first_answer_right(r), sc.first_answer_right(before)
    above = sc.size_ratio(r) >= 1.0 or not r["hidden"]
    key = (sorted(r["rounds"][0]["missing"]), sorted(r["rounds"][0].get("learned_claims") or []))
    kb = (sorted(d["missing"]), sorted(d.get("learned_claims") or []))
    n += 1; same += key == kb
    if r["hidden"] and sc.size_ratio(r) >= 1.0:
        tot["n"] += 1; tot["before"] += b; tot["after"] += a
    if key != kb or a != b:
        rows.append(f"| {r['index']} | {', '.join(r['hidden']) or 'none'} | {', '.join(kb[0] + ['L:'+x for x in kb[1]]) or 'nothing'} ({'right' if b else 'wrong'}) | {', '.join(key[0] + ['L:'+x for x in key[1]]) or 'nothing'} ({'right' if a else 'wrong'}) |")
print(f"draws compared {n}; the same claims {same}; at or above the floor with a hidden effect: before {tot['before']}/{tot['n']}, after {tot['after']}/{tot['n']}")
print("| draw | hidden | before (e17f08f) | after (76a0e41) |\n|---|---|---|---|")
print("\n".join(rows))
