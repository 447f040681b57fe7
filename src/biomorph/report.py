"""HTML report assembled from sections (used by ``biomorph demo`` and batch commands).

Images are referenced relative to the report so the output folder can be moved or zipped.
"""

from __future__ import annotations

import html
import os
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from biomorph.io.atomic import write_text


@dataclass
class Table:
    """A small table: header row and rows of already formatted cells."""

    header: Sequence[str]
    rows: Sequence[Sequence[object]]
    caption: str = ""


@dataclass
class Section:
    """One block of the report: a title, a paragraph, pictures and tables."""

    title: str
    text: str = ""
    images: list[Path] = field(default_factory=list)
    tables: list[Table] = field(default_factory=list)
    files: list[Path] = field(default_factory=list)


def _cell(v: object) -> str:
    if isinstance(v, float):
        return f"{v:.4g}"
    return html.escape(str(v))


def render_html(sections: Sequence[Section], base: Path, title: str = "biomorph report") -> str:
    """HTML text of a report whose relative links resolve from folder ``base``."""
    parts = [
        "<!doctype html><html><head><meta charset='utf-8'>",
        f"<title>{html.escape(title)}</title>",
        "<style>body{font-family:system-ui,sans-serif;max-width:1200px;margin:2em auto;"
        "padding:0 1em;color:#222}img{max-width:100%;border:1px solid #ddd;margin:.5em 0}"
        "table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #ccc;"
        "padding:.2em .6em;text-align:right}th{background:#f4f4f4}"
        "caption{caption-side:top;text-align:left;font-style:italic}"
        "section{border-top:2px solid #eee;margin-top:1.5em}</style></head><body>",
        f"<h1>{html.escape(title)}</h1>",
    ]
    if sections:
        parts.append(
            "<ul>"
            + "".join(
                f"<li><a href='#s{i}'>{html.escape(s.title)}</a></li>"
                for i, s in enumerate(sections)
            )
            + "</ul>"
        )
    for i, sec in enumerate(sections):
        parts.append(f"<section id='s{i}'><h2>{html.escape(sec.title)}</h2>")
        if sec.text:
            parts.extend(f"<p>{html.escape(p)}</p>" for p in sec.text.split("\n\n"))
        for img in sec.images:
            rel = os.path.relpath(Path(img), base)
            alt = html.escape(Path(img).stem)
            parts.append(
                f"<figure><img src='{html.escape(rel)}' alt='{alt}'>"
                f"<figcaption>{html.escape(Path(img).name)}</figcaption></figure>"
            )
        for tab in sec.tables:
            parts.append("<table>")
            if tab.caption:
                parts.append(f"<caption>{html.escape(tab.caption)}</caption>")
            parts.append(
                "<tr>" + "".join(f"<th>{html.escape(str(h))}</th>" for h in tab.header) + "</tr>"
            )
            for row in tab.rows:
                parts.append("<tr>" + "".join(f"<td>{_cell(c)}</td>" for c in row) + "</tr>")
            parts.append("</table>")
        if sec.files:
            parts.append(
                "<p>Files: "
                + ", ".join(
                    f"<a href='{html.escape(os.path.relpath(Path(f), base))}'>"
                    f"{html.escape(Path(f).name)}</a>"
                    for f in sec.files
                )
                + "</p>"
            )
        parts.append("</section>")
    parts.append("</body></html>")
    return "\n".join(parts)


def write_report(
    path: str | os.PathLike[str], sections: Sequence[Section], title: str = "biomorph report"
) -> Path:
    """Write ``sections`` as an HTML report at ``path`` (atomically)."""
    p = Path(path)
    return write_text(p, render_html(sections, p.parent, title))
