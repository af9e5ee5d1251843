"""Named output channels of the native BEM as linear functionals of section quantities.

Every channel is ``value[k] = m[k] · Σ_s Σ_i w_i Q[k, s, i] / n_sectors`` for one
section quantity Q (``Np``, ``Tp`` [N/m], ``cn``, ``ct`` [-]), station weights w and a
per-point multiplier m (blade count, rotor speed). The same functional maps section
sensitivities to channel sensitivities, so values and Jacobians cannot disagree.

Spanwise channels are named ``<q>@<r/R>`` (e.g. ``cn@0.30``) with

- ``cn``, ``ct``: normal and chordwise force coefficients in chord axes
  (C_N = C_L cos α + C_D sin α, C_T = C_L sin α − C_D cos α, positive toward the leading
  edge), the quantities of pressure-tap measurements [-];
- ``fn``, ``ft``: force per unit length normal to and in the rotor plane [N/m].

Values are interpolated linearly in r between the blade stations and averaged over
the azimuth sectors.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from calib.errors import InputError
from calib.types import Channel

ROTOR_CHANNELS = {
    "power": ("W", "Tp", "torque", "omega", "aerodynamic rotor power"),
    "thrust": ("N", "Np", "thrust", "blades", "rotor thrust along the shaft"),
    "torque": ("N m", "Tp", "torque", "blades", "aerodynamic low-speed-shaft torque"),
    "root_flap_moment": ("N m", "Np", "flap_root", "one", "out-of-plane moment of one blade about its root"),
    "root_edge_moment": ("N m", "Tp", "flap_root", "one", "in-plane moment of one blade about its root"),
    "hub_flap_moment": ("N m", "Np", "flap_hub", "one", "out-of-plane moment of one blade about the rotor centre"),
}
SPANWISE = {
    "cn": ("-", "cn", "normal force coefficient (chord axes)"),
    "ct": ("-", "ct", "chordwise force coefficient (chord axes, + toward leading edge)"),
    "fn": ("N/m", "Np", "force per length normal to the rotor plane"),
    "ft": ("N/m", "Tp", "force per length in the rotor plane (direction of rotation)"),
}
_SPAN_RE = re.compile(r"^(cn|ct|fn|ft)@([0-9]*\.?[0-9]+)$")


@dataclass(frozen=True)
class ChannelSpec:
    channel: Channel
    quantity: str
    weights: np.ndarray      # (n_stations,)
    multiplier: str          # "omega", "blades" or "one"


def available_channels() -> list[str]:
    """Names accepted by :func:`channel_specs` (spanwise as patterns)."""
    return list(ROTOR_CHANNELS) + [f"{q}@<r/R>" for q in SPANWISE]


def _span_weights(r: np.ndarray, interior: np.ndarray, radius: float) -> np.ndarray:
    w = np.zeros(r.size)
    ri = np.flatnonzero(interior)
    x = r[ri]
    if radius <= x[0]:
        w[ri[0]] = 1.0
    elif radius >= x[-1]:
        w[ri[-1]] = 1.0
    else:
        j = int(np.searchsorted(x, radius)) - 1
        t = (radius - x[j]) / (x[j + 1] - x[j])
        w[ri[j]], w[ri[j + 1]] = 1.0 - t, t
    return w


def channel_specs(names, rotor, weights: dict, interior: np.ndarray) -> list[ChannelSpec]:
    """Build the specs of the requested channels.

    Raises
    ------
    InputError
        For an unknown channel name or a spanwise station outside the blade (names the valid ones).
    """
    specs = []
    for name in names:
        if name in ROTOR_CHANNELS:
            unit, q, wkey, mult, desc = ROTOR_CHANNELS[name]
            specs.append(ChannelSpec(Channel(name, unit, desc), q, weights[wkey], mult))
            continue
        m = _SPAN_RE.match(name)
        if not m:
            raise InputError(f"unknown channel {name!r}; valid: {', '.join(available_channels())}",
                             "BemModel", field="channels")
        q, eta = m.group(1), float(m.group(2))
        if not (rotor.hub_radius / rotor.tip_radius <= eta <= 1.0):
            raise InputError(f"spanwise station r/R = {eta:g} lies outside the blade "
                             f"[{rotor.hub_radius / rotor.tip_radius:.3f}, 1]", "BemModel", field="channels")
        unit, qty, desc = SPANWISE[q]
        w = _span_weights(rotor.r, interior, eta * rotor.tip_radius)
        specs.append(ChannelSpec(Channel(name, unit, f"{desc} at r/R = {eta:g}"), qty, w, "one"))
    return specs


def multipliers(spec: ChannelSpec, n_blades: int, omega: np.ndarray) -> np.ndarray:
    if spec.multiplier == "omega":
        return n_blades * omega
    if spec.multiplier == "blades":
        return np.full(omega.shape, float(n_blades))
    return np.ones(omega.shape)


def channel_values(specs, sections: dict, n_blades: int, omega: np.ndarray, n_sectors: int) -> np.ndarray:
    """Values (n_points, n_channels) from section fields (n_points, n_sectors, n_stations)."""
    out = np.empty((omega.size, len(specs)))
    for c, spec in enumerate(specs):
        out[:, c] = multipliers(spec, n_blades, omega) * np.einsum(
            "ksi,i->k", sections[spec.quantity], spec.weights) / n_sectors
    return out
