"""One twin calibration, three forward models: the native BEM, FMU variant A (FMI 2.0, SI,
scalar nodes) and FMU variant B (FMI 3.0, kW/kN/rad/s, node arrays). The calibrator and its
settings are the same; only the model (for the FMUs: the mapping file) differs.

Data: the native BEM with a known correction field on the calibration grid, 1 % noise. The
rotor is a small synthetic one (10 stations, analytic polars) so that an FMU simulation costs
milliseconds. The FMUs run quasi-steady (rigid blades, no dynamic inflow, tower, shear or yaw),
where they solve the same equations as the BEM (values agree to ~4e-4, the 0.25-deg polar
tabulation of the FMU resources, far below the noise), so each must find
the same θ (coordinates of the estimate along the BEM's retained singular directions) within
its standard deviation, and the truth within 3σ. A wrong unit, sign or node order in either
mapping would move its estimate by many σ.
"""

from __future__ import annotations

import numpy as np
from synthetic import synthetic_rotor
from test_fmu_model import BEM_SETTINGS, CHANNELS, FAST, GRID, QUIET, WINDOW, conditions

from calib.calibration import calibrate
from calib.fmu.build import build_fmu, mapping_path
from calib.fmu.model import FmuModel
from calib.measurements import synthesize
from calib.models.bem_model import BemModel
from calib.types import nominal_vector

SETTINGS = dict(sigma_bar=1.0, cd_min=None, max_relinearizations=3)


def test_same_twin_same_theta_on_bem_and_both_fmu_variants():
    rotor = synthetic_rotor(n_stations=10, tip_radius=40.0)
    cond = conditions(rotor, tsr=(5.0, 6.5, 8.0, 9.5), pitch=(0.0, 3.0), rpm=15.0)
    bem = BemModel(rotor, GRID, CHANNELS, BEM_SETTINGS, nuisance=())
    p_true = nominal_vector(bem.parameters)
    p_true[:GRID.n_lift] = [0.00, 0.05, 0.08, -0.04, 0.02, -0.06]    # ΔC_L at (α, η) nodes, α-major
    p_true[GRID.n_lift:] = [0.002, 0.0, -0.002, 0.001, 0.003, 0.0]   # ΔC_D
    meas = synthesize(bem, p_true, cond, relative_sigma={c: 0.01 for c in CHANNELS}, seed=11)
    results = {"bem": calibrate(bem, meas, **SETTINGS)}
    for v in "AB":
        model = FmuModel(build_fmu(v, rotor, GRID), mapping_path(v), CHANNELS, parameters=[], switches=QUIET,
                         settings=FAST, steady=WINDOW,
                         jacobian=dict(warm_start=True))
        results[v] = calibrate(model, meas, **SETTINGS)
        model.close()
    ref = results["bem"]
    V = ref.identifiability.V[:, ref.identifiability.retained]
    sigma = ref.identifiability.sigma_theta[ref.identifiability.retained]
    assert 2 <= sigma.size < GRID.n_params

    def theta(p):
        return V.T @ ((np.asarray(p) - ref.estimate.p_nominal) / ref.estimate.scale)

    t_true, t_bem = theta(p_true), theta(ref.estimate.p_hat)
    assert np.all(np.abs(t_bem - t_true) < 3 * sigma)
    for v in "AB":
        r = results[v]
        assert r.estimate.status == "converged" and r.fit.failures["final"] == 0
        assert int(np.count_nonzero(r.identifiability.retained)) == sigma.size
        np.testing.assert_allclose(r.identifiability.sigma_theta[r.identifiability.retained], sigma, rtol=0.05)
        t = theta(r.estimate.p_hat)
        assert np.all(np.abs(t - t_bem) < sigma), (v, (t - t_bem) / sigma)
        assert np.all(np.abs(t - t_true) < 3 * sigma)
