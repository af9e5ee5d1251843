"""The native BEM behind the ForwardModel contract."""

from __future__ import annotations

from dataclasses import asdict, replace
from typing import Sequence

import numpy as np

from calib.bem.chain import EffectChain
from calib.bem.jacobian import project, project_probes
from calib.bem.stages import ProbeMap
from calib.bem.outputs import channel_specs, channel_values, multipliers
from calib.bem.polar_grid import SectionPolars
from calib.bem.solver import BemSettings, integration_weights, interior_stations, solve_bem
from calib.corrections import CorrectionGrid
from calib.effects import Effect, effect_from_spec, make_effect
from calib.effects.correction_field import CorrectionFieldEffect
from calib.errors import InputError
from calib.parametrizations.correction_field import CorrectionField, seen_from_extras
from calib.models.base import Capabilities
from calib.types import Channel, Evaluation, OperatingConditions, Parameter, check_parameter_vector
from calib.rotor.geometry import Rotor
from calib.rotor.serialize import rotor_from_dict

NUISANCE_EFFECTS = {"pitch_offset": "pitch_offset", "wind_scale": "wind_speed_scale"}
"""Nuisance parameter name -> the effect that carries it."""

NUISANCE: dict[str, Parameter] = {name: make_effect(effect).parameters()[0]
                                  for name, effect in NUISANCE_EFFECTS.items()}
"""The nuisance parameters a :class:`BemModel` accepts in ``nuisance``, by name."""

DEFAULT_NUISANCE: tuple[str, ...] = ("pitch_offset",)
"""The nuisance parameters of a ``[model]`` table that names none (a workflow's, ``calib diagnose --config``'s)."""


class BemModel:
    """Native steady BEM with a chain of effects: a polar-correction field, nuisance parameters and more.

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
    rotor_source : dict, optional
        Where the rotor came from (a workflow ``[rotor]`` table, absolute paths); default
        ``{"name": rotor.name}`` for an embedded rotor. :meth:`spec` records it and its files'
        digests for provenance; saved results rebuild their model from the rotor data
        :meth:`spec` records beside it.
    effects : sequence, optional
        Further effects of :mod:`calib.effects`: instances (``make_effect("tip_loss")``),
        registry names, or ``{"name": ..., "options": {...}}`` tables. Their parameters follow
        the nuisance parameters in ``p``, in this order.
    rotor_files : dict, optional
        Provenance of the rotor files as read (:func:`calib.rotor.provenance.file_provenance`:
        every file with its SHA-256 and path relative to the workflow); without it
        :meth:`spec` hashes the files ``rotor_source`` names when called.
    polars : SectionPolars, optional
        The polar tables of a model of the same rotor with the same ``polar_smoothing`` and
        ``kinematic_viscosity`` (:meth:`with_grid` passes its own: they do not depend on the
        grid); built from the rotor when not given.

    Notes
    -----
    The model evaluates the chain ``[correction_field(grid)] + nuisance effects + effects``
    (:attr:`chain`); ``p`` is the concatenation of their parameters in that order: the
    correction nodes (lift block, drag block), the nuisance parameters in the given order,
    then each extra effect's parameters. The chain applies them stage by stage (conditions,
    polar, induction, loads); the correction field comes last in the polar stage, on top of
    the other polar effects.

    ``jacobian`` is exact: implicit-function sensitivities of every section (Ning 2014)
    pushed through the same linear output functionals as the values, at the cost of one
    extra dual-number pass, not one solve per parameter.
    """

    def __init__(self, rotor: Rotor, grid: CorrectionGrid | None = None,
                 channels: Sequence[str] = ("power", "thrust"), settings: BemSettings | None = None,
                 nuisance: Sequence[str] = ("pitch_offset", "wind_scale"), rotor_source: dict | None = None,
                 effects: Sequence = (), rotor_files: dict | None = None, polars: SectionPolars | None = None):
        self.rotor = rotor
        self.rotor_files = rotor_files
        if rotor_source is None:
            from calib.rotor.library import ROTORS

            rotor_source = {"name": rotor.name} if rotor.name in ROTORS else None
        self.rotor_source = rotor_source
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
        self._polars = polars if polars is not None else SectionPolars.from_rotor(
            rotor, smoothing=self.settings.polar_smoothing, kinematic_viscosity=self.settings.kinematic_viscosity)
        self.effects: tuple[Effect, ...] = tuple(effect_from_spec(e, "BemModel") for e in effects)
        chain = [CorrectionFieldEffect(grid)] if grid is not None else []
        chain += [make_effect(NUISANCE_EFFECTS[n]) for n in self.nuisance]
        self.chain = EffectChain(chain + list(self.effects))
        self._parameters = self.chain.parameters

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

    def solve(self, p, conditions: OperatingConditions, sensitivities: bool = False):
        """The full :class:`calib.bem.solver.BemResult` at parameters ``p``."""
        p = check_parameter_vector(p, self._parameters, "BemModel parameter vector")
        return solve_bem(self.rotor, conditions, self.settings, self.chain, p, sensitivities=sensitivities,
                         polars=self._polars)

    def _evaluation(self, res) -> Evaluation:
        values = channel_values(self._specs, res.sections, self.rotor.n_blades, res.omega, res.n_sectors)
        values[~res.ok] = np.nan
        alpha = np.nanmean(res.sections["alpha_deg"], axis=1) if res.n_sectors > 1 else \
            res.sections["alpha_deg"][:, 0, :].copy()
        alpha[:, ~self._interior] = np.nan          # hub and tip stations carry no load
        extras = {"alpha_deg": alpha,
                  "eta": self.rotor.eta.copy(), "interior": self._interior.copy(),
                  "cp": res.cp, "ct": res.ct,
                  # points whose residual has several roots at some section (root of smallest |φ| kept)
                  "multiple_roots": res.multiple_roots.copy(),
                  "n_multiple_root_sections": res.n_multiple_root_sections.copy()}
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
        G = np.zeros((len(conditions), len(self._specs), len(self._parameters)))
        for c, spec in enumerate(self._specs):
            scale = multipliers(spec, self.rotor.n_blades, res.omega) / res.n_sectors
            G[:, c, :] = project(res.sensitivities, spec.quantity, spec.weights) * scale[:, None]
        G[~res.ok] = np.nan
        self._last_jacobian = (np.array(p, float), conditions, res, ev)
        return ev, G

    def __getstate__(self) -> dict:
        """Pickled (to worker processes) without the last solve :meth:`field_jacobian` keeps."""
        state = self.__dict__.copy()
        state.pop("_last_jacobian", None)
        return state

    def field_jacobian(self, grid: CorrectionGrid, p, conditions: OperatingConditions):
        """The exact sensitivities to the nodal values of a correction field on ``grid`` that equals this
        model's field at ``p`` wherever the sections are, from the last :meth:`jacobian` at the same
        ``p`` and ``conditions`` (the same object), without another solve; None when there is none or
        when a loaded section of a converged point lies outside ``grid``'s nodes or the drag floors differ.

        Where the two fields agree the BEM's roots and section derivatives are the same; the field
        enters a section only through its two probes (an additive C_L and C_D), so the derivatives
        with respect to ``grid``'s nodes are the probes' derivatives times ``grid``'s hat functions
        at the section's (α, η) (:func:`calib.bem.jacobian.project_probes`). The caller states the
        agreement (e.g. a refinement whose nodal values interpolate this field,
        :func:`calib.parametrizations.aliasing.fine_sensitivities`).

        Returns
        -------
        evaluation : Evaluation
        G : ndarray, shape (n_points, n_channels, 2 * grid.n_lift)
            d y / d (lift nodes, then drag nodes) in ``grid.basis`` order; NaN on failed points.
        """
        last = getattr(self, "_last_jacobian", None)
        if (last is None or last[1] is not conditions or self.grid is None or grid.cd_floor != self.grid.cd_floor
                or not np.array_equal(last[0], np.asarray(p, float))):
            return None
        _, _, res, ev = last
        sens = res.sensitivities
        block = next((b for b in sens.blocks if b.effect == CorrectionFieldEffect.name), None)
        if block is None or sens.alpha_deg is None:
            return None
        alpha = sens.alpha_deg
        eta = np.broadcast_to(self.rotor.eta, alpha.shape)
        site = np.isfinite(alpha)
        loaded = site & res.ok[:, None, None] & self._interior[None, None, :]
        a, e = alpha[loaded], eta[loaded]
        if a.size and (a.min() < grid.alpha_nodes_deg[0] or a.max() > grid.alpha_nodes_deg[-1]
                       or e.min() < grid.eta_nodes[0] or e.max() > grid.eta_nodes[-1]):
            return None
        index, value, _ = grid.basis(np.where(site, alpha, grid.alpha_nodes_deg[0]), eta)
        value = np.where(site[..., None], value, 0.0)
        pm = ProbeMap(np.concatenate([index, index + grid.n_lift], axis=-1), np.concatenate([value, value], axis=-1),
                      np.array([0, 0, 0, 0, 1, 1, 1, 1]))
        G = np.zeros((len(conditions), len(self._specs), 2 * grid.n_lift))
        for c, spec in enumerate(self._specs):
            scale = multipliers(spec, self.rotor.n_blades, res.omega) / res.n_sectors
            G[:, c, :] = project_probes(sens.columns[spec.quantity], block.column, pm, spec.weights,
                                        2 * grid.n_lift) * scale[:, None]
        G[~res.ok] = np.nan
        return ev, G

    # -- declared capabilities and their calls --------------------------------
    @property
    def capabilities(self) -> Capabilities:
        """A correction field (empty layout without a grid) on any grid, rebuildable, exact derivatives."""
        return Capabilities("BemModel", correction_field=True, refinable=True, rebuildable=True, derivatives="exact")

    def correction_field(self) -> CorrectionField:
        """The correction field of this model's parameters (empty layout without a grid)."""
        return CorrectionField(self._parameters, self.nominal_coefficients, seen_from_extras)

    def with_grid(self, grid: CorrectionGrid) -> "BemModel":
        """The same model (rotor, channels, settings, nuisance, effects) on another correction
        grid (``capabilities.refinable``)."""
        return BemModel(self.rotor, grid, [c.name for c in self.channels], self.settings, self.nuisance,
                        self.rotor_source, self.effects, polars=self._polars)

    @property
    def rotor_radius(self) -> float:
        """Rotor radius [m] (for tip-speed ratios)."""
        return float(self.rotor.rotor_radius)

    def spec(self) -> dict:
        """A JSON-able description from which :func:`calib.models.registry.build_model` rebuilds the model.

        The rotor is recorded as data (``rotor_data``, :func:`calib.rotor.serialize.rotor_to_dict`:
        stations, chord, twist, airfoil tables, hub, orientation, name, source) with its
        digest (``rotor_sha256``, :func:`calib.rotor.serialize.rotor_digest`), so the model is
        rebuilt without the rotor files; ``rotor`` keeps the ``[rotor]`` table it came from
        (absolute paths) and ``rotor_files`` each file's absolute path, path relative to the
        workflow's folder and SHA-256 (:func:`calib.rotor.provenance.recorded_rotor_files`),
        for provenance.
        """
        from calib.rotor.serialize import rotor_digest, rotor_to_dict
        from calib.rotor.provenance import recorded_rotor_files

        spec = {"kind": "bem", "rotor": dict(self.rotor_source or {}), "settings": asdict(self.settings),
                "tilt_deg": float(self.rotor.tilt_deg), "precone_deg": float(self.rotor.precone_deg),
                "grid": self.grid.to_dict() if self.grid is not None else None,
                "channels": [c.name for c in self.channels], "nuisance": list(self.nuisance),
                "effects": [e.spec() for e in self.effects],
                "rotor_data": rotor_to_dict(self.rotor), "rotor_sha256": rotor_digest(self.rotor)}
        files = recorded_rotor_files(self.rotor_source, self.rotor_files)
        if files is not None:
            spec["rotor_files"] = files
        return spec

    @classmethod
    def from_spec(cls, spec: dict, base_dir=None, source: str = "model spec") -> "BemModel":
        """Rebuild a model from :meth:`spec`.

        The rotor comes from the recorded ``rotor_data`` (its digest checked); a spec without
        it (written by older versions) rebuilds the rotor from the embedded rotor's name, or
        from the recorded files, looked for at their absolute paths and then in ``base_dir``
        (:func:`calib.rotor.sources.rotor_from_recorded_files`), refused when one is missing
        or changed since the run.

        Parameters
        ----------
        spec : dict
        base_dir : str or Path, optional
            The result's folder (where relocated rotor files are looked for).
        source : str
            Where the spec came from (named in errors).

        Raises
        ------
        InputError
            Recorded rotor data that do not match their digest or are not valid; a rotor file
            missing or changed (named).
        """
        from calib.history import content_digest
        from calib.rotor.library import load_rotor

        rotor_table = dict(spec["rotor"] or {})
        data = spec.get("rotor_data")
        if data is not None:
            rotor = rotor_from_dict(data, f"{source}.rotor_data")
            recorded, digest = spec.get("rotor_sha256"), content_digest(rotor)
            if recorded is not None and digest != recorded:
                raise InputError(f"the recorded rotor data do not match their recorded digest (SHA-256 "
                                 f"{str(recorded)[:12]}... recorded, {digest[:12]}... of the data): the result "
                                 "was edited or damaged", source, field="rotor_data")
        else:
            # no rotor data (older results): the embedded rotor by name, or the files, checked by their
            # own SHA-256 (the rotor's digest cannot be compared: it holds the path strings the files were
            # read under, which differ with the working directory and the files' place)
            if not rotor_table:
                raise InputError("the spec records neither rotor data nor a rotor table", source, field="rotor")
            if set(rotor_table) == {"name"}:
                rotor = load_rotor(rotor_table["name"])
            else:
                from calib.rotor.sources import rotor_from_recorded_files

                rotor = rotor_from_recorded_files(rotor_table, spec.get("rotor_files"), base_dir, source).rotor
            changes = {k: float(spec[k]) for k in ("tilt_deg", "precone_deg") if k in spec}
            if changes:
                rotor = replace(rotor, **changes)
        grid = CorrectionGrid(**spec["grid"]) if spec.get("grid") else None
        return cls(rotor, grid, spec["channels"], BemSettings(**spec["settings"]), spec["nuisance"],
                   rotor_source=rotor_table, effects=spec.get("effects") or ())

    def nominal_coefficients(self, alpha_deg, eta):
        """Nominal C_L, C_D [-] of the station nearest to each η, at ``alpha_deg`` [deg]."""
        alpha_deg, eta = np.broadcast_arrays(np.asarray(alpha_deg, float), np.asarray(eta, float))
        station = np.abs(self.rotor.eta[None, :] - eta.reshape(-1)[:, None]).argmin(axis=1)
        cl, cd, _, _ = self._polars.lookup(alpha_deg.reshape(-1), station)
        return cl.reshape(alpha_deg.shape), cd.reshape(alpha_deg.shape)
