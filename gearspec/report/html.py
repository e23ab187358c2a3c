"""A report's Markdown as one self-contained HTML page (``report.html`` beside ``report.md``).

The page is the same content rendered with the ``markdown`` library (extensions ``tables``,
``fenced_code``, ``toc``): every figure the Markdown references is embedded as a base64 data URI, the
style sheet and the few lines of script that sort a table by a click on its header are inline, and
nothing is fetched from the network (no CDN, font or external script), so the single file opens
offline and can be sent on its own.

Raw HTML in the Markdown is not interpreted: the reports write things like ``alias of <label>`` or
``sum <r0, Delta>`` as plain text, and they read the same in the page.
"""

from __future__ import annotations

import base64
import html
import re
import xml.etree.ElementTree as etree
from pathlib import Path
from urllib.parse import unquote, urlsplit

import markdown
from markdown.extensions import Extension
from markdown.preprocessors import Preprocessor
from markdown.treeprocessors import Treeprocessor

__all__ = ["write_html", "render_html"]

#: figure types embedded as data URIs (by file suffix)
MIME = {".png": "image/png", ".jpg": "image/jpeg", ".jpeg": "image/jpeg", ".gif": "image/gif",
        ".svg": "image/svg+xml", ".webp": "image/webp"}

CSS = """
*{box-sizing:border-box}
body{margin:0;color:#1f2328;background:#fff;font:15px/1.55 system-ui,-apple-system,"Segoe UI",Roboto,
"Helvetica Neue",Arial,sans-serif}
.page{max-width:1100px;margin:0 auto;padding:12px 28px 28px}
h1{font-size:1.7em;border-bottom:1px solid #d0d7de;padding-bottom:.25em}
h2{font-size:1.35em;border-bottom:1px solid #e6e9ed;padding-bottom:.2em;margin-top:1.8em}
h3{font-size:1.1em;margin-top:1.4em}
a{color:#0969da}
nav.toc{background:#f6f8fa;border:1px solid #d0d7de;border-radius:6px;padding:8px 16px;margin:1em 0;
font-size:14px}
nav.toc ul{margin:.2em 0;padding-left:1.3em}
nav.toc>ul{columns:2 320px}
nav.toc li{break-inside:avoid}
.table-wrap{overflow-x:auto;margin:1em 0;max-width:100%}
table{border-collapse:collapse;font-size:13px;font-variant-numeric:tabular-nums}
th,td{border:1px solid #d0d7de;padding:3px 8px;text-align:left;vertical-align:top}
thead th{background:#eef1f4;white-space:nowrap}
tbody tr:nth-child(even){background:#f8f9fa}
table.sortable thead th{cursor:pointer;user-select:none}
table.sortable thead th::after{content:" \\2195";color:#8c959f;font-weight:normal}
table.sortable thead th[aria-sort=ascending]::after{content:" \\25B2";color:#1f2328}
table.sortable thead th[aria-sort=descending]::after{content:" \\25BC";color:#1f2328}
img{max-width:100%;height:auto;display:block;margin:.6em 0}
code,pre{font-family:ui-monospace,SFMono-Regular,"DejaVu Sans Mono",Menlo,Consolas,monospace;font-size:.9em}
code{background:#f3f4f6;padding:.05em .3em;border-radius:3px}
pre{background:#f6f8fa;border:1px solid #e6e9ed;border-radius:6px;padding:10px 12px;overflow-x:auto;
line-height:1.4}
pre code{background:none;padding:0}
footer{color:#59636e;font-size:13px;border-top:1px solid #d0d7de;margin-top:2.5em;padding-top:.8em}
@media print{nav.toc{display:none}.table-wrap{overflow:visible}}
"""

#: sorts a table by a click on a header cell; ``gearspecOrder`` is the pure part (tested in Chromium)
SCRIPT = r"""
(function () {
  "use strict";
  var NUMBER = /^[+-]?(\d+\.?\d*|\.\d+)(e[+-]?\d+)?/i;
  function key(text) {          // a number when the cell starts with one, else the text; null if empty
    var t = text.trim().replace(/^\u2212/, "-");
    if (!t) return null;
    var m = t.match(NUMBER);
    return m ? parseFloat(m[0]) : t;
  }
  function compare(a, b) {      // numbers before text; numbers by value, text by its words and digits
    if (typeof a === "number" && typeof b === "number") return a - b;
    if (typeof a === "number") return -1;
    if (typeof b === "number") return 1;
    return a.localeCompare(b, undefined, {numeric: true, sensitivity: "base"});
  }
  function order(texts, descending) {   // row indices sorted by their cells; empty cells last; stable
    var keys = texts.map(key);
    var idx = texts.map(function (_, i) { return i; });
    idx.sort(function (i, j) {
      var a = keys[i], b = keys[j];
      if (a === null || b === null) return ((a === null) - (b === null)) || i - j;
      var c = compare(a, b);
      return (descending ? -c : c) || i - j;
    });
    return idx;
  }
  window.gearspecOrder = order;
  function sortBy(th) {
    var table = th.closest("table"), body = table.tBodies[0], col = th.cellIndex;
    var descending = th.getAttribute("aria-sort") === "ascending";
    var rows = Array.prototype.slice.call(body.rows);
    var texts = rows.map(function (r) { return r.cells[col] ? r.cells[col].textContent : ""; });
    order(texts, descending).forEach(function (i) { body.appendChild(rows[i]); });
    Array.prototype.forEach.call(th.parentNode.cells, function (c) { c.removeAttribute("aria-sort"); });
    th.setAttribute("aria-sort", descending ? "descending" : "ascending");
  }
  document.querySelectorAll("table.sortable thead th").forEach(function (th) {
    th.title = "click to sort";
    th.addEventListener("click", function () { sortBy(th); });
  });
})();
"""


class _Embed(Treeprocessor):
    """Figures as data URIs, ``x.md`` links as ``x.html`` when that page exists, tables sortable and
    scrollable."""

    def __init__(self, md, folder: Path):
        super().__init__(md)
        self.folder = folder
        self.embedded: list[str] = []
        self.missing: list[str] = []

    def _local(self, ref: str) -> Path | None:
        """The file a relative reference names inside the report's folder, or None."""
        parts = urlsplit(ref)
        if not ref or parts.scheme or parts.netloc or ref.startswith(("#", "/")):
            return None
        return self.folder / unquote(parts.path)

    def run(self, root):
        for img in list(root.iter("img")):
            src = img.get("src", "")
            path = self._local(src)
            if path is None or src.startswith("data:"):
                continue
            if path.is_file() and path.suffix.lower() in MIME:
                data = base64.b64encode(path.read_bytes()).decode("ascii")
                img.set("src", f"data:{MIME[path.suffix.lower()]};base64,{data}")
                img.set("data-file", src)
                self.embedded.append(src)
            else:
                self.missing.append(src)
        for a in list(root.iter("a")):
            path = self._local(a.get("href", ""))
            if path is not None and path.suffix == ".md" and path.with_suffix(".html").is_file():
                a.set("href", a.get("href")[:-3] + ".html")
        parents = {child: parent for parent in root.iter() for child in parent}
        for table in list(root.iter("table")):
            table.set("class", "sortable")
            parent = parents[table]
            wrap = etree.Element("div", {"class": "table-wrap"})
            at = list(parent).index(table)
            parent.remove(table)
            wrap.append(table)
            wrap.tail, table.tail = table.tail, None
            parent.insert(at, wrap)


class _TableStars(Preprocessor):
    """A lone ``*`` in a table row is a product (``sign(v)*[0.002*|v|^0.5]``, a law printed by a report),
    not emphasis: escaped outside code spans, so the page shows the formula as written in the Markdown.
    ``**bold**`` and already escaped stars are left alone."""

    STAR = re.compile(r"(?<![\\*])\*(?!\*)")

    def run(self, lines):
        return ["`".join(self.STAR.sub(r"\\*", part) if i % 2 == 0 else part
                         for i, part in enumerate(line.split("`")))
                if line.lstrip().startswith("|") else line for line in lines]


class _EmbedExtension(Extension):
    def __init__(self, folder: Path):
        super().__init__()
        self.folder = folder
        self.processor: _Embed | None = None

    def extendMarkdown(self, md):  # noqa: N802 (the markdown library's name)
        self.processor = _Embed(md, self.folder)
        md.treeprocessors.register(self.processor, "gearspec_embed", 1)
        md.preprocessors.register(_TableStars(md), "gearspec_table_stars", 20)   # after fenced code (25)


def _toc(tokens: list[dict]) -> str:
    """Nested list of the headings (below the page's single title, when there is one)."""
    if len(tokens) == 1 and tokens[0]["level"] == 1:
        tokens = tokens[0]["children"]
    return f'<nav class="toc"><strong>Contents</strong>{_toc_list(tokens)}</nav>' if tokens else ""


def _toc_list(tokens: list[dict]) -> str:
    if not tokens:
        return ""
    return "<ul>" + "".join(f'<li><a href="#{t["id"]}">{t["html"]}</a>{_toc_list(t["children"])}</li>'
                            for t in tokens) + "</ul>"


def render_html(md_text: str, folder, title: str | None = None) -> str:
    """The HTML page of the Markdown ``md_text`` whose figures are files relative to ``folder``.

    Parameters
    ----------
    md_text : str
        A report's Markdown (GitHub tables, fenced code, ``![caption](figure.png)``).
    folder : path-like
        Folder the Markdown's relative references are read from (the report's folder).
    title : str, optional
        Page title (plain text); default the first level-1 heading, else "gearspec report".

    Returns
    -------
    str
        The complete page: inline style and script, figures as base64 data URIs.
    """
    from .. import __version__

    embed = _EmbedExtension(Path(folder))
    conv = markdown.Markdown(extensions=["tables", "fenced_code", "toc", embed])
    conv.preprocessors.deregister("html_block")   # raw HTML is text: `alias of <label>` stays visible
    conv.inlinePatterns.deregister("html")
    body = conv.convert(md_text)
    tokens = conv.toc_tokens
    if body.startswith("<h1"):   # the contents right below the title
        end = body.index("</h1>") + len("</h1>")
        body = body[:end] + "\n" + _toc(tokens) + body[end:]
    else:
        body = _toc(tokens) + "\n" + body
    if title is not None:
        head_title = html.escape(title)
    else:
        head_title = tokens[0]["name"] if tokens and tokens[0]["level"] == 1 else "gearspec report"
    n = len(embed.processor.embedded)
    note = (f"Self-contained page: its {n} figure{'s' if n != 1 else ''} {'are' if n != 1 else 'is'} embedded in "
            "this file and nothing is fetched from the network, so it opens offline and can be sent on its own; "
            "the data files it names (CSV, JSON) stay in the report's folder. Click a table's header to sort it.")
    if embed.processor.missing:
        note += " Not found when the page was written: " + ", ".join(html.escape(m) for m in embed.processor.missing)
    return ("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n"
            "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">\n"
            f"<meta name=\"generator\" content=\"gearspec {__version__}\">\n<title>{head_title}</title>\n"
            f"<style>{CSS}</style>\n</head>\n<body>\n<div class=\"page\">\n<main>\n{body}\n</main>\n"
            f"<footer>{note} Written by gearspec {__version__} from report.md.</footer>\n</div>\n"
            f"<script>{SCRIPT}</script>\n</body>\n</html>\n")


def write_html(md_text: str, out_dir, title: str | None = None, name: str = "report.html") -> Path:
    """Write the Markdown ``md_text`` as the self-contained page ``out_dir/name``; returns its path.

    Parameters
    ----------
    md_text : str
        The report's Markdown, as written to ``report.md``.
    out_dir : path-like
        The report's folder: figures are read from it (relative paths) and the page written into it.
    title : str, optional
        Page title; default the Markdown's first level-1 heading.
    name : str
        File name of the page (default ``report.html``).

    Returns
    -------
    pathlib.Path
        Path of the page written.
    """
    path = Path(out_dir) / name
    path.write_text(render_html(md_text, out_dir, title=title), encoding="utf-8")
    return path
