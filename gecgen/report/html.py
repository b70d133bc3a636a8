"""A report as one self-contained HTML page: report.html, figures embedded as base64 PNG, no
external file, script or font (it opens offline, attached to a mail, years later)."""
from __future__ import annotations

import base64
import re
from pathlib import Path

import jinja2
from markupsafe import Markup, escape

from gecgen.model.files import write_atomically
from gecgen.report.blocks import Bullets, Figure, Report, Table

HERE = Path(__file__).resolve().parent


def inline(text: str) -> Markup:
    """Escaped text with the Markdown the reports use inline: `code` and **strong**."""
    out = str(escape(text))
    out = re.sub(r"`([^`]+)`", r"<code>\1</code>", out)
    return Markup(re.sub(r"\*\*([^*]+)\*\*", r"<strong>\1</strong>", out))


def numeric(cell: str) -> bool:
    """A table cell that reads as a number (right-aligned, in tabular figures): it starts with a
    figure, a minus sign before one, or is "-" (a figure not known); "0 %", "-0.28 to 0.28 m" too."""
    return re.match(r"-?\.?[0-9]|-$", cell) is not None


def _kind(block) -> str:
    return {Table: "table", Bullets: "bullets", Figure: "figure"}.get(type(block), "text")


def render(report: Report) -> str:
    env = jinja2.Environment(loader=jinja2.FileSystemLoader(HERE / "templates"), autoescape=True,
                             trim_blocks=True, lstrip_blocks=True, undefined=jinja2.StrictUndefined)
    env.filters["inline"] = inline
    env.filters["kind"] = _kind
    env.tests["numeric"] = numeric
    env.filters["base64"] = lambda png: base64.b64encode(png).decode("ascii")
    env.filters["anchor"] = lambda title: re.sub(r"[^a-z0-9]+", "-", title.lower()).strip("-")
    return env.get_template("report.html.j2").render(report=report)


def write(report: Report, outdir: Path) -> Path:
    """report.html in outdir; returns its path."""
    return write_atomically(outdir / "report.html", render(report))
