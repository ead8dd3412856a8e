"""A small document model rendered both as Markdown and as self-contained HTML, so the two
report formats always say the same thing. No frames here."""

from __future__ import annotations

import html
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

Cell = str | int | float | None


def fmt(value: Cell, digits: int = 1) -> str:
    """A table cell: None/NaN as an en dash, floats with ``digits`` decimals."""
    if value is None:
        return "–"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        if not math.isfinite(value):
            return "–"
        return f"{value:.{digits}f}"
    return str(value)


@dataclass(frozen=True, slots=True)
class Table:
    headers: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]


@dataclass(frozen=True, slots=True)
class Image:
    file: str
    """Relative to the document."""
    caption: str


@dataclass(frozen=True, slots=True)
class Paragraph:
    text: str


@dataclass(frozen=True, slots=True)
class Bullets:
    items: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class Code:
    text: str


Block = Table | Image | Paragraph | Bullets | Code


@dataclass
class Section:
    title: str
    blocks: list[Block] = field(default_factory=list)

    def table(self, headers: Sequence[str], rows: Sequence[Sequence[str]]) -> None:
        self.blocks.append(Table(tuple(headers), tuple(tuple(r) for r in rows)))

    def para(self, text: str) -> None:
        self.blocks.append(Paragraph(text))

    def bullets(self, items: Sequence[str]) -> None:
        self.blocks.append(Bullets(tuple(items)))

    def image(self, file: str, caption: str) -> None:
        self.blocks.append(Image(file, caption))

    def code(self, text: str) -> None:
        self.blocks.append(Code(text))


@dataclass
class Document:
    title: str
    sections: list[Section] = field(default_factory=list)

    def section(self, title: str) -> Section:
        s = Section(title)
        self.sections.append(s)
        return s

    def markdown(self) -> str:
        out = [f"# {self.title}", ""]
        for s in self.sections:
            out += [f"## {s.title}", ""]
            for b in s.blocks:
                out += [*_md_block(b), ""]
        return "\n".join(out).rstrip() + "\n"

    def html(self) -> str:
        e = html.escape
        out = ["<!DOCTYPE html>", "<html lang=\"en\"><head><meta charset=\"utf-8\">",
               f"<title>{e(self.title)}</title>", f"<style>{_CSS}</style></head><body>",
               f"<h1>{e(self.title)}</h1>"]
        for s in self.sections:
            out.append(f"<h2>{e(s.title)}</h2>")
            out += [_html_block(b) for b in s.blocks]
        out.append("</body></html>")
        return "\n".join(out) + "\n"


def _md_cell(text: str) -> str:
    return text.replace("|", "\\|").replace("\n", " ")


def _md_block(b: Block) -> list[str]:
    if isinstance(b, Table):
        lines = ["| " + " | ".join(_md_cell(h) for h in b.headers) + " |",
                 "|" + "|".join("---" for _ in b.headers) + "|"]
        lines += ["| " + " | ".join(_md_cell(c) for c in row) + " |" for row in b.rows]
        return lines
    if isinstance(b, Image):
        return [f"![{b.caption}]({b.file})", "", f"*{b.caption}*"]
    if isinstance(b, Paragraph):
        return [b.text]
    if isinstance(b, Bullets):
        return [f"- {item}" for item in b.items]
    return ["```", b.text.rstrip("\n"), "```"]


def _html_block(b: Block) -> str:
    e = html.escape
    if isinstance(b, Table):
        head = "".join(f"<th>{e(h)}</th>" for h in b.headers)
        body = "".join("<tr>" + "".join(f"<td>{e(c)}</td>" for c in row) + "</tr>"
                       for row in b.rows)
        return f"<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>"
    if isinstance(b, Image):
        return (f"<figure><img src=\"{e(b.file)}\" alt=\"{e(b.caption)}\">"
                f"<figcaption>{e(b.caption)}</figcaption></figure>")
    if isinstance(b, Paragraph):
        return f"<p>{e(b.text)}</p>"
    if isinstance(b, Bullets):
        return "<ul>" + "".join(f"<li>{e(i)}</li>" for i in b.items) + "</ul>"
    return f"<pre>{e(b.text)}</pre>"


_CSS = (
    "body{font-family:system-ui,sans-serif;max-width:70em;margin:1em auto;padding:0 1em;"
    "color:#222}table{border-collapse:collapse;margin:.5em 0 1em}th,td{border:1px solid #bbb;"
    "padding:.25em .6em;text-align:right}th{background:#eee}td:first-child,th:first-child"
    "{text-align:left}figure{margin:1em 0}img{max-width:100%}figcaption{color:#555;"
    "font-size:.9em}pre{background:#f6f6f6;padding:.6em;overflow-x:auto}"
)
