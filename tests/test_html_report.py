"""report.html, the page every command writes beside report.md, opened in a real browser.

Each test renders a page in headless Chromium (Debian's /usr/bin/chromium, started here) twice: a
screenshot checked for content, and the DOM after the page's load (``--dump-dom``), into which the
test injects a probe script reporting what the browser made of the page (figures decoded and their
size on screen, page width, the order of table rows after clicks on a header).  Without Chromium the
tests skip with the reason, except in CI (environment variable CI set), where they fail.

Commands run on a small SILO4 twin (280 and 1000 rpm, both directions, one 4 s plateau each);
``gearspec demo`` and ``gearspec repro lola`` (tens of seconds each) are marked slow.
"""

from __future__ import annotations

import base64
import json
import os
import re
import subprocess
import tempfile
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from gearspec.cli import main
from gearspec.report import markdown_table, write_report
from gearspec.report.html import write_html

CHROMIUM = Path("/usr/bin/chromium")
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync")
WIDTH, HEIGHT = 1200, 2000

#: dark pixels (grey < 200 of 255: text strokes, table rules, plot lines) in a 1200 x 2000 screenshot.
#: Measured: an empty page 0; a page holding only its title and the footer 0.27 %; the first screen of
#: each command's report (contents, tables, a figure) 4 to 5 %.  1.5 % is five times the near-empty
#: page and a third of the lowest report measured: a report whose tables or figures did not render
#: falls below it.
MIN_INK = 0.015

#: the probe: what the browser made of the page, written into the DOM once it has loaded
PROBE = """<script>
window.addEventListener("load", function () {
  var p = document.createElement("pre");
  p.id = "gearspec-probe";
  p.textContent = JSON.stringify({
    images: Array.prototype.map.call(document.images, function (i) {
      var r = i.getBoundingClientRect();
      return {file: i.getAttribute("data-file"), natural: [i.naturalWidth, i.naturalHeight],
              box: [r.left, r.top, r.width, r.height]};
    }),
    scrollWidth: document.documentElement.scrollWidth, innerWidth: window.innerWidth,
    sorted: window.gearspecSorted || null});
  document.body.appendChild(p);
});
</script>"""


def need_chromium(path: Path = CHROMIUM) -> Path:
    """Chromium's path; skip when absent, but fail in CI, which must run these tests."""
    if path.is_file():
        return path
    reason = f"headless Chromium not found at {path} (Debian: apt-get install chromium)"
    if os.environ.get("CI"):
        pytest.fail(reason + "; CI must render the HTML reports")
    pytest.skip(reason)


def test_missing_chromium_skips_locally_and_fails_in_ci(tmp_path, monkeypatch):
    def outcome():
        try:
            need_chromium(tmp_path / "no-chromium")
        except (pytest.skip.Exception, pytest.fail.Exception) as stop:
            return type(stop), str(stop)
        return None, ""

    monkeypatch.delenv("CI", raising=False)
    kind, reason = outcome()
    assert kind is pytest.skip.Exception and "not found" in reason
    monkeypatch.setenv("CI", "true")
    kind, reason = outcome()
    assert kind is pytest.fail.Exception and "CI must render" in reason


def _chromium(page: Path, *args: str) -> str:
    with tempfile.TemporaryDirectory() as profile:
        done = subprocess.run([str(need_chromium()), *FLAGS, f"--user-data-dir={profile}",
                               f"--window-size={WIDTH},{HEIGHT}", *args, page.resolve().as_uri()],
                              capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout


def screenshot(page: Path) -> np.ndarray:
    """The page's first 1200 x 2000 pixels in grey levels 0-255."""
    png = page.with_name(page.stem + "_shot.png")
    _chromium(page, f"--screenshot={png}")
    return np.asarray(Image.open(png).convert("L"), dtype=float)


class _Dom(HTMLParser):
    """Headings, images (attributes), table cells and the text of a dumped DOM."""

    def __init__(self):
        super().__init__()
        self.headings, self.images, self.cells, self.text, self._in = [], [], [], [], []

    def handle_starttag(self, tag, attrs):
        if tag in ("h1", "h2", "h3", "td", "th"):
            self._in.append(tag)
            (self.headings if tag[0] == "h" else self.cells).append("")
        if tag == "img":
            self.images.append(dict(attrs))

    def handle_endtag(self, tag):
        if self._in and tag == self._in[-1]:
            self._in.pop()

    def handle_data(self, data):
        self.text.append(data)
        if self._in:
            if self._in[-1][0] == "h":
                self.headings[-1] += data
            else:
                self.cells[-1] += data


def markdown_cells(md: str) -> list[str]:
    """The text of every table cell of the Markdown ``md`` as a reader of the Markdown reads it
    (escaped pipes and stars as themselves, no code or bold marks); cells holding links left out."""
    cells = []
    for line in md.splitlines():
        if line.startswith("|") and not re.fullmatch(r"\|[-:| ]*", line):
            for cell in re.split(r"(?<!\\)\|", line.strip()[1:-1]):
                if "](" not in cell:
                    cells.append(re.sub(r"\\([|*])", r"\1", cell).replace("**", "").replace("`", "").strip())
    return cells


def dom(page: Path, script: str = "") -> tuple[_Dom, dict]:
    """The DOM Chromium holds after loading ``page`` (with the probe and ``script`` added), and the
    probe's report."""
    probe = page.with_name(page.stem + "_probe.html")
    probe.write_text(page.read_text(encoding="utf-8").replace("</body>", script + PROBE + "</body>"),
                     encoding="utf-8")
    out = _chromium(probe, "--dump-dom")
    found = re.search(r'<pre id="gearspec-probe">(.*?)</pre>', out, re.S)
    assert found, "the page did not finish loading"
    parsed = _Dom()
    parsed.feed(out[:found.start()])
    return parsed, json.loads(found.group(1).replace("&amp;", "&").replace("&lt;", "<").replace("&gt;", ">"))


def check_page(page: Path, headings: list[str]) -> tuple[_Dom, dict]:
    """What every report page must show: content on screen, its sections, each figure of the
    Markdown embedded and decoded, nothing wider than the window, nothing fetched."""
    html = page.read_text(encoding="utf-8")
    assert not re.search(r"<(link|iframe)\b|<script\s+src|\bsrc=\"(?!data:)|@import|url\(", html)
    assert (ink := (screenshot(page) < 200).mean()) > MIN_INK, f"{page}: {ink:.2%} of the screenshot inked"
    parsed, probe = dom(page)
    for h in headings:
        assert h in parsed.headings, f"{page}: no section '{h}' in {parsed.headings}"
    figures = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", page.with_suffix(".md").read_text())
    assert figures, f"{page}: the report has no figure"
    assert [i.get("data-file") for i in parsed.images] == figures
    for img, seen in zip(parsed.images, probe["images"]):
        prefix, data = img["src"].split(",", 1)
        assert prefix == "data:image/png;base64"
        assert base64.b64decode(data) == (page.parent / img["data-file"]).read_bytes()
        assert tuple(seen["natural"]) == Image.open(page.parent / img["data-file"]).size   # decoded by the browser
    assert probe["scrollWidth"] <= probe["innerWidth"], "the page is wider than the window"
    shown = {c.strip() for c in parsed.cells}
    missing = [c for c in markdown_cells(page.with_suffix(".md").read_text()) if c not in shown]
    assert not missing, f"{page}: table cells not shown as in the Markdown: {missing[:5]}"
    text = "".join(parsed.text)
    assert "&lt;" not in text and "&amp;" not in text and "\\|" not in text   # nothing escaped twice
    assert "embedded" in text   # the footer says the page travels alone
    return parsed, probe


# ---------------------------------------------------------------------- write_html on a hand-made page
SORT = """<script>
(function () {
  var table = document.querySelector("table.sortable"), th = table.tHead.rows[0].cells, out = [];
  function names() { return Array.prototype.map.call(table.tBodies[0].rows, function (r) {
    return r.cells[0].textContent; }).join(","); }
  th[1].click(); out.push(names());
  th[1].click(); out.push(names());
  th[0].click(); out.push(names());
  window.gearspecSorted = out;
})();
</script>"""


def test_write_html_unit_page(tmp_path):
    need_chromium()
    Image.new("L", (3000, 300), 0).save(tmp_path / "black.png")   # a black block wider than any screen
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "report.md").write_text("# sub\n")
    (tmp_path / "sub" / "report.html").write_text("<p>sub</p>")
    table = markdown_table(__import__("pandas").DataFrame(
        {"name": list("abcdefg"), "value": ["10", "9", "-1e-3", "", "n/a", "2 %", "1.5e+01"],
         "law": ["tau = sign(v)*[0.002*|v|^0.5]"] * 7}))
    wide = "| " + " | ".join(f"column {i}" for i in range(40)) + " |\n|" + "---|" * 40 + "\n| " + \
        " | ".join(f"{i * 1.2345e-5:.4g}" for i in range(40)) + " |\n"
    md = ("# Unit page\n\nFriction |v| in N·m, a & b, `x|y`, alias of <label>.\n\n![black](black.png)\n\n"
          f"## Sorting\n\n{table}\n## Wide\n\n{wide}\n## Links\n\n[sub](sub/report.md), [other](other.md)\n\n"
          "```\nx < y & z\n```\n")
    page = write_html(md, tmp_path)
    assert page == tmp_path / "report.html"
    html = page.read_text(encoding="utf-8")
    assert 'href="sub/report.html"' in html and 'href="other.md"' in html   # .html only where it exists
    assert "<title>Unit page</title>" in html and 'href="#sorting"' in html   # contents
    (tmp_path / "report.md").write_text(md)
    parsed, probe = check_page(page, ["Unit page", "Sorting", "Wide", "Links"])
    text = "".join(parsed.text)
    for literal in ("Friction |v| in N·m, a & b", "x|y", "alias of <label>", "sign(v)*[0.002*|v|^0.5]", "x < y & z"):
        assert literal in text, literal
    # the 3000 x 300 block is scaled to the text column (max-width 100 %), keeping its aspect ratio,
    # and painted black: every pixel of its box in the screenshot (1 px margin for antialiasing)
    left, top, w, h = probe["images"][0]["box"]
    assert 900 < w < WIDTH - 40 and h == pytest.approx(w / 10, abs=1)
    shot = screenshot(page)
    assert shot[int(top) + 1:int(top + h) - 1, int(left) + 1:int(left + w) - 1].max() < 10
    # sorting (a = 10, b = 9, ...): numbers by value (-1e-3 < 2 % < 9 < 10 < 1.5e+01, where text order puts "10"
    # before "9"), text after numbers, empty cells last in both directions; text by letters
    parsed, probe = dom(page, SORT)
    assert probe["sorted"] == ["c,f,b,a,g,e,d", "e,g,a,b,f,c,d", "a,b,c,d,e,f,g"]


def test_write_report_writes_both(tmp_path):
    md = ["# t", "", "| a |", "|---|", "| 1 |"]
    path = write_report(tmp_path, md)
    assert path.read_text() == "\n".join(md)
    assert "<td>1</td>" in (tmp_path / "report.html").read_text()


# ---------------------------------------------------------------------- each command's report
HEADINGS = {
    "spectrum": ["gearspec spectrum report", "Recording", "Gear train", "Segments", "Declared lines", "Method"],
    "fit": ["gearspec fit report", "Recording", "Model: coulomb_viscous (joint fit)", "How well the models predict",
            "Stribeck curve", "Residuals", "Method"],
    "diagnose": ["gearspec diagnose report", "Recording", "Summary", "Baseline model", "Residual spectra",
                 "Final model", "Method"],
    "discover": ["gearspec discover report", "Data", "Selected law", "Inclusion probabilities", "Method"],
}
#: text the Markdown writes with characters HTML would take for markup; the page must show it as is
LITERAL = {"spectrum": "DC motor -> planetary 14", "fit": "tau_c + B|v|", "diagnose": "sum <r0, Delta>",
           "discover": "tau = sign(v)*["}


@pytest.fixture(scope="module")
def twin(tmp_path_factory):
    out = tmp_path_factory.mktemp("twin")
    assert main(["simulate", "silo4", "--out", str(out), "--speeds-rpm", "280,-280,1000,-1000",
                 "--repetitions", "1", "--duration", "4", "--quiet"]) == 0
    return out


@pytest.mark.parametrize("command", list(HEADINGS))
def test_command_report_in_browser(command, twin, tmp_path, capsys):
    need_chromium()
    out = tmp_path / command
    law = ["--law", "coulomb_viscous"] if command in ("fit", "diagnose") else []   # 2 speeds per direction
    assert main([command, str(twin / "silo4_twin.csv"), "--gear", str(twin / "silo4_twin_gear.toml"),
                 "--out", str(out), *law]) == 0
    assert f"html: {out}/report.html" in capsys.readouterr().out
    parsed, _ = check_page(out / "report.html", HEADINGS[command])
    assert LITERAL[command] in "".join(parsed.text)


@pytest.mark.slow
def test_demo_and_repro_reports_in_browser(tmp_path, capsys):
    need_chromium()
    assert main(["demo", "--out", str(tmp_path / "demo")]) == 0
    assert f"html: {tmp_path}/demo/report.html" in capsys.readouterr().out
    parsed, _ = check_page(tmp_path / "demo" / "report.html",
                           ["Table 2: parameters recovered from the twin", "Figures", "Run"])
    assert 'href="fit/report.html"' in (tmp_path / "demo" / "report.html").read_text()
    check_page(tmp_path / "demo" / "fit" / "report.html", HEADINGS["fit"][:1] + ["Stribeck curve", "Residuals"])
    assert main(["repro", "lola", "--out", str(tmp_path / "lola")]) == 0
    assert f"html: {tmp_path}/lola/report.html" in capsys.readouterr().out
    check_page(tmp_path / "lola" / "report.html", ["Table IV: law (11) recovered from the twin", "Figures", "Run"])
