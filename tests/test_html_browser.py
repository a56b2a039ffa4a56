"""The results page in a real headless browser (Debian's Chromium through selenium): it loads
with no console error, holds every agent's row with the stored numbers, shows a script-named
agent as text without running it, and renders to a screenshot that is not blank.

Slow tier (``make test-slow``); ``.ci/install-browser`` installs Chromium and its driver, which
``.ci/run`` calls first."""

from __future__ import annotations

import io
import shutil
from pathlib import Path

import pytest

from rmm_bench.cli import main
from tests.test_html import EVIL, _evil_copy

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
    rows = {}
    for tr in browser.find_elements(By.CSS_SELECTOR, "table.table-i tbody tr"):
        cells = [td.text for td in tr.find_elements(By.TAG_NAME, "td")]
        rows[cells[0]] = cells
    stored = {}
    for line in (page / "table_I.md").read_text().splitlines()[2:]:
        if line.startswith("| "):
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            stored[cells[0]] = cells
    assert set(rows) == {"lrmm", "cbf", EVIL} and rows == stored
    images = browser.find_elements(By.TAG_NAME, "img")
    assert len(images) == 2 and all(browser.execute_script("return arguments[0].naturalWidth", i) > 0 for i in images)
    shot = Image.open(io.BytesIO(browser.get_screenshot_as_png())).convert("L")
    colours = shot.getcolors(maxcolors=1 << 16) or []
    dark = sum(n for n, c in colours if c < 200) / (shot.width * shot.height)
    assert len(colours) > 10 and dark > 0.01, (len(colours), dark)  # text and tables drawn, not blank
    shutil.copy(page / "results.html", page / "checked.html")
