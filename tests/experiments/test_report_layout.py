"""The study report's layout (issue 36): on a narrow screen a wide table scrolls inside its own
box and the page itself does not run off the right edge; figures shrink to the page's width
with their titles whole. Checked in headless Chromium at 800 and 1280 px (the measurements a
script in the page makes, read back with ``--dump-dom``), and the CSS rule without a browser."""

from __future__ import annotations

import io
import json
import re
import shutil
import subprocess

import numpy as np
import pandas as pd
import pytest

from bounce_cli.experiments.report import STYLE, Section, embed_png, html_table, page

CHROMIUM = next((shutil.which(name) for name in ("chromium", "chromium-browser",
                                                  "google-chrome") if shutil.which(name)), None)

#: measures every table against its box and the page; writes the answer into the DOM
MEASURE = """
<script>
const page = document.documentElement;
const tables = [...document.querySelectorAll('table')].map(t => {
  const box = t.parentElement;
  return {box: box.className, boxWidth: box.getBoundingClientRect().width,
          boxRight: box.getBoundingClientRect().right, tableWidth: t.scrollWidth,
          scrolls: getComputedStyle(box).overflowX};
});
const images = [...document.querySelectorAll('figure img')].map(i => ({
  right: i.getBoundingClientRect().right, width: i.clientWidth, natural: i.naturalWidth,
  height: i.clientHeight, naturalHeight: i.naturalHeight}));  // client*: without the border
const out = document.createElement('pre');
out.id = 'measured';
out.textContent = JSON.stringify({viewport: page.clientWidth, pageWidth: page.scrollWidth,
                                  tables, images});
document.body.appendChild(out);
</script>
"""


def wide_report() -> str:
    """A report like ``bounce study``'s: a table of 40 columns, a narrow one, a wide figure
    with a long title."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    wide = pd.DataFrame({f"quantity_with_a_long_name_{k}": np.linspace(0, 1, 4) + k
                         for k in range(40)})
    wide.insert(0, "subject", ["s1", "s2", "s3", "s4"])
    narrow = pd.DataFrame({"a": [1.0, 2.0]})
    figure, axes = plt.subplots(figsize=(12, 4), dpi=100)
    axes.plot([0, 1], [0, 1])
    figure.suptitle("Fig. 6 over the study: learning trends (mixed model, random intercept "
                    "and slope per subject)")
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png")
    plt.close(figure)
    sections = [Section("Study", [html_table(wide, digits=4), html_table(narrow)]),
                Section("Fig. 6", [embed_png(buffer.getvalue(), "Fig. 6")])]
    return page("bounce study", sections)


def test_every_table_is_in_a_box_that_scrolls_sideways():
    """Without a browser: each table sits in ``div.table``, whose rule scrolls sideways, and
    no rule gives a table a width that could push the page wider."""
    document = wide_report()
    assert document.count("<table>") == document.count("<div class='table'><table>") == 2
    rule = re.search(r"div\.table\s*\{([^}]*)\}", STYLE)
    assert rule and "overflow-x: auto" in rule.group(1) and "max-width: 100%" in rule.group(1)
    assert "height: auto" in re.search(r"figure img\s*\{([^}]*)\}", STYLE).group(1)


def measure(path, width: int, scratch) -> dict:
    """What Chromium lays out for the HTML file ``path`` at ``width`` px: the page's width,
    every table against its box, every figure's image (``MEASURE``, via ``--dump-dom``)."""
    measured_page = scratch / "measured.html"
    measured_page.write_text(path.read_text(encoding="utf-8").replace("</body>",
                                                                      MEASURE + "</body>"),
                             encoding="utf-8")
    run = subprocess.run([CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu",
                          f"--user-data-dir={scratch / 'profile'}", f"--window-size={width},2000",
                          "--virtual-time-budget=2000", "--dump-dom", measured_page.as_uri()],
                         capture_output=True, text=True, timeout=120)
    found = re.search(r"<pre id=\"measured\">(.*?)</pre>", run.stdout, re.S)
    assert found, run.stderr[-2000:]
    return json.loads(found.group(1).replace("&quot;", '"').replace("&amp;", "&"))


def assert_nothing_runs_off(measured: dict, width: int) -> None:
    """No sideways scroll of the page; each table in a box that scrolls and ends inside the
    page; each figure inside the page with its aspect ratio (its title whole)."""
    viewport = measured["viewport"]
    assert 0 < viewport <= width
    assert measured["pageWidth"] <= viewport, measured
    for table in measured["tables"]:
        assert table["box"] == "table" and table["scrolls"] == "auto", table
        assert table["boxRight"] <= viewport + 0.5, table
    for image in measured["images"]:
        assert image["right"] <= viewport + 0.5 and image["width"] <= image["natural"], image
        assert image["height"] == pytest.approx(image["naturalHeight"] * image["width"]
                                                / image["natural"], abs=1.5), image


needs_chromium = pytest.mark.skipif(
    CHROMIUM is None, reason="headless Chromium is not installed (apt-get install chromium)")


@pytest.mark.slow
@needs_chromium
@pytest.mark.parametrize("width", [800, 1280])
def test_no_table_runs_off_the_page_in_chromium(tmp_path, width):
    path = tmp_path / "report.html"
    path.write_text(wide_report(), encoding="utf-8")
    measured = measure(path, width, tmp_path)
    assert_nothing_runs_off(measured, width)
    wide, narrow = measured["tables"]
    assert wide["tableWidth"] > wide["boxWidth"]  # the wide one is wider: it scrolls in its box
    assert len(measured["images"]) == 1
