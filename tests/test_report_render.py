"""The interactive report renders in a real headless browser (Debian's Chromium), with
no network; skipped where no Chromium is installed (CI's setup.sh installs none)."""

import shutil
import subprocess
from pathlib import Path

import pytest

from ato_nodes.reports.report import write_report
from ato_nodes.bags.bagio import Run
from ato_nodes.core.run.loop import simulate
from ato_nodes.core.config.scenario import apply_overrides, load_scenario
from commands import invocation

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.skipif(
    not (shutil.which("chromium") or shutil.which("chromium-browser")),
    reason="no Chromium on PATH (Debian: apt-get install chromium); the render check "
           "needs a real browser")


def screenshot(page: Path, out: Path, *extra: str) -> subprocess.CompletedProcess:
    return subprocess.run([*invocation("screenshot_report"),
                           str(page), "--out", str(out), "--size", "1000x1400", *extra],
                          capture_output=True, text=True, timeout=400)


def test_the_report_renders_every_figure_offline(tmp_path):
    values = apply_overrides(load_scenario("hsr-neutral"), ["run.duration=120"])
    run = Run(tmp_path / "hsr", simulate(values), values, {})
    _, page = write_report([run], [], tmp_path / "report")
    result = screenshot(page, tmp_path / "shot.png", "--time", "10:30")
    assert result.returncode == 0, result.stderr
    assert "2 Plotly figures, 2 drawn" in result.stdout
    assert (tmp_path / "shot.png").stat().st_size > 10_000


def test_a_page_whose_figures_do_not_draw_fails_the_check(tmp_path):
    page = tmp_path / "broken.html"
    page.write_text("<!doctype html><html><body><h1>ATO run report</h1>"
                    "<div class=\"plotly-graph-div\"></div><script>Plotly.newPlot()</script>"
                    "</body></html>")
    result = screenshot(page, tmp_path / "shot.png")
    assert result.returncode == 1
    assert "1 Plotly figures, 0 drawn" in result.stdout
    assert result.stderr.strip() == "error: the report did not render"
