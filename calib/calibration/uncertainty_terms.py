"""The uncertainty terms that need the model, at an estimate: :class:`ModelTerms`.

The field between the correction nodes (:mod:`calib.parametrizations.aliasing`), the data's
check of the field's prior amplitude (:mod:`calib.checks.prior_check`), the frozen directions' prior
through the model's curvature, the retained directions that fold points determine
(:mod:`calib.calibration.identifiability`), and which measurements would tighten the non-field parameters
(:mod:`calib.calibration.tightening`). Each calls the model; :mod:`calib.calibration.uncertainty` assembles what they
return into the covariance, and :class:`calib.calibration.calibrator.Calibrator` orchestrates.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from calib.calibration.fold_directions import fold_dominated_directions
from calib.calibration.frozen_curvature import frozen_curvature_covariance
from calib.calibration.problem import ProblemStatement
from calib.calibration.settings import CalibrationSettings
from calib.errors import InputError
from calib.measurements import Measurements
from calib.parametrizations.aliasing import FineSensitivities


def marginal_likelihood_data(z: np.ndarray, field_scaled: np.ndarray, Z_other: np.ndarray
                             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The prior check's data (:func:`calib.checks.prior_check.prior_amplitude`: whitened pseudo-data
    z, the field's Z_f K_f^½ and the other parameters' Z_n, n_rows rows each) made as small as the
    marginal likelihood allows, which depends on them only through the singular values and left
    vectors of B^(−½) Z_f K_f^½, B = I + Z_n K_n Z_nᵀ: with more field columns than rows, Z_f K_f^½ Q
    (Q an orthonormal basis of its row space, from a QR of its transpose), the same left vectors and
    singular values; with more rows than columns, every matrix in the orthonormal basis of the span
    of [Z_f K_f^½, Z_n, z] (a QR of them side by side), which keeps every inner product. Equal to
    round-off; the singular value decomposition of the check then costs the square of the smaller
    side, not the product of both (280 × 1 792 at paper size, 5 184 × 1 376 at 2 592 points)."""
    n_rows, n_f = field_scaled.shape
    if 0 < n_rows < n_f:
        return z, np.linalg.qr(field_scaled.T, mode="r").T, Z_other
    stacked = np.column_stack([field_scaled, Z_other, z])
    if n_f == 0 or n_rows <= stacked.shape[1]:
        return z, field_scaled, Z_other
    R = np.linalg.qr(stacked, mode="r")
    return R[:, -1], R[:, :n_f], R[:, n_f:-1]


@dataclass(frozen=True, eq=False)
class ModelTerms:
    """One calibration problem (model, settings, measurements and its statement) and its
    model-derived uncertainty terms; the result is assembled from it
    (:func:`calib.calibration.result_assembly.assemble_result`).

    Parameters
    ----------
    model : ForwardModel
    field : CorrectionField or None
        The model's correction field (None without one).
    settings : CalibrationSettings
    measurements : Measurements
    statement : ProblemStatement
        The parameters, their nominal values, scales, effective bounds and prior [parameter
        units], and the model channel of each measured channel (read from it, not copied).
    """

    model: object
    field: object
    settings: CalibrationSettings
    measurements: Measurements
    statement: ProblemStatement

    def prior_cov_scaled(self) -> np.ndarray:
        """The stated prior covariance of the scaled parameters [scale units²], P = D C D.

        D = diag(``prior_std`` / ``scale``); C the prior correlation: block-diagonal, the
        correction field's nodes correlated by the smooth-field prior
        (:meth:`calib.parametrizations.CorrectionField.node_correlation`), every other parameter
        independent of all (identity rows). Never the outer product σσᵀ alone, which states
        that all parameters move together (rank one; the MAP then moves them along σ)."""
        prior_scaled = self.statement.prior_std / self.statement.scale
        n = len(prior_scaled)
        corr = np.eye(n) if self.field is None else self.field.node_correlation(self.settings.prior_correlation)
        return prior_scaled[:, None] * corr * prior_scaled[None, :]

    def aliasing(self, problem, lin, svd, alpha_seen, eta_seen, gain: np.ndarray | None = None
                  ) -> tuple[np.ndarray | None, float, str, FineSensitivities | None]:
        """Cov of the retained θ from the field between the nodes (scale units²), the χ² it adds
        to the residuals on average, why it is left out ('' when it is in, or when there is
        no correction field or nothing for it to act on; :mod:`calib.parametrizations.aliasing`),
        and the fine-grid sensitivities it used (None when left out). With ``gain`` (the MAP
        estimate's linear response to the whitened data, p̃ per row [scale units]) the covariance is
        that of the whole scaled vector, gain W Σ_δ Wᵀ gainᵀ, and the χ² is not computed (0)."""
        st = self.settings
        if self.field is None or self.field.grid is None or not svd.retained.any() or not alpha_seen.size:
            return None, 0.0, "", None
        left_out = ("the bands leave out how a field varying between the correction nodes biases the retained θ, "
                    "so they can be too narrow for polars that vary between the nodes")
        if not st.representation_error:
            return None, 0.0, f"representation_error = false: {left_out}.", None
        if st.prior_correlation <= 0:
            return None, 0.0, (f"prior_correlation = 0 (independent nodes) defines no field between the nodes to "
                               f"propagate: {left_out}; the field's variance at each reached point is in the "
                               f"bands."), None
        if not self.model.capabilities.refinable:
            return None, 0.0, (f"the model ({self.model.capabilities.name}) cannot be rebuilt on a finer correction "
                               f"grid (no with_grid, e.g. an FMU): {left_out}."), None
        lay = self.field.layout
        if (lay.lift_index < 0).any() or (lay.drag_index < 0).any():
            return None, 0.0, f"the correction field does not carry both lift and drag at every node: {left_out}.", None
        from calib.parametrizations.aliasing import aliasing_covariance, fine_sensitivities

        r = svd.retained
        statement = self.statement
        fine = fine_sensitivities(self.model, lin.p, problem.conditions, problem.sigma, statement.channel_index,
                                  lin.ok, alpha_seen, eta_seen)
        if gain is not None:
            from calib.parametrizations.aliasing import discrepancy_propagated

            return (discrepancy_propagated(gain @ fine.W, self.field, fine, statement.prior_std, st.prior_correlation),
                    0.0, "", fine)
        cov, chi2 = aliasing_covariance(self.model, lin.p, problem.conditions, problem.sigma, statement.channel_index,
                                        lin.ok, lin.M, svd.V[:, r], 1.0 / svd.sigma_theta[r], statement.prior_std,
                                        st.prior_correlation, alpha_seen, eta_seen, sensitivities=fine)
        return cov, chi2, "", fine

    def prior_check(self, problem, lin, fine) -> dict:
        """The data's estimate of the correction field's prior amplitude (:mod:`calib.checks.prior_check`),
        linearized at the MAP under the stated prior (:func:`calib.checks.prior_check.map_point`, from the
        estimate): on the fine grid of the aliasing term when it was computed (``fine`` given),
        else on the calibration nodes; {} without a correction field or with ``prior_check`` off."""
        if self.field is None or self.field.grid is None or not self.settings.prior_check:
            return {}
        from calib.checks.prior_check import MapPoint, map_point, prior_amplitude
        from calib.parametrizations.aliasing import fine_sensitivities, grid_correlation_factors, times_kron

        n_ch = len(self.statement.channel_index)
        P = self.prior_cov_scaled()

        last = {}

        def linearize_at(x):
            p = problem.unscaled(x, clip=True)
            last["at"] = at = problem.linearize(p)
            return problem.scaled(p), at.residual.reshape(-1), np.repeat(at.ok, n_ch), at.M

        def evaluate_at(x):
            p = problem.unscaled(x, clip=True)
            out = problem.evaluate(p)
            return problem.scaled(p), out.residual.reshape(-1), np.repeat(out.ok, n_ch)

        if self.settings.estimator == "map":
            # the MAP estimator's result is the MAP point of the stated prior already (up to its flat
            # priors), and ``lin`` the model linearized there: no model call
            last["at"] = lin
            mp = MapPoint(problem.scaled(lin.p), lin.residual.reshape(-1), np.repeat(lin.ok, n_ch), lin.M, 0, True)
        else:
            failed_before = problem.n_failed_points_total   # the check's own evaluations are not the fit's failures
            mp = map_point(linearize_at, problem.scaled(lin.p), P, evaluate_at=evaluate_at)
            problem.n_failed_points_total = failed_before
        lay = self.field.layout
        blocks = [idx[idx >= 0] for idx in (lay.lift_index.ravel(), lay.drag_index.ravel())]
        field_cols = np.concatenate(blocks)
        other = np.setdiff1d(np.arange(len(self.statement.parameters)), field_cols)
        rows = mp.ok_rows
        M = mp.M[rows]
        z = mp.residual[rows] + M @ mp.x
        if fine is not None:
            at_map = last["at"]                 # map_point ends on the point it linearized last
            if np.max(np.abs(at_map.p - lin.p) / self.statement.scale) > 1e-9:   # (the MAP estimator's is that point)
                fine = fine_sensitivities(self.model, at_map.p, problem.conditions, problem.sigma,
                                          self.statement.channel_index, at_map.ok,
                                          *self.field.seen(at_map.evaluation))
            L_a, L_e = grid_correlation_factors(fine.fine, self.field.correlation_lengths(self.settings.prior_correlation))
            sd = [float(np.sqrt(np.mean(self.statement.prior_std[b] ** 2))) for b in blocks]
            # Z_f K_f^½ with K_f^½ = diag(sd_lift, sd_drag) ⊗ L_α ⊗ L_η, block by block
            W, n = fine.W[rows], fine.n_fine
            Z_f = np.concatenate([sd[b] * times_kron(W[:, b * n:(b + 1) * n], L_a, L_e) for b in (0, 1)], axis=1)
            z, Z_f, Z_o = marginal_likelihood_data(z, Z_f, M[:, other])
            K_f, L_f = None, np.eye(Z_f.shape[1])
        else:
            Z_f, K_f, L_f, Z_o = M[:, field_cols], P[np.ix_(field_cols, field_cols)], None, M[:, other]
        check = prior_amplitude(z, Z_f, K_f, Z_o, P[np.ix_(other, other)], between_nodes=fine is not None,
                                field_sqrt=L_f)
        check = replace(check, chi2_map=mp.chi2, chi2_estimate=float(np.sum(lin.residual[lin.ok] ** 2)),
                         map_iterations=mp.iterations,
                         map_converged=True if self.settings.estimator == "map" else mp.converged)
        return check.to_dict()

    def curvature(self, problem, lin, svd, prior_cov) -> tuple[np.ndarray | None, dict]:
        """The retained θ's covariance from the frozen directions' prior through the model's
        curvature (:func:`calib.calibration.frozen_curvature.frozen_curvature_covariance`) [scale units²],
        and what it adds relative to the noise part (``result.curvature``); (None, {}) when
        there is nothing to propagate, (None, {"samples": 0}) when the term is switched off."""
        st = self.settings
        r = svd.retained
        if not r.any() or r.all():
            return None, {}
        if st.curvature_samples == 0:
            return None, {"samples": 0}
        statement = self.statement
        n_ch = len(statement.channel_index)

        def residual_at(step):
            p = np.clip(lin.p + statement.scale * step, statement.lower, statement.upper)
            out = problem.evaluate(p)
            return out.residual.reshape(-1), np.repeat(out.ok, n_ch), (p - lin.p) / statement.scale

        failed_before = problem.n_failed_points_total   # prior draws are not the fit's failures
        cov, info = frozen_curvature_covariance(residual_at, lin.residual.reshape(-1), np.repeat(lin.ok, n_ch),
                                                lin.M, svd.V, svd.sigma_theta, r, prior_cov, st.curvature_samples)
        problem.n_failed_points_total = failed_before
        # its size against the noise part, per retained θ: tr(S² C)/k and the largest ratio
        ratio = np.diag(cov) / svd.sigma_theta[r] ** 2
        return cov, {**info, "variance_ratio_mean": float(np.mean(ratio)), "variance_ratio_max": float(np.max(ratio))}

    def fold_directions(self, lin, svd, multiple_roots) -> list:
        """Retained directions that points with several roots of the BEM equations determine
        (:func:`calib.calibration.fold_directions.fold_dominated_directions`): one record per (point, direction);
        their stated covariance gets the prior variance along them added (:func:`calib.calibration.uncertainty.fold_inflation`),
        so their σ is at least the prior's."""
        Vr = svd.V[:, svd.retained]
        return fold_dominated_directions(lin.M, len(self.statement.channel_index), Vr,
                                         svd.singular_values[svd.retained], multiple_roots, lin.ok)

    def tightening(self, problem, lin, cov_p, radius) -> dict:
        """Which measurements would tighten the σ of each parameter that is not a correction node
        (:mod:`calib.calibration.tightening`); {} without such parameters, without a rotor radius, or for a model
        whose every probe is a simulation (one that cannot be refined, e.g. an FMU)."""
        field_cols = set()
        if self.field is not None:
            lay = self.field.layout
            field_cols = {int(j) for idx in (lay.lift_index, lay.drag_index) for j in idx[idx >= 0].ravel()}
        names = [q.name for j, q in enumerate(self.statement.parameters) if j not in field_cols]
        if not self.settings.tightening or not names or radius is None \
                or not self.model.capabilities.refinable:
            return {}
        from calib.calibration.tightening import tightening

        m = self.measurements
        y = np.abs(lin.evaluation.values[:, self.statement.channel_index])
        rel = {c: float(np.median((problem.sigma[:, i] / np.maximum(y[:, i], 1e-300))[lin.ok]))
               for i, c in enumerate(m.channels) if lin.ok.any()}
        field_variance = None
        st = self.settings
        if self.field is not None and self.field.grid is not None and st.representation_error \
                and st.prior_correlation > 0:
            from calib.parametrizations.aliasing import discrepancy_propagated, fine_sensitivities

            a_cal, e_cal = self.field.seen(lin.evaluation)

            def field_variance(cond, cols, ev):
                a, e = self.field.seen(ev)
                fs = fine_sensitivities(self.model, lin.p, cond, np.ones((len(cond), len(cols))), cols, ev.ok,
                                        np.concatenate([a, a_cal]), np.concatenate([e, e_cal]))
                var = discrepancy_propagated(fs.W, self.field, fs, self.statement.prior_std, st.prior_correlation,
                                             diagonal=True)
                return var.reshape(len(cond), len(cols))
        scale = self.statement.scale
        try:
            return tightening(self.model, lin.p, cov_p / np.outer(scale, scale), scale, m.conditions,
                              radius, list(m.channels), rel, names, field_variance=field_variance)
        except (InputError, np.linalg.LinAlgError, ValueError) as exc:     # advice, not the result
            return {"failed": f"{type(exc).__name__}: {exc}"}

