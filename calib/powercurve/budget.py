"""The AEP table of a calibrated power curve with its 1-σ per source: :func:`aep_rows`
(what :meth:`calib.powercurve.curve.CalibratedPowerCurve.aep_table` returns)."""

from __future__ import annotations

import numpy as np

from calib.errors import InputError
from calib.powercurve.aep import aep_weights
from calib.powercurve.field import split_variance, variance_at_amplitude
from calib.powercurve.measurement import aep_uncertainty

__all__ = ["aep_rows"]


def aep_rows(pc, cdfs: dict, availability: float = 1.0) -> list[dict]:
    """AEP [MWh] per wind distribution with its 1-σ per source, P50 and P90.

    P50 is the central curve's AEP; sources: the calibration through the draws (and, beside
    it, its delta-method value, not added again), the model discrepancy (through its second
    moments across the bins, ``discrepancy_cov``: its conditional mean common to all bins, its
    variance correlated by the process's kernel; linearly over the bins, an upper bound, where that
    is not available), the field between the nodes
    (through its covariance across the bins, ``field_cov``: σ² = c Σ cᵀ; linearly where that is
    not available), each measurement item (combined as IEC 61400-12-1 does,
    :func:`calib.powercurve.measurement.aep_uncertainty`: category B correlated across the bins,
    category A not; ``sigma_measurement_mwh`` per category). The total
    adds the sources in quadrature; P90 = P50 − 1.2816 σ (normal). Draws with a failed bin where
    the distribution has weight are left out of the draws' σ and counted. Without draws the delta
    method's σ enters the total.

    ``sigma_calibration_sampling_mwh``: the spread of the calibrated AEP over repeated noise at a fixed
    truth (frequentist, linearized: g Cov_s gᵀ with Cov_s the sandwich of
    :func:`calib.powercurve.sampling.sampling_covariance`), not added to the total: the posterior σ is the
    Bayesian statement (truth drawn from the prior), the sampling σ leaves out the prior's shrinkage, the
    field between the nodes and the discrepancy, which at a fixed truth are a bias, not a spread.

    Beside it, for a MAP result with a prior check (``prior_split``): the delta method's
    calibration variance split into its data-determined and prior-dominated directions
    (``sigma_calibration_split_mwh``) and ``empirical_bayes``: the total σ and P90 with the
    field's prior amplitude at the prior check's τ̂ (and at its 95 % interval's ends) instead of
    the stated 1, the nodal part by :func:`calib.powercurve.field.variance_at_amplitude` and the
    field between the nodes scaled by τ², the estimate kept.
    """
    if not 0 < availability <= 1:
        raise InputError(f"availability must be in (0, 1], got {availability!r}", "--availability",
                         field="availability")
    eta = pc.generator_efficiency
    rows = []
    for name, cdf in cdfs.items():
        c = aep_weights(pc.wind_speed, cdf) * availability * eta / 1e6     # MWh per W
        P = pc.central.power
        central = float(c @ P) if np.all(np.isfinite(P[c > 0])) else float("nan")
        nominal = float(c @ np.nan_to_num(pc.nominal.power))
        Pd = pc.draws["power"]
        used = np.all(np.isfinite(Pd[:, c > 0]), axis=1)
        aep_d = np.nan_to_num(Pd[used]) @ c
        sig = {"calibration (draws)": float(np.std(aep_d, ddof=1)) if aep_d.size > 1 else float("nan")}
        if pc.grad_power is not None and pc.cov is not None:
            g = c @ np.nan_to_num(pc.grad_power)
            sig_delta = float(np.sqrt(max(g @ pc.cov @ g, 0.0)))
        else:
            sig_delta = float("nan")
        sig_sampling = _sampling_sigma(pc, g if np.isfinite(sig_delta) else None)
        if getattr(pc, "discrepancy_cov", None) is not None:
            sig["model discrepancy"] = float(np.sqrt(max(c @ pc.discrepancy_cov @ c, 0.0)))
        else:
            sig["model discrepancy"] = float(c @ np.nan_to_num(pc.discrepancy_std))
        if pc.field_cov is not None:
            sig["field between nodes"] = float(np.sqrt(max(c @ pc.field_cov @ c, 0.0)))
        else:
            sig["field between nodes"] = float(c @ np.nan_to_num(pc.field_std))
        # the items act on the electrical power: weights per W electrical are c / η
        meas = aep_uncertainty(pc.measurements, pc.wind_speed, eta * P, c / eta)
        sig.update(meas["items"])
        # without draws (--draws 0) the calibration enters the total by its delta-method value
        cal = sig["calibration (draws)"] if np.isfinite(sig["calibration (draws)"]) else sig_delta
        total = float(np.sqrt(np.nan_to_num(cal) ** 2 + sum(np.nan_to_num(s) ** 2 for k, s in sig.items()
                                                         if k != "calibration (draws)")))
        split, eb = None, None
        if pc.prior_split is not None and pc.grad_power is not None:
            g = c @ np.nan_to_num(pc.grad_power)
            split = {k: float(np.sqrt(x)) for k, x in split_variance(pc.prior_split, g).items()}
            others = sum(np.nan_to_num(s) ** 2 for k, s in sig.items()
                         if k not in ("calibration (draws)", "field between nodes"))
            eb = {}
            for label in ("tau", "tau_lower", "tau_upper"):
                t = pc.prior_split[label]
                if not np.isfinite(t):
                    continue
                var = variance_at_amplitude(pc.prior_split, g, t) + (t * sig["field between nodes"]) ** 2 + others
                eb[label] = {"amplitude": t, "sigma_total_mwh": float(np.sqrt(var)),
                             "p90_mwh": central - 1.2815515655446004 * float(np.sqrt(var))}
        rows.append({"distribution": name, "sigma_calibration_split_mwh": split, "empirical_bayes": eb,
                     "sigma_measurement_mwh": {k: meas[k] for k in ("A", "B", "total")}, "aep_mwh": central, "nominal_aep_mwh": nominal,
                     "draws_mean_aep_mwh": float(np.mean(aep_d)) if aep_d.size else float("nan"),
                     "sigma_mwh": sig, "sigma_calibration_delta_mwh": sig_delta, "sigma_total_mwh": total,
                     "sigma_calibration_sampling_mwh": sig_sampling,
                     "p50_mwh": central, "p90_mwh": central - 1.2815515655446004 * total,
                     "draws_used": int(used.sum()), "draws_left_out": int((~used).sum()),
                     "availability": availability})
    return rows


def _sampling_sigma(pc, g) -> float:
    """√(g Cov_s gᵀ) with ``pc.sampling_cov`` (:func:`calib.powercurve.sampling.sampling_covariance`) and the AEP
    gradient ``g`` [MWh per parameter unit]; NaN without either."""
    cs = getattr(pc, "sampling_cov", None)
    if g is None or cs is None or cs.shape != (g.size, g.size):
        return float("nan")
    return float(np.sqrt(max(g @ cs @ g, 0.0)))
