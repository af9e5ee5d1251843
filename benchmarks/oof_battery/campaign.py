"""What the out-of-family battery measures: operating points, set-ups, data sets, noise.

Numpy only: imported both in the project's environment (generator, runner) and in the
CCBlade environment ``.bench-venv`` (``ccblade_truth.py``), so both sides read the same
definitions.

Operating points (63): the demo campaign's 32 points (``workflows/data/make_demo_campaign.py``:
a tip-speed-ratio sweep λ = 3 … 11 in steps of 0.5 at pitch 0 and pitch sweeps −2, 2, 4, 6,
8 deg at λ = 4.5, 7, 9.5) at 9 rpm, and the same points at 6 rpm without λ = 3 (31 points).
The second rotor speed gives equal-λ points at two wind speeds, i.e. two Reynolds numbers
(the non-dimensional BEM gives one C_P(λ, β) for both), which is what tells a Reynolds-number
effect from a change of the polars that does not depend on the Reynolds number. The wind
speed is V = Ω R / λ with R the rotor radius of the embedded rotor (tip radius times
cos(precone) = 62.94 m), the same in both set-ups.
"""

from __future__ import annotations

import math

import numpy as np

#: Rotor speeds of the campaign [rpm].
ROTOR_SPEEDS_RPM = (9.0, 6.0)

#: Channels of the data sets (calib's names). ``hub_flap_moment`` is CCBlade's ``Mb``: the
#: out-of-plane moment of one blade about the rotor centre (calib's ``root_flap_moment`` is
#: about the blade root, r = hub radius, and CCBlade does not give it).
CHANNELS = ("power", "thrust", "torque", "hub_flap_moment")

#: CCBlade's output key of each channel.
CCBLADE_KEYS = {"power": "P", "thrust": "T", "torque": "Q", "hub_flap_moment": "Mb"}

#: 1-σ noise as a fraction of the channel's RMS over the data set's points [-].
RELATIVE_NOISE = 0.01

#: First noise seed of the battery (seed of data set k: SEED0 + k); the committed subset uses SUBSET_SEED.
SEED0 = 25000
SUBSET_SEED = 24999

#: The two set-ups: the CCBlade run and calib's ``[model]`` table describe the same rotor and inflow.
SETUPS = {
    "rigid": {"tilt_deg": 0.0, "precone_deg": 0.0, "shear_exp": 0.0, "n_sector": 1,
              "describe": "rigid axisymmetric: tilt 0, precone 0, no shear, one azimuth sector"},
    "tilted": {"tilt_deg": 5.0, "precone_deg": 2.5, "shear_exp": 0.2, "n_sector": 4,
               "describe": "the rotor's own 5 deg tilt and 2.5 deg precone, shear exponent 0.2 "
                           "(hub height 90 m), 4 azimuth sectors"},
}

#: Data sets: the hidden effect of each and the names of calib's candidates that count as right.
#: ``right`` lists calib effect names; ``"none"`` means the control (right = nothing named).
DATA_SETS = {
    "control": {"hidden": "none", "right": ("none",),
                "describe": "no effect: CCBlade with the rotor's own polars"},
    "rotational_augmentation": {
        "hidden": "correction3D", "right": ("rotational_augmentation",),
        "describe": "WISDEM Polar.correction3D (Du-Selig lift, Eggers drag) at the design tip-speed ratio"},
    "reynolds_following": {
        "hidden": "reynolds", "right": ("reynolds_number",),
        "describe": "skin-friction drag ~ Re^-0.2 and C_L,max loss per decade below each section's Re_ref, "
                    "at the Reynolds number CCBlade computes per section and point"},
    "uniform_table": {
        "hidden": "uniform", "right": ("reynolds_number", "leading_edge_erosion"),
        "describe": "the change of reynolds_following at one Reynolds-number ratio for every section and "
                    "point: polars at another Reynolds number, uniform on the blade"},
    "leading_edge_erosion": {
        "hidden": "erosion", "right": ("leading_edge_erosion",),
        "describe": "linear ramp from r/R 0.6 to full damage at the tip: drag rise and lift-slope loss"},
    "wind_tunnel_blockage": {
        "hidden": "blockage", "right": ("wind_tunnel_blockage",),
        "describe": "momentum-theory blockage (rotor in a closed test section, area ratio 0.10) solved "
                    "exactly, iterated with CCBlade's thrust"},
}


def operating_points(rotor_radius: float) -> dict:
    """The battery's 63 operating points.

    Parameters
    ----------
    rotor_radius : float
        Radius that defines the tip-speed ratio [m] (calib's ``Rotor.rotor_radius``).

    Returns
    -------
    dict
        ``wind_speed`` [m/s], ``rotor_speed_rpm`` [rpm], ``pitch_deg`` [deg], ``tsr`` [-]: lists
        of 63 floats.
    """
    tsr_sweep = list(np.linspace(3.0, 11.0, 17))
    pitch_sweep = [(lam, b) for lam in (4.5, 7.0, 9.5) for b in (-2.0, 2.0, 4.0, 6.0, 8.0)]
    pts = []
    for rpm in ROTOR_SPEEDS_RPM:
        lams = tsr_sweep if rpm == ROTOR_SPEEDS_RPM[0] else [x for x in tsr_sweep if x > 3.0]
        pts += [(lam, 0.0, rpm) for lam in lams] + [(lam, b, rpm) for lam, b in pitch_sweep]
    lam = np.array([p[0] for p in pts])
    rpm = np.array([p[2] for p in pts])
    v = rpm * math.pi / 30.0 * rotor_radius / lam
    return {"wind_speed": v.tolist(), "rotor_speed_rpm": rpm.tolist(), "pitch_deg": [p[1] for p in pts],
            "tsr": lam.tolist()}


def noise_sigma(truth: np.ndarray, relative: float = RELATIVE_NOISE) -> np.ndarray:
    """1-σ noise per channel: ``relative`` times the RMS of the noise-free values over the points.

    Parameters
    ----------
    truth : ndarray, shape (n_points, n_channels)
        Noise-free values [channel units].

    Returns
    -------
    ndarray, shape (n_channels,)
        [channel units]; the rule of ``calib.measurements.synthesize(relative_sigma=...)``.
    """
    truth = np.asarray(truth, float)
    return relative * np.sqrt(np.mean(truth ** 2, axis=0))


def noisy(truth: np.ndarray, sigma: np.ndarray, seed: int) -> np.ndarray:
    """``truth`` plus independent Gaussian noise of standard deviation ``sigma`` per channel.

    Parameters
    ----------
    truth : ndarray, shape (n_points, n_channels)
    sigma : ndarray, shape (n_channels,)
    seed : int
        Seed of ``numpy.random.default_rng``.
    """
    rng = np.random.default_rng(seed)
    truth = np.asarray(truth, float)
    return truth + rng.standard_normal(truth.shape) * np.asarray(sigma, float)
