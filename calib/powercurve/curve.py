"""A calibrated model's power curve with its uncertainty: :func:`calibrated_power_curve`.

The schedule (:mod:`calib.powercurve.schedule`) is solved at the estimate p̂ (the central curve),
at the nominal parameters (the nominal model's curve) and at every posterior draw
p_d ~ N(p̂, Cov(p̂)) (the Laplace covariance of the estimate, ``result.uncertainty.cov_p``, re-formed
with the fit scale under noise + discrepancy where a model discrepancy applies:
:func:`calib.calibration.discrepancy_scale.discrepancy_aware_covariance`), clipped
to the parameter bounds: the schedule is re-solved per draw, so a draw moves the optimal λ and
the rated wind speed. Beside the draws' spread, the linearized (delta-method) 1-σ from the exact
Jacobian at the central schedule (:func:`calib.powercurve.linearized.delta_method`). Failed BEM
solves are counted per bin and per draw, never dropped silently.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from calib.calibration.discrepancy import fit_discrepancy
from calib.calibration.discrepancy_scale import discrepancy_aware_covariance
from calib.errors import InputError
from calib.powercurve.draws import solve_draws
from calib.powercurve.field import prior_split as split_prior
from calib.powercurve.budget import aep_rows
from calib.powercurve.fmu import FmuPowerModel, is_fmu_model
from calib.powercurve.linearized import delta_method
from calib.powercurve.sampling import sampling_covariance
from calib.powercurve.terms import prediction_terms
from calib.powercurve.schedule import ScheduledCurve
from calib.powercurve.statements import posterior_statement, schedule_warnings

__all__ = ["CalibratedPowerCurve", "calibrated_power_curve", "iec_bins", "posterior_draws"]



def iec_bins(start: float, stop: float, step: float = 0.5) -> np.ndarray:
    """Bin centres [m/s] from ``start`` to ``stop`` (inclusive) every ``step`` (IEC 61400-12-1: 0.5 m/s)."""
    if not (np.isfinite(start) and np.isfinite(stop) and np.isfinite(step)) or step <= 0 or stop <= start \
            or start < 0:
        raise InputError(f"--wind {start:g}:{stop:g}:{step:g}: needs 0 <= start < stop and step > 0", "--wind",
                         field="wind")
    n = int(np.floor((stop - start) / step + 1e-9)) + 1
    return start + step * np.arange(n)


def posterior_draws(p_hat, cov, lower, upper, n_draws: int, seed: int = 0):
    """Gaussian draws from N(p̂, cov), clipped to [lower, upper].

    Returns
    -------
    draws : ndarray, shape (n_draws, n_params)
    n_clipped : int
        Draws with at least one parameter clipped to a bound.
    """
    p_hat = np.asarray(p_hat, float)
    cov = 0.5 * (np.asarray(cov, float) + np.asarray(cov, float).T)
    w, V = np.linalg.eigh(cov) if cov.size else (np.zeros(0), np.zeros((0, 0)))
    L = V * np.sqrt(np.clip(w, 0.0, None))
    z = np.random.default_rng(seed).standard_normal((n_draws, p_hat.size))
    raw = p_hat + z @ L.T
    draws = np.clip(raw, lower, upper)
    return draws, int(np.count_nonzero(np.any(draws != raw, axis=1)))


@dataclass(eq=False)
class CalibratedPowerCurve:
    """A calibrated model's power curve with its uncertainty.

    Attributes
    ----------
    wind_speed : ndarray, shape (n_bins,)
        Bin centres [m/s] (hub height, at ``air_density``).
    air_density : float
        [kg/m^3]
    central, nominal : ScheduledCurve
        At the estimate p̂ and at the nominal parameters.
    draws : dict of str to ndarray, shape (n_draws, n_bins)
        Per quantity of :data:`calib.powercurve.draws.QUANTITIES`, every draw's curve (NaN where its solve failed).
    draw_status : ndarray of int, shape (n_draws, n_bins)
    tsr_opt : ndarray, shape (n_draws,)
    delta_std : dict of str to ndarray, shape (n_bins,)
        Delta-method 1-σ (:func:`calib.powercurve.linearized.delta_method`); empty when the model
        has no Jacobian.
    grad_power : ndarray, shape (n_bins, n_params) or None
    discrepancy_std, field_std : ndarray, shape (n_bins,)
        Model-discrepancy and between-node field 1-σ of power from the prediction machinery
        (:func:`calib.calibration.prediction.predict_outputs`), zero in region 3 (the pitch holds
        rated power) and where the result has no power channel [W].
    measurements : tuple of MeasurementItem
    envelope : tuple of str
        Per bin, "" inside the calibration envelope, else why not (an extrapolation).
    generator_efficiency : float
    notes : list of str
        Plain sentences on what was included and left out.
    n_clipped : int
        Draws clipped to a parameter bound.
    seconds : float
        Wall time of the draws.
    n_bem_points : int
        BEM points solved for the draws.
    cov : ndarray, shape (n_params, n_params)
        The covariance the draws came from.
    warnings : list of str
        What the schedule could not do (:func:`calib.powercurve.statements.schedule_warnings`), for the report's first paragraph.
    field_cov : ndarray, shape (n_bins, n_bins) or None
        Covariance of power across the bins from the field between the nodes [W²]
        (:func:`calib.powercurve.field.field_covariance`; its diagonal is ``field_std``²); None where the
        prediction leaves that term out (then the AEP adds ``field_std`` linearly over the bins, an upper bound).
    simulations : int or None
        Simulations an FMU model ran for this curve (None for the native BEM).
    discrepancy_cov : ndarray, shape (n_bins, n_bins) or None
        Second moments of power across the bins from the model discrepancy [W²]
        (:func:`calib.powercurve.discrepancy.discrepancy_covariance`; its diagonal is ``discrepancy_std``²);
        None where no discrepancy process applies (then the AEP adds ``discrepancy_std`` linearly).
    prior_split : dict or None
        The nodal covariance by prior-dominated and data-determined directions and the empirical-Bayes
        amplitude (:func:`calib.powercurve.field.prior_split`); None when not a MAP result with a prior check.
    sampling_cov : ndarray, shape (n_params, n_params) or None
        The estimate's spread over repeated noise at a fixed truth (frequentist, linearized: the sandwich
        k D K Kᵀ D of :func:`calib.powercurve.sampling.sampling_covariance`) [parameter units²]; None without a gain.
    fit_scale : float
        The noise-variance factor in ``cov`` and ``sampling_cov`` [-]: the result's k, or k' where a model
        discrepancy carries the misfit (:func:`calib.calibration.discrepancy_scale.discrepancy_aware_covariance`).
    """

    wind_speed: np.ndarray
    air_density: float
    schedule: object
    central: ScheduledCurve
    nominal: ScheduledCurve
    draws: dict
    draw_status: np.ndarray
    tsr_opt: np.ndarray
    delta_std: dict
    grad_power: np.ndarray | None
    discrepancy_std: np.ndarray
    field_std: np.ndarray
    measurements: tuple
    envelope: tuple
    generator_efficiency: float
    rotor_radius: float
    notes: list = field(default_factory=list)
    n_clipped: int = 0
    seconds: float = 0.0
    n_bem_points: int = 0
    cov: np.ndarray | None = None
    warnings: list = field(default_factory=list)
    field_cov: np.ndarray | None = None
    prior_split: dict | None = None
    simulations: int | None = None
    discrepancy_cov: np.ndarray | None = None
    sampling_cov: np.ndarray | None = None
    fit_scale: float = 1.0

    # ------------------------------------------------------------------ per bin
    @property
    def n_draws(self) -> int:
        return int(self.draw_status.shape[0])

    @property
    def failed_per_bin(self) -> np.ndarray:
        """Draws whose solve failed, per bin."""
        return np.count_nonzero(self.draw_status != 0, axis=0)

    @property
    def failed_draws(self) -> int:
        """Draws with at least one failed bin."""
        return int(np.count_nonzero(np.any(self.draw_status != 0, axis=1)))

    def draw_std(self, quantity: str) -> np.ndarray:
        """1-σ over the draws that converged, per bin (NaN where fewer than two did)."""
        x = self.draws[quantity]
        n = np.count_nonzero(np.isfinite(x), axis=0)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            return np.where(n > 1, np.nanstd(x, axis=0, ddof=1) if x.shape[0] > 1 else np.nan, np.nan)

    def draw_quantile(self, quantity: str, q: float) -> np.ndarray:
        """The draws' ``q`` quantile per bin (NaN where none converged)."""
        x = self.draws[quantity]
        if x.shape[0] == 0:
            return np.full(x.shape[1], np.nan)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            return np.nanquantile(x, q, axis=0)

    def calibration_power_std(self) -> np.ndarray:
        """The calibration's 1-σ of aerodynamic power per bin [W]: the draws', or the delta method's
        where fewer than two draws converged (``--draws 0``)."""
        sd = self.draw_std("power")
        delta = self.delta_std.get("power", np.full(sd.shape, np.nan))
        return np.where(np.isfinite(sd), sd, delta)

    def measurement_std(self) -> dict:
        """u_P per bin [W] of each stated measurement item, at the central curve (electrical power)."""
        P = self.central.power * self.generator_efficiency
        return {m.name: m.power_std(self.wind_speed, P) for m in self.measurements}

    def power_std_total(self) -> np.ndarray:
        """Combined 1-σ of electrical power per bin [W]: the calibration (:meth:`calibration_power_std`),
        discrepancy, field and measurement items in quadrature."""
        eta = self.generator_efficiency
        parts = [eta * self.calibration_power_std(), eta * self.discrepancy_std, eta * self.field_std]
        parts += list(self.measurement_std().values())
        return np.sqrt(sum(np.nan_to_num(p) ** 2 for p in parts))

    # ------------------------------------------------------------------ AEP
    def aep_table(self, cdfs: dict, availability: float = 1.0) -> list[dict]:
        """AEP [MWh] per wind distribution with its 1-σ per source, P50 and P90: the sources, how they
        combine and the prior split are described at :func:`calib.powercurve.budget.aep_rows`.

        Parameters
        ----------
        cdfs : dict
            Wind distributions by name (their cumulative distribution functions of wind speed).
        availability : float
            Availability factor in (0, 1].
        """
        return aep_rows(self, cdfs, availability)


def _power_model(model):
    """The same BEM model with channels power and thrust (for the delta method)."""
    if not hasattr(model, "spec") or not getattr(model.capabilities, "rebuildable", False):
        return None
    from calib.models.bem_model import BemModel
    if not isinstance(model, BemModel):
        return None
    return BemModel(model.rotor, model.grid, ("power", "thrust"), model.settings, model.nuisance, model.rotor_source,
                    model.effects)


def calibrated_power_curve(result, wind_speed, schedule=None, air_density: float = 1.225, n_draws: int = 1000,
                           seed: int = 0, measurements=(), model=None, tsr_rule: str = "optimal",
                           progress=None, batched: bool | None = None) -> CalibratedPowerCurve:
    """The calibrated model's power curve with its uncertainty.

    Parameters
    ----------
    result : CalibrationResult
    wind_speed : array_like, shape (n_bins,)
        Hub-height wind speeds, the bin centres [m/s].
    schedule : VariableSpeed, FixedSpeed or TableSchedule, optional
        Default: the rotor's own variable-speed schedule (:meth:`VariableSpeed.from_rotor`).
    air_density : float
        [kg/m^3]
    n_draws : int
        Posterior draws (0: the delta method only).
    seed : int
    measurements : sequence of MeasurementItem
    model : BemModel, optional
        Default: rebuilt from the result.
    tsr_rule : str
        For the default schedule: ``"optimal"`` or ``"design"``.
    progress : callable, optional
        Called as ``progress(done, total)`` during the draws.
    batched : bool, optional
        None (default): the draws are solved batched (:mod:`calib.powercurve.batch`) where the model
        allows it, else one by one (a note says why); False: one by one (the reference path);
        True: batched or an :class:`InputError`.

    Returns
    -------
    CalibratedPowerCurve

    Raises
    ------
    InputError
        A negative density, an FMU result with another schedule than a fixed speed or a table, a
        parameter count that differs from the result's, a rotor without a schedule and none given.
    """
    from calib.powercurve.schedule import VariableSpeed

    if not (np.isfinite(air_density) and air_density > 0):
        raise InputError(f"--density must be > 0 kg/m^3, got {air_density!r}", "--density", field="density")
    if n_draws < 0:
        raise InputError(f"--draws must be >= 0, got {n_draws}", "--draws", field="draws")
    model = result.rebuild_model() if model is None else model
    model, fmu = _solvable(model, schedule, result.name)
    schedule = VariableSpeed.from_rotor(model.rotor, tsr_rule) if schedule is None else schedule
    if hasattr(schedule, "check_reachable"):
        schedule.check_reachable(wind_speed, air_density, getattr(model.rotor, "source", "schedule"))
    v = np.asarray(wind_speed, float)
    p_hat, cov, est_cov = _estimate(result, model)
    lower = np.array([q.lower for q in model.parameters], float)
    upper = np.array([q.upper for q in model.parameters], float)
    notes = []
    central = schedule.solve(model.solve, p_hat, v, air_density)
    nominal = schedule.solve(model.solve, model.chain.nominal(), v, air_density, guess=central)
    warnings = schedule_warnings(schedule, central)
    notes += posterior_statement(result) + ([est_cov.note] if est_cov.note else [])

    disc, fld, envelope, fld_cov, disc_cov = prediction_terms(result, model, central, air_density, notes,
                                                              covariances=True)
    if fld_cov is not None and result.uncertainty.cov_alias.shape == cov.shape:
        # the field term replaces the nodal aliasing term (as predict_outputs does): drawing from
        # Cov(p̂) with Cov_alias in it as well counted the field between the nodes twice
        cov = cov - np.asarray(result.uncertainty.cov_alias, float)
        notes.append("the parameter draws and the delta method use Cov(p̂) − Cov_alias: the field between the nodes "
                     "enters once, as its own term (correlated across the bins), not also through the nodes")

    pm = _power_model(model)
    delta, grad, pitch_grad, dP_dpitch = {}, None, None, None
    if pm is not None:
        delta, grad, pitch_grad, dP_dpitch = delta_method(pm, p_hat, cov, central, air_density, schedule)
    else:
        notes.append("no delta-method value: the model has no exact Jacobian here")

    draws_p, n_clipped = posterior_draws(p_hat, cov, lower, upper, n_draws, seed)
    t0 = time.perf_counter()
    out, status, tsr, n_pts, how = solve_draws(model, schedule, draws_p, p_hat, v, air_density, central, pitch_grad,
                                               dP_dpitch, batched, progress, result.name)
    notes += how
    seconds = time.perf_counter() - t0
    n_sim = None if fmu is None else fmu.simulation_count() - fmu.simulations_before
    if fmu is not None:
        executor = getattr(fmu, "executor", None)
        notes.append(f"the FMU ran {n_sim} simulations for this power curve (the central, nominal and "
                     f"{draws_p.shape[0]} draws' schedules, one evaluation per draw with its bins on the executor "
                     f"{type(executor).__name__ if executor is not None else 'serial'}; the prediction's terms)")

    return CalibratedPowerCurve(v, float(air_density), schedule, central, nominal, out, status, tsr, delta, grad,
                                disc, fld, tuple(measurements), envelope,
                                float(getattr(schedule, "generator_efficiency", 1.0)),
                                float(model.rotor.rotor_radius), notes, n_clipped, seconds, n_pts, cov, warnings,
                                fld_cov, split_prior(result, model, cov), n_sim, disc_cov,
                                sampling_covariance(result, est_cov.fit_scale), est_cov.fit_scale)


def _solvable(model, schedule, name):
    """``model`` with the ``solve`` the schedules call (an FMU wrapped in :class:`FmuPowerModel`, which is
    also returned second; None for the native BEM), or an :class:`InputError` naming ``name``."""
    if is_fmu_model(model):
        if getattr(schedule, "kind", None) not in ("fixed_speed", "table"):
            raise InputError("an FMU result's power curve needs a fixed-speed or table schedule (--schedule fixed "
                             "--rotor-speed RPM --pitch DEG, or --schedule TABLE.csv): the variable-speed schedule is "
                             "the native BEM's only", name, field="schedule")
        fmu = FmuPowerModel(model, name)
        return fmu, fmu
    if not hasattr(model, "solve") or not hasattr(model, "rotor"):
        raise InputError(f"the power curve needs the native BEM model or an FMU; the result's model is a "
                         f"{type(model).__name__}", name, field="model")
    return model, None


def _estimate(result, model):
    """p̂ and Cov(p̂) of ``result`` [parameter units], checked against ``model``'s parameters, re-formed with k'
    where a model discrepancy carries the misfit (:func:`calib.calibration.discrepancy_scale.discrepancy_aware_covariance`),
    and the :class:`calib.calibration.discrepancy_scale.EstimateCovariance` that says so."""
    p_hat = np.asarray(result.estimate.p_hat, float)
    if p_hat.size != len(model.parameters):
        raise InputError(f"the result has {p_hat.size} parameters, the model {len(model.parameters)}", result.name,
                         field="parameters")
    cov = np.asarray(result.uncertainty.cov_p, float)
    if cov.shape != (p_hat.size, p_hat.size) or not np.all(np.isfinite(cov)):
        raise InputError(f"the result records no usable covariance of the estimate (result.uncertainty.cov_p has "
                         f"shape {cov.shape}, {int(np.count_nonzero(~np.isfinite(cov)))} non-finite entries; expected "
                         f"a finite {p_hat.size}x{p_hat.size} matrix): there is no posterior to draw from or to "
                         "linearize; re-run the calibration", result.name, field="uncertainty.cov_p")
    est_cov = discrepancy_aware_covariance(result, fit_discrepancy(result) if result.fit.measured.size else None)
    return p_hat, (est_cov.cov_p if est_cov.reformed else cov), est_cov
