"""Reports people read: after the loop, from what a command already has (fits, calibrations,
diagnoses, measurements), a Markdown report with PNG plots and a self-contained HTML page.

`content` builds each command's report as sections of paragraphs, tables and figures;
`plots` draws the figures; `markdown` and `html` render the same sections.

The modules are imported on first use (`report.content`): every command imports this package for
`report.verdict`, and only one asked for a report needs the sections and their renderers.
"""
from __future__ import annotations

import importlib
from pathlib import Path

_MODULES = ("blocks", "content", "html", "markdown", "plots", "verdict")


def __getattr__(name):
    if name in _MODULES:
        return importlib.import_module(f"gecgen.report.{name}")
    raise AttributeError(f"module 'gecgen.report' has no attribute {name!r}")


def write(report, outdir: str | Path) -> dict[str, str]:
    """report.md (its figures as PNG files beside it) and report.html (figures embedded) in outdir
    of a `blocks.Report`, its figures drawn first; returns {report: markdown path, report_html: html
    path}."""
    from gecgen.report import html, markdown
    from gecgen.report.content import drawn

    report = drawn(report)
    outdir = Path(outdir)
    return {"report": str(markdown.write(report, outdir)), "report_html": str(html.write(report, outdir))}
