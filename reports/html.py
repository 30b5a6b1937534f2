"""report.md as one self-contained HTML page (images inlined as data URIs, no scripts, no network).

`render_html(markdown, base_dir)` converts the markdown subset the reports use (headings, paragraphs,
bullet lists, pipe tables, images, `code`, **bold**, *italic*); every image is read from `base_dir`
and inlined, so the page can be mailed or archived alone. Engine names in an "engine" column get a
swatch of the engine's colour (reports.style), marks get colours. A missing image is an error,
not a broken page.
"""
from __future__ import annotations

import base64
import html
import re
from pathlib import Path

from impactval.errors import ImpactvalError
from impactval.reports.style import engine_colour

_CSS = """
body{font-family:system-ui,-apple-system,'Segoe UI',Roboto,sans-serif;max-width:1200px;margin:1.5em auto;
padding:0 1em;color:#1a1a1a;line-height:1.45}
h1{font-size:1.6em;border-bottom:2px solid #333}h2{font-size:1.25em;margin-top:1.6em;border-bottom:1px solid #bbb}
table{border-collapse:collapse;margin:.6em 0;font-size:.86em}th,td{border:1px solid #ccc;padding:2px 7px}
th{background:#f1f1f1}td.r{text-align:right;font-variant-numeric:tabular-nums}tr:nth-child(even){background:#fafafa}
code{background:#f3f3f3;padding:0 3px;border-radius:3px}img{max-width:100%;height:auto;border:1px solid #ddd}
td.nw{white-space:nowrap}.sw{display:inline-block;width:.8em;height:.8em;border-radius:2px;margin-right:.35em;vertical-align:-1px}
.m-worse,.m-fail{color:#b00000;font-weight:bold}.m-better,.m-fixed{color:#00713c;font-weight:bold}.m-x{color:#777}
figure{margin:1em 0}figcaption{font-style:italic;color:#444}
"""
_MARK_CLASS = {"+": "m-worse", "!": "m-fail", "-": "m-better", "*": "m-fixed", "x": "m-x"}
_IMG = re.compile(r"^!\[([^\]]*)\]\(([^)]+)\)\s*$")


def _inline(text: str) -> str:
    """Escape, then `code`, **bold**, *italic*."""
    parts = re.split(r"(`[^`]*`)", text)
    out = []
    for p in parts:
        if len(p) >= 2 and p.startswith("`") and p.endswith("`"):
            out.append(f"<code>{html.escape(p[1:-1])}</code>")
            continue
        s = html.escape(p, quote=False)
        s = re.sub(r"\*\*([^*]+)\*\*", r"<strong>\1</strong>", s)
        s = re.sub(r"(?<![\w*])\*(\S[^*]*\S|\S)\*(?![\w*])", r"<em>\1</em>", s)
        out.append(s)
    return "".join(out)


def _split_row(line: str) -> list[str]:
    cells = re.split(r"(?<!\\)\|", line.strip().strip("|")) if line.strip() != "||" else []
    return [c.strip().replace("\\|", "|") for c in cells]


def _data_uri(path: Path) -> str:
    kind = {".png": "image/png", ".svg": "image/svg+xml", ".jpg": "image/jpeg", ".jpeg": "image/jpeg"}.get(
        path.suffix.lower())
    if kind is None:
        raise ImpactvalError(f"{path}: report images must be PNG, SVG or JPEG.")
    return f"data:{kind};base64,{base64.b64encode(path.read_bytes()).decode()}"


def _table(lines: list[str]) -> str:
    header = _split_row(lines[0])
    aligns = ["r" if c.endswith(":") else "" for c in _split_row(lines[1])]
    out = ["<table>", "<thead><tr>" + "".join(f"<th>{_inline(h)}</th>" for h in header) + "</tr></thead>", "<tbody>"]
    for line in lines[2:]:
        cells = _split_row(line)
        tds = []
        for i, c in enumerate(cells):
            col = header[i] if i < len(header) else ""
            cls = aligns[i] if i < len(aligns) else ""
            body = _inline(c)
            if col == "engine" and c:
                body = f'<span class="sw" style="background:{engine_colour(c)}"></span>{body}'
                cls = "nw"
            if col == "mark" and c in _MARK_CLASS:
                body = f'<span class="{_MARK_CLASS[c]}">{body}</span>'
            tds.append(f'<td class="{cls}">{body}</td>' if cls else f"<td>{body}</td>")
        out.append("<tr>" + "".join(tds) + "</tr>")
    return "\n".join([*out, "</tbody></table>"])


def render_html(markdown: str, base_dir: str | Path, title: str | None = None) -> str:
    """The HTML page of a report.md whose images are relative to `base_dir`."""
    base = Path(base_dir)
    lines = markdown.splitlines()
    body: list[str] = []
    para: list[str] = []
    i = 0

    def flush() -> None:
        if para:
            body.append("<p>" + _inline(" ".join(para)) + "</p>")
            para.clear()

    while i < len(lines):
        line = lines[i]
        stripped = line.strip()
        if not stripped:
            flush()
            i += 1
            continue
        m = re.match(r"^(#{1,4})\s+(.*)$", stripped)
        if m:
            flush()
            level = len(m.group(1))
            if title is None and level == 1:
                title = m.group(2)
            body.append(f"<h{level}>{_inline(m.group(2))}</h{level}>")
            i += 1
            continue
        m = _IMG.match(stripped)
        if m:
            flush()
            path = base / m.group(2)
            if not path.is_file():
                raise ImpactvalError(f"{path}: image referenced by the report does not exist.")
            body.append(f'<figure><img src="{_data_uri(path)}" alt="{html.escape(m.group(1))}"></figure>')
            i += 1
            continue
        if stripped.startswith("|") and i + 1 < len(lines) and re.match(r"^\|[\s:|-]+\|$", lines[i + 1].strip()):
            flush()
            block = []
            while i < len(lines) and lines[i].strip().startswith("|"):
                block.append(lines[i])
                i += 1
            body.append(_table(block))
            continue
        if stripped.startswith("- "):
            flush()
            items = []
            while i < len(lines) and lines[i].strip().startswith("- "):
                items.append(f"<li>{_inline(lines[i].strip()[2:])}</li>")
                i += 1
            body.append("<ul>" + "".join(items) + "</ul>")
            continue
        para.append(stripped)
        i += 1
    flush()
    head = (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
            f'<meta name="viewport" content="width=device-width,initial-scale=1">'
            f"<title>{html.escape(title or 'impactval report')}</title><style>{_CSS}</style></head><body>")
    return head + "\n" + "\n".join(body) + "\n</body></html>\n"


def write_html(report_md: str | Path, out: str | Path | None = None) -> Path:
    """Write report.html next to `report_md` (or to `out`); returns its path."""
    src = Path(report_md)
    dest = Path(out) if out is not None else src.with_suffix(".html")
    dest.write_text(render_html(src.read_text(), src.parent), encoding="utf-8")
    return dest
