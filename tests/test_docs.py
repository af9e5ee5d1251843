"""The README and the documentation pages: short README, links that resolve, examples that run."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", ROOT / "CHANGELOG.md", *sorted((ROOT / "docs").rglob("*.md"))]
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")


def test_the_readme_is_short():
    assert len((ROOT / "README.md").read_text().splitlines()) <= 150


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_every_relative_link_resolves(page):
    bad = []
    for target in LINK.findall(page.read_text()):
        if re.match(r"^[a-z]+:", target) or target.startswith("#"):
            continue
        path = (page.parent / target.split("#", 1)[0]).resolve()
        if not path.exists():
            bad.append(target)
    assert not bad, f"{page.relative_to(ROOT)}: links to missing files: {bad}"


def test_every_page_is_reachable_from_the_readme():
    """Each documentation page is linked from the README or from a page linked from it."""
    seen, todo = set(), [ROOT / "README.md"]
    while todo:
        page = todo.pop()
        if page in seen or page.suffix != ".md" or not page.exists():
            continue
        seen.add(page)
        for target in LINK.findall(page.read_text()):
            if not re.match(r"^[a-z]+:", target) and not target.startswith("#"):
                todo.append((page.parent / target.split("#", 1)[0]).resolve())
    missing = [str(p.relative_to(ROOT)) for p in PAGES if p.resolve() not in seen]
    assert not missing, f"pages no link reaches: {missing}"


def test_the_readme_python_example_runs(tmp_path):
    """The README's Python block, on the shipped own-turbine table instead of ``campaign.csv``."""
    text = (ROOT / "README.md").read_text()
    block = re.search(r"```python\n(.*?)```", text, re.S).group(1)
    assert '"campaign.csv"' in block
    table = ROOT / "workflows" / "data" / "own_turbine_field.csv"
    script = tmp_path / "example.py"
    script.write_text(block.replace('"campaign.csv"', repr(str(table))))
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert out.returncode == 0, out.stderr[-2000:]
    assert "chi2/dof before" in out.stdout


def test_each_command_speaks_under_its_own_prefix(tmp_path):
    """``calib diagnose`` with automatic α nodes says where it put them as ``[calib diagnose]``,
    never as ``[calib run]`` (the committed CCBlade control, rigid set-up)."""
    import logging

    from calib.diagnosis.command import run_diagnose
    from calib.logs import command_logging

    data = ROOT / "tests" / "data" / "oof"
    config = tmp_path / "config.toml"
    config.write_text((data / "config_rigid.toml").read_text()
                      + '\n[grid]\nalpha_nodes_deg = "auto"\neta_nodes = [0.3, 0.6, 1.0]\n')
    lines = []
    with command_logging(tmp_path / "out"):
        handler = logging.Handler()
        handler.emit = lambda record: lines.append(record.getMessage())
        logging.getLogger("calib").addHandler(handler)
        try:
            diag = run_diagnose("nrel5mw", str(data / "rigid_control.csv"), str(tmp_path / "out"),
                                config=str(config), history=False, printer=lines.append)
        finally:
            logging.getLogger("calib").removeHandler(handler)
    assert any(line.startswith("[calib diagnose] set-up: alpha nodes from the data") for line in lines), lines[:20]
    assert not [line for line in lines if line.startswith("[calib run]")]
    # the report's first sentence on a control: nothing named, and why
    from calib.report.diagnosis_report import decision_words
    assert diag.effect == "none" and decision_words(diag).startswith("No effect is named: the nominal model is consistent")
    assert "No effect is named" in (tmp_path / "out" / "report.html").read_text()


def test_the_python_page_example_runs(tmp_path):
    """docs/user_guide/python.md: the pandas example, run from the repository root."""
    pytest.importorskip("pandas")
    block = re.search(r"```python\n(.*?)```", (ROOT / "docs" / "user_guide" / "python.md").read_text(), re.S).group(1)
    script = tmp_path / "example.py"
    script.write_text(block + "\nprint(result.parameters_frame().loc['pitch_offset', 'verdict'])\n"
                      "print(prediction.to_dataframe(meas.conditions).shape)\n")
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert out.returncode == 0, out.stderr[-2000:]
    assert "(30, " in out.stdout


def test_the_documentation_site_builds_without_warnings(docs_site):
    """``make docs``: MkDocs in strict mode (a broken link, a missing page, a docstring the API
    reference cannot render is an error); the build is the session's ``docs_site`` (tests/conftest.py)."""
    site, out = docs_site
    assert out.returncode == 0, out.stderr[-3000:]
    assert (site / "api" / "calibration" / "index.html").stat().st_size > 50_000
    assert "CalibrationSettings" in (site / "api" / "calibration" / "index.html").read_text()
    assert "calibration.prior_std" in (site / "reference" / "settings" / "index.html").read_text()
    # the examples ran during the build: their pages hold the code's output
    demo = (site / "examples" / "diagnose_demo" / "index.html").read_text()
    assert "best explanation: rotational_augmentation" in demo
    assert "To tighten pitch_offset" in (site / "examples" / "own_turbine" / "index.html").read_text()
    # a validation page says "Not published yet" only where its data file is missing (issue 35: the coverage
    # page said so beside coverage_map.json and coverage_truncated.json)
    for page in (site / "validation").rglob("index.html"):
        for sentence in re.findall(r"Not published yet[^*<]*", page.read_text()):
            names = re.findall(r"docs/validation/data/([\w.]+\.json)", sentence)
            assert names and not any((ROOT / "docs" / "validation" / "data" / n).is_file() for n in names), \
                (page, sentence)
    assert "Not published yet" not in (site / "validation" / "coverage" / "index.html").read_text()
    # no docstring role left raw (issue 35: ":class:`~calib.history.RecordedModel`" in 636 places)
    raw = [(p.relative_to(site), m) for p in site.rglob("*.html")
           for m in re.findall(r":(?:class|func|meth|mod|attr|data|obj|exc):(?:<code>|`)[^<`]*", p.read_text())]
    assert not raw, raw[:5]


def test_every_setting_is_documented_where_the_reference_is_generated_from():
    """The settings reference (docs/reference/settings.md) is generated from these docstrings: a
    field without a description would reach the page as "(undocumented)"."""
    from calib.bem import BemSettings
    from calib.calibration import CalibrationSettings
    from calib.diagnosis.settings import DiagnosisSettings
    from calib.report.settings_doc import parameter_docs, settings_markdown, undocumented_fields
    from calib.workflow.validation import ValidationSettings

    for cls in (CalibrationSettings, BemSettings, DiagnosisSettings, ValidationSettings):
        assert undocumented_fields(cls) == [], cls.__name__
        assert all(desc for _, desc in parameter_docs(cls).values()), cls.__name__
    table = settings_markdown(CalibrationSettings, "calibration")
    assert '| `calibration.estimator` | `"map"` |' in table and "(undocumented)" not in table
    assert "<!-- settings: calib.calibration.settings.CalibrationSettings calibration -->" in \
        (ROOT / "docs" / "reference" / "settings.md").read_text()
