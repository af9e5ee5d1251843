"""Write the embedded demo campaign ``calib/data/demo_campaign/nrel5mw_campaign.csv``.

A synthetic NREL 5-MW test campaign for ``make demo`` (``calib demo``): a tip-speed-ratio sweep
at fine pitch and pitch sweeps at three tip-speed ratios, at 9 rpm, with hub loads (power,
thrust) and blade-root loads (flap and edge moments). The "measurements" come from the native
BEM with a hidden effect the nominal model lacks, rotational augmentation (stall delay) in the
Du & Selig (1998) form with strength 1 — while the library fits Snel's form — plus 1 % Gaussian
noise (σ columns given). Seeded: ``.venv/bin/python workflows/data/make_demo_campaign.py``
rewrites the same file.
"""

from pathlib import Path

import numpy as np

from calib.bem import BemSettings
from calib.effects import make_effect
from calib.measurements import synthesize
from calib.models.bem_model import BemModel
from calib.rotor.library import load_rotor
from calib.types import OperatingConditions

OUT = Path(__file__).resolve().parents[2] / "calib" / "data" / "demo_campaign" / "nrel5mw_campaign.csv"
CHANNELS = ("power", "thrust", "root_flap_moment", "root_edge_moment")
HIDDEN = {"name": "rotational_augmentation", "variant": "du_selig", "strength": 1.0}


def campaign_conditions(rotor, rpm: float = 9.0) -> OperatingConditions:
    """λ sweep 3…11 at pitch 0 and pitch sweeps −2…8 deg at λ = 4.5, 7, 9.5."""
    tsr = list(np.linspace(3.0, 11.0, 17))
    pitch = [0.0] * len(tsr)
    for lam in (4.5, 7.0, 9.5):
        for b in (-2.0, 2.0, 4.0, 6.0, 8.0):
            tsr.append(lam)
            pitch.append(b)
    tsr = np.array(tsr)
    v = rpm * np.pi / 30.0 * rotor.rotor_radius / tsr
    return OperatingConditions(v, np.full(v.size, rpm), np.array(pitch))


def main(seed: int = 5) -> Path:
    rotor = load_rotor("nrel5mw")
    effect = make_effect(HIDDEN["name"], variant=HIDDEN["variant"],
                         nominal={"stall_delay_strength": HIDDEN["strength"]})
    truth = BemModel(rotor, None, CHANNELS, BemSettings(use_tilt=False), (), effects=[effect])
    p = np.array([q.nominal for q in truth.parameters])
    meas = synthesize(truth, p, campaign_conditions(rotor), relative_sigma={c: 0.01 for c in CHANNELS}, seed=seed,
                      source="demo campaign")
    OUT.parent.mkdir(parents=True, exist_ok=True)
    meas.write_csv(OUT)
    return OUT


if __name__ == "__main__":
    print(main())
