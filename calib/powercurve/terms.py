"""The prediction machinery's terms for a power curve: the model discrepancy and the field between the
nodes per bin (and the covariance of each across the bins), and the envelope flags: :func:`prediction_terms`."""

from __future__ import annotations

import numpy as np

from calib.errors import InputError
from calib.types import OperatingConditions

__all__ = ["prediction_terms"]


def prediction_terms(result, model, central, air_density, notes, covariances: bool = False):
    """The model-discrepancy and between-node field 1-σ of power per bin [W] (zero in region 3), the
    envelope flags, from :func:`calib.calibration.prediction.predict_outputs` at the central
    schedule, and the field's covariance of power across the bins [W²]
    (:func:`calib.powercurve.field.field_covariance`, None where the prediction leaves the field out);
    a sentence on each appended to ``notes``. With ``covariances``, a fifth value: the model
    discrepancy's second moments across the bins [W²] (:func:`discrepancy_terms`; None where no
    channel's process applies)."""
    v = central.wind_speed
    disc, fld, envelope, fld_cov = np.zeros(v.size), np.zeros(v.size), ("",) * v.size, None
    disc_cov = None
    try:
        cond = OperatingConditions(v, central.rotor_speed, central.pitch, air_density)
        rmodel = _result_channels_model(model, result)
        pred = result.predict(cond, rmodel)
        envelope = tuple(pred.envelope) if pred.envelope else envelope
        # power is the torque times the rotor speed (a condition): a calibration on torque carries its
        # terms to power exactly, scaled by Ω
        source = "power" if "power" in pred.channels else "torque" if "torque" in pred.channels else None
        if source is not None:
            i = list(pred.channels).index(source)
            scale = 1.0 if source == "power" else central.rotor_speed * np.pi / 30.0
            r2 = central.region != 3
            disc = np.where(r2, scale * np.nan_to_num(pred.discrepancy_std[:, i]), 0.0)
            if pred.field_std is not None:
                fld = np.where(r2, scale * np.nan_to_num(pred.field_std[:, i]), 0.0)
            from calib.powercurve.field import field_covariance
            in_model = source in [c.name for c in rmodel.channels]
            raw = field_covariance(result, rmodel, cond, source) if in_model else None
            if raw is not None:
                # at the amplitude predict_outputs gives each point (inside the envelope the stated
                # prior's, outside it pred.field_amplitude), times Ω for torque, zero in region 3
                amp = np.where(pred.outside, pred.field_amplitude, 1.0) if pred.envelope else np.ones(v.size)
                d = np.where(r2 & np.isfinite(scale * amp), scale * amp, 0.0)
                fld_cov = d[:, None] * raw * d[None, :]
            if covariances:
                disc_cov = discrepancy_terms(result, cond, source, disc, notes)
            notes.append(f"model discrepancy of {source}: {pred.discrepancy or 'none recorded'}; field between the "
                         f"nodes: {pred.representation}; both added in quadrature per bin"
                         f"{' (as torque x rotor speed)' if source == 'torque' else ''}, zero in region 3")
        else:
            notes.append("the calibration has no power or torque channel: no model-discrepancy or between-node "
                         "field term for power (only the parameter uncertainty)")
    except InputError as exc:
        notes.append(f"no discrepancy term and no envelope check: {exc}")
    if covariances:
        return disc, fld, envelope, fld_cov, disc_cov
    return disc, fld, envelope, fld_cov


def discrepancy_terms(result, cond, source, disc, notes):
    """The model discrepancy of ``source`` as second moments of power across the bins [W²]: the
    per-bin σ ``disc`` [W] (the prediction's, zero in region 3) on both sides of the process's
    correlation at the bins (:func:`calib.powercurve.discrepancy.discrepancy_correlation`: its
    conditional mean common to all bins, its conditional variance correlated over the kernel's
    length). None where no process of ``source`` applies (then the AEP adds the per-bin σ linearly)."""
    if not np.any(disc > 0):
        return None
    from calib.calibration.discrepancy import fit_discrepancy
    from calib.powercurve.discrepancy import discrepancy_correlation
    dis = fit_discrepancy(result) if result.fit.measured.size else None
    process = None if dis is None else dis.processes.get(source)
    if process is None:
        notes.append(f"the model discrepancy of {source} is added linearly over the bins (fully correlated, an "
                     "upper bound): its process was not found")
        return None
    R = discrepancy_correlation(process, dis.features(cond.as_dict(), result.provenance.rotor_radius))
    notes.append(f"the model discrepancy of {source} enters the AEP through its covariance across the bins (the "
                 f"process's conditional mean common to all bins, its variance correlated over the lengths "
                 f"{process.length_words()} of the calibration span)")
    return disc[:, None] * R * disc[None, :]


def _result_channels_model(model, result):
    """``model`` with the result's channels (what :func:`predict_outputs` needs)."""
    names = [c.name for c in model.channels]
    if all(c in names for c in result.channels):
        return model
    from calib.models.bem_model import BemModel
    return BemModel(model.rotor, model.grid, tuple(result.channels), model.settings, model.nuisance,
                    model.rotor_source, model.effects)
