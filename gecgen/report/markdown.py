"""A report as Markdown: report.md, each figure a PNG file beside it."""
from __future__ import annotations

from pathlib import Path

from gecgen.model.files import write_atomically
from gecgen.report.blocks import Bullets, Figure, Report, Table


def _block(block, outdir: Path) -> list[str]:
    if isinstance(block, Table):
        return [f"| {' | '.join(block.header)} |", f"|{'---|' * len(block.header)}",
                *(f"| {' | '.join(row)} |" for row in block.rows), ""]
    if isinstance(block, Bullets):
        return [*(f"- {item}" for item in block.items), ""]
    if isinstance(block, Figure):
        write_atomically(outdir / f"{block.name}.png", block.png)
        return [f"![{block.caption}]({block.name}.png)", ""]
    return [block, ""]


def write(report: Report, outdir: Path) -> Path:
    """report.md and its PNG figures in outdir; returns the Markdown path."""
    lines = [f"# {report.title}", ""]
    for text in report.intro:
        lines += [text, ""]
    lines += ["The same report with its figures embedded: `report.html`.", ""]
    for section in report.sections:
        lines += [f"## {section.title}", ""]
        for block in section.blocks:
            lines += _block(block, outdir)
    return write_atomically(outdir / "report.md", "\n".join(lines))
