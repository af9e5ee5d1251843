"""Write ``own_turbine_field.csv``: a field-style measurement table for ``workflows/own_turbine.toml``.

An NREL 5-MW (the OpenFAST r-test deck's rotor) on its steady schedule between 4 and 24 m/s,
plus runs at off-schedule pitch, "measured" by a truth model that has an outboard lift loss
(ΔC_L = −0.08 between 6 and 12 deg over r/R > 0.7, as leading-edge roughness might cause) and a
0.5 deg pitch offset, with 1.5 % noise. Written as a spreadsheet would: a timestamp column, an
ID column, power in kW, thrust in kN, root flap moment in kN m, semicolons. Run from the
project root: ``.venv/bin/python workflows/data/make_own_turbine_csv.py`` (seeded, so the file
is reproducible).
"""

from pathlib import Path

import numpy as np

from calib.bem import BemSettings
from calib.bem.steady_control import steady_power_curve
from calib.corrections import CorrectionGrid
from calib.models.bem_model import BemModel
from calib.rotor.openfast import rotor_from_openfast
from calib.types import OperatingConditions

HERE = Path(__file__).resolve().parent
DECK = HERE.parents[1] / "tests" / "data" / "openfast" / "5MW_Land_DLL_WTurb" / "5MW_Land_DLL_WTurb.fst"


def main(seed: int = 2026) -> Path:
    rotor = rotor_from_openfast(DECK)
    # the deck's set-up: AIDrag/TIDrag off, shear 0.2 at hub height, tilt 5 deg
    settings = BemSettings(drag_in_axial_induction=False, drag_in_tangential_induction=False,
                           shear_exponent=0.2, kinematic_viscosity=1.464e-5)
    from calib.rotor.library import load_rotor
    schedule_rotor = load_rotor("nrel5mw")  # the deck has no controller schedule: take the embedded one
    pc = steady_power_curve(schedule_rotor, np.arange(4.0, 24.5, 1.0), settings)
    ws, rpm, pitch = pc.wind_speed, pc.rotor_speed, pc.pitch
    # pitch steps at three region-2 wind speeds (a test campaign's off-schedule runs)
    extra_v = np.repeat([6.0, 8.0, 10.0], 3)
    extra_rpm = np.interp(extra_v, ws, rpm)
    extra_pitch = np.tile([2.0, 4.0, 6.0], 3)
    cond = OperatingConditions(np.r_[ws, extra_v], np.r_[rpm, extra_rpm], np.r_[pitch, extra_pitch])
    grid = CorrectionGrid(np.arange(-10.0, 30.5, 1.0), np.arange(0.0, 1.0001, 0.05), cl_bound=5, cd_bound=5)
    truth = BemModel(rotor, grid, ("power", "thrust", "root_flap_moment"), settings, ("pitch_offset",))
    p = np.zeros(len(truth.parameters))
    A, E = np.meshgrid(grid.alpha_nodes_deg, grid.eta_nodes, indexing="ij")
    box = 0.25 * (1 + np.tanh((A - 6) / 1.5)) * (1 - np.tanh((A - 12) / 1.5))
    p[:grid.n_lift] = (-0.08 * box * 0.5 * (1 + np.tanh((E - 0.7) / 0.03))).ravel()
    p[-1] = 0.5
    ev = truth.evaluate(p, cond)
    rng = np.random.default_rng(seed)
    y = ev.values * (1 + 0.015 * rng.standard_normal(ev.values.shape))
    out = HERE / "own_turbine_field.csv"
    lines = ["timestamp;turbine_id;Wind_Speed [m/s];Rotor_Speed [rpm];Pitch [deg];Power [kW];Thrust [kN];"
             "Root_Flap_Moment [kN m]"]
    for k in range(len(cond)):
        lines.append(f"2026-03-{1 + k // 24:02d}T{k % 24:02d}:00;T07;{cond.wind_speed[k]:.3f};"
                     f"{cond.rotor_speed[k]:.4f};{cond.pitch[k]:.3f};{y[k, 0] / 1e3:.2f};{y[k, 1] / 1e3:.3f};"
                     f"{y[k, 2] / 1e3:.2f}")
    out.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return out


if __name__ == "__main__":
    print(main())
