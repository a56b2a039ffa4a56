"""The results page in a real headless browser (Debian's Chromium through selenium): it loads
with no console error, holds every agent's row with the stored numbers, shows a script-named
agent as text without running it, and renders to a screenshot that is not blank; on the shipped
Dubins4D reference results (nine agents, 2,048 episodes) at 1280 x 800 it shows the rates figure
above the first table, no table scrolls sideways, and the pairwise matrices replace the rows
per pair and outcome (issue 53).

Slow tier (``make test-slow``); ``.ci/install-browser`` installs Chromium and its driver, which
``.ci/run`` calls first."""

from __future__ import annotations

import io
import shutil
from pathlib import Path

import pytest

from rmm_bench.cli import main
from rmm_bench.reference import reference_dbs
from tests.test_html import EVIL, _evil_copy, page_table_i, stored_table_i

pytestmark = pytest.mark.slow

CHROMIUM, DRIVER = Path("/usr/bin/chromium"), Path("/usr/bin/chromedriver")


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    if not (CHROMIUM.exists() and DRIVER.exists()):
        pytest.fail("Chromium or chromedriver is missing: run .ci/install-browser (CI's .ci/run does)")
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = str(CHROMIUM)
    for flag in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                 "--disable-background-networking", "--disable-component-update", "--disable-sync",
                 "--window-size=1366,900", f"--user-data-dir={tmp_path_factory.mktemp('profile')}"):  # fmt: skip
        options.add_argument(flag)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(service=Service(str(DRIVER)), options=options)
    yield driver
    driver.quit()


@pytest.fixture(scope="module")
def page(tmp_path_factory):
    root = tmp_path_factory.mktemp("browser")
    run = root / "run"
    argv = ["--agent", "lrmm,cbf,inactive", "--episodes", "24", "--clock", "fixed:1", "--workers", "1"]
    assert main([*argv, "--no-progress", "--out", str(run)]) == 0
    evil = _evil_copy(run, root)
    gif = evil / "replays" / "lrmm-episode-2.gif"
    gif.parent.mkdir()
    assert main(["replay", str(evil), "--agent", "lrmm", "--episode", "2", "--video", str(gif), "--size", "160"]) == 0
    assert main(["report", str(evil), "--html"]) == 0
    return evil


def test_the_page_in_a_real_browser(browser, page):
    from PIL import Image
    from selenium.common.exceptions import NoAlertPresentException
    from selenium.webdriver.common.by import By

    browser.get((page / "results.html").as_uri())
    assert browser.title == "rmm-bench results"
    errors = [e for e in browser.get_log("browser") if e["level"] in ("SEVERE", "ERROR")]
    assert errors == []
    with pytest.raises(NoAlertPresentException):  # the script-named agent did not run
        browser.switch_to.alert.text  # noqa: B018
    shown = _Shown()
    for table in browser.find_elements(By.CSS_SELECTOR, "table.table-i, table.constant"):
        shown.tables.append(({"class": table.get_attribute("class")}, []))
        for tr in table.find_elements(By.TAG_NAME, "tr"):
            cells = [c.text for c in tr.find_elements(By.CSS_SELECTOR, "th, td")]
            shown.rows.setdefault(table.get_attribute("class"), []).append(cells)
    rows = page_table_i(shown)
    assert set(rows) == {"lrmm", "cbf", EVIL} and rows == stored_table_i(page)
    images = browser.find_elements(By.TAG_NAME, "img")  # the rates figure, outcomes.png, the GIF
    assert len(images) == 3 and all(browser.execute_script("return arguments[0].naturalWidth", i) > 0 for i in images)
    shot = Image.open(io.BytesIO(browser.get_screenshot_as_png())).convert("L")
    colours = shot.getcolors(maxcolors=1 << 16) or []
    dark = sum(n for n, c in colours if c < 200) / (shot.width * shot.height)
    assert len(colours) > 10 and dark > 0.01, (len(colours), dark)  # text and tables drawn, not blank
    shutil.copy(page / "results.html", page / "checked.html")


class _Shown:
    """Table rows as the browser shows them, in the shape :func:`tests.test_html.page_table_i` reads."""

    def __init__(self) -> None:
        self.rows: dict[str, list[list[str]]] = {}
        self.tables: list = []


#: measured in the page at 1280 x 800, every <details> opened: where the figure and the first table
#: are, and each table whose content is wider than its box (which would scroll sideways)
MEASURE = """
document.querySelectorAll('details').forEach(d => { d.open = true; });
const figure = document.querySelector('figure.rates');
const table = document.querySelector('table');
const wide = [];
document.querySelectorAll('table').forEach(t => {
  const box = t.parentElement;
  if (box.scrollWidth > box.clientWidth + 1 || t.scrollWidth > t.clientWidth + 1
      || t.getBoundingClientRect().right > document.documentElement.clientWidth + 1) {
    wide.push(t.className + ' ' + t.scrollWidth + ' > ' + box.clientWidth);
  }
});
return {
  viewport: [window.innerWidth, window.innerHeight],
  figureTop: figure.getBoundingClientRect().top,
  figureBottom: figure.getBoundingClientRect().bottom,
  figureImage: figure.querySelector('img').currentSrc.length,
  tableTop: table.getBoundingClientRect().top,
  pageWide: document.documentElement.scrollWidth > document.documentElement.clientWidth,
  wide: wide,
  matrices: Array.from(document.querySelectorAll('table.matrix')).map(t => t.dataset.outcome),
  perPairRows: document.querySelectorAll('table.pairs').length,
  pairs: document.querySelectorAll('details.pair').length,
};
"""


@pytest.fixture(scope="module")
def reference_page(tmp_path_factory):
    (db,) = [d for d in reference_dbs() if d.stem == "dubins4d"]
    folder = tmp_path_factory.mktemp("reference")
    shutil.copy(db, folder / "results.db")
    assert main(["report", str(folder), "--html", str(folder / "page.html")]) == 0
    return folder / "page.html"


def test_the_reference_page_leads_with_the_figure_and_fits_1280_px(browser, reference_page):
    browser.execute_cdp_cmd(
        "Emulation.setDeviceMetricsOverride", {"width": 1280, "height": 800, "deviceScaleFactor": 1, "mobile": False}
    )
    try:
        browser.get(reference_page.as_uri())
        m = browser.execute_script(MEASURE)
    finally:
        browser.execute_cdp_cmd("Emulation.clearDeviceMetricsOverride", {})
    assert m["viewport"] == [1280, 800]
    assert m["figureImage"] > 0 and 0 <= m["figureTop"] < 800  # on the first screen
    assert m["figureBottom"] <= m["tableTop"], m  # the rates figure above the first table
    assert m["wide"] == [] and not m["pageWide"], m["wide"]  # no table scrolls sideways, details open too
    assert m["matrices"] == ["goal", "collision", "avoidable collision", "timeout"]
    assert m["perPairRows"] == 0 and m["pairs"] == 36  # nine agents: 36 pairs, each folded
