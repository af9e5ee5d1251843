"""The HTML reports and the documentation site in a real browser: headless Chromium driven through WebDriver.

Four reports are made from small, fast inputs, in four processes at once: the calibration report of
``calib run`` on the wind-tunnel study of ``workflows/wind_tunnel_hub_loads.toml`` (6 x 2 operating
points) and on the own-turbine job of ``workflows/own_turbine.toml``, and the diagnosis report of
``calib diagnose`` on the demo campaign (as ``calib demo`` runs it) and on the measured Phase VI
sequence H (``workflows/diagnose/phase_vi.toml``). Each is opened at 1100 px (the width a report must
fit, issue 43) and at 1280 px, and must show: every image loaded (``naturalWidth > 0``), no console
message of level SEVERE, no horizontal overflow (``scrollWidth <= clientWidth`` of the document
element, with every ``<details>`` unfolded), no table wider than its container (the scroll box the
reports put it in included: a table that needs it fails), and no name or number broken across lines
inside a table cell (measured in the browser: the client rectangles of a Range over each token of
``[A-Za-z0-9_.:]``, such as ``rotational_augmentation:chaviaropoulos_hansen``, lie on one line). The
diagnosis reports' candidate rows are one or two lines each. A full-page screenshot of each is kept in
``test_artifacts/`` (git-ignored) and its path printed.

The validation pages of the documentation site (``mkdocs build --strict``, built once per session by
the ``docs_site`` fixture of ``tests/conftest.py``, which ``tests/test_docs.py`` shares) get the same
table checks at both widths: their tables come from ``docs/validation/data/*.json`` through
``docs/hooks.py``. The build takes 12-25 s on two cores, once for both files.

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
#: The window widths every page is checked at: the width a report and a validation page must fit
#: without a table scrolling (issue 43), and the common laptop width.
WIDTHS = (1100, 1280)
#: No host name resolves (--host-resolver-rules): a page never waits on the network (the site's web
#: fonts took 10 s to fail), and a report that fetches anything fails its console check.
CHROMIUM_FLAGS = ["--headless", "--no-sandbox", "--disable-gpu", "--no-first-run", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync", "--host-resolver-rules=MAP * ~NOTFOUND"]
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
#: report name -> the fewest images it embeds
REPORTS = {"calibration": 5, "diagnosis": 2, "phase_vi_diagnosis": 2, "own_turbine": 5}


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
    """``{name: report.html}`` of :data:`REPORTS`, made by the CLI in four processes at once."""
    tmp = tmp_path_factory.mktemp("reports")
    runs = {"calibration": ["run", str(_small_workflow(tmp)), "--out", str(tmp / "run")],
            "diagnosis": ["diagnose", "--rotor", "nrel5mw", "--data", str(CAMPAIGN), "--out", str(tmp / "diagnose")],
            "phase_vi_diagnosis": ["diagnose", "--config", str(ROOT / "workflows" / "diagnose" / "phase_vi.toml"),
                                   "--data", str(ROOT / "workflows" / "data" / "phase_vi_sequence_H.csv"),
                                   "--out", str(tmp / "phase_vi")],
            "own_turbine": ["run", str(ROOT / "workflows" / "own_turbine.toml"), "--out", str(tmp / "own")]}
    # the package of this checkout, not whichever one the environment has installed
    path = os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH", "")) if p)
    env = dict(os.environ, MPLBACKEND="Agg", PYTHONPATH=path)
    procs = {k: subprocess.Popen([sys.executable, "-c", CLI, *args], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                 text=True, env=env, cwd=tmp) for k, args in runs.items()}
    for name, proc in procs.items():
        out, _ = proc.communicate(timeout=600)
        assert proc.returncode == 0, f"calib {runs[name][0]} failed:\n{out[-3000:]}"
    paths = {name: Path(args[args.index("--out") + 1]) / "report.html" for name, args in runs.items()}
    for path in paths.values():
        assert path.is_file(), path
    return paths


@pytest.fixture(scope="module")
def validation_pages(docs_site):
    """The built site's validation pages (``site/validation/**/index.html``)."""
    site, build = docs_site
    assert build.returncode == 0, f"mkdocs build failed (tests/test_docs.py says more):\n{build.stderr[-3000:]}"
    pages = sorted((site / "validation").rglob("index.html"))
    assert len(pages) >= 8, pages
    return pages


# ----------------------------------------------------------------------------- the checks
IMAGES_JS = "return Array.from(document.images).map(i => [i.alt, i.complete, i.naturalWidth, i.naturalHeight]);"
OVERFLOW_JS = """
const root = document.documentElement, limit = root.clientWidth;
const wide = Array.from(document.body.querySelectorAll('*'))
    .filter(e => e.getBoundingClientRect().right > limit + 0.5 || e.scrollWidth > limit)
    .slice(0, 5).map(e => e.tagName.toLowerCase() + (e.className ? '.' + e.className : '') + ' right='
                          + Math.round(e.getBoundingClientRect().right) + ' scrollWidth=' + e.scrollWidth);
return [root.scrollWidth, root.clientWidth, window.innerWidth, wide];
"""


#: Every table wider than its container (the scroll box it sits in, or the table as its own scroll
#: box, as MkDocs-Material makes it): "table N ("first cell") is W px wide, E px more than its container".
TABLES_JS = """
const label = t => (t.querySelector('th,td') || {textContent: ''}).textContent.trim().slice(0, 40);
const out = [];
document.querySelectorAll('table').forEach((t, i) => {
  const r = t.getBoundingClientRect(), extent = r.left + Math.max(r.width, t.scrollWidth);
  for (let box = t; box && box !== document.documentElement; box = box.parentElement) {
    const right = box.getBoundingClientRect().left + box.clientLeft + box.clientWidth;
    const over = box === t ? t.scrollWidth - t.clientWidth : extent - right;
    if (over > 1) {
      out.push(`table ${i + 1} ("${label(t)}") is ${Math.round(Math.max(r.width, t.scrollWidth))} px wide, `
               + `${Math.round(over)} px more than its container ${box.tagName.toLowerCase()}.${box.className}`);
      break;
    }
  }
});
return out;
"""
#: Every token of a table cell that the lines break inside: a name of [A-Za-z0-9_.:] (the cell's
#: text nodes joined, so that a name split by <wbr> or markup counts as one) or a number in scientific
#: notation ("3.6e-12"); measured as the client rectangles of a Range over the token, which lie on
#: one line when it is whole. Returns [token, first cell text].
BROKEN_JS = """
const TOKEN = /[A-Za-z0-9_.:]*[0-9.]e[-+][0-9]+|[A-Za-z0-9_.:]{2,}/g;
const out = [];
document.querySelectorAll('td, th').forEach(cell => {
  const nodes = [], starts = [];
  let text = '';
  const walker = document.createTreeWalker(cell, NodeFilter.SHOW_TEXT);
  for (let n = walker.nextNode(); n; n = walker.nextNode()) { nodes.push(n); starts.push(text.length); text += n.data; }
  const at = k => { let j = nodes.length - 1; while (j > 0 && starts[j] > k) j--; return [nodes[j], k - starts[j]]; };
  for (const m of text.matchAll(TOKEN)) {
    const range = document.createRange();
    range.setStart(...at(m.index));
    range.setEnd(...at(m.index + m[0].length));
    const rects = Array.from(range.getClientRects()).filter(q => q.width > 0);
    if (rects.some(q => q.top >= rects[0].bottom - 1)) out.push([m[0], text.trim().slice(0, 60)]);
  }
});
return out;
"""
#: The lines of each main row of a diagnosis report's candidate table: [candidate, lines of its tallest cell].
ROW_LINES_JS = """
const lines = cell => {
  const range = document.createRange(), tops = [];
  range.selectNodeContents(cell);
  for (const q of range.getClientRects())
    if (q.width > 0 && !tops.some(t => Math.abs(t - q.top) < q.height / 2)) tops.push(q.top);
  return tops.length;
};
return Array.from(document.querySelectorAll('table.candidates tr.candidate'))
    .map(row => [row.cells[0].textContent, Math.max(...Array.from(row.cells).map(lines))]);
"""


def open_page(driver, path: Path, width: int = WIDTH) -> None:
    """``path`` loaded at a ``width`` px wide window, every ``<details>`` open; the console log of the
    pages before discarded."""
    driver.get_log("browser")
    driver.set_window_size(width, 900)
    driver.get(path.resolve().as_uri())
    deadline = time.monotonic() + 30
    while driver.execute_script("return document.readyState") != "complete":
        assert time.monotonic() < deadline, f"{path} did not finish loading in 30 s"
        time.sleep(0.1)
    # what a reader can unfold counts too (the calibration report's reproducibility block)
    driver.execute_script("document.querySelectorAll('details').forEach(d => d.open = true);")


def table_problems(driver) -> list[str]:
    """Tables of the open page wider than their container, and names or numbers broken inside a cell."""
    inner = driver.execute_script("return window.innerWidth")
    problems = [f"at a {inner} px window {p}" for p in driver.execute_script(TABLES_JS)]
    problems += [f"at a {inner} px window {token!r} breaks across lines in the cell {cell!r}"
                 for token, cell in driver.execute_script(BROKEN_JS)]
    return problems


def page_problems(driver) -> list[str]:
    """What is wrong with the open page: broken images, console errors, horizontal overflow, tables."""
    problems = []
    images = driver.execute_script(IMAGES_JS)
    for alt, complete, width, height in images:
        if not (complete and width > 0 and height > 0):
            problems.append(f"image {alt!r} did not load (naturalWidth {width})")
    for entry in driver.get_log("browser"):
        if entry["level"] == "SEVERE":
            problems.append(f"console error: {entry['message']}")
    scroll, client, inner, wide = driver.execute_script(OVERFLOW_JS)
    if scroll > client:
        problems.append(f"horizontal overflow at a {inner} px window: scrollWidth {scroll} > clientWidth {client}; "
                        f"widest elements: {', '.join(wide)}")
    return problems + table_problems(driver)


def screenshot(driver, name: str, width: int = WIDTH) -> Path:
    """A full-page PNG in ``test_artifacts/`` (the window grown to the page's height)."""
    height = driver.execute_script("return document.documentElement.scrollHeight")
    driver.set_window_size(width, min(max(int(height), 600), 16000))
    ARTIFACTS.mkdir(exist_ok=True)
    path = ARTIFACTS / f"report_{name}_{width}.png"
    assert driver.save_screenshot(str(path)), path
    driver.set_window_size(width, 900)
    print(f"\nscreenshot: {path}")
    return path


@pytest.mark.parametrize("width", WIDTHS)
@pytest.mark.parametrize("name", list(REPORTS))
def test_report_renders_in_chromium(browser, reports, name, width):
    open_page(browser, reports[name], width)
    assert browser.execute_script("return window.innerWidth") == width
    assert len(browser.execute_script(IMAGES_JS)) >= REPORTS[name]
    problems = page_problems(browser)
    shot = screenshot(browser, name, width)
    assert shot.stat().st_size > 10_000
    assert not problems, f"{reports[name]} ({shot}):\n" + "\n".join(problems)


@pytest.mark.parametrize("name", [n for n in REPORTS if n.endswith("diagnosis")])
def test_candidate_rows_are_one_or_two_lines(browser, reports, name):
    """The decision in the diagnosis report's candidate table reads row by row at 1100 px: no
    candidate's main row is taller than two lines (the long text is on the line under it)."""
    open_page(browser, reports[name], min(WIDTHS))
    rows = browser.execute_script(ROW_LINES_JS)
    assert len(rows) >= 5, f"{reports[name]}: {len(rows)} main rows of a candidate table (table.candidates tr.candidate)"
    tall = [(candidate, n) for candidate, n in rows if n > 2]
    assert not tall, f"{reports[name]}: candidate rows of more than two lines at {min(WIDTHS)} px: {tall}"


@pytest.mark.parametrize("width", WIDTHS)
def test_validation_pages_tables_fit(browser, validation_pages, width):
    """Every table of the documentation's validation pages fits the content column, no name broken."""
    problems = []
    for page in validation_pages:
        open_page(browser, page, width)
        problems += [f"{page.parent.name}: {p}" for p in table_problems(browser)]
    assert not problems, "\n".join(problems)


def test_checks_catch_overflow_broken_image_and_console_error(browser, tmp_path):
    """The checks above can fail: a page with each fault is reported with each."""
    page = tmp_path / "faulty.html"
    page.write_text("<!DOCTYPE html><html><head><meta charset='utf-8'><link rel='icon' href='data:,'></head><body>"
                    "<div class='too-wide' style='width:2000px'>wide</div>"
                    "<div class='table' style='overflow-x:auto'><table><tr><td style='min-width:3000px'>x</td></tr>"
                    "</table></div>"
                    "<div style='width:200px'><table><tr><td style='white-space:nowrap'>a row wider than the box it is in"
                    "</td></tr></table></div>"
                    "<table style='width:80px'><tr><td style='overflow-wrap:anywhere'>leading_edge_erosion:slope"
                    "</td><td>rotational_augmentation:<wbr>chaviaropoulos_hansen</td><td>3.638e-12</td></tr></table>"
                    "<table class='candidates' style='width:200px'><tr class='candidate'><td>tip_loss</td>"
                    "<td>one two three four five six seven eight nine ten eleven</td></tr></table>"
                    "<img alt='missing' src='no_such_figure.png'>"
                    "<script>console.error('deliberate error')</script></body></html>")
    open_page(browser, page)
    problems = page_problems(browser)
    assert any(p.startswith("horizontal overflow") and "div.too-wide" in p for p in problems), problems
    assert any(p.startswith("image 'missing' did not load") for p in problems), problems
    assert any("deliberate error" in p for p in problems), problems
    assert any('table 1 ("x")' in p and "more than its container div.table" in p for p in problems), problems
    assert any('table 2 ("a row wider than the box it is in")' in p for p in problems), problems
    for token in ("leading_edge_erosion:slope", "rotational_augmentation:chaviaropoulos_hansen", "3.638e-12"):
        assert any(f"{token!r} breaks across lines" in p for p in problems), (token, problems)
    assert browser.execute_script(ROW_LINES_JS)[0][1] > 2
