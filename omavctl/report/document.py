"""The report as a document: format-neutral blocks, written out as HTML or Markdown.

A report is first built as a :class:`Document`, a title and a list of blocks
(headings, paragraphs, bulleted lists, tables, figures, code), and then written
by :func:`to_html` (one self-contained page: inline CSS, figures embedded as
base64 PNG, nothing that refers to the network) or :func:`to_markdown` (the
same content; figures are left out and say so). Both writers escape every
string they are given, so blocks may carry text straight from an input file.
"""

from __future__ import annotations

import base64
import html
import re
from dataclasses import dataclass, field

__all__ = [
    "Block",
    "Bullets",
    "Cell",
    "Code",
    "Content",
    "Document",
    "FigureBlock",
    "Heading",
    "Inline",
    "Lines",
    "Para",
    "Span",
    "Table",
    "to_html",
    "to_markdown",
]


# ------------------------------------------------------------------ blocks
@dataclass(frozen=True)
class Span:
    """Inline text with a style: '' plain, 'code', 'strong' or 'em'."""

    text: str
    style: str = ""


Inline = str | Span
#: A table cell or a paragraph: one inline or a sequence of them; a cell may
#: also be a list of lines (:class:`Lines`).
Content = Inline | tuple[Inline, ...]


@dataclass(frozen=True)
class Lines:
    """A table cell of several lines."""

    lines: tuple[Content, ...]


Cell = Content | Lines


@dataclass
class Heading:
    """A heading of ``level`` 1-4; ``anchor`` its id for in-page links."""

    level: int
    text: str
    anchor: str | None = None


@dataclass
class Para:
    """A paragraph; ``note`` paragraphs are shown muted."""

    content: Content
    note: bool = False


@dataclass
class Bullets:
    """A bulleted list."""

    items: list[Content]


@dataclass
class Table:
    """A table; ``groups`` (title, span) is an optional header row above ``columns``.
    ``align`` has one letter per column, 'l' (text), 'r' (numbers, kept on one line)
    or 'w' (numbers followed by words, right-aligned and wrapped: an effect's parameters
    with why they are not pinned down); default: the first column left, the others
    right."""

    columns: list[str]
    rows: list[list[Cell]]
    groups: list[tuple[str, int]] | None = None
    align: str | None = None

    def right(self, i: int) -> bool:
        """Whether column ``i`` is right-aligned."""
        return self.align[i] in "rw" if self.align else i > 0

    def wraps(self, i: int) -> bool:
        """Whether column ``i`` is right-aligned text that may wrap."""
        return self.align is not None and self.align[i] == "w"

    caption: str | None = None


@dataclass
class FigureBlock:
    """An embedded PNG figure with its alt text and caption."""

    png: bytes
    alt: str
    caption: str


@dataclass
class Code:
    """A preformatted block (a command to copy)."""

    text: str


Block = Heading | Para | Bullets | Table | FigureBlock | Code


@dataclass
class Document:
    """The report: a title and its blocks in order."""

    title: str
    blocks: list[Block] = field(default_factory=list)

    def add(self, *blocks: Block) -> None:
        """Append ``blocks`` in order."""
        self.blocks.extend(blocks)


# -------------------------------------------------------------------- HTML
CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,Helvetica,Arial,sans-serif;
margin:0 auto;max-width:1240px;padding:1em 1.5em;color:#222;line-height:1.4;
overflow-wrap:break-word}
@media (max-width:900px){body{padding:.5em .8em}}
h1{font-size:1.6em}h2{border-bottom:1px solid #ccc;margin-top:2em}h3{margin-top:1.5em}
div.tw{max-width:100%;overflow-x:auto}
table{border-collapse:collapse;margin:.6em 0;font-size:.85em}
th,td{border:1px solid #ccc;padding:.2em .5em;vertical-align:top;text-align:left}
th{background:#f2f2f2}td.n{text-align:right;font-variant-numeric:tabular-nums;white-space:nowrap}
td.w{text-align:right;font-variant-numeric:tabular-nums;min-width:16em;max-width:30em}
pre{background:#f6f6f6;border:1px solid #ddd;padding:.6em;white-space:pre-wrap;
overflow-wrap:anywhere}
code{font-family:ui-monospace,Menlo,Consolas,monospace;font-size:.95em}
figure{margin:1em 0}figure img{max-width:100%;height:auto}
figcaption{font-size:.85em;color:#555}p.note{color:#555;font-style:italic}
""".strip()


def _html_inline(c: Content) -> str:
    if isinstance(c, tuple):
        return "".join(_html_inline(x) for x in c)
    if isinstance(c, str):
        return html.escape(c)
    text = html.escape(c.text)
    if c.style == "code":
        return f"<code>{text}</code>"
    if c.style == "strong":
        return f"<strong>{text}</strong>"
    if c.style == "em":
        return f"<em>{text}</em>"
    if c.style == "link":
        anchor, _, title = c.text.partition("|")
        return f'<a href="{html.escape(anchor)}">{html.escape(title)}</a>'
    return text


def _html_cell(c: Cell) -> str:
    if isinstance(c, Lines):
        return "<br>".join(_html_inline(x) for x in c.lines)
    return _html_inline(c)


def _html_table(t: Table) -> str:
    out = ['<div class="tw"><table>']
    if t.caption:
        out.append(f"<caption>{html.escape(t.caption)}</caption>")
    out.append("<thead>")
    if t.groups:
        cells = "".join(
            f'<th colspan="{span}">{html.escape(title)}</th>'
            if span > 1
            else f"<th>{html.escape(title)}</th>"
            for title, span in t.groups
        )
        out.append(f"<tr>{cells}</tr>")
    out.append("<tr>" + "".join(f"<th>{html.escape(c)}</th>" for c in t.columns) + "</tr>")
    out.append("</thead><tbody>")
    for row in t.rows:
        cells = "".join(
            f'<td class="{"w" if t.wraps(i) else "n"}">{_html_cell(c)}</td>'
            if t.right(i)
            else f"<td>{_html_cell(c)}</td>"
            for i, c in enumerate(row)
        )
        out.append(f"<tr>{cells}</tr>")
    out.append("</tbody></table></div>")
    return "\n".join(out)


def to_html(doc: Document) -> str:
    """``doc`` as one self-contained HTML page (inline CSS, figures as base64 PNG)."""
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en">',
        "<head>",
        '<meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>{html.escape(doc.title)}</title>",
        f"<style>\n{CSS}\n</style>",
        "</head>",
        "<body>",
    ]
    for b in doc.blocks:
        if isinstance(b, Heading):
            anchor = f' id="{html.escape(b.anchor)}"' if b.anchor else ""
            parts.append(f"<h{b.level}{anchor}>{html.escape(b.text)}</h{b.level}>")
        elif isinstance(b, Para):
            cls = ' class="note"' if b.note else ""
            parts.append(f"<p{cls}>{_html_inline(b.content)}</p>")
        elif isinstance(b, Bullets):
            items = "".join(f"<li>{_html_inline(i)}</li>" for i in b.items)
            parts.append(f"<ul>{items}</ul>")
        elif isinstance(b, Table):
            parts.append(_html_table(b))
        elif isinstance(b, FigureBlock):
            data = base64.b64encode(b.png).decode("ascii")
            parts.append(
                f'<figure><img src="data:image/png;base64,{data}" alt="{html.escape(b.alt)}">'
                f"<figcaption>{html.escape(b.caption)}</figcaption></figure>"
            )
        elif isinstance(b, Code):
            parts.append(f"<pre><code>{html.escape(b.text)}</code></pre>")
    parts += ["</body>", "</html>", ""]
    return "\n".join(parts)


# ---------------------------------------------------------------- Markdown
_MD_SPECIAL = re.compile(r"([\\`*_\[\]#|])")


def _md_text(s: str, in_table: bool = False) -> str:
    s = _MD_SPECIAL.sub(r"\\\1", html.escape(s, quote=False))
    return s.replace("\n", " ") if in_table else s


def _md_code(s: str, in_table: bool) -> str:
    fence = "``" if "`" in s else "`"
    s = s.replace("|", "\\|") if in_table else s
    return f"{fence}{s}{fence}" if fence == "`" else f"{fence} {s} {fence}"


def _md_inline(c: Content, in_table: bool = False) -> str:
    if isinstance(c, tuple):
        return "".join(_md_inline(x, in_table) for x in c)
    if isinstance(c, str):
        return _md_text(c, in_table)
    if c.style == "code":
        return _md_code(c.text, in_table)
    if c.style in ("strong", "em"):
        # emphasis markers must touch the text: keep surrounding spaces outside
        core = c.text.strip()
        lead, trail = c.text[: len(c.text) - len(c.text.lstrip())], c.text[len(c.text.rstrip()) :]
        mark = "**" if c.style == "strong" else "*"
        return f"{lead}{mark}{_md_text(core, in_table)}{mark}{trail}" if core else c.text
    if c.style == "link":
        anchor, _, title = c.text.partition("|")
        return f"[{_md_text(title)}]({anchor})"
    return _md_text(c.text, in_table)


def _md_cell(c: Cell) -> str:
    if isinstance(c, Lines):
        return "<br>".join(_md_inline(x, True) for x in c.lines)
    return _md_inline(c, True)


def _md_table(t: Table) -> str:
    columns = list(t.columns)
    if t.groups:
        titles = [title for title, span in t.groups for _ in range(span)]
        columns = [f"{g} {c}".strip() for g, c in zip(titles, columns, strict=True)]
    lines = ["| " + " | ".join(_md_text(c, True) for c in columns) + " |"]
    lines.append("|" + "|".join("---:" if t.right(i) else "---" for i in range(len(columns))) + "|")
    for row in t.rows:
        lines.append("| " + " | ".join(_md_cell(c) for c in row) + " |")
    return "\n".join(lines)


def to_markdown(doc: Document) -> str:
    """``doc`` as Markdown: the same blocks; each figure is replaced by a note."""
    parts: list[str] = []
    for b in doc.blocks:
        if isinstance(b, Heading):
            anchor = f'<a id="{html.escape(b.anchor)}"></a>\n' if b.anchor else ""
            parts.append(f"{anchor}{'#' * b.level} {_md_text(b.text)}")
            if b.level == 1:
                parts.append(
                    "*Markdown version: the figures are only in the HTML report "
                    "(`omavctl report ... --format html`).*"
                )
        elif isinstance(b, Para):
            text = _md_inline(b.content)
            parts.append(f"*{text}*" if b.note else text)
        elif isinstance(b, Bullets):
            parts.append("\n".join(f"- {_md_inline(i)}" for i in b.items))
        elif isinstance(b, Table):
            parts.append(_md_table(b))
        elif isinstance(b, FigureBlock):
            caption = _md_text(b.caption.rstrip("."))
            parts.append(f"*Figure not available in Markdown: {caption}.*")
        elif isinstance(b, Code):
            fence = "````" if "```" in b.text else "```"
            parts.append(f"{fence}\n{b.text}\n{fence}")
    return "\n\n".join(parts) + "\n"
