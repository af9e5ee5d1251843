"""The HTML reports in a real browser: headless Chromium driven through WebDriver.

Two reports are made from small, fast inputs, in two processes at once: the calibration
report of ``calib run`` (the wind-tunnel study of ``workflows/wind_tunnel_hub_loads.toml``
on 6 x 2 operating points) and the diagnosis report of ``calib diagnose`` on the demo
campaign (as ``calib demo`` runs it). Each is opened at a 1280 px wide window and must
show: every image loaded (``naturalWidth > 0``), no console message of level SEVERE, no
horizontal overflow (``scrollWidth <= clientWidth`` of the document element, with every
``<details>`` unfolded), and no table that needs the scroll box the reports put it in. A full-page
screenshot of each is kept in ``test_artifacts/`` (git-ignored) and its path printed.

Chromium and its WebDriver come from the Debian packages ``chromium`` and
``chromium-driver``, installed by the set-up of ``make test`` (``make test-browser``, i.e.
``tests/install_browser.sh``), never by the tests: a test run does not change the machine.
Where either is missing the tests are skipped with the command to run, except under
``CI=true``, where a missing browser is a failure. Why WebDriver (``selenium``): the console log at a
level, the window size and screenshots are one call each, and ``chromedriver`` comes from
the same Debian release as ``chromium``, so the two always match; the DevTools protocol
would need a WebSocket client and event bookkeeping written here.
"""

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
ARTIFACTS = ROOT / "test_artifacts"
WIDTH = 1280
CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync"]
APT_PACKAGES = ["chromium", "chromium-driver"]

pytestmark = pytest.mark.slow


# ----------------------------------------------------------------------------- the browser
def require_browser(ci: bool) -> None:
    """Skip (or, on CI, fail) when chromium or chromedriver is not on PATH."""
    missing = [name for name in ("chromium", "chromedriver") if shutil.which(name) is None]
    if not missing:
        return
    message = (f"{' and '.join(missing)} not on PATH: run 'make test-browser' (installs the Debian packages "
               f"{' '.join(APT_PACKAGES)})")
    if ci:
        pytest.fail(f"CI=true and {message}")
    pytest.skip(message)


def test_missing_browser_fails_on_ci_and_skips_elsewhere(monkeypatch):
    monkeypatch.setattr(shutil, "which", lambda name: None)
    with pytest.raises(pytest.fail.Exception, match="make test-browser"):
        require_browser(ci=True)
    with pytest.raises(pytest.skip.Exception, match="make test-browser"):
        require_browser(ci=False)


@pytest.fixture(scope="module")
def browser(tmp_path_factory):
    """A headless Chromium at a 1280 px wide window, with a fresh profile, through chromedriver."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    require_browser(os.environ.get("CI", "").lower() == "true")
    options = webdriver.ChromeOptions()
    options.binary_location = shutil.which("chromium")
    for flag in CHROMIUM_FLAGS + [f"--user-data-dir={tmp_path_factory.mktemp('chromium-profile')}",
                                  f"--window-size={WIDTH},900"]:
        options.add_argument(flag)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    driver = webdriver.Chrome(options=options, service=Service(executable_path=shutil.which("chromedriver")))
    try:
        yield driver
    finally:
        driver.quit()


# ----------------------------------------------------------------------------- the reports
WORKFLOW = ROOT / "workflows" / "wind_tunnel_hub_loads.toml"
CAMPAIGN = ROOT / "calib" / "data" / "demo_campaign" / "nrel5mw_campaign.csv"
CLI = "import sys; from calib.cli import main; sys.exit(main(sys.argv[1:]))"


def _small_workflow(tmp_path: Path) -> Path:
    """The wind-tunnel study on 6 tip-speed ratios x 2 pitch angles (instead of 12 x 6)."""
    text = WORKFLOW.read_text()
    full_tsr = "tsr = [2.0, 2.5, 3.0, 3.5, 4.0, 4.5, 5.0, 5.5, 6.0, 6.5, 7.0, 7.5]"
    full_pitch = "pitch = [-2.0, 0.0, 2.0, 4.0, 6.0, 8.0]"
    assert full_tsr in text and full_pitch in text, f"{WORKFLOW} changed: update the small copy in this test"
    path = tmp_path / "wind_tunnel_small.toml"
    path.write_text(text.replace(full_tsr, "tsr = [2.5, 3.5, 4.5, 5.5, 6.5, 7.5]")
                    .replace(full_pitch, "pitch = [0.0, 4.0]"))
    return path


@pytest.fixture(scope="module")
def reports(tmp_path_factory):
    """``{"calibration": report.html, "diagnosis": report.html}``, made by the CLI in two processes at once."""
    tmp = tmp_path_factory.mktemp("reports")
    runs = {"calibration": ["run", str(_small_workflow(tmp)), "--out", str(tmp / "run")],
            "diagnosis": ["diagnose", "--rotor", "nrel5mw", "--data", str(CAMPAIGN), "--out", str(tmp / "diagnose")]}
    env = dict(os.environ, MPLBACKEND="Agg")
    procs = {k: subprocess.Popen([sys.executable, "-c", CLI, *args], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                 text=True, env=env, cwd=tmp) for k, args in runs.items()}
    for name, proc in procs.items():
        out, _ = proc.communicate(timeout=600)
        assert proc.returncode == 0, f"calib {runs[name][0]} failed:\n{out[-3000:]}"
    paths = {"calibration": tmp / "run" / "report.html", "diagnosis": tmp / "diagnose" / "report.html"}
    for path in paths.values():
        assert path.is_file(), path
    return paths


# ----------------------------------------------------------------------------- the checks
IMAGES_JS = "return Array.from(document.images).map(i => [i.alt, i.complete, i.naturalWidth, i.naturalHeight]);"
OVERFLOW_JS = """
const root = document.documentElement, limit = root.clientWidth;
const wide = Array.from(document.body.querySelectorAll('*'))
    .filter(e => e.getBoundingClientRect().right > limit + 0.5 || e.scrollWidth > limit)
    .slice(0, 5).map(e => e.tagName.toLowerCase() + (e.className ? '.' + e.className : '') + ' right='
                          + Math.round(e.getBoundingClientRect().right) + ' scrollWidth=' + e.scrollWidth);
const boxes = Array.from(document.querySelectorAll('.table'))
    .filter(b => b.scrollWidth > b.clientWidth).map(b => b.scrollWidth + ' > ' + b.clientWidth);
return [root.scrollWidth, root.clientWidth, window.innerWidth, wide, boxes];
"""


def open_page(driver, path: Path) -> None:
    driver.set_window_size(WIDTH, 900)
    driver.get(path.resolve().as_uri())
    deadline = time.monotonic() + 30
    while driver.execute_script("return document.readyState") != "complete":
        assert time.monotonic() < deadline, f"{path} did not finish loading in 30 s"
        time.sleep(0.1)
    # what a reader can unfold counts too (the calibration report's reproducibility block)
    driver.execute_script("document.querySelectorAll('details').forEach(d => d.open = true);")


def page_problems(driver) -> list[str]:
    """What is wrong with the open page: broken images, console errors, horizontal overflow."""
    problems = []
    images = driver.execute_script(IMAGES_JS)
    for alt, complete, width, height in images:
        if not (complete and width > 0 and height > 0):
            problems.append(f"image {alt!r} did not load (naturalWidth {width})")
    for entry in driver.get_log("browser"):
        if entry["level"] == "SEVERE":
            problems.append(f"console error: {entry['message']}")
    scroll, client, inner, wide, boxes = driver.execute_script(OVERFLOW_JS)
    if scroll > client:
        problems.append(f"horizontal overflow at a {inner} px window: scrollWidth {scroll} > clientWidth {client}; "
                        f"widest elements: {', '.join(wide)}")
    for box in boxes:       # the reports' scroll boxes keep the page in bounds; at 1280 px none should scroll
        problems.append(f"a table scrolls inside its box at a {inner} px window (scrollWidth {box})")
    return problems


def screenshot(driver, name: str) -> Path:
    """A full-page PNG in ``test_artifacts/`` (the window grown to the page's height)."""
    height = driver.execute_script("return document.documentElement.scrollHeight")
    driver.set_window_size(WIDTH, min(max(int(height), 600), 16000))
    ARTIFACTS.mkdir(exist_ok=True)
    path = ARTIFACTS / f"report_{name}.png"
    assert driver.save_screenshot(str(path)), path
    driver.set_window_size(WIDTH, 900)
    print(f"\nscreenshot: {path}")
    return path


@pytest.mark.parametrize("name, min_images", [("calibration", 5), ("diagnosis", 2)])
def test_report_renders_in_chromium(browser, reports, name, min_images):
    open_page(browser, reports[name])
    assert browser.execute_script("return window.innerWidth") == WIDTH
    assert len(browser.execute_script(IMAGES_JS)) >= min_images
    problems = page_problems(browser)
    shot = screenshot(browser, name)
    assert shot.stat().st_size > 10_000
    assert not problems, f"{reports[name]} ({shot}):\n" + "\n".join(problems)


def test_checks_catch_overflow_broken_image_and_console_error(browser, tmp_path):
    """The checks above can fail: a page with each fault is reported with each."""
    page = tmp_path / "faulty.html"
    page.write_text("<!DOCTYPE html><html><head><meta charset='utf-8'><link rel='icon' href='data:,'></head><body>"
                    "<div class='too-wide' style='width:2000px'>wide</div>"
                    "<div class='table' style='overflow-x:auto'><table><tr><td style='min-width:3000px'>x</td></tr>"
                    "</table></div>"
                    "<img alt='missing' src='no_such_figure.png'>"
                    "<script>console.error('deliberate error')</script></body></html>")
    open_page(browser, page)
    problems = page_problems(browser)
    assert any(p.startswith("horizontal overflow") and "div.too-wide" in p for p in problems), problems
    assert any(p.startswith("image 'missing' did not load") for p in problems), problems
    assert any("deliberate error" in p for p in problems), problems
    assert any(p.startswith("a table scrolls inside its box") for p in problems), problems
