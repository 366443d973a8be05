"""A small HTML writer for reports: sections, captioned figure grids, tables, notes.

Pictures are PNG files beside ``report.html``, referenced by relative file name, so the output
folder is self-contained (it can be moved, zipped or served as is), the HTML stays small, and
every figure is also usable on its own. The page loads nothing from the network; its style is
inline.
"""

from __future__ import annotations

import html
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

_STYLE = """
body { font-family: system-ui, -apple-system, "Segoe UI", sans-serif; margin: 2em auto;
       max-width: 1400px; padding: 0 1.5em; color: #222; line-height: 1.45; }
h1 { margin-bottom: 0.1em; } h2 { border-bottom: 1px solid #ddd; padding-bottom: 0.2em;
     margin-top: 1.8em; }
.subtitle { color: #666; margin-top: 0; }
.grid { display: grid; gap: 1em; align-items: start; }
.cols1 { grid-template-columns: 1fr; } .cols2 { grid-template-columns: repeat(2, 1fr); }
.cols3 { grid-template-columns: repeat(3, 1fr); } .cols4 { grid-template-columns: repeat(4, 1fr); }
figure { margin: 0; } figure img { width: 100%; height: auto; border: 1px solid #ddd;
         image-rendering: auto; }
figcaption { font-size: 0.9em; color: #444; margin-top: 0.3em; }
table { border-collapse: collapse; font-size: 0.92em; margin: 0.5em 0; }
th, td { border: 1px solid #ddd; padding: 0.25em 0.6em; text-align: right; }
th { background: #f4f4f4; } td.l, th.l { text-align: left; }
.swatch { display: inline-block; width: 1em; height: 1em; border: 1px solid #888;
          vertical-align: middle; margin-right: 0.3em; }
.warn { background: #fff4e0; border-left: 4px solid #e69500; padding: 0.6em 1em; }
pre { background: #f7f7f7; padding: 0.8em; overflow-x: auto; font-size: 0.85em; }
"""


def esc(text: object) -> str:
    """HTML-escape any value's string form."""
    return html.escape(str(text))


@dataclass
class Figure:
    """A picture in a grid.

    Attributes
    ----------
    src : str
        File name relative to the report (a PNG beside it).
    caption : str
        Plain-text caption.
    """

    src: str
    caption: str


def figure_grid(figures: Sequence[Figure], columns: int = 2) -> str:
    """Figures in a responsive grid with captions."""
    cells = "".join(
        f'<figure><a href="{esc(f.src)}"><img src="{esc(f.src)}" alt="{esc(f.caption)}" '
        f'loading="lazy"></a><figcaption>{esc(f.caption)}</figcaption></figure>'
        for f in figures
    )
    return f'<div class="grid cols{max(1, min(columns, 4))}">{cells}</div>'


def table(header: Sequence[str], rows: Sequence[Sequence[object]], raw: bool = False,
          left: int = 1) -> str:
    """A table; the first ``left`` columns are left-aligned, the rest right-aligned.

    Cells are escaped unless ``raw`` is true (for cells that carry their own markup, such as
    colour swatches, which the caller must escape itself).
    """
    def cell(tag: str, i: int, value: object) -> str:
        cls = ' class="l"' if i < left else ""
        return f"<{tag}{cls}>{value if raw else esc(value)}</{tag}>"

    head = "".join(cell("th", i, esc(h) if raw else h) for i, h in enumerate(header))
    body = "".join(
        "<tr>" + "".join(cell("td", i, v) for i, v in enumerate(row)) + "</tr>" for row in rows
    )
    return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"


def swatch(rgb: Sequence[int]) -> str:
    """A small coloured square (markup) for an RGB colour."""
    r, g, b = (int(c) for c in rgb)
    return f'<span class="swatch" style="background: rgb({r},{g},{b})"></span>'


def bullet_list(items: Sequence[str]) -> str:
    """An escaped bullet list (empty string for no items)."""
    if not items:
        return ""
    return "<ul>" + "".join(f"<li>{esc(i)}</li>" for i in items) + "</ul>"


def warning(text: str) -> str:
    """A highlighted message box (e.g. why 3D views are missing)."""
    return f'<p class="warn">{esc(text)}</p>'


def section(title: str, body: str) -> str:
    """A titled section (``body`` is markup)."""
    return f"<section><h2>{esc(title)}</h2>{body}</section>"


def paragraph(text: str) -> str:
    """An escaped paragraph."""
    return f"<p>{esc(text)}</p>"


def preformatted(text: str, summary: str) -> str:
    """Collapsed preformatted text (e.g. the resolved config)."""
    return f"<details><summary>{esc(summary)}</summary><pre>{esc(text)}</pre></details>"


def write_page(path: Path, title: str, subtitle: str, sections: Sequence[str]) -> Path:
    """Write a complete HTML page and return its path."""
    doc = (
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
        f"<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
        f"<title>{esc(title)}</title><style>{_STYLE}</style></head><body>"
        f"<h1>{esc(title)}</h1><p class=\"subtitle\">{esc(subtitle)}</p>"
        + "".join(sections)
        + "</body></html>\n"
    )
    path = Path(path)
    path.write_text(doc, encoding="utf-8")
    return path
