/*
 * structure.c -- modal blade model: one flap (out-of-plane) and one edge (in-plane)
 * mode per blade, each a damped oscillator in its generalized coordinate q [m, tip
 * deflection]:
 *   M* q'' + 2 zeta omega M* q' + omega^2 M* q = Q,   Q = int f(r) phi(r) dr,
 * with phi(s) = s^2, s = (r - R_hub) / (R_tip - R_hub), the classical quadratic
 * approximation of a cantilever's first bending mode (e.g. Hansen, Aerodynamics of
 * Wind Turbines, ch. 11), M* = int m phi^2 dr. The natural frequencies are the
 * rotating ones (centrifugal stiffening included in the parameter), structural
 * twist and flap-edge coupling are neglected.
 *
 * Mass per length: linear taper m(s) = m0 (1 - 0.9 s), with m0 set so that the blade
 * mass is the parameter blade_mass (NREL 5-MW: 17 740 kg, Jonkman et al.,
 * NREL/TP-500-38060, 2009).
 *
 * Root moments include the inertial load of the mode: M_root = int (f - m phi q'')
 * (r - R_hub) dr, and, with gravity on, the in-plane blade weight m g sin(psi).
 */
#include <math.h>

#include "core_internal.h"

#define N_QUAD 400
#define GRAVITY 9.80665

double structure_mass_per_length(const RotorCore *core, double r)
{
    const RotorData *d = &core->data;
    double length = d->tip_radius - d->hub_radius;
    double s = (r - d->hub_radius) / length;
    double m0 = core->dyn.par.blade_mass / (0.55 * length);
    return m0 * (1.0 - 0.9 * s);
}

void structure_setup(RotorCore *core)
{
    const RotorData *d = &core->data;
    CoreStructure *st = &core->st;
    double length = d->tip_radius - d->hub_radius, h = length / N_QUAD;
    int i;
    st->gen_mass = st->mass_phi = st->mass_phi_arm = st->mass_arm = 0.0;
    for (i = 0; i <= N_QUAD; i++) {          /* trapezoid rule */
        double s = (double)i / N_QUAD, r = d->hub_radius + s * length;
        double w = (i == 0 || i == N_QUAD) ? 0.5 * h : h;
        double m = structure_mass_per_length(core, r), phi = s * s;
        st->gen_mass += w * m * phi * phi;
        st->mass_phi += w * m * phi;
        st->mass_phi_arm += w * m * phi * (r - d->hub_radius);
        st->mass_arm += w * m * (r - d->hub_radius);
    }
    for (i = 0; i < d->n_stations; i++) {
        double s = (d->r[i] - d->hub_radius) / length;
        st->phi[i] = s * s;
    }
}

void structure_accelerations(const RotorCore *core, int blade, double force_flap,
                             double force_edge, double *qdd_flap, double *qdd_edge)
{
    const CoreParams *p = &core->dyn.par;
    const CoreDynamic *dyn = &core->dyn;
    double m = core->st.gen_mass;
    double wf = 2.0 * M_PI * p->flap_freq_hz, we = 2.0 * M_PI * p->edge_freq_hz;
    if (p->flexible < 0.5) {
        *qdd_flap = *qdd_edge = 0.0;
        return;
    }
    *qdd_flap = force_flap / m - 2.0 * p->flap_damping * wf * dyn->qd[blade][0]
                - wf * wf * dyn->q[blade][0];
    *qdd_edge = force_edge / m - 2.0 * p->edge_damping * we * dyn->qd[blade][1]
                - we * we * dyn->q[blade][1];
}

/* Semi-implicit (symplectic) Euler with the accelerations of the last evaluation;
 * stable for omega dt < 2, the step control keeps omega dt well below 1. */
void structure_advance(RotorCore *core, double dt)
{
    CoreDynamic *dyn = &core->dyn;
    int b, m, nb = (int)dyn->par.n_blades;
    if (dyn->par.flexible < 0.5) return;
    for (b = 0; b < nb; b++) {
        for (m = 0; m < 2; m++) {
            dyn->qd[b][m] += dt * dyn->qdd[b][m];
            dyn->q[b][m] += dt * dyn->qd[b][m];
        }
    }
}

double structure_gravity(void) { return GRAVITY; }
