"""The design problem of a workflow file (:func:`problem_from_workflow`): model, linearization point,
prior, noise, envelope and sensor groups, what :func:`calib.design.design` needs.

The workflow file states the model (native BEM or FMU), the correction grid, the prior
(``[calibration]``) and the noise (``[noise] relative`` of a synthetic workflow, else
``[calibration] relative_sigma``); its data points (the measured table or the
``[conditions]`` grid) span the operating envelope. The sensitivities of every candidate come from
one call of the model's Jacobian (:meth:`DesignProblem.blocks`) at the linearization point (the
nominal parameters, or a calibrated result's estimate with ``after``).

Noise: channel c's 1-σ is its relative level times the RMS of the nominal model's output over the
workflow's data points (as :func:`calib.calibration.noise.relative_noise` and the synthetic data
of :func:`calib.measurements.synthesize` define it), the same at every candidate; a channel without
a stated level gets the median of the stated ones (as :mod:`calib.calibration.tightening` does).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from calib.checks.prior_check import psd_sqrt
from calib.design import candidates as cand
from calib.design.sensors import check_groups, parse_groups
from calib.errors import InputError
from calib.types import OperatingConditions

__all__ = ["DesignProblem", "problem_from_workflow"]

DEFAULT_RELATIVE = 0.01


@dataclass
class DesignProblem:
    """What a design needs from a workflow.

    Attributes
    ----------
    model : ForwardModel
        Built with the sensor groups' channels.
    p : ndarray, shape (n,)
        Linearization point [parameter units].
    scale : ndarray, shape (n,)
        Parameter scales [parameter units].
    L : ndarray, shape (n, n)
        Square root of the prior covariance of the scaled parameters, P = L Lᵀ [scale units].
    names : list of str
    channels : list of str
    sigma : ndarray, shape (n_channels,)
        Noise 1-σ per channel [channel units].
    envelope : Envelope
    reference : OperatingConditions
        The workflow's data points.
    groups : list of SensorGroup
    source : str
    notes : list of str
    between_nodes : dict, optional
        With ``prior_std`` [parameter units], ``correlation`` [node spacings] and the (α, η) the data
        reach (``alpha``, ``eta``): the variance the correction field between and beyond the nodes adds
        to each candidate output is added to its noise (:meth:`field_variance`), as the tightening advice
        of :mod:`calib.calibration.tightening` does.
    """

    model: object
    p: np.ndarray
    scale: np.ndarray
    L: np.ndarray
    names: list
    channels: list
    sigma: np.ndarray
    envelope: cand.Envelope
    reference: OperatingConditions
    groups: list
    source: str
    notes: list = field(default_factory=list)
    prior_from: str = "the workflow's prior"
    lower: np.ndarray | None = None
    upper: np.ndarray | None = None
    field_index: np.ndarray | None = None
    between_nodes: dict | None = None
    executor: object = None

    def close(self) -> None:
        """Close the executor the problem opened (an FMU's, from the workflow's ``[executor]``)."""
        if self.executor is not None:
            self.executor.close()
            self.executor = None

    def field_variance(self, conditions: OperatingConditions, p: np.ndarray, ok: np.ndarray, evaluation):
        """Variance of each output from the correction field the nodes do not carry (the smooth-field prior
        between the nodes on a refined grid, :func:`calib.parametrizations.aliasing.discrepancy_propagated`,
        diagonal only), shape (n_points, n_channels) [channel unit²]."""
        from calib.parametrizations.aliasing import discrepancy_propagated, fine_sensitivities

        b = self.between_nodes
        corr = self.model.correction_field()
        a, e = corr.seen(evaluation)
        m = len(self.channels)
        fs = fine_sensitivities(self.model, p, conditions, np.ones((len(conditions), m)), list(range(m)), ok,
                                np.concatenate([a, b["alpha"]]), np.concatenate([e, b["eta"]]))
        var = discrepancy_propagated(fs.W, corr, fs, b["prior_std"], b["correlation"], diagonal=True)
        return var.reshape(len(conditions), m)

    def field_draws(self, n: int, seed: int = 0) -> np.ndarray:
        """``n`` parameter vectors with the correction field drawn from the prior about ``p`` (the other
        parameters at ``p``), clipped to the bounds; shape (n, n_params) [parameter units]."""
        rng = np.random.default_rng(seed)
        idx = np.arange(len(self.p)) if self.field_index is None else self.field_index
        out = np.tile(self.p, (n, 1))
        step = (rng.normal(size=(n, len(self.p))) @ self.L.T) * self.scale
        out[:, idx] += step[:, idx]
        if self.lower is not None:
            out = np.clip(out, self.lower, self.upper)
        return out

    def blocks(self, conditions: OperatingConditions, p: np.ndarray | None = None):
        """The prior-whitened blocks H_j = R^{-½} ∂y_j/∂p̃ L of every point (one model Jacobian call),
        at ``p`` (default the linearization point).

        Returns
        -------
        H : ndarray, shape (n_points, n_channels, n)
            Zero at failed points.
        ok : ndarray of bool, shape (n_points,)
            Converged points with finite sensitivities.
        """
        p = self.p if p is None else p
        ev, G = self.model.jacobian(p, conditions)
        ok = np.asarray(ev.ok, bool) & np.all(np.isfinite(G), axis=(1, 2)) & np.all(np.isfinite(ev.values), axis=1)
        sigma = np.broadcast_to(self.sigma, (len(conditions), len(self.sigma)))
        if self.between_nodes is not None:
            sigma = np.sqrt(sigma ** 2 + np.nan_to_num(self.field_variance(conditions, p, ok, ev)))
        M = np.where(ok[:, None, None], G, 0.0) * self.scale / sigma[:, :, None]
        return np.nan_to_num(M) @ self.L, ok


def _reference(workflow, setup):
    from calib.workflow.setup import measurements_of, synthetic_conditions

    if workflow.measurements is not None:
        return measurements_of(workflow, setup.channels).conditions
    return synthetic_conditions(workflow.conditions, setup.rotor, setup.density, setup.yaw)


def _relative_levels(workflow, setup, channels, notes) -> dict:
    s = setup.calibration
    stated = dict(workflow.noise.relative) if workflow.noise is not None and workflow.measurements is None else {}
    stated = {**dict(s.relative_sigma or {}), **stated}
    from calib.calibration.noise import group_of

    rel = {c: stated.get(c, stated.get(group_of(c))) for c in channels}
    known = [float(v) for v in rel.values() if v is not None]
    fill = float(np.median(known)) if known else DEFAULT_RELATIVE
    missing = [c for c, v in rel.items() if v is None]
    if missing:
        notes.append(f"no stated noise for {', '.join(missing)}: {100 * fill:.3g} % of the channel's RMS assumed"
                     + (" (the median of the stated ones)" if known else " (default)"))
    return {c: float(v) if v is not None else fill for c, v in rel.items()}


def problem_from_workflow(path, sensors=None, after=None, executor=None, between_nodes: bool = False,
                          effects=(), history=None, progress=None) -> DesignProblem:
    """The design problem of a workflow file.

    Parameters
    ----------
    path : str or Path
        The workflow TOML.
    sensors : sequence of str, optional
        Sensor groups ``NAME[:COST]`` (:mod:`calib.design.sensors`); default the workflow's channels.
    after : str or Path, optional
        A calibrated result's folder (``calib run`` stage folder): its estimate is the
        linearization point and its posterior covariance the prior.
    executor : optional
        The FMU's executor; default the workflow's ``[executor]`` for an FMU (``problem.executor``, to be
        closed by the caller: :meth:`DesignProblem.close`).
    between_nodes : bool
        Add the variance of the correction field between and beyond the nodes to the candidates' noise
        (native BEM with a correction grid and ``prior_correlation`` > 0).
    effects : sequence, optional
        Effects the native BEM carries (e.g. those a ``[diagnosis]`` named,
        :func:`calib.diagnosis.in_workflow.named_effect_specs`), their parameters estimated too.
    history : History, optional
        For an FMU: every model call (the sensitivities in chunks of the executor's workers' points) is
        written to this run history and, when it resumes a killed or finished design, answered from it
        (:func:`calib.models.recorded_model.recorded`): a rerun simulates nothing it has on record.
    progress : callable(done, total, label), optional
        For an FMU: called after each chunk of points (e.g. :func:`calib.logs.progress_line`).
    """
    from calib.calibration.calibrator import Calibrator
    from calib.calibration.map_fit import MapFit
    from calib.calibration.noise import relative_noise
    from calib.measurements import Measurements
    from calib.workflow.schema import load_workflow
    from calib.workflow.setup import prepare

    workflow = load_workflow(path)
    setup = prepare(workflow)
    src = workflow.source
    notes = list(setup.notes)
    if setup.rotor is None:
        raise InputError("calib design needs the rotor's radius: give a [rotor] table", src, field="rotor")
    reference = _reference(workflow, setup)
    grid = setup.grid(reference)
    groups = parse_groups(sensors, setup.channels)
    own = None
    if executor is None and setup.is_fmu:
        from calib.models.from_config import executor_of
        executor = own = executor_of(setup.executor, src)
    try:
        model, channels = check_groups(groups, lambda ch: setup.model(grid, ch, executor, effects))
        model = _recorded(model, setup, executor, history, progress)
        ev = model.evaluate(np.array([q.nominal for q in model.parameters], float), reference)
        if not np.any(ev.ok):
            raise InputError("the nominal model fails at every data point of the workflow", src, field="model")
        rel = _relative_levels(workflow, setup, channels, notes)
        values = ev.values[ev.ok]
        sigma = relative_noise(values, channels, rel, src, field="noise.relative")[0]
        meas = Measurements(reference.subset(np.flatnonzero(ev.ok)), tuple(channels), values)
        settings = setup.calibration
        cal = Calibrator(model, meas, settings)
        stmt = cal.statement
        P = MapFit(cal).prior_cov_scaled() if settings.estimator == "map" else cal.prior_cov_scaled()
        p, prior_from = stmt.p0.copy(), "the workflow's prior"
        names = [q.name for q in stmt.parameters]
        if after is not None:
            p, P = _posterior_of(after, names, stmt.scale)
            prior_from = f"the posterior of {after}"
        env = cand.envelope_of(reference, setup.rotor.rotor_radius)
        kinds = ("lift_correction", "drag_correction")
        field_index = np.array([j for j, q in enumerate(stmt.parameters) if str(q.kind) in kinds], int)
        extra = None
        if between_nodes:
            if not hasattr(model, "with_grid") or settings.prior_correlation <= 0 or grid is None:
                raise InputError("the field between the nodes needs a native-BEM model with a correction grid and "
                                 "[calibration] prior_correlation > 0", src, field="between_nodes")
            a, e = model.correction_field().seen(ev)
            extra = {"prior_std": np.array(stmt.prior_std), "correlation": settings.prior_correlation,
                     "alpha": a, "eta": e}
        return DesignProblem(model, p, np.array(stmt.scale), psd_sqrt(P), names, channels, sigma, env, reference,
                             groups, src, notes, prior_from, np.array(stmt.lower), np.array(stmt.upper), field_index,
                             extra, own)
    except BaseException:
        if own is not None:
            own.close()
        raise


def _recorded(model, setup, executor, history, progress):
    """An FMU's model with its calls recorded in ``history`` in chunks of the executor's workers' points (a
    kill loses at most one chunk; :func:`calib.models.recorded_model.recorded`); else ``model``."""
    if not setup.is_fmu or history is None:
        return model
    from calib.models.recorded_model import recorded

    chunk = max(int(getattr(executor, "workers", 1) or 1), 1)
    return recorded(model, history, "design", chunk, progress=progress)


def _posterior_of(rdir, names, scale):
    from calib.calibration.result_files import load_result

    rdir = Path(rdir)
    if not rdir.exists():
        raise InputError(f"no such result folder: {rdir}", "--after", field="after")
    res = load_result(rdir)
    theirs = [q.name for q in res.parameter_objects]
    if theirs != names:
        raise InputError(f"the result's {len(theirs)} parameters are not the workflow model's {len(names)} "
                         f"(first difference: {next((a for a, b in zip(theirs, names) if a != b), 'count')})",
                         str(rdir), field="parameters")
    cov = np.asarray(res.uncertainty.cov_p, float) / np.outer(scale, scale)
    return np.array(res.estimate.p_hat, float), 0.5 * (cov + cov.T)
