"""A small synthetic ForwardModel for twin experiments (test helper, not a test module).

A smooth, mildly nonlinear "strip theory" with frozen induction: per station the inflow
angle follows from the tip-speed ratio, α = φ − twist − (pitch + pitch_offset), the
polars are C_L = π sin 2α + ΔC_L(α, η), C_D = 0.01 + 0.05(1 − cos 2α) + ΔC_D(α, η), and the
loads integrate ½ρW²c(c_n, c_t) with a loading-dependent factor (1 − k c_n)² that makes
the outputs nonlinear in the corrections. Sensitivities by central differences.
"""

from __future__ import annotations

import numpy as np

from calib.corrections import CorrectionGrid
from calib.models.base import Capabilities
from calib.parametrizations.correction_field import CorrectionField, seen_from_extras
from calib.types import Channel, Evaluation, OperatingConditions, Parameter, Status

RADIUS = 10.0


class TwinModel:
    """Analytic stand-in for a BEM model with a correction-field parametrization."""

    def __init__(self, grid: CorrectionGrid | None = None, channels=("power", "thrust"),
                 nuisance=("pitch_offset",), n_stations: int = 14, nonlinearity: float = 0.05,
                 fail_above_wind: float | None = None):
        self.grid = grid or CorrectionGrid([-4.0, 2.0, 8.0, 14.0, 20.0], [0.2, 0.6, 1.0])
        self.eta = np.linspace(0.2, 0.96, n_stations)
        self.r = self.eta * RADIUS
        self.dr = np.gradient(self.r)
        self.chord = 1.0 - 0.6 * self.eta
        self.twist = np.degrees(np.arctan((2.0 / 3.0) / (7.0 * self.eta))) - 6.0
        self.k = nonlinearity
        self.fail_above_wind = fail_above_wind
        self._params = list(self.grid.parameters())
        nuis = {"pitch_offset": Parameter("pitch_offset", 0.0, -5.0, 5.0, 0.5, "deg", "nuisance"),
                "wind_scale": Parameter("wind_scale", 1.0, 0.8, 1.2, 0.02, "-", "nuisance")}
        self._params += [nuis[n] for n in nuisance]
        self.nuisance = tuple(nuisance)
        units = {"power": "W", "thrust": "N", "root_flap_moment": "N m"}
        self._channels = tuple(Channel(c, units.get(c, "-")) for c in channels)

    #: a correction field (no other grid, no spec): what the calibrator may ask of it
    capabilities = Capabilities("TwinModel", correction_field=True, derivatives="exact")

    @property
    def parameters(self):
        return tuple(self._params)

    @property
    def channels(self):
        return self._channels

    def correction_field(self) -> CorrectionField:
        return CorrectionField(self._params, self.nominal_coefficients, seen_from_extras)

    def nominal_coefficients(self, alpha_deg, eta):
        a = np.radians(np.asarray(alpha_deg, float))
        return np.pi * np.sin(2 * a) + 0 * np.asarray(eta), 0.01 + 0.05 * (1 - np.cos(2 * a)) + 0 * np.asarray(eta)

    def _outputs(self, p, cond: OperatingConditions):
        n = self.grid.n_params
        pitch_offset = p[n + self.nuisance.index("pitch_offset")] if "pitch_offset" in self.nuisance else 0.0
        wind_scale = p[n + self.nuisance.index("wind_scale")] if "wind_scale" in self.nuisance else 1.0
        V = cond.wind_speed[:, None] * wind_scale
        omega = cond.rotor_speed[:, None] * np.pi / 30.0
        lam_r = omega * self.r[None, :] / V
        phi = np.arctan((2.0 / 3.0) / lam_r)
        alpha = np.degrees(phi) - self.twist[None, :] - (cond.pitch[:, None] + pitch_offset)
        eta = np.broadcast_to(self.eta, alpha.shape)
        dcl, dcd, _, _ = self.grid.evaluate(p[:n], alpha, eta)
        cl0, cd0 = self.nominal_coefficients(alpha, eta)
        cl, cd = cl0 + dcl, cd0 + dcd
        cn = cl * np.cos(phi) + cd * np.sin(phi)
        ct = cl * np.sin(phi) - cd * np.cos(phi)
        W2 = (V * 2.0 / 3.0) ** 2 + (omega * self.r) ** 2
        q = 0.5 * cond.air_density[:, None] * W2 * self.chord * (1.0 - self.k * cn) ** 2
        fn, ft = q * cn, q * ct
        out = {"thrust": 3 * (fn * self.dr).sum(1), "power": 3 * omega[:, 0] * (ft * self.r * self.dr).sum(1),
               "root_flap_moment": (fn * (self.r - self.r[0]) * self.dr).sum(1)}
        for c in self._channels:
            if "@" in c.name:
                qn, at = c.name.split("@")
                src = {"cn": cn, "ct": ct, "fn": fn, "ft": ft}[qn]
                out[c.name] = np.array([np.interp(float(at), self.eta, row) for row in src])
        values = np.column_stack([out[c.name] for c in self._channels])
        return values, alpha

    def evaluate(self, p, conditions):
        p = np.asarray(p, float)
        values, alpha = self._outputs(p, conditions)
        status = np.zeros(len(conditions), int)
        messages = [""] * len(conditions)
        if self.fail_above_wind is not None:
            bad = conditions.wind_speed > self.fail_above_wind
            status[bad] = Status.NOT_CONVERGED
            values[bad] = np.nan
            for k in np.flatnonzero(bad):
                messages[k] = "synthetic failure"
        return Evaluation(values, status, tuple(messages), self._channels,
                          {"alpha_deg": alpha, "eta": self.eta})

    def jacobian(self, p, conditions):
        p = np.asarray(p, float)
        ev = self.evaluate(p, conditions)
        G = np.zeros(ev.values.shape + (p.size,))
        for j, q in enumerate(self._params):
            h = 1e-4 * q.scale
            e = np.zeros_like(p)
            e[j] = h
            G[:, :, j] = (self._outputs(p + e, conditions)[0] - self._outputs(p - e, conditions)[0]) / (2 * h)
        G[~ev.ok] = np.nan
        return ev, G


def twin_conditions(tsr=(4.0, 5.5, 7.0, 8.5, 10.0), pitch=(-2.0, 0.0, 2.0, 4.0), wind=(6.0, 9.0)):
    """A TSR × pitch × wind grid of operating conditions."""
    T, P, V = np.meshgrid(tsr, pitch, wind, indexing="ij")
    V, T, P = V.ravel(), T.ravel(), P.ravel()
    rpm = T * V / RADIUS * 30.0 / np.pi
    return OperatingConditions(V, rpm, P)
