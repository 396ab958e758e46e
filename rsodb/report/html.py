"""Self-contained HTML documents: headings, paragraphs, tables and embedded PNG figures.

A `Document` is immutable; `add` returns a new document with more blocks, and `to_html`
renders one file with no external references (figures are base64 PNGs in ``<img>`` tags,
the style sheet is inline), so a report can be mailed or archived as it is.

>>> doc = Document("Spin periods").add(Heading("Summary"), Paragraph("3 passes."))
>>> '<h2 id="summary">Summary</h2>' in doc.to_html()
True
"""

from __future__ import annotations

import base64
from dataclasses import dataclass, field
import html
import io
import os
from pathlib import Path
import tempfile

import numpy as np

from rsodb.plotting import pyplot

__all__ = ["Document", "Heading", "Paragraph", "Figure", "Table", "Link", "Raw", "figure_from_matplotlib", "anchor"]

_STYLE = """
body { font-family: -apple-system, "Segoe UI", Helvetica, Arial, sans-serif; margin: 2em auto;
       max-width: 1200px; color: #222; line-height: 1.4; padding: 0 1em; }
h1 { font-size: 1.6em; border-bottom: 2px solid #444; padding-bottom: .2em; }
h2 { font-size: 1.3em; margin-top: 1.6em; border-bottom: 1px solid #bbb; }
h3 { font-size: 1.1em; margin-top: 1.2em; }
table { border-collapse: collapse; font-size: .85em; margin: .8em 0; }
th, td { border: 1px solid #ccc; padding: .25em .5em; text-align: left; vertical-align: top; }
th { background: #f0f0f0; }
td.num { text-align: right; font-variant-numeric: tabular-nums; }
figure { margin: 1em 0; }
figure img { max-width: 100%; border: 1px solid #ddd; }
figcaption { font-size: .85em; color: #555; }
.meta { color: #666; font-size: .85em; }
table.sortable th { cursor: pointer; user-select: none; }
table.sortable th::after { content: " \\2195"; color: #999; font-size: .8em; }
.trust-high { background: #e3f4e3; } .trust-medium { background: #fdf3d8; }
.trust-low { background: #fbe0dc; } .trust-none { background: #eee; }
"""

# Click a header of a sortable table to sort by that column (again: reverse). Cells that read
# as numbers sort as numbers; cells without a value ("-") sort last either way.
_SORT_SCRIPT = """
document.querySelectorAll("table.sortable").forEach(function (table) {
  table.querySelectorAll("th").forEach(function (th, column) {
    th.addEventListener("click", function () {
      var body = table.tBodies[0], rows = Array.from(body.rows);
      var up = th.dataset.order !== "up";
      table.querySelectorAll("th").forEach(function (h) { delete h.dataset.order; });
      th.dataset.order = up ? "up" : "down";
      function key(row) {
        var text = row.cells[column].dataset.sort || row.cells[column].textContent.trim();
        var number = parseFloat(text);
        return text === "-" || text === "" ? null : (isNaN(number) ? text.toLowerCase() : number);
      }
      rows.sort(function (a, b) {
        var x = key(a), y = key(b);
        if (x === null || y === null) { return (x === null) - (y === null); }
        if (typeof x !== typeof y) { x = String(x); y = String(y); }
        return (x < y ? -1 : x > y ? 1 : 0) * (up ? 1 : -1);
      });
      rows.forEach(function (row) { body.appendChild(row); });
    });
  });
});
"""


@dataclass(frozen=True)
class Heading:
    """A section title; level 2 (section) or 3 (subsection)."""

    text: str
    level: int = 2

    def to_html(self) -> str:
        level = min(max(int(self.level), 1), 6)
        ident = f' id="{html.escape(anchor(self.text))}"' if level <= 3 else ""
        return f"<h{level}{ident}>{html.escape(self.text)}</h{level}>"


@dataclass(frozen=True)
class Paragraph:
    """Plain text (escaped); `css_class` styles it (e.g. ``"meta"``)."""

    text: str
    css_class: str = ""

    def to_html(self) -> str:
        cls = f' class="{html.escape(self.css_class)}"' if self.css_class else ""
        return f"<p{cls}>{html.escape(self.text)}</p>"


@dataclass(frozen=True)
class Raw:
    """Trusted HTML inserted as is (for links and lists built by the report code)."""

    markup: str

    def to_html(self) -> str:
        return self.markup


@dataclass(frozen=True)
class Figure:
    """A PNG image embedded as base64, with a caption."""

    png: bytes
    caption: str = ""
    alt: str = ""

    def to_html(self) -> str:
        data = base64.b64encode(self.png).decode("ascii")
        caption = f"<figcaption>{html.escape(self.caption)}</figcaption>" if self.caption else ""
        alt = html.escape(self.alt or self.caption or "figure")
        return f'<figure><img src="data:image/png;base64,{data}" alt="{alt}">{caption}</figure>'


@dataclass(frozen=True)
class Link:
    """A table cell that links to `href` (another report, or an anchor in one)."""

    text: str
    href: str

    def __str__(self) -> str:
        return self.text

    def to_html(self) -> str:
        return f'<a href="{html.escape(self.href)}">{html.escape(self.text)}</a>'


def _cell_html(cell) -> str:
    return cell.to_html() if isinstance(cell, Link) else html.escape(cell)


@dataclass(frozen=True)
class Table:
    """A table of text cells; columns listed in `numeric` are right-aligned.

    A `sortable` table sorts by a column when its header is clicked. `row_classes` gives each
    row a CSS class (e.g. ``"trust-low"``), or is empty.
    """

    columns: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]
    caption: str = ""
    numeric: frozenset[int] = field(default_factory=frozenset)
    sortable: bool = False
    row_classes: tuple[str, ...] = ()

    def __post_init__(self):
        object.__setattr__(self, "columns", tuple(str(c) for c in self.columns))
        rows = tuple(tuple(cell if isinstance(cell, Link) else str(cell) for cell in row) for row in self.rows)
        for i, row in enumerate(rows):
            if len(row) != len(self.columns):
                raise ValueError(f"table row {i} has {len(row)} cells but there are {len(self.columns)} columns")
        object.__setattr__(self, "rows", rows)
        object.__setattr__(self, "numeric", frozenset(self.numeric))
        object.__setattr__(self, "row_classes", tuple(self.row_classes))
        if self.row_classes and len(self.row_classes) != len(rows):
            raise ValueError(f"{len(self.row_classes)} row classes for {len(rows)} rows")

    @classmethod
    def from_pandas(cls, frame, caption: str = "", float_format: str = "{:.4g}") -> Table:
        """A table from a DataFrame (index dropped; numeric columns formatted and right-aligned)."""
        numeric = frozenset(i for i, dtype in enumerate(frame.dtypes) if np.issubdtype(dtype, np.number))
        rows = tuple(
            tuple(
                float_format.format(v) if i in numeric and isinstance(v, float) else str(v)
                for i, v in enumerate(record)
            )
            for record in frame.itertuples(index=False)
        )
        return cls(tuple(frame.columns), rows, caption, numeric)

    def to_html(self) -> str:
        head = "".join(f"<th>{html.escape(c)}</th>" for c in self.columns)
        classes = self.row_classes or ("",) * len(self.rows)
        body = "\n".join(
            (f'<tr class="{html.escape(css)}">' if css else "<tr>")
            + "".join(
                f'<td class="num">{_cell_html(cell)}</td>' if i in self.numeric else f"<td>{_cell_html(cell)}</td>"
                for i, cell in enumerate(row)
            )
            + "</tr>"
            for row, css in zip(self.rows, classes)
        )
        caption = f"<caption>{html.escape(self.caption)}</caption>" if self.caption else ""
        opening = '<table class="sortable">' if self.sortable else "<table>"
        return f"{opening}{caption}<thead><tr>{head}</tr></thead><tbody>\n{body}\n</tbody></table>"


Block = Heading | Paragraph | Figure | Table | Raw


@dataclass(frozen=True)
class Document:
    """An HTML report: a title and a sequence of blocks.

    Attributes
    ----------
    title : str
    blocks : tuple
        `Heading`, `Paragraph`, `Figure`, `Table` or `Raw` objects, in order.
    """

    title: str
    blocks: tuple = ()

    def add(self, *blocks) -> Document:
        """A new document with `blocks` appended."""
        for block in blocks:
            if not callable(getattr(block, "to_html", None)):
                raise TypeError(
                    f"{type(block).__name__} is not a report block; use Heading, Paragraph, Figure, Table or Raw"
                )
        return Document(self.title, self.blocks + tuple(blocks))

    def extend(self, other: Document) -> Document:
        """A new document with the blocks of `other` appended (its title dropped)."""
        return Document(self.title, self.blocks + other.blocks)

    def table_of_contents(self) -> str:
        """A list of links to the level-2 headings."""
        items = "".join(
            f'<li><a href="#{html.escape(anchor(b.text))}">{html.escape(b.text)}</a></li>'
            for b in self.blocks
            if isinstance(b, Heading) and b.level == 2
        )
        return f"<ul>{items}</ul>" if items else ""

    def to_html(self) -> str:
        """The whole page as one string."""
        body = "\n".join(block.to_html() for block in self.blocks)
        if any(isinstance(block, Table) and block.sortable for block in self.blocks):
            body += f"\n<script>{_SORT_SCRIPT}</script>"
        return (
            '<!DOCTYPE html>\n<html lang="en">\n<head>\n<meta charset="utf-8">\n'
            f"<title>{html.escape(self.title)}</title>\n<style>{_STYLE}</style>\n</head>\n<body>\n"
            f"<h1>{html.escape(self.title)}</h1>\n{body}\n</body>\n</html>\n"
        )

    def write(self, path) -> Path:
        """Write the page to `path` atomically (a temporary file renamed into place); returns the path."""
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        handle, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
        try:
            with os.fdopen(handle, "w", encoding="utf-8") as stream:
                stream.write(self.to_html())
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(tmp, 0o666 & ~umask)  # mkstemp creates 0600; a report is for sharing
            os.replace(tmp, path)
        except BaseException:
            Path(tmp).unlink(missing_ok=True)
            raise
        return path


def figure_from_matplotlib(fig, caption: str = "", dpi: int = 110) -> Figure:
    """Render a matplotlib figure to an embedded PNG `Figure` and close it."""
    buffer = io.BytesIO()
    fig.savefig(buffer, format="png", dpi=dpi, bbox_inches="tight")
    pyplot().close(fig)
    return Figure(buffer.getvalue(), caption)


def anchor(text: str) -> str:
    """The id a heading with this text gets (for links within the page)."""
    return "".join(c.lower() if c.isalnum() else "-" for c in text).strip("-") or "section"
