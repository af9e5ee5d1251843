"""The share test of the naming rounds (issue 37, item 4): does a candidate explain at least a
given share of the misfit a model leaves beyond the noise and the model-form tolerance, by more
than the noise can make it seem to?

A physical effect is named after another effect, or over the model form, only when its likelihood
ratio Λ explains at least ``share`` (:data:`calib.diagnosis.naming.LATER_EFFECT_SHARE`) of the
excess χ² − dof the model without it leaves. The share measured on one data set
is a noisy estimate: χ² − dof scatters by about √(2 dof) (22 on 252 residuals), so the share of a
misfit of 136 is known to about ±13 %. On the lifting-line fast-wake control (another method, no
physical effect) the best separable physical candidate explains 47-59 % of what the joint model form
leaves (seeds 26000-26004; 59 % on 27009); on seed 27009, once both model-form parameters were named,
``pitch_offset`` explained 75 % ± 13 % of the misfit of 136 they left (Λ 102.7) and was named by the
point threshold: a share within one standard deviation of it.

:func:`share_test` therefore asks whether the share exceeds the threshold beyond the noise: a
one-sided test of H0 "the candidate's true share is at most ``share``" at level
``alpha / n_candidates`` (the best of ``n_candidates`` compared candidates is tested: Bonferroni's
bound on the chance that any of them passes by noise).

Model (linearized least squares, whitened residuals; Cochran's theorem): with the base model's
residual r = d + ε (d its deterministic misfit, ε ~ N(0, I) over ``dof`` dimensions), the
candidate's k parameters take A = Λ ~ χ'²_k(δ_A) and leave B ~ χ'²_{dof−k}(δ_B), independent, with
δ_A + δ_B = |d|² the misfit beyond the noise (E[χ² − dof] = |d|²). The true share is
δ_A / (δ_A + δ_B). T = (A − k) − s₀ (A + B − dof) has mean (1 − s₀) δ_A − s₀ δ_B, zero on the
boundary of H0, and variance 2 (1 − s₀)² (k + 2 δ_A) + 2 s₀² (dof − k + 2 δ_B) (the noncentral
χ²'s mean k + δ and variance 2 (k + 2 δ): Johnson, Kotz & Balakrishnan, Continuous Univariate
Distributions, vol. 2, 2nd ed., Wiley 1995, ch. 29), evaluated on the boundary with δ_A = s₀ D and
δ_B = (1 − s₀) D, D = max(χ² − dof, 0) the observed excess. z = T / √var; the candidate passes
when z ≥ Φ⁻¹(1 − alpha / n_candidates).
"""

from __future__ import annotations

import dataclasses
import math
from statistics import NormalDist


@dataclasses.dataclass(frozen=True)
class ShareTest:
    """Result of :func:`share_test`.

    Attributes
    ----------
    share : float
        Λ / (χ² − dof): the share of the excess the candidate explains (inf when there is no excess) [-].
    z : float
        The test statistic (standard deviations above the threshold share) [-].
    z_needed : float
        Φ⁻¹(1 − alpha / n_candidates) [-].
    sd : float
        Standard deviation of the share estimate on the boundary of H0 [-] (√var / D; inf when D = 0).
    passed : bool
        z ≥ z_needed.
    """

    share: float
    z: float
    z_needed: float
    sd: float
    passed: bool

    def words(self, threshold: float) -> str:
        """E.g. ``"75 % ± 14 %, z = 0.7 above 65 % (needs 3.0)"``."""
        share = "all" if not math.isfinite(self.share) else f"{100 * self.share:.0f} %"
        sd = "" if not math.isfinite(self.sd) else f" ± {100 * self.sd:.0f} %"
        return f"{share}{sd}, z = {self.z:.2g} above {100 * threshold:.0f} % (needs {self.z_needed:.2g})"


def share_test(lr: float, n_params: int, chi2_base: float, dof_base: int, share: float, alpha: float,
               n_candidates: int = 1) -> ShareTest:
    """Whether a candidate explains at least ``share`` of the excess χ² − dof beyond the noise.

    Parameters
    ----------
    lr : float
        The candidate's likelihood ratio Λ = χ²_base − χ²_with [-].
    n_params : int
        The candidate's parameter count k [-].
    chi2_base : float
        χ² of the model without the candidate (against σ² + (tolerance·y)²) [-].
    dof_base : int
        Its degrees of freedom (residuals − parameters) [-].
    share : float
        The threshold share s₀ of the excess, in (0, 1) [-].
    alpha : float
        Level of the test over all compared candidates [-].
    n_candidates : int
        Candidates the tested one was the best of (Bonferroni) [-].

    Returns
    -------
    ShareTest
    """
    k, m = float(n_params), float(dof_base)
    excess = float(chi2_base) - m
    point = lr / excess if excess > 0 else math.inf
    d = max(excess, 0.0)
    t = (lr - k) - share * excess
    var = 2.0 * (1.0 - share) ** 2 * (k + 2.0 * share * d) + 2.0 * share ** 2 * (max(m - k, 0.0)
                                                                               + 2.0 * (1.0 - share) * d)
    z = t / math.sqrt(var) if var > 0 else (math.inf if t > 0 else -math.inf)
    z_needed = NormalDist().inv_cdf(1.0 - alpha / max(int(n_candidates), 1))
    sd = math.sqrt(var) / d if d > 0 else math.inf
    return ShareTest(point, float(z), z_needed, sd, bool(z >= z_needed))


def share_record(fit_name: str, effect: str, lr: float, n_params: int, chi2_base: float, dof_base: int,
                 n_candidates: int, decision: str, test: ShareTest) -> dict:
    """One decision taken on a share, as a round of ``diagnosis.json`` records it (``shares``): enough to
    recompute :func:`share_test` at any threshold.

    Parameters
    ----------
    fit_name, effect : str
        The candidate (variant label) and its effect's name.
    lr, n_params, chi2_base, dof_base, n_candidates
        As :func:`share_test` takes them [-].
    decision : str
        ``"point"`` (the point share decides: a physical effect over the model form) or ``"test"`` (the
        share test decides: a later effect).
    test : ShareTest
        The test as it was made.
    """
    return {"candidate": fit_name, "effect": effect, "lr": float(lr), "n_params": int(n_params),
            "chi2_base": float(chi2_base), "dof_base": int(dof_base), "n_candidates": int(max(n_candidates, 1)),
            "decision": decision, "share": float(test.share), "sd": float(test.sd), "z": float(test.z),
            "z_needed": float(test.z_needed)}


def naming_probability(record: dict, threshold: float, alpha: float) -> float:
    """The chance that the decision ``record`` (:func:`share_record`'s form) names its candidate at
    ``threshold``, given the share's own noise: Φ(z − z_req), z the share test's statistic at
    ``threshold`` and z_req its z_needed for a ``"test"`` decision, 0 for a ``"point"`` one [-]."""
    test = share_test(record["lr"], record["n_params"], record["chi2_base"], record["dof_base"], threshold, alpha,
                      record["n_candidates"])
    return NormalDist().cdf(test.z - (test.z_needed if record["decision"] == "test" else 0.0))


def balanced_threshold(true: list, stand_ins: list, alpha: float, grid_step: float = 0.001) -> dict:
    """The share threshold that balances the two errors of the naming (the rule of issue 37 that sets
    :data:`calib.diagnosis.naming.LATER_EFFECT_SHARE`).

    Miss rate M(t): the mean over ``true`` decisions (a hidden effect the data hold) of
    1 − :func:`naming_probability`; false-naming rate F(t): the mean over ``stand_ins`` (an effect the data
    do not hold) of :func:`naming_probability`. M rises and F falls with t; the threshold is the grid point
    in [0.30, 0.95] where |M − F| is least, rounded to 0.01.

    Parameters
    ----------
    true, stand_ins : list of dict
        Decisions in :func:`share_record`'s form (at least one each).
    alpha : float
        The diagnosis's significance [-].
    grid_step : float
        Spacing of the thresholds tried [-].

    Returns
    -------
    dict
        ``threshold`` (rounded to 0.01), ``exact`` (the grid point), ``miss`` and ``false`` (M and F there),
        ``curve`` [(t, M, F)] every 0.05.
    """
    if not true or not stand_ins:
        raise ValueError("balanced_threshold needs decisions of both kinds (true effects and stand-ins)")
    n = int(round((0.95 - 0.30) / grid_step))
    rows = []
    for i in range(n + 1):
        t = 0.30 + i * grid_step
        miss = sum(1.0 - naming_probability(r, t, alpha) for r in true) / len(true)
        false = sum(naming_probability(r, t, alpha) for r in stand_ins) / len(stand_ins)
        rows.append((t, miss, false))
    t, miss, false = min(rows, key=lambda r: abs(r[1] - r[2]))
    step = max(1, int(round(0.05 / grid_step)))
    return {"threshold": round(t, 2), "exact": t, "miss": miss, "false": false, "curve": rows[::step]}
