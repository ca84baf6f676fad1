#!/usr/bin/env python3
"""Render an analyze.py report.html in headless Chromium, check that it rendered, and
keep a screenshot.

    python scripts/screenshot_report.py REPORT_DIR/report.html --out shot.png [--size 1400x2600]
        [--time START:END]     # the time axes zoomed on that stretch, s

Needs Debian's Chromium (`apt-get install chromium`). Rendered means: every Plotly
figure of the page was drawn once its scripts ran (the page counts them in its body's
data-plots-rendered, and each drawn figure holds Plotly's SVG), and the screenshot is
not blank. Prints what it checked; exit 1 if the page did not render, 2 on bad input.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import tempfile
from pathlib import Path

import _cli

from ato_nodes.reports.report_html import RENDERED_ATTRIBUTE

BROWSERS = ("chromium", "chromium-browser")
SCRIPT_TIME = 60.0    # s of the page's (virtual) time for its scripts before the capture
WALL_TIMEOUT = 180.0  # s: a browser that takes longer is stuck
MIN_INKED = 0.01      # share of the screenshot's pixels that are not the background
COLOURS = 256         # the kept screenshot's palette: a report's few flat colours fit


def browser() -> str | None:
    return next((path for path in map(shutil.which, BROWSERS) if path), None)


def chromium(page: str, *arguments: str, size: str) -> str:
    """Chromium's stdout for the page, headless, in a profile of its own (several may run
    at once), every host name unresolvable (the page must need no network);
    --no-sandbox since the tools here run as root."""
    width, _, height = size.partition("x")
    with tempfile.TemporaryDirectory(prefix="report-browser-") as profile:
        result = subprocess.run(
            [browser(), "--headless", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
             "--no-first-run", "--mute-audio", f"--user-data-dir={profile}",
             "--host-resolver-rules=MAP * ~NOTFOUND",
             f"--window-size={width},{height}",
             f"--virtual-time-budget={int(SCRIPT_TIME * 1000)}", *arguments, page],
            capture_output=True, text=True, timeout=WALL_TIMEOUT)
    if result.returncode != 0:
        raise RuntimeError(f"chromium exited with {result.returncode}: "
                           f"{result.stderr.strip().splitlines()[-1:]}")
    return result.stdout


def rendered_figures(dom: str) -> tuple[int, int, int]:
    """(Plotly figure divs, figures the page says it drew, Plotly SVG roots) in the DOM
    as it stands after the scripts ran."""
    divs = len(re.findall(r'class="[^"]*\bplotly-graph-div\b', dom))
    marker = re.search(rf'<body[^>]*\b{RENDERED_ATTRIBUTE}="(\d+)"', dom)
    svgs = len(re.findall(r'class="main-svg"', dom))
    return divs, int(marker.group(1)) if marker else 0, svgs


def inked_share(png: Path) -> float:
    """Share of pixels unlike the top-left one (the page's background)."""
    from PIL import Image
    import numpy as np
    pixels = np.asarray(Image.open(png).convert("RGB"), dtype=int)
    return float(np.mean(np.any(pixels != pixels[0, 0], axis=-1)))


def main() -> None:
    parser = _cli.argument_parser(__doc__)
    parser.add_argument("page", type=Path, help="report.html of analyze.py")
    parser.add_argument("--out", type=Path, required=True, help="screenshot to write (PNG)")
    parser.add_argument("--size", default="1400x2600", help="window WIDTHxHEIGHT in pixels")
    parser.add_argument("--time", metavar="START:END", help="zoom the time axes, s")
    args = parser.parse_args()
    if not args.page.is_file():
        _cli.fail(f"{args.page} is not a file")
    if not re.fullmatch(r"[1-9]\d{1,4}x[1-9]\d{1,4}", args.size):
        _cli.fail(f"--size expects WIDTHxHEIGHT in pixels, e.g. 1400x2600; got {args.size!r}")
    if args.time is not None and not re.fullmatch(r"\d+(\.\d*)?:\d+(\.\d*)?", args.time):
        _cli.fail(f"--time expects START:END in seconds, e.g. 1190:1260; got {args.time!r}")
    if browser() is None:
        _cli.fail("no Chromium on PATH (Debian: apt-get install chromium)")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    page = args.page.resolve().as_uri() + (f"#t={args.time}" if args.time else "")
    try:
        divs, drawn, svgs = rendered_figures(chromium(page, "--dump-dom", size=args.size))
        with tempfile.TemporaryDirectory(prefix="report-shot-") as scratch:
            shot = Path(scratch) / "shot.png"
            chromium(page, f"--screenshot={shot}", size=args.size)
            inked = inked_share(shot)
            from PIL import Image
            Image.open(shot).convert("RGB").quantize(COLOURS).save(args.out, optimize=True)
    except (OSError, RuntimeError, subprocess.TimeoutExpired) as exc:
        _cli.fail(f"{args.page}: {exc}")
    print(f"{args.page}: {divs} Plotly figures, {drawn} drawn, {svgs} SVG roots; "
          f"{inked:.1%} of the screenshot inked; {args.out} "
          f"({args.out.stat().st_size / 1024:.0f} KiB)")
    if divs == 0 or drawn != divs or svgs < divs or inked < MIN_INKED:
        _cli.fail("the report did not render", status=1)


if __name__ == "__main__":
    _cli.interrupted_quietly(main)
