"""Write ``phase_vi_sequence_H.csv``: the measured NREL Phase VI sequence H loads as a calib table.

Source (copied verbatim into ``calib/data/phase_vi/``, see its ``PROVENANCE.txt``): the NREL
WDH "UAE Phase VI statistics" workbook, sheet ``ldsmean`` (DOI 10.21947/WDH-DAP/1910052),
rows h0700000 ... h2500000 (upwind, 0 deg yaw, 3 deg tip pitch, rigid hub, 72 rpm), via
github efirvida/of-plugins @ 5648ee65 (``sequence_H_performance.csv``,
``sequence_H_spanwise.csv``).

Columns written (SI or the units named in the header):

- conditions: wind speed [m/s], rotor speed [rpm], the tip pitch 3 deg (the package's Phase VI
  twist is stored relative to the tip, so the test condition is pitch = 3 deg), the recorded
  yaw [deg] (|yaw| <= 0.13 deg) and the air density [kg/m^3] computed by the source from the
  row's barometric pressure and temperature;
- channels: ``torque`` = LSSTQCOR (low-speed-shaft torque corrected for the rotor's own
  friction and inertia) [N m], ``thrust`` = EAEROTH (aerodynamic thrust estimated from the
  root flap bending gauges) [N], and the pressure-tap normal and chordwise force
  coefficients ``cn@r/R``, ``ct@r/R`` at r/R = 0.30, 0.47, 0.63, 0.80, 0.95 [-].

ROTPOW (power) is not written: it is the torque times the measured rotor speed, so it would
count the torque twice in the likelihood.

Run from the project root: ``.venv/bin/python workflows/data/make_phase_vi_csv.py``.
"""

import csv
from pathlib import Path

HERE = Path(__file__).resolve().parent
SOURCE = HERE.parents[1] / "calib" / "data" / "phase_vi"
OUT = HERE / "phase_vi_sequence_H.csv"
STATIONS = ("0.30", "0.47", "0.63", "0.80", "0.95")
TIP_PITCH_DEG = 3.0   # calib.rotor.library.PHASE_VI_TIP_PITCH_DEG


def _rows(name: str) -> list[dict]:
    with open(SOURCE / name, newline="") as f:
        return list(csv.DictReader(f))


def main() -> Path:
    perf = _rows("sequence_H_performance.csv")
    span = _rows("sequence_H_spanwise.csv")
    header = ["file_name", "wind_speed [m/s]", "rotor_speed [rpm]", "pitch [deg]", "yaw [deg]",
              "air_density [kg/m^3]", "torque [N m]", "thrust [N]"]
    header += [f"cn@{s}" for s in STATIONS] + [f"ct@{s}" for s in STATIONS]
    lines = []
    for row in perf:
        taps = {f"{float(r['r_over_R']):.2f}": r for r in span if r["file_name"] == row["file_name"]}
        if sorted(taps) != sorted(STATIONS):
            raise SystemExit(f"{row['file_name']}: spanwise stations {sorted(taps)}, expected {STATIONS}")
        lines.append([row["file_name"], row["wind_speed_m_s"], row["rpm"], f"{TIP_PITCH_DEG:.1f}", row["yaw_deg"],
                      f"{float(row['rho_kg_m3']):.5f}", row["lsstqcor_nm"], row["eaeroth_n"]]
                     + [taps[s]["cn"] for s in STATIONS] + [taps[s]["ct"] for s in STATIONS])
    with open(OUT, "w", newline="") as f:
        f.write("# NREL UAE Phase VI, sequence H (upwind, 0 deg yaw, 3 deg tip pitch), NASA Ames 80x120 ft; "
                "WDH ldsmean 10-min means, DOI 10.21947/WDH-DAP/1910052 (see calib/data/phase_vi/PROVENANCE.txt)\n"
                "# written by workflows/data/make_phase_vi_csv.py; torque = LSSTQCOR, thrust = EAEROTH, "
                "cn/ct = pressure-tap force coefficients\n")
        w = csv.writer(f)
        w.writerow(header)
        w.writerows(lines)
    return OUT


if __name__ == "__main__":
    print(main())
