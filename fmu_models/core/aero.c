/*
 * aero.c -- blade-element aerodynamics: polars, correction field, stall delay and the
 * quasi-steady BEM solution of one element.
 *
 * Polars: linear interpolation on the uniform alpha grid written at build time from
 * calib.bem.polar_grid.tabulate_polars, i.e. on the same polars as the native BEM.
 *
 * Corrections (Bottasso, Cacciola & Iriarte, JWEIA 124, 2014): additive
 *   dCL(alpha, eta) = sum_ij N_i(alpha) H_j(eta) pL_ij, dCD likewise,
 * with the piecewise-linear hat functions of calib.corrections (the end hats ramp to
 * zero over one node spacing outside the node range). Lift node (i, j) has index
 * i * n_eta + j. The corrected C_D is held at or above min(CD_FLOOR, C_D,0), as in
 * calib.effects.correction_field.floor_drag (default cd_floor of calib.corrections).
 *
 * Stall delay (rotational augmentation), increment on C_L added before the correction:
 *   Snel et al. (ECN-C--94-107, 1994):   dCL = s * 3 (c/r)^2 (CL_inv - CL)
 *   Du & Selig (AIAA-98-0021, 1998):     dCL = s * f_L (CL_inv - CL),
 *       f_L = 1/(2 pi) [1.6 (c/r)/0.1267 (1 - (c/r)^(R/(Lambda r))) / (1 + (c/r)^(R/(Lambda r))) - 1]
 * with CL_inv = 2 pi (alpha - alpha0), only where the increment is positive and faded
 * out linearly between 25 and 35 deg of angle of attack; s = stall_delay_strength.
 *
 * BEM element (S.A. Ning, Wind Energy 17 (2014) 1327-1345, as in CCBlade): residual in
 * the inflow angle phi with Prandtl tip and hub loss and Buhl's high-induction branch
 * (M.L. Buhl, NREL/TP-500-36834, 2005); solved with Brent's method on Ning's brackets.
 */
#include <math.h>

#include "core_internal.h"

/* Interpolated base polar of a station at alpha [deg] (wrapped to [-180, 180)). */
static void base_polar(const RotorData *d, int st, double alpha_deg, double *cl, double *cd)
{
    double x, t;
    int k;
    const double *rcl = d->cl + (size_t)st * (size_t)d->n_polar;
    const double *rcd = d->cd + (size_t)st * (size_t)d->n_polar;
    x = (alpha_deg - d->alpha_start_deg) / d->alpha_step_deg;
    /* clamp before converting: (int) of NaN or of a value beyond int is undefined
     * behaviour; a NaN angle gives NaN coefficients (and a step error), never UB */
    if (!(x >= 0.0)) k = 0;
    else if (x >= d->n_polar - 2) k = d->n_polar - 2;
    else k = (int)x;
    t = x - k;
    *cl = rcl[k] + t * (rcl[k + 1] - rcl[k]);
    *cd = rcd[k] + t * (rcd[k + 1] - rcd[k]);
}

/* Hat-function weights along alpha (same rule as calib.corrections.hat_weights). */
static void alpha_hats(const RotorData *d, double x, int *k, double w[2])
{
    core_hat_weights(x, d->alpha_nodes_deg, d->n_alpha_nodes, k, w);
}

static double stall_delay_increment(const Element *e, double alpha_deg, double cl)
{
    const RotorCore *core = e->core;
    const CoreParams *p = &core->dyn.par;
    const RotorData *d = &core->data;
    double c_r = e->chord / e->r, f, cl_inv, fade, model = p->stall_model;
    if (model < 0.5 || p->stall_strength == 0.0) return 0.0;
    if (alpha_deg <= d->alpha0_deg[e->station] || alpha_deg >= 35.0) return 0.0;
    if (model < 1.5) {                                   /* Snel */
        f = 3.0 * c_r * c_r;
    } else {                                             /* Du & Selig */
        double lam = e->lambda_rotor > 1e-6 ? e->lambda_rotor : 1e-6;
        double ex = pow(c_r, d->tip_radius / (lam * e->r));
        f = (1.6 * c_r / 0.1267 * (1.0 - ex) / (1.0 + ex) - 1.0) / (2.0 * M_PI);
        if (f < 0.0) f = 0.0;
    }
    cl_inv = 2.0 * M_PI * (alpha_deg - d->alpha0_deg[e->station]) * DEG2RAD;
    if (cl_inv <= cl) return 0.0;
    fade = alpha_deg <= 25.0 ? 1.0 : (35.0 - alpha_deg) / 10.0;
    return p->stall_strength * fade * f * (cl_inv - cl);
}

#define CD_FLOOR 0.001   /* least corrected drag coefficient [-] (calib.corrections.CorrectionGrid.cd_floor) */

void aero_coefficients(const Element *e, double alpha, double *cl, double *cd)
{
    const RotorData *d = &e->core->data;
    const CoreParams *p = &e->core->dyn.par;
    int st = e->station, ka, ke, nl = d->n_eta_nodes, i, j;
    double a_deg, wa[2], floor;
    a_deg = fmod(alpha * RAD2DEG + 180.0, 360.0);
    if (a_deg < 0.0) a_deg += 360.0;
    a_deg -= 180.0;
    base_polar(d, st, a_deg, cl, cd);
    *cl += stall_delay_increment(e, a_deg, *cl);
    floor = *cd < CD_FLOOR ? *cd : CD_FLOOR;
    alpha_hats(d, a_deg, &ka, wa);
    ke = d->eta_index[st];
    for (i = 0; i < 2; i++) {
        for (j = 0; j < 2; j++) {
            double w = wa[i] * d->eta_weight[st][j];
            int node = (ka + i) * nl + (ke + j);
            if (w != 0.0) {
                *cl += w * p->dcl[node];
                *cd += w * p->dcd[node];
            }
        }
    }
    if (*cd < floor) *cd = floor;
}

/* Induction factors and residual at inflow angle phi (Ning 2014, eqs. as in CCBlade). */
static double residual(const Element *e, double phi, double *a_out, double *ap_out)
{
    const RotorCore *core = e->core;
    const RotorData *d = &core->data;
    const CoreParams *p = &core->dyn.par;
    double cl, cd, sphi = sin(phi), cphi = cos(phi), cn, ct, F = 1.0, k, kp, a, ap, lambda_r;
    double B = p->n_blades;
    aero_coefficients(e, phi - e->theta, &cl, &cd);
    cn = cl * cphi + cd * sphi;
    ct = cl * sphi - cd * cphi;
    if (p->tip_loss > 0.5) {
        double ftip = B / 2.0 * (d->tip_radius - e->r) / (e->r * fabs(sphi));
        F *= 2.0 / M_PI * acos(exp(-ftip));
    }
    if (p->hub_loss > 0.5) {
        double fhub = B / 2.0 * (e->r - d->hub_radius) / (d->hub_radius * fabs(sphi));
        F *= 2.0 / M_PI * acos(exp(-fhub));
    }
    if (F < 1e-12) F = 1e-12;
    k = e->sigma_p * cn / (4.0 * F * sphi * sphi);
    if (phi > 0.0) {
        if (k <= 2.0 / 3.0) {
            a = k / (1.0 + k);
        } else {                                   /* Buhl high-induction branch */
            double g1 = 2.0 * F * k - (10.0 / 9.0 - F);
            double g2 = 2.0 * F * k - F * (4.0 / 3.0 - F);
            double g3 = 2.0 * F * k - (25.0 / 9.0 - 2.0 * F);
            if (g2 < 0.0) g2 = 0.0;
            if (fabs(g3) < 1e-6) a = 1.0 - 1.0 / (2.0 * sqrt(g2 > 1e-300 ? g2 : 1e-300));
            else a = (g1 - sqrt(g2)) / g3;
        }
    } else {                                       /* propeller-brake region */
        a = k > 1.0 ? k / (k - 1.0) : 0.0;
    }
    kp = e->sigma_p * ct / (4.0 * F * sphi * cphi);
    ap = kp / (1.0 - kp);
    lambda_r = e->vy / e->vx;
    if (a_out) *a_out = a;
    if (ap_out) *ap_out = ap;
    if (phi > 0.0) return sphi / (1.0 - a) - cphi / lambda_r * (1.0 - kp);
    return sphi * (1.0 - k) - cphi / lambda_r * (1.0 - kp);
}

/* Brent's method (Brent 1973, "zeroin") on [xa, xb] with f(xa) f(xb) <= 0. */
static double brent(const Element *e, double xa, double xb, double fa, double fb)
{
    double c = xa, fc = fa, dd = xb - xa, ee = dd, tol, m, s, pp, q, r;
    int it;
    for (it = 0; it < 100; it++) {
        if ((fb > 0.0 && fc > 0.0) || (fb < 0.0 && fc < 0.0)) {
            c = xa; fc = fa; dd = ee = xb - xa;
        }
        if (fabs(fc) < fabs(fb)) {
            xa = xb; xb = c; c = xa;
            fa = fb; fb = fc; fc = fa;
        }
        tol = 2.0 * 2.2e-16 * fabs(xb) + 0.5e-13;
        m = 0.5 * (c - xb);
        if (fabs(m) <= tol || fb == 0.0) break;
        if (fabs(ee) >= tol && fabs(fa) > fabs(fb)) {
            s = fb / fa;
            if (xa == c) {
                pp = 2.0 * m * s; q = 1.0 - s;
            } else {
                q = fa / fc; r = fb / fc;
                pp = s * (2.0 * m * q * (q - r) - (xb - xa) * (r - 1.0));
                q = (q - 1.0) * (r - 1.0) * (s - 1.0);
            }
            if (pp > 0.0) q = -q; else pp = -pp;
            if (2.0 * pp < fmin(3.0 * m * q - fabs(tol * q), fabs(ee * q))) {
                ee = dd; dd = pp / q;
            } else {
                dd = m; ee = m;
            }
        } else {
            dd = m; ee = m;
        }
        xa = xb; fa = fb;
        xb += fabs(dd) > tol ? dd : (m > 0.0 ? tol : -tol);
        fb = residual(e, xb, NULL, NULL);
    }
    return xb;
}

/* Sign change on [lo, hi] with finite end values (a root is bracketed). */
static int brackets(double flo, double fhi)
{
    return isfinite(flo) && isfinite(fhi) && flo * fhi <= 0.0;
}

/* Ning's (2014, section 2.3) bracketing rule, as calib.bem.rootfind.bracket:
 *   1. [eps, pi/2] (windmill) if the residual changes sign there;
 *   2. else [-pi/4, -eps] (propeller brake) only if R(-pi/4) < 0 < R(-eps);
 *   3. else [pi/2, pi - eps] (windmill with phi > 90 deg, e.g. where the in-plane
 *      velocity reverses near the root in yaw).
 * Taking rule 2 on any sign change would pick a spurious phi < 0 root where R(-eps) < 0
 * < R(-pi/4). Returns 0 and the bracket, or -1 when none of the three brackets a root. */
static int ning_bracket(const Element *e, double *lo, double *hi, double *flo, double *fhi)
{
    const double eps = 1e-6;
    double fa, fb;
    *lo = eps; *hi = M_PI / 2.0;
    *flo = residual(e, *lo, NULL, NULL);
    *fhi = residual(e, *hi, NULL, NULL);
    if (brackets(*flo, *fhi)) return 0;
    fa = residual(e, -M_PI / 4.0, NULL, NULL);
    fb = residual(e, -eps, NULL, NULL);
    if (fa < 0.0 && fb > 0.0) {
        *lo = -M_PI / 4.0; *hi = -eps;
        *flo = fa; *fhi = fb;
        return 0;
    }
    *lo = M_PI / 2.0; *hi = M_PI - eps;
    *flo = *fhi;
    *fhi = residual(e, *hi, NULL, NULL);
    return brackets(*flo, *fhi) ? 0 : -1;
}

int aero_solve_element(const Element *e, double *phi, double *a, double *ap)
{
    double lo, hi, flo, fhi;
    if (fabs(e->vx) < 1e-8 || fabs(e->vy) < 1e-8) {   /* no axial or no tangential flow */
        *phi = atan2(e->vx, e->vy);
        *a = 0.0; *ap = 0.0;
        return 0;
    }
    if (ning_bracket(e, &lo, &hi, &flo, &fhi) != 0) {
        *phi = atan2(e->vx, e->vy);
        *a = 0.0; *ap = 0.0;
        return -1;
    }
    *phi = brent(e, lo, hi, flo, fhi);
    residual(e, *phi, a, ap);
    return 0;
}
