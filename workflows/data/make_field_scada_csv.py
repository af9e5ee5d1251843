"""Write ``field_scada.csv``: a SCADA-style export of 10-minute means for ``workflows/field_scada.toml``.

Provenance: synthetic, written by this script (seed 2040) from calib's native BEM of the NREL 5-MW
(``calib.rotor.library``, tilt off) with a smooth lift and drag change on a 6 × 3 node correction
field (ΔC_L = 0.04 sin k at the lift nodes, ΔC_D = 0.001), through
:func:`calib.calibration.eiv_campaign.synthesize_campaign`: 60 records, true hub wind 5-16 m/s, a
nacelle anemometer reading 0.97 of the true wind speed with 3 % scatter per record, a pitch reading
0.5 deg below the blades' with 0.2 deg scatter, the air density from a drawn temperature and
pressure (ideal gas, dry air), output noise 1 % (power) and 2 % (thrust, root flap moment) of each
channel's RMS. The true values the workflow should find: ``wind_scale`` = 1/0.97 = 1.0309,
``pitch_offset`` = 0.5 deg.

Written as an export would be: a timestamp every 10 minutes, a turbine ID, power in kW, thrust in
kN, root flap moment in kN m, the outputs' 1-σ per record; the anemometer's and the pitch
encoder's uncertainty are not columns here but instrument accuracies stated in the workflow's
``[calibration]``. Run from the project root: ``.venv/bin/python workflows/data/make_field_scada_csv.py``.
"""

from pathlib import Path

import numpy as np

from calib.bem import BemSettings
from calib.calibration.eiv_campaign import CampaignSpec, synthesize_campaign
from calib.corrections import CorrectionGrid
from calib.models.bem_model import BemModel
from calib.rotor.library import load_rotor
from calib.types import nominal_vector

HERE = Path(__file__).resolve().parent
SEED = 2040
CHANNELS = ("power", "thrust", "root_flap_moment")
UNITS = {"power": ("Power [kW]", 1e-3), "thrust": ("Thrust [kN]", 1e-3),
         "root_flap_moment": ("Root_Flap_Moment [kN m]", 1e-3)}


def main(seed: int = SEED) -> Path:
    grid = CorrectionGrid(np.linspace(-4.0, 16.0, 6), np.array([0.3, 0.65, 1.0]))
    truth = BemModel(load_rotor("nrel5mw"), grid, CHANNELS, BemSettings(use_tilt=False), nuisance=())
    pt = nominal_vector(truth.parameters)
    pt[:grid.n_lift] = 0.04 * np.sin(np.arange(grid.n_lift))
    pt[grid.n_lift:grid.n_params] = 0.001
    meas, _ = synthesize_campaign(truth, pt, CampaignSpec(n_records=60), seed)
    c = meas.conditions
    order = np.argsort(c.wind_speed, kind="stable")   # an export sorted by nothing in particular is fine too
    path = HERE / "field_scada.csv"
    head = ["timestamp", "turbine_id", "Wind_Speed [m/s]", "Rotor_Speed [rpm]", "Pitch [deg]",
            "Air_Density [kg/m^3]"]
    for ch in CHANNELS:
        name, _ = UNITS[ch]
        unit = name[name.index("["):]
        head += [name, f"{ch}_sigma {unit}"]
    lines = [f"# synthetic SCADA-style export: workflows/data/make_field_scada_csv.py, seed {seed} (see its docstring)",
             ",".join(head)]
    t0 = np.datetime64("2026-05-01T00:00")
    for n, k in enumerate(order):
        row = [str(t0 + np.timedelta64(10 * n, "m")), "T03", f"{c.wind_speed[k]:.3f}", f"{c.rotor_speed[k]:.4f}",
               f"{c.pitch[k]:.3f}", f"{c.air_density[k]:.4f}"]
        for j, ch in enumerate(CHANNELS):
            f = UNITS[ch][1]
            row += [f"{meas.values[k, j] * f:.6g}", f"{meas.sigma[k, j] * f:.4g}"]
        lines.append(",".join(row))
    path.write_text("\n".join(lines) + "\n")
    return path


if __name__ == "__main__":
    print(main())
