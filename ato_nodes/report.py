"""The report of runs and tunings that analyze.py writes: report.md with its PNG
figures and report.html (ato_nodes.analysis judges and plots, ato_nodes.report_html
draws the page), and indices.json.
"""

from __future__ import annotations

from pathlib import Path

from ato_nodes import jsontext, report_html
from ato_nodes.analysis import (judge, markdown_report, plot_convergence, plot_runs,
                                read_tuning, verdict_rows)
from ato_nodes.bagio import Run


def write_report(runs: list[Run], tunings: list[Path], out: Path) -> tuple[Path, Path]:
    """report.md with the PNG figures, report.html (interactive) and indices.json in
    `out`. Every run is judged and every tuning read before anything is written: a
    bad report.* parameter in a bag is a ScenarioError, a tuning directory that is not
    tune.py's a ReportError (one line each)."""
    reports = [judge(run) for run in runs]
    rows = verdict_rows(reports)
    histories = [read_tuning(directory) for directory in tunings]
    out.mkdir(parents=True, exist_ok=True)
    figures = plot_runs(runs, out) if runs else []
    if histories:
        figures.append(plot_convergence(histories, out / "convergence.png"))
    (out / "indices.json").write_text(jsontext.dumps(
        {report.label: {**report.indices, **({"partial": report.partial} if report.partial
                                             else {})} for report in reports}, indent=2))
    md_path = out / "report.md"
    md_path.write_text(markdown_report(reports, rows, figures))
    html_path = out / "report.html"
    report_html.write_html(reports, rows, histories, html_path)
    return md_path, html_path
