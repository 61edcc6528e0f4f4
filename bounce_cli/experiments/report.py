"""Self-contained HTML reports (``bounce study``'s ``report.html``): figures embedded as PNG
data, tables as HTML, no scripts, no network: the file opens from the file system anywhere."""

from __future__ import annotations

import base64
import html
import math
from dataclasses import dataclass, field

import pandas as pd

STYLE = """
body { font-family: -apple-system, 'Segoe UI', Helvetica, Arial, sans-serif; margin: 2em auto;
       max-width: 1100px; color: #222; line-height: 1.4; padding: 0 1em; }
h1 { border-bottom: 2px solid #444; padding-bottom: .2em; }
h2 { border-bottom: 1px solid #bbb; padding-bottom: .1em; margin-top: 2em; }
div.table { overflow-x: auto; max-width: 100%; margin: .5em 0 1em; }
table { border-collapse: collapse; font-size: 12px; }
th, td { border: 1px solid #ccc; padding: 2px 6px; text-align: right; white-space: nowrap; }
th { background: #f0f0f0; }
td.text { text-align: left; }
figure { margin: 1em 0; }
figure img { max-width: 100%; height: auto; border: 1px solid #ddd; }
figcaption { font-size: 12px; color: #555; }
.warn { color: #a40; font-weight: bold; }
nav a { margin-right: 1em; }
"""


@dataclass
class Section:
    """A titled part of a report: HTML fragments in order."""

    title: str
    parts: list[str] = field(default_factory=list)

    @property
    def anchor(self) -> str:
        return "".join(c if c.isalnum() else "-" for c in self.title.lower()).strip("-")


def embed_png(data: bytes, caption: str) -> str:
    """A figure as an ``<img>`` holding its PNG bytes (no file beside the report needed)."""
    encoded = base64.b64encode(data).decode("ascii")
    return (f"<figure><img alt='{html.escape(caption)}' src='data:image/png;base64,{encoded}'>"
            f"<figcaption>{html.escape(caption)}</figcaption></figure>")


def _cell(value, digits: int) -> tuple[str, bool]:
    if isinstance(value, float):
        if math.isnan(value):
            return "", False
        return f"{value:.{digits}g}", False
    if isinstance(value, (bool,)) or value is None:
        return html.escape(str(value)), True
    if isinstance(value, int):
        return str(value), False
    return html.escape(str(value)), True


def html_table(frame: pd.DataFrame, digits: int = 6, max_rows: int = 200) -> str:
    """A DataFrame as an HTML table (floats to ``digits`` significant digits, NaN empty), in a
    box that scrolls sideways where the table is wider than the page."""
    head = "".join(f"<th>{html.escape(str(c))}</th>" for c in frame.columns)
    rows = []
    for record in frame.head(max_rows).itertuples(index=False):
        cells = []
        for value in record:
            text, is_text = _cell(value.item() if hasattr(value, "item") else value, digits)
            cells.append(f"<td class='text'>{text}</td>" if is_text else f"<td>{text}</td>")
        rows.append("<tr>" + "".join(cells) + "</tr>")
    more = (f"<p>({len(frame) - max_rows} more rows in the CSV)</p>"
            if len(frame) > max_rows else "")
    # the table scrolls inside its box on a narrow screen, the page itself does not
    return f"<div class='table'><table><tr>{head}</tr>{''.join(rows)}</table></div>{more}"


def page(title: str, sections: list[Section]) -> str:
    """The whole HTML document: a title, a table of contents, the sections."""
    nav = " ".join(f"<a href='#{s.anchor}'>{html.escape(s.title)}</a>" for s in sections)
    body = "\n".join(f"<section id='{s.anchor}'><h2>{html.escape(s.title)}</h2>\n"
                     + "\n".join(s.parts) + "</section>" for s in sections)
    return (f"<!DOCTYPE html>\n<html lang='en'><head><meta charset='utf-8'>"
            f"<title>{html.escape(title)}</title><style>{STYLE}</style></head><body>"
            f"<h1>{html.escape(title)}</h1><nav>{nav}</nav>\n{body}\n</body></html>\n")
