"""Fly the own tune draws' logs again (session 25) with the plant whose log records the
actuators at each row's instant: the dynamics are the same, only the logged tilts and rotor
speeds move. FROZEN: a tree with the plant of 778d8e0 or later; run as
``python refly.py /work/sc19/own-drag.jsonl ...``."""

import json
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

FROZEN = Path("/work/frozen25c")
OUT = Path("/work/sc25")
OUT.mkdir(exist_ok=True)
for rec_path in sys.argv[1:]:
    rec_path = Path(rec_path)
    shutil.copyfile(rec_path, OUT / rec_path.name)
    for line in rec_path.read_text().splitlines():
        r = json.loads(line)
        if r.get("error"):
            continue
        src = rec_path.parent / f"{r['split']}-{r['index']:04d}"
        dst = OUT / src.name
        if (dst / "done").exists():
            continue
        dst.mkdir(exist_ok=True)
        for f in ("fit-ref.csv", "held-ref.csv", "truth.yaml"):
            shutil.copyfile(src / f, dst / f)
        for c in r["commands"]:
            cmd = c if isinstance(c, str) else c["command"]
            argv = shlex.split(cmd)
            if argv[1] != "simulate":
                continue
            out = argv[argv.index("--out") + 1]
            if (dst / out).exists():
                shutil.rmtree(dst / out) if (dst / out).is_dir() else (dst / out).unlink()
            subprocess.run(
                [sys.executable, "-m", "omavctl", *argv[1:], "-q"],
                cwd=dst,
                check=True,
                env={
                    "PYTHONPATH": str(FROZEN),
                    "PATH": "/usr/bin:/bin",
                    "OPENBLAS_NUM_THREADS": "1",
                },
            )
        (dst / "done").write_text("ok")
        print(dst.name, flush=True)
