"""The report of runs and tunings that analyze.py writes: report.md with its PNG
figures and report.html (ato_nodes.reports.analysis judges and plots, ato_nodes.reports.report_html
draws the page), and indices.json.
"""

from __future__ import annotations

from pathlib import Path

from ato_nodes.reports import report_html, report_journey
from ato_nodes.results import jsontext
from ato_nodes.reports.analysis import (judge, markdown_report, plot_convergence, plot_runs,
                                        read_tuning, verdict_rows)
from ato_nodes.bags.bagio import Run


def write_report(runs: list[Run], tunings: list[Path], out: Path) -> tuple[Path, Path]:
    """report.md with the PNG figures, report.html (interactive) and indices.json in
    `out`, with a journey run's tables and figure (ato_nodes.reports.report_journey). Every run
    is judged and every tuning read before anything is written: a bad report.*
    parameter or a kept timetable that does not load is a ScenarioError, a tuning
    directory that is not tune.py's a ReportError (one line each)."""
    reports = [judge(run) for run in runs]
    rows = verdict_rows(reports)
    histories = [read_tuning(directory) for directory in tunings]
    journeys, notes = report_journey.journey_reports(reports)
    out.mkdir(parents=True, exist_ok=True)
    figures = plot_runs(runs, out) if runs else []
    figures += [report_journey.plot_journey(journey, out / f"journey_{number + 1}.png")
                for number, journey in enumerate(journeys)]
    if histories:
        figures.append(plot_convergence(histories, out / "convergence.png"))
    (out / "indices.json").write_text(jsontext.dumps(
        {report.label: {**report.indices, **({"partial": report.partial} if report.partial
                                             else {})} for report in reports}, indent=2))
    md_path = out / "report.md"
    md_path.write_text(markdown_report(reports, rows, figures, report_journey.markdown_sections(
        journeys, notes)))
    html_path = out / "report.html"
    report_html.write_html(
        reports, rows, histories, html_path, report_journey.html_sections(journeys, notes),
        [(f"Journey: {journey.label}, speed against position",
          report_journey.journey_figure(journey)) for journey in journeys])
    return md_path, html_path
