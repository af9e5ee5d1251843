"""The calib command: the demo job and clean errors."""

import json

import numpy as np
import pytest

from calib.cli import main


def test_demo_writes_figures_and_summary(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path)]) == 0
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert (tmp_path / "cp_surface.png").stat().st_size > 10_000
    assert (tmp_path / "power_curve.png").stat().st_size > 10_000
    # NREL 5-MW: maximum C_P near 0.48 at λ ≈ 7-8 and fine pitch (Jonkman et al. 2009, §7)
    assert 0.46 < summary["cp_max"] < 0.50
    assert 6.5 < summary["tsr_at_cp_max"] < 8.5
    assert summary["surface_failed"] == 0 and summary["power_curve_failed"] == 0
    assert 10.5 < summary["rated_wind_speed"] < 12.5
    # the 5° shaft tilt explains the difference from an untilted rotor's maximum (the CCBlade comparison's):
    # the wind's normal component scales by cos(tilt), the power by about cos³(tilt)
    ratio = summary["cp_max"] / summary["cp_max_untilted"]
    assert summary["shaft_tilt_deg"] == 5.0 and abs(ratio - np.cos(np.radians(5.0)) ** 3) < 0.002, ratio
    assert "with the 5° shaft tilt, " in (tmp_path / "report.html").read_text()
    # the diagnosis on the embedded campaign names its hidden effect (stall delay)
    diagnosis = json.loads((tmp_path / "diagnosis" / "diagnosis.json").read_text())
    assert diagnosis["effect"] == "rotational_augmentation"
    assert diagnosis["before"]["chi2_per_dof"] >= 5 and diagnosis["after"]["chi2_per_dof"] <= 1.5
    report = (tmp_path / "diagnosis" / "report.html").read_text()
    # the report explains its statistics where they appear and gives units
    assert "How to read the table" in report and "BIC weight</b> is the" in report
    assert "RMS per channel (measured − model)" in report and " W, thrust " in report
    # the demo's own report: the surface, the power curve, what the data hide and the decision
    demo = (tmp_path / "report.html").read_text()
    assert demo.count("data:image/png;base64,") == 2 and "Du &amp; Selig (1998) form, strength 1" in demo
    assert "best explanation: rotational_augmentation" in demo and 'href="diagnosis/report.html"' in demo
    out = capsys.readouterr().out
    assert "report.html" in out
    # every line under the demo's own prefix, the diagnosis's set-up lines too (issue 35)
    assert "[calib demo] set-up: alpha nodes" in out and "[calib diagnose]" not in out


def test_unknown_rotor_is_a_clean_error(tmp_path, capsys):
    assert main(["demo", "--out", str(tmp_path), "--rotor", "vestas"]) == 2
    err = capsys.readouterr().err
    assert "nrel5mw" in err and "Traceback" not in err


def test_fmu_without_subcommand_is_a_usage_error(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["fmu"])
    assert exc.value.code == 2
    assert "build" in capsys.readouterr().err


def _help(args, capsys):
    with pytest.raises(SystemExit) as exc:
        main(args + ["--help"])
    assert exc.value.code == 0
    return capsys.readouterr().out


@pytest.mark.parametrize("command", [[], ["demo"], ["run"], ["predict"], ["fmu"], ["fmu", "build"], ["rotors"]])
def test_help_is_plain_and_describes_every_argument(command, capsys):
    text = _help(command, capsys)
    assert "``" not in text and ":func:" not in text and ":class:" not in text
    assert "rest" not in text.split()
    # every option line of argparse's listing carries a description after the option itself
    lines = text.splitlines()
    for k, line in enumerate(lines):
        stripped = line.strip()
        if stripped.startswith("--") and stripped != "--version":
            described = len(stripped.split("  ")) > 1 or (k + 1 < len(lines) and lines[k + 1].startswith(" " * 10))
            assert described, line
    if command == ["run"]:
        assert "workflows/README.md" in text
    if command == ["fmu", "build"]:
        assert "--variant" in text and "--rotor" in text and "--force" in text


def test_version(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    from calib import __version__
    assert capsys.readouterr().out.strip() == f"calib {__version__}"
