"""Embedded rotors, Phase VI data and the shipped reference tables."""

import csv

import numpy as np
import pytest

from calib.errors import InputError
from calib.rotor.aerodyn import read_aerodyn_polar
from calib.rotor.geometry import Rotor
from calib.rotor.library import (DATA_DIR, PHASE_VI_TIP_PITCH_DEG, ROTORS, S809_ATTACHED_LIMIT_DEG,
                                 load_phase_vi_measurements, load_rotor, phase_vi_s809_table,
                                 reference_path)
from calib.rotor.windio import read_windio


@pytest.mark.parametrize("name", list(ROTORS))
def test_every_rotor_loads_with_full_circle_polars(name):
    rotor = load_rotor(name)
    assert isinstance(rotor, Rotor) and rotor.name == name
    assert rotor.r[0] >= rotor.hub_radius and rotor.r[-1] == pytest.approx(rotor.tip_radius)
    for af in rotor.airfoils:
        assert all(t.covers_full_circle for t in af.tables)
    assert set(np.unique(rotor.airfoil_id)) == set(range(len(rotor.airfoils)))


def test_unknown_rotor_lists_valid_names():
    with pytest.raises(InputError) as err:
        load_rotor("nrel_5mw")
    for name in ROTORS:
        assert name in str(err.value)
    assert load_rotor("NREL5MW").n_stations == 19  # case-insensitive


def test_nrel5mw():
    rotor = load_rotor()
    assert rotor.n_stations == 19 and rotor.n_blades == 3
    assert rotor.hub_radius == 1.5 and rotor.tip_radius == pytest.approx(63.0, abs=2e-4)
    assert rotor.chord[0] == pytest.approx(3.542) and rotor.chord[-1] == pytest.approx(1.419)
    assert (rotor.precone_deg, rotor.tilt_deg, rotor.hub_height) == (2.5, 5.0, 90.0)
    assert [a.name for a in rotor.airfoils] == ["Cylinder1", "Cylinder2", "DU40_A17", "DU35_A17", "DU30_A17",
                                                "DU25_A17", "DU21_A17", "NACA64_A17"]
    s = rotor.schedule
    assert s.rated_power == pytest.approx(5.296610e6, rel=1e-6)
    assert s.rated_power * s.generator_efficiency == pytest.approx(5.0e6)
    assert (s.min_rotor_speed, s.max_rotor_speed, s.design_tsr) == (6.9, 12.1, 7.55)
    assert (s.cut_in, s.cut_out, s.fine_pitch) == (3.0, 25.0, 0.0)


def test_iea34_aerodyn_route_matches_windio_route():
    aero = load_rotor("iea3.4")
    wind = read_windio(DATA_DIR / "iea3p4" / "IEA-3.4-130-RWT_windIO.yaml", n_stations=aero.n_stations)
    for field in ("hub_radius", "n_blades", "precone_deg", "tilt_deg", "hub_height"):
        assert getattr(aero, field) == pytest.approx(getattr(wind, field))
    assert aero.tip_radius == pytest.approx(wind.tip_radius, abs=0.1)  # 64.91 vs 65.0 m
    np.testing.assert_allclose(aero.eta, wind.eta, atol=2e-3)
    np.testing.assert_allclose(aero.chord, wind.chord, rtol=0.01)
    np.testing.assert_allclose(aero.twist_deg, wind.twist_deg, atol=0.1)
    np.testing.assert_allclose(aero.precurve, wind.precurve, atol=0.1)
    assert aero.schedule.design_tsr == wind.schedule.design_tsr
    assert aero.schedule.max_rotor_speed == pytest.approx(12.1, abs=1e-3)


def test_iea34_generator_efficiency_from_ccblade_table():
    table = np.loadtxt(reference_path("IEA-3.4-130-RWT_performance_ccblade.dat"))
    assert table.shape == (50, 12)
    s = load_rotor("iea3.4").schedule
    assert s.generator_efficiency == pytest.approx(table[-1, 3] / table[-1, 4], rel=1e-6)
    assert s.rated_power == pytest.approx(table[:, 4].max(), rel=1e-4)  # aero power above rated


def test_iea15():
    rotor = load_rotor("iea15")
    assert rotor.n_stations == 50 and len(rotor.airfoils) == 50
    assert rotor.tip_radius == pytest.approx(241.94 / 2, abs=1e-3)
    assert rotor.precurve_tip == pytest.approx(4.0, abs=2e-3)   # 4 m upwind prebend, CCBlade sign
    s = rotor.schedule
    assert s.rated_power * s.generator_efficiency == pytest.approx(15e6)
    assert (s.min_rotor_speed, s.max_rotor_speed, s.design_tsr) == pytest.approx((5.0, 7.56, 9.0))


def _rows(path):
    with open(path, newline="") as fh:
        return [r for r in csv.reader(fh) if r and not r[0].startswith("#")]


def test_phase_vi_geometry_and_twist_convention():
    rotor = load_rotor("phase_vi")
    raw = np.array(_rows(DATA_DIR / "phase_vi" / "phaseVI_blade.csv"), dtype=float)
    assert rotor.n_blades == 2 and rotor.n_stations == 26
    assert rotor.tip_radius == pytest.approx(5.029) and rotor.hub_radius == pytest.approx(0.432)
    np.testing.assert_allclose(rotor.r, raw[:, 0])
    np.testing.assert_allclose(rotor.chord, raw[:, 1])
    assert rotor.twist_deg[-1] == 0.0
    # OpenFAST runs the report twist with BlPitch = 4.815 deg: same section angles as ours at 3 deg
    key = {r[0]: r[1] for r in _rows(DATA_DIR / "phase_vi" / "UAE_ElastoDyn_key_parameters.csv")}
    np.testing.assert_allclose(rotor.twist_deg + PHASE_VI_TIP_PITCH_DEG, raw[:, 2] + float(key["BlPitch"]),
                               atol=1e-9)
    names = [rotor.airfoils[i].name for i in rotor.airfoil_id]
    assert names[:6] == ["cylinder"] * 6 and names[6:] == ["S809"] * 20
    assert rotor.r[6] == pytest.approx(1.2575)


def test_phase_vi_s809_polar_agrees_with_openfast_certtest():
    cert = read_aerodyn_polar(reference_path("S809_AD15.dat")).tables[0]
    m = (cert.alpha_deg >= -20.1) & (cert.alpha_deg <= 26.1)
    pressure = phase_vi_s809_table(drag="pressure")
    np.testing.assert_allclose(pressure.alpha_deg, cert.alpha_deg[m])
    np.testing.assert_allclose(pressure.cl, cert.cl[m])
    np.testing.assert_allclose(pressure.cd, cert.cd[m])
    np.testing.assert_allclose(pressure.cm, cert.cm[m])
    combined = phase_vi_s809_table()
    np.testing.assert_allclose(combined.cl, cert.cl[m])
    wake = combined.cd != cert.cd[m]
    assert np.all(np.abs(combined.alpha_deg[wake]) <= S809_ATTACHED_LIMIT_DEG)
    assert np.all(combined.cd[wake] > cert.cd[m][wake])  # total drag >= pressure drag
    assert combined.cd[combined.alpha_deg == 0.0] == pytest.approx(0.0085)
    # the extended polar used by the rotor keeps the measured rows
    s809 = load_rotor("phase_vi").airfoils[1].tables[0]
    assert s809.covers_full_circle
    np.testing.assert_allclose(np.interp(cert.alpha_deg[m], s809.alpha_deg, s809.cl), cert.cl[m])


def test_phase_vi_measurements():
    data = load_phase_vi_measurements()
    perf, span = data["performance"], data["spanwise"]
    np.testing.assert_allclose(perf["wind_speed"], [7, 10, 13, 15, 20, 25])
    assert perf["power"][0] == pytest.approx(5945.8)  # kW -> W
    # independent columns agree: P = Q * Omega within 1 %
    omega = perf["rotor_speed"] * np.pi / 30
    np.testing.assert_allclose(perf["lss_torque"] * omega, perf["power"], rtol=0.01)
    assert np.all((perf["air_density"] > 1.1) & (perf["air_density"] < 1.3))
    np.testing.assert_allclose(span["r_over_R"], [0.30, 0.47, 0.63, 0.80, 0.95])
    assert span["cn"].shape == span["ct"].shape == span["cm"].shape == (6, 5)
    assert span["cn"][2, 0] == pytest.approx(2.0322)  # 13 m/s, r/R = 0.30


def test_reference_paths():
    for name in ("IEA-3.4-130-RWT_performance_ccblade.dat", "NREL5MW_Oper_openfast_sim.csv",
                 "NREL_Reference_5MW_126_powercurve_turbine-models.csv", "S809_AD15.dat"):
        assert reference_path(name).is_file()
    with pytest.raises(InputError, match="valid names: .*S809_AD15.dat"):
        reference_path("missing.csv")
    for folder in ("nrel5mw", "iea3p4", "iea15", "phase_vi", "reference"):
        text = (DATA_DIR / folder / "PROVENANCE.txt").read_text()
        assert "copied from shared/data/" in text and "2026-11-21" in text
