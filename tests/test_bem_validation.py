"""The native BEM against independent references.

- IEA 3.4-MW: CCBlade's steady performance table (independent BEM code), run with that
  table's set-up (precone, prebend, tilt 5 deg, shear exponent 0.2, 4 azimuth sectors,
  CCBlade's polar smoothing, tip radius of the rotor definition).
- NREL 5-MW: OpenFAST steady operating points (rows at 5 m/s and above).
- Phase VI: measured sequence H low-speed-shaft torque (the known stall under-prediction).
"""

import csv

import numpy as np

from calib.bem import BemSettings, SectionPolars, solve_bem
from calib.models.base import OperatingConditions
from calib.rotor.library import load_phase_vi_measurements, load_rotor, reference_path

CCBLADE_SMOOTHING = (0.01, 0.001)  # CCAirfoil's RectBivariateSpline s for C_L and C_D (WISDEM 4.2.9)


def iea34_comparison(smoothing=CCBLADE_SMOOTHING):
    rotor = load_rotor("iea3.4")
    table = np.loadtxt(reference_path("IEA-3.4-130-RWT_performance_ccblade.dat"))
    cond = OperatingConditions(table[:, 0], table[:, 1], table[:, 2])
    res = solve_bem(rotor, cond, BemSettings(shear_exponent=0.2, n_sectors=4),
                    polars=SectionPolars.from_rotor(rotor, smoothing=smoothing))
    rel = {"power": res.power / table[:, 4] - 1, "thrust": res.thrust / table[:, 5] - 1,
           "torque": res.torque / table[:, 6] - 1,
           "hub_flap_moment": res.hub_flap_moment / table[:, 7] - 1,
           "root_flap_moment": res.root_flap_moment / table[:, 7] - 1}
    below = table[:, 4] < 0.999 * table[:, 4].max()          # rows below rated power
    return res, rel, below


def test_iea34_reproduces_ccblade_table(capsys):
    res, rel, below = iea34_comparison()
    assert res.n_failed == 0
    assert rel["power"].size == 50
    for name in ("power", "thrust"):
        assert np.max(np.abs(rel[name][below])) <= 0.02, name
        # with CCAirfoil's own smoothing (s = 0.01 on C_L) the median row agrees to 0.3 %; the s = 0.1
        # once used here gives 0.48 % in thrust
        assert np.median(np.abs(rel[name])) <= 0.003, name
    with capsys.disabled():
        print("\nIEA 3.4-MW vs CCBlade table, |relative difference| [%]: median / max below rated / "
              "max above rated")
        for name, r in rel.items():
            print(f"  {name:17s} {100 * np.median(np.abs(r)):6.2f} {100 * np.abs(r[below]).max():6.2f} "
                  f"{100 * np.abs(r[~below]).max():6.2f}")
        print(f"  points with several roots at a section (smallest-φ root kept, flagged): "
              f"{int(res.multiple_roots.sum())} of {res.multiple_roots.size}")
        _, rel_raw, _ = iea34_comparison(smoothing=None)
        d = 100 * np.abs(rel_raw["power"][below])
        print("  without CCBlade's polar smoothing, power |relative difference| [%] of the first rows below "
              "rated: " + ", ".join(f"{x:.2f}" for x in d[:4]) + f"; max of the others {d[4:].max():.2f}")
    # the table's flap moment is about the rotor centre (CCBlade integrates N' z): it agrees; the
    # moment about the blade root is smaller by the hub-radius arm and must NOT match
    assert np.median(np.abs(rel["hub_flap_moment"])) < 0.015
    assert np.median(np.abs(rel["root_flap_moment"])) > 0.03


def nrel5mw_comparison():
    """The native BEM at OpenFAST's steady operating points (5 m/s and above): the relative differences
    in aerodynamic power (Ω × shaft torque) and thrust, the wind speeds and the region-2 mask."""
    rotor = load_rotor("nrel5mw")
    with open(reference_path("NREL5MW_Oper_openfast_sim.csv"), newline="") as fh:
        rows = [r for r in csv.DictReader(fh) if float(r["WS_[m/s]"]) >= 5.0]
    col = lambda k: np.array([float(r[k]) for r in rows])  # noqa: E731
    cond = OperatingConditions(col("WS_[m/s]"), col("RotSpeed_[rpm]"), col("BldPitch_[deg]"))
    res = solve_bem(rotor, cond, BemSettings())
    # aerodynamic power from the shaft torque (steady: no acceleration) and the aero thrust; the
    # table's RtAeroCp uses the disc-averaged relative wind, so C_P is not compared directly
    power_ref = col("RotTorq_[kN-m]") * 1e3 * cond.rotor_speed * np.pi / 30
    thrust_ref = col("RtAeroFxh_[kN]") * 1e3
    return res, res.power / power_ref - 1, res.thrust / thrust_ref - 1, cond.wind_speed, col("BldPitch_[deg]") < 0.5


def test_nrel5mw_against_openfast_steady_table():
    res, dp, dt, _, region2 = nrel5mw_comparison()
    assert res.n_failed == 0
    # region 2: the rigid steady BEM is 1-3 % above OpenFAST in power, within 1.5 % in thrust
    assert np.all(np.abs(dp[region2]) < 0.03)
    assert np.all(np.abs(dt[region2]) < 0.015)
    # above rated OpenFAST's flexible blades deflect downwind (coning, less swept area) at the same
    # pitch, so the rigid BEM carries more load; the gap grows with wind speed but stays below 8 %
    assert np.all((dp[~region2] > 0) & (dp[~region2] < 0.08))
    assert np.all((dt[~region2] > 0) & (dt[~region2] < 0.05))


def phase_vi_comparison():
    """The native BEM with the 2-D S809 polars at sequence H's operating points: the solution and the
    measured performance table (``lss_torque`` [N m])."""
    rotor = load_rotor("phase_vi")
    meas = load_phase_vi_measurements()["performance"]
    cond = OperatingConditions(meas["wind_speed"], meas["rotor_speed"], 3.0, meas["air_density"], 0.0)
    return solve_bem(rotor, cond, BemSettings(use_tilt=False)), meas


def test_phase_vi_two_dimensional_polars_underpredict_stalled_torque(capsys):
    res, meas = phase_vi_comparison()
    assert res.n_failed == 0
    ratio = res.torque / meas["lss_torque"]
    with capsys.disabled():
        print("\nPhase VI sequence H: LSS torque [N m], measured vs native BEM (2-D S809 polars)")
        for v, m, b, multi in zip(meas["wind_speed"], meas["lss_torque"], res.torque, res.multiple_roots):
            note = "  several roots at a section: smallest-φ root kept, flagged" if multi else ""
            print(f"  {v:5.1f} m/s  measured {m:8.1f}  BEM {b:8.1f}  ratio {b / m:5.2f}{note}")
    v = meas["wind_speed"]
    # attached flow (7, 10 m/s): within 15 % of the measurement
    assert np.all(np.abs(ratio[v <= 10.0] - 1) < 0.15)
    # stall (13-25 m/s): the 2-D polars miss rotational augmentation on the inboard blade; the
    # deficit opens at 13 m/s and exceeds a factor of 2 from 15 m/s on
    assert np.all(ratio[v >= 13.0] < 0.9)
    assert np.all(ratio[v >= 15.0] < 0.5)
