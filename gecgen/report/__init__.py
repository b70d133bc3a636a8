"""Reports people read: after the loop, from what a command already has (fits, calibrations,
diagnoses, measurements), a Markdown report with PNG plots and a self-contained HTML page.

`content` builds each command's report as sections of paragraphs, tables and figures;
`plots` draws the figures; `markdown` and `html` render the same sections.
"""
from __future__ import annotations

from pathlib import Path

from gecgen.report.blocks import Report
from gecgen.report.content import drawn


def write(report: Report, outdir: str | Path) -> dict[str, str]:
    """report.md (its figures as PNG files beside it) and report.html (figures embedded) in outdir,
    its figures drawn first; returns {report: markdown path, report_html: html path}."""
    from gecgen.report import html, markdown

    report = drawn(report)
    outdir = Path(outdir)
    return {"report": str(markdown.write(report, outdir)), "report_html": str(html.write(report, outdir))}
