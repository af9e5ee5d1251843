"""La Haute Borne (ENGIE open data) through calib.scada against OpenOA's IEC power curve.

The committed extract (tests/data/scada/la_haute_borne_R80711_2014-03.csv, its provenance in
tests/data/scada/PROVENANCE) is read, filtered with the settings OpenOA's filters were given in
benchmarks/openoa_reference.py, and binned with OpenOA's bin edges; each bin's mean power must be
within 1 % of OpenOA's (committed in openoa_reference_R80711_2014-03.json, computed with openoa 3.2).
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from calib.measurements import read_measurements
from calib.scada import FilterSettings, power_curve, read_scada

DATA = Path(__file__).parent / "data" / "scada"
EXTRACT = DATA / "la_haute_borne_R80711_2014-03.csv"
REFERENCE = DATA / "openoa_reference_R80711_2014-03.json"


def openoa_settings(settings: dict) -> FilterSettings:
    """calib's FilterSettings equal to the OpenOA filters of the reference (kW -> W)."""
    rated = settings["rated_power_kw"] * 1e3
    return FilterSettings(rated_power=rated,
                          ranges={"wind_speed": tuple(settings["wind_speed_range"]),
                                  "power": tuple(1e3 * np.array(settings["power_range_kw"]))},
                          frozen_signals=("wind_speed",), frozen_count=settings["frozen_count"],
                          operating_window=tuple(settings["operating_window"]),
                          stop_power=settings["stop_power_kw"] * 1e3, fine_pitch=settings["fine_pitch"],
                          pitch_margin=settings["pitch_margin"],
                          curtailment_fraction=settings["curtailment_fraction"],
                          enabled=("out_of_range", "frozen", "start_stop", "curtailment"))


def compare(records, reference: dict) -> dict:
    """Per turbine: the largest |Δ| of the bin powers in % of OpenOA's (bins with N >= 3 and |P| > 1 % of
    rated), and the counts of both sides."""
    settings = openoa_settings(reference["settings"])
    out = {}
    for name, ref in reference["turbines"].items():
        mine = power_curve(records.select(records.turbine == name), settings, normalize=False, align="left")
        lower = np.array(ref["bins"]["lower_m_s"])
        p_ref, n_ref = np.array(ref["bins"]["power_kw"]) * 1e3, np.array(ref["bins"]["n"])
        rows = {round(float(a), 6): i for i, a in enumerate(mine.bins.lower)}
        worst, compared, n_equal = 0.0, 0, True
        for j, a in enumerate(lower):
            i = rows.get(round(float(a), 6))
            n_mine = 0 if i is None else int(mine.bins.n[i])
            n_equal &= n_mine == n_ref[j]
            if n_ref[j] >= 3 and i is not None and abs(p_ref[j]) > 0.01 * settings.rated_power:
                worst = max(worst, 100 * abs(mine.bins.power[i] - p_ref[j]) / abs(p_ref[j]))
                compared += 1
        out[name] = {"max_percent": worst, "bins_compared": compared, "n_equal": bool(n_equal),
                     "kept": mine.report.counts["kept"], "kept_openoa": ref["kept"], "report": mine.report}
    return out


@pytest.fixture(scope="module")
def result():
    return compare(read_scada(EXTRACT), json.loads(REFERENCE.read_text()))


def test_extract_has_its_provenance_line():
    text = (DATA / "PROVENANCE").read_text()
    assert EXTRACT.name in text and "Etalab" in text and "openoa 3.2" in text


def test_power_per_bin_within_one_percent_of_openoa(result):
    r = result["R80711"]
    assert r["bins_compared"] >= 15
    assert r["max_percent"] < 1.0, r["max_percent"]


def test_same_records_kept_as_openoa(result):
    r = result["R80711"]
    assert r["kept"] == r["kept_openoa"]
    assert r["n_equal"]


def test_duplicate_stamps_of_the_dst_change_are_flagged_not_dropped(result):
    counts = result["R80711"]["report"].counts
    assert counts["duplicate_stamp"] == 6          # 2014-03-30 03:00..03:50 +02:00 written twice
    assert counts["frozen"] == 115                 # OpenOA's unresponsive_flag on the same series
    assert counts["removed"] + counts["kept"] == 4464


def test_calib_scada_command_prints_counts_and_writes_bins(tmp_path, capsys):
    from calib.cli import main
    from calib.measurements import read_measurements
    out = tmp_path / "bins.csv"
    assert main(["scada", str(EXTRACT), "--rated-power", "2050", "--pressure", "965", "--bins-out", str(out),
                 "--fill", "rotor_speed=15"]) == 0
    text = capsys.readouterr().out
    assert "duplicate_stamp         6" in text and "frozen                115" in text
    # the bins with 3 or more records whose mean power is > 0 (the 0-3 m/s bins hold a parked or idling
    # rotor: counted, not written), from the printed table's own rows
    rows = [ln.split() for ln in text.splitlines() if re.match(r"\s+\d+\.\d\d\s+\d+\s", ln)]
    operating = [r for r in rows if int(r[1]) >= 3 and float(r[3]) > 0]
    assert len(operating) >= 15 and len(rows) > len(operating)
    assert len(read_measurements(out).values) == len(operating)
    assert f"{sum(int(r[1]) >= 3 for r in rows) - len(operating)} rows not in operation" in text


def test_calib_scada_command_without_rotor_speed_says_so(tmp_path, capsys):
    from calib.cli import main
    assert main(["scada", str(EXTRACT), "--rated-power", "2050", "--bins-out", str(tmp_path / "b.csv")]) == 2
    assert "rotor_speed" in capsys.readouterr().err


def test_calib_scada_writes_the_density_sigma_of_its_sensors(tmp_path, capsys):
    """``--temperature-sigma`` and ``--pressure-sigma`` give the kept records an ``air_density_sigma``
    column; for the extract's dry air at the given 965 hPa it is the closed form
    σ_ρ/ρ = √((σ_T/T)² + (σ_B/B)²) with T = B/(R₀ ρ); a negative sensor σ is refused naming the flag."""
    from calib.cli import main
    out = tmp_path / "records.csv"
    assert main(["scada", str(EXTRACT), "--rated-power", "2050", "--pressure", "965", "--records-out", str(out),
                 "--fill", "rotor_speed=15", "--temperature-sigma", "0.5", "--pressure-sigma", "3"]) == 0
    lines = [ln for ln in out.read_text().splitlines() if not ln.startswith("#")]
    names = lines[0].split(",")
    table = dict(zip(names, np.array([[float(x) for x in ln.split(",")] for ln in lines[1:]]).T))
    rho = table["air_density"]
    t = 96500.0 / (287.05 * rho)
    assert rho.size > 100
    np.testing.assert_allclose(table["air_density_sigma"] / rho, np.hypot(0.5 / t, 300.0 / 96500.0), rtol=1e-6)
    # the records a calibration can use: in operation only (the parked records at 0 m/s and the idling ones
    # with negative power are counted, not written), so calib reads the table back
    assert np.all(table["wind_speed"] > 0) and np.all(table["power"] > 0)
    assert "rows not in operation" in out.read_text()
    assert "rows not in operation" in capsys.readouterr().out
    meas = read_measurements(out)
    assert len(meas.conditions.wind_speed) == rho.size
    assert main(["scada", str(EXTRACT), "--rated-power", "2050", "--pressure", "965", "--records-out", str(out),
                 "--fill", "rotor_speed=15", "--temperature-sigma", "-1", "--pressure-sigma", "3"]) == 2
    assert "--temperature-sigma" in capsys.readouterr().err


def test_calib_scada_refuses_a_fill_that_is_not_a_number(tmp_path, capsys):
    """Two conditions in one ``--fill`` (or a word) is refused naming the flag and the condition, exit 2."""
    from calib.cli import main
    for bad in ("rotor_speed=15,pitch=0", "rotor_speed=fast", "rotor_speed=nan"):
        assert main(["scada", str(EXTRACT), "--rated-power", "2050", "--pressure", "965", "--records-out",
                     str(tmp_path / "r.csv"), "--fill", bad]) == 2
        err = capsys.readouterr().err
        assert "--fill rotor_speed" in err and "expected a number" in err and "Traceback" not in err
    assert not (tmp_path / "r.csv").exists()
