"""Screenshots of generated reports in headless Chromium, for the docs.

Run (after `make demo`):
    python tools/screenshots.py examples/build/report.html --out docs/img --name report
writes docs/img/report-800.png and docs/img/report-1400.png: the first screen of
the report at 800 and 1400 px wide (the verdict and the first figures).

Uses the system Chromium (Debian package `chromium`) through Playwright's Python
API; `playwright install` is not needed.
"""

from __future__ import annotations

import argparse
import shutil
import sys
from pathlib import Path

ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("html", type=Path, help="report to open")
    ap.add_argument("--out", type=Path, default=Path("docs/img"), help="output folder")
    ap.add_argument("--name", default="report", help="file name stem")
    ap.add_argument("--widths", default="800,1400", help="viewport widths, px")
    ap.add_argument("--height", type=int, default=1100, help="viewport height, px")
    ap.add_argument("--chromium", default=shutil.which("chromium") or "/usr/bin/chromium")
    args = ap.parse_args(argv)
    from playwright.sync_api import sync_playwright

    args.out.mkdir(parents=True, exist_ok=True)
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=args.chromium, args=ARGS)
        for width in (int(w) for w in args.widths.split(",")):
            page = browser.new_page(viewport={"width": width, "height": args.height})
            page.goto(args.html.resolve().as_uri(), wait_until="load")
            out = args.out / f"{args.name}-{width}.png"
            page.screenshot(path=str(out))
            print(f"wrote {out}")
            page.close()
        browser.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
