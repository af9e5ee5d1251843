"""A generic test rotor exported as an FMI 2.0 co-simulation FMU by PythonFMU (not by calib's
C toolchain): another vendor's names, units and exposure of tuning parameters.

Built at test time (``pythonfmu build -f GenericRotor.py --handle-state --serialize-state``);
never committed as an FMU. Inputs: wind speed ``v_kmh`` [km/h], rotor speed ``omega`` [rad/s],
pitch ``beta`` [rad]. Tunable parameters: ``cp_gain``, ``ct_gain`` [-] and ``beta_bias`` [rad].
Outputs ``p_kw`` [kW] and ``t_kn`` [kN] follow the quasi-steady values

    P = 1/2 rho A V^3 cp_gain 0.47 exp(-((lambda - 8)/3)^2 / 2) cos^2(beta + beta_bias)
    T = 1/2 rho A V^2 ct_gain 0.85 (1 - exp(-lambda/4)) cos(beta + beta_bias)

(lambda = omega R / V, R = 40 m, rho = 1.225 kg/m^3) through a first-order lag of 0.5 s, so a
simulation has to settle; there is no azimuth output.
"""

import math

from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real

RADIUS = 40.0
TIME_CONSTANT = 0.5


class GenericRotor(Fmi2Slave):
    author = "calib tests"
    description = "Generic test rotor: Cp/Ct surfaces with tuning gains and a pitch bias, first-order lag"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.v_kmh = 30.0
        self.omega = 1.0
        self.beta = 0.0
        self.cp_gain = 1.0
        self.ct_gain = 1.0
        self.beta_bias = 0.0
        self.p_kw = 0.0
        self.t_kn = 0.0
        for name in ("v_kmh", "omega", "beta"):
            self.register_variable(Real(name, causality=Fmi2Causality.input))
        for name in ("cp_gain", "ct_gain", "beta_bias"):
            self.register_variable(Real(name, causality=Fmi2Causality.parameter, variability=Fmi2Variability.tunable))
        for name in ("p_kw", "t_kn"):
            self.register_variable(Real(name, causality=Fmi2Causality.output))

    def do_step(self, current_time, step_size):
        v = self.v_kmh / 3.6
        lam = self.omega * RADIUS / v
        b = self.beta + self.beta_bias
        cp = self.cp_gain * 0.47 * math.exp(-0.5 * ((lam - 8.0) / 3.0) ** 2) * math.cos(b) ** 2
        ct = self.ct_gain * 0.85 * (1.0 - math.exp(-lam / 4.0)) * math.cos(b)
        q = 0.5 * 1.225 * math.pi * RADIUS ** 2
        k = 1.0 - math.exp(-step_size / TIME_CONSTANT)
        self.p_kw += (q * v ** 3 * cp / 1e3 - self.p_kw) * k
        self.t_kn += (q * v ** 2 * ct / 1e3 - self.t_kn) * k
        return True
