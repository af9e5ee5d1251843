"""The native BEM behind the ForwardModel contract."""

from __future__ import annotations

from typing import Sequence

import numpy as np

from calib.bem.outputs import channel_specs, channel_values, multipliers
from calib.bem.polar_grid import SectionPolars
from calib.bem.solver import BemSettings, integration_weights, interior_stations, solve_bem
from calib.corrections import CorrectionGrid
from calib.errors import InputError
from calib.models.base import (Channel, Evaluation, OperatingConditions, Parameter,
                               check_parameter_vector)
from calib.rotor.geometry import Rotor

NUISANCE = {
    "pitch_offset": Parameter("pitch_offset", 0.0, -5.0, 5.0, 0.5, "deg", "nuisance",
                              description="collective pitch offset added to the measured pitch"),
    "wind_scale": Parameter("wind_scale", 1.0, 0.8, 1.2, 0.02, "-", "nuisance",
                            description="factor on the measured wind speed (anemometry, blockage)"),
}


class BemModel:
    """Native steady BEM with an additive polar-correction field and nuisance parameters.

    Parameters
    ----------
    rotor : Rotor
    grid : CorrectionGrid, optional
        Correction nodes; their parameters come first in ``p`` (lift block, drag block).
    channels : sequence of str
        Output channels: ``power`` [W], ``thrust`` [N], ``torque``, ``root_flap_moment``,
        ``root_edge_moment``, ``hub_flap_moment`` [N m], spanwise ``cn@0.30``, ``ct@..``,
        ``fn@..``, ``ft@..`` (see :mod:`calib.bem.outputs`).
    settings : BemSettings, optional
    nuisance : sequence of str
        Nuisance parameters appended after the corrections: ``pitch_offset`` [deg],
        ``wind_scale`` [-].

    Notes
    -----
    ``jacobian`` is exact: implicit-function sensitivities of every section (Ning 2014)
    pushed through the same linear output functionals as the values, at the cost of one
    extra dual-number pass, not one solve per parameter.
    """

    def __init__(self, rotor: Rotor, grid: CorrectionGrid | None = None,
                 channels: Sequence[str] = ("power", "thrust"), settings: BemSettings | None = None,
                 nuisance: Sequence[str] = ("pitch_offset", "wind_scale")):
        self.rotor = rotor
        self.grid = grid
        self.settings = settings or BemSettings()
        for name in nuisance:
            if name not in NUISANCE:
                raise InputError(f"unknown nuisance parameter {name!r}; valid: {', '.join(NUISANCE)}",
                                 "BemModel", field="nuisance")
        self.nuisance = tuple(nuisance)
        self._interior = interior_stations(rotor)
        self._weights = integration_weights(rotor, self._interior)
        if isinstance(channels, str):
            channels = (channels,)
        if len(channels) == 0:
            raise InputError("at least one channel is needed", "BemModel", field="channels")
        self._specs = channel_specs(list(channels), rotor, self._weights, self._interior)
        self._polars = SectionPolars.from_rotor(rotor)
        params = list(grid.parameters()) if grid is not None else []
        params += [NUISANCE[n] for n in self.nuisance]
        self._parameters = tuple(params)

    # -- contract ---------------------------------------------------------
    @property
    def parameters(self) -> tuple[Parameter, ...]:
        return self._parameters

    @property
    def channels(self) -> tuple[Channel, ...]:
        return tuple(s.channel for s in self._specs)

    @property
    def polars(self) -> SectionPolars:
        return self._polars

    def _split(self, p):
        p = check_parameter_vector(p, self._parameters, "BemModel parameter vector")
        n = self.grid.n_params if self.grid is not None else 0
        corr = p[:n] if self.grid is not None else None
        extra = dict(zip(self.nuisance, p[n:]))
        return corr, extra.get("pitch_offset", 0.0), extra.get("wind_scale", 1.0)

    def solve(self, p, conditions: OperatingConditions, sensitivities: bool = False):
        """The full :class:`calib.bem.solver.BemResult` at parameters ``p``."""
        corr, pitch_offset, wind_scale = self._split(p)
        return solve_bem(self.rotor, conditions, self.settings, self.grid, corr, pitch_offset, wind_scale,
                         sensitivities=sensitivities, polars=self._polars)

    def _evaluation(self, res) -> Evaluation:
        values = channel_values(self._specs, res.sections, self.rotor.n_blades, res.omega, res.n_sectors)
        values[~res.ok] = np.nan
        alpha = np.nanmean(res.sections["alpha_deg"], axis=1) if res.n_sectors > 1 else \
            res.sections["alpha_deg"][:, 0, :].copy()
        alpha[:, ~self._interior] = np.nan          # hub and tip stations carry no load
        extras = {"alpha_deg": alpha,
                  "eta": self.rotor.eta.copy(), "interior": self._interior.copy(),
                  "cp": res.cp, "ct": res.ct}
        return Evaluation(values, res.status.copy(), res.messages, self.channels, extras)

    def evaluate(self, p, conditions: OperatingConditions) -> Evaluation:
        """Channel values (n_points, n_channels) and per-point status at parameters ``p``."""
        return self._evaluation(self.solve(p, conditions))

    def jacobian(self, p, conditions: OperatingConditions):
        """Exact sensitivities ``G[k, c, j] = d y[k, c] / d p[j]``.

        Returns
        -------
        evaluation : Evaluation
        G : ndarray, shape (n_points, n_channels, n_params)
            NaN on failed points.
        """
        res = self.solve(p, conditions, sensitivities=True)
        ev = self._evaluation(res)
        sens = res.sensitivities
        n_pts, n_par = len(conditions), len(self._parameters)
        G = np.zeros((n_pts, len(self._specs), n_par))
        n_corr = self.grid.n_params if self.grid is not None else 0
        point = np.arange(n_pts)[:, None, None, None]
        for c, spec in enumerate(self._specs):
            scale = multipliers(spec, self.rotor.n_blades, res.omega) / res.n_sectors
            q, w = spec.quantity, spec.weights
            if self.grid is not None:
                for block, d in ((0, sens.d_cl[q]), (self.grid.n_lift, sens.d_cd[q])):
                    contrib = (d * w)[..., None] * sens.basis_value
                    flat = (point * n_par + block + sens.basis_index).reshape(-1)
                    G[:, c, :] += np.bincount(flat, contrib.reshape(-1), n_pts * n_par).reshape(n_pts, n_par)
            for j, name in enumerate(self.nuisance):
                d = sens.d_pitch[q] if name == "pitch_offset" else sens.d_wind_scale[q]
                G[:, c, n_corr + j] = np.einsum("ksi,i->k", d, w)
            G[:, c, :] *= scale[:, None]
        G[~res.ok] = np.nan
        return ev, G

    # -- helpers for the calibrator -------------------------------------
    def nominal_coefficients(self, alpha_deg, eta):
        """Nominal C_L, C_D [-] of the station nearest to each η, at ``alpha_deg`` [deg]."""
        alpha_deg, eta = np.broadcast_arrays(np.asarray(alpha_deg, float), np.asarray(eta, float))
        station = np.abs(self.rotor.eta[None, :] - eta.reshape(-1)[:, None]).argmin(axis=1)
        cl, cd, _, _ = self._polars.lookup(alpha_deg.reshape(-1), station)
        return cl.reshape(alpha_deg.shape), cd.reshape(alpha_deg.shape)
