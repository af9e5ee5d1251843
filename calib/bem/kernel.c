/* Compiled root search of the native BEM: Ning's residual, his brackets and the
 * Anderson-Bjorck iteration, one section at a time (calib/bem/kernel.py builds and loads it).
 *
 * The same arithmetic, in the same order, as calib/bem/residual.py (section_equations on
 * plain arrays, no induction-stage effect), calib/bem/polar_grid.py (SectionPolars.lookup)
 * and calib/bem/rootfind.py (bracket, solve_brackets): compiled with -ffp-contract=off and
 * without -ffast-math, a root differs from the numpy path's only through the last bit of
 * sin, cos, exp, acos (libm against numpy's own loops).
 */
#include <math.h>
#include <stdint.h>

#define EPS_PHI 1e-6
#define PI 3.141592653589793
#define HALF_PI (0.5 * PI)

typedef struct {
    const double *cl_nodes, *cd_nodes, *cl_slopes, *cd_slopes;  /* (n_stations, n_grid), C order */
    int64_t n_grid;
    double step_deg;
    /* per section */
    const int64_t *station;
    const double *theta, *vx, *vy, *r, *sigma, *chord, *rho;
    double hub_radius, tip_radius, n_blades;
    int tip_loss, hub_loss, drag_axial, drag_tangential, wake_rotation;
} Problem;

/* numpy's float mod (np.mod): the sign of the divisor */
static double py_mod(double a, double b) {
    double m = fmod(a, b);
    if (m != 0.0) {
        if ((b < 0) != (m < 0)) m += b;
    } else {
        m = copysign(0.0, b);
    }
    return m;
}

static void lookup(const Problem *p, int64_t j, double alpha_deg, double *cl, double *cd) {
    double h = p->step_deg;
    double a = py_mod(alpha_deg + 180.0, 360.0);
    double x = a / h;
    if (!isfinite(x)) {             /* numpy would fail to index; a NaN residual stops the section */
        *cl = *cd = NAN;
        return;
    }
    int64_t i = (int64_t)x;
    if (i > p->n_grid - 2) i = p->n_grid - 2;
    double t = x - (double)i;
    double t2 = t * t, t3 = t * t * t;
    double h00 = 2 * t3 - 3 * t2 + 1, h10 = t3 - 2 * t2 + t, h01 = -2 * t3 + 3 * t2, h11 = t3 - t2;
    int64_t k = p->station[j] * p->n_grid + i;
    *cl = h00 * p->cl_nodes[k] + h10 * (p->cl_slopes[k] * h) + h01 * p->cl_nodes[k + 1]
          + h11 * (p->cl_slopes[k + 1] * h);
    *cd = h00 * p->cd_nodes[k] + h10 * (p->cd_slopes[k] * h) + h01 * p->cd_nodes[k + 1]
          + h11 * (p->cd_slopes[k + 1] * h);
}

/* (2/pi) acos(exp(-f)): exactly (2/pi) acos(0) once exp(-f) < 3.2e-17 (f > 38), where the
 * correctly rounded acos of the tiny argument is already the double nearest pi/2 */
static double prandtl(double f) {
    if (f > 38.0) return (2.0 / PI) * 1.5707963267948966;
    return (2.0 / PI) * acos(exp(-f));
}

typedef struct { double residual, a, ap, cn, ct, F; } Equations;

/* section_equations at inflow angle phi with the polar's cl, cd given */
static Equations equations(const Problem *p, int64_t j, double phi, double cl, double cd) {
    Equations e;
    double s = sin(phi), c = cos(phi);
    double r = p->r[j], B = p->n_blades;
    double F = 1.0, tip = 1.0, hub = 1.0;
    double as = fabs(s);
    if (p->tip_loss) tip = prandtl(B * (p->tip_radius - r) / (2.0 * r) / as);
    if (p->hub_loss) hub = prandtl(B * (r - p->hub_radius) / (2.0 * p->hub_radius) / as);
    if (!p->tip_loss) F = hub;
    else F = p->hub_loss ? tip * hub : tip;
    double cn = cl * c + cd * s;
    double ct = cl * s - cd * c;
    double cn_i = p->drag_axial ? cn : cl * c;
    double ct_i = p->drag_tangential ? ct : cl * s;
    double k = p->sigma[j] * cn_i / (4.0 * F * s * s);
    double kp = p->sigma[j] * ct_i / (4.0 * F * s * c);
    double a;
    if (phi > 0) {
        if (k <= 2.0 / 3.0) {
            a = k / (1.0 + k);
        } else {
            double g1 = 2.0 * F * k - (10.0 / 9.0 - F);
            double g2 = 2.0 * F * k - F * (4.0 / 3.0 - F);
            double g3 = 2.0 * F * k - (25.0 / 9.0 - 2.0 * F);
            a = fabs(g3) < 1e-6 ? 1.0 - 0.5 / sqrt(g2) : (g1 - sqrt(g2)) / g3;
        }
    } else {
        a = k > 1.0 ? k / (k - 1.0) : 0.0 * k;
    }
    if (!p->wake_rotation) kp = 0.0 * kp;
    double lam = p->vy[j] / p->vx[j];
    e.residual = phi > 0 ? s / (1.0 - a) - c / lam * (1.0 - kp) : s * (1.0 - k) - c / lam * (1.0 - kp);
    e.a = a;
    e.ap = kp / (1.0 - kp);
    e.cn = cn;
    e.ct = ct;
    e.F = F;
    return e;
}

static double residual_at(const Problem *p, int64_t j, double phi, double cl, double cd) {
    return equations(p, j, phi, cl, cd).residual;
}

static double residual(const Problem *p, int64_t j, double phi) {
    double cl, cd;
    lookup(p, j, (phi - p->theta[j]) * (180.0 / PI), &cl, &cd);
    return residual_at(p, j, phi, cl, cd);
}

/* R at (index[m], phi[m]) for m < n */
void bem_residual(const Problem *p, int64_t n, const int64_t *index, const double *phi, double *out) {
    for (int64_t m = 0; m < n; m++) out[m] = residual(p, index[m], phi[m]);
}

/* Ning's bracket and the Anderson-Bjorck iteration per section (rootfind.bracket and
 * rootfind.solve_brackets); outputs lo, hi (the bracket), flo, fhi, found, phi, fphi, iters. */
void bem_solve(const Problem *p, int64_t n, double xtol, double ftol, int64_t max_iter,
               double *lo_out, double *hi_out, double *flo_out, double *fhi_out, uint8_t *found_out,
               double *phi_out, double *fphi_out, int64_t *iters_out) {
    for (int64_t j = 0; j < n; j++) {
        double lo = EPS_PHI, hi = HALF_PI;
        double flo = residual(p, j, lo), fhi = residual(p, j, hi);
        int found = isfinite(flo) && isfinite(fhi) && (flo * fhi <= 0);
        if (!found) {
            double fa = residual(p, j, -0.25 * PI), fb = residual(p, j, -EPS_PHI);
            if (fa < 0 && fb > 0) {
                lo = -0.25 * PI; hi = -EPS_PHI; flo = fa; fhi = fb;
                found = 1;
            } else {
                double fc = residual(p, j, PI - EPS_PHI);
                lo = HALF_PI; hi = PI - EPS_PHI; flo = fhi; fhi = fc;
                found = isfinite(flo) && isfinite(fc) && (flo * fc <= 0);
            }
        }
        lo_out[j] = lo; hi_out[j] = hi; flo_out[j] = flo; fhi_out[j] = fhi; found_out[j] = (uint8_t)found;
        double phi = NAN, fphi = NAN;
        int64_t iters = 0;
        if (found) {
            double a = lo, b = hi, fa = flo, fb = fhi;
            if (fabs(fa) <= ftol || fabs(fb) <= ftol) {
                int pick_a = fabs(fa) <= fabs(fb);
                phi = pick_a ? a : b;
                fphi = pick_a ? fa : fb;
            } else {
                int done = 0;
                for (int64_t it = 1; it <= max_iter; it++) {
                    double c = b - fb * (b - a) / (fb - fa);
                    double lo_w = a < b ? a : b, hi_w = a > b ? a : b;
                    if (!isfinite(c) || c <= lo_w || c >= hi_w || it % 8 == 0) c = 0.5 * (a + b);
                    double fc = residual(p, j, c);
                    int flip = fc * fb < 0;
                    double m = 1.0 - fc / fb;
                    if (!(m > 0 && isfinite(m))) m = 0.5;
                    double new_a = flip ? b : a;
                    double new_fa = flip ? fb : fa * m;
                    a = new_a; fa = new_fa; b = c; fb = fc;
                    iters = it;
                    double ac = fabs(c);
                    int conv = (fabs(fc) <= ftol || fabs(c - new_a) <= xtol * (ac > 1.0 ? ac : 1.0)) && isfinite(fc);
                    if (conv) {
                        phi = c; fphi = fc; done = 1;
                        break;
                    }
                }
                if (!done) { phi = b; fphi = fb; }
            }
        }
        phi_out[j] = phi; fphi_out[j] = fphi; iters_out[j] = iters;
    }
}

/* One-sided differences of the residual in phi, C_L, C_D at given sections (the screen for
 * several roots; sections._residual_partials): d0, d_cl, d_cd. */
void bem_residual_partials(const Problem *p, int64_t n, const int64_t *index, const double *phi,
                           const double *cl, const double *cd, double rel_step, double *d0, double *d_cl,
                           double *d_cd) {
    for (int64_t m = 0; m < n; m++) {
        int64_t j = index[m];
        double aphi = fabs(phi[m]), acl = fabs(cl[m]), acd = fabs(cd[m]);
        double h = rel_step * (aphi > 1.0 ? aphi : 1.0);
        double hc = rel_step * (acl > 1.0 ? acl : 1.0);
        double hd = rel_step * (acd > 1e-2 ? acd : 1e-2);
        double r0 = residual_at(p, j, phi[m] + 0.0, cl[m] + 0.0, cd[m] + 0.0);
        d0[m] = (residual_at(p, j, phi[m] + h, cl[m] + 0.0, cd[m] + 0.0) - r0) / h;
        d_cl[m] = (residual_at(p, j, phi[m] + 0.0, cl[m] + hc, cd[m] + 0.0) - r0) / hc;
        d_cd[m] = (residual_at(p, j, phi[m] + 0.0, cl[m] + 0.0, cd[m] + hd) - r0) / hd;
    }
}

/* C_L, C_D at (index[m], phi[m]) (SectionPolars.lookup at alpha = phi - theta) */
void bem_polar(const Problem *p, int64_t n, const int64_t *index, const double *phi, double *cl, double *cd) {
    for (int64_t m = 0; m < n; m++)
        lookup(p, index[m], (phi[m] - p->theta[index[m]]) * (180.0 / PI), cl + m, cd + m);
}

/* Every section at its root phi[j] (sections.section_pass without effects, k = 0): angle of
 * attack [deg], C_L, C_D, residual, a, a', c_n, c_t (rotor axes), F, W [m/s], N', T' [N/m],
 * c_n, c_t (chord axes); out is (14, n), row-major. */
void bem_values(const Problem *p, int64_t n, const double *phi, double *out) {
    for (int64_t j = 0; j < n; j++) {
        double alpha_rad = phi[j] - p->theta[j];
        double alpha_deg = alpha_rad * (180.0 / PI);
        double cl, cd;
        lookup(p, j, alpha_deg, &cl, &cd);
        Equations e = equations(p, j, phi[j], cl, cd);
        double ux = p->vx[j] * (1.0 - e.a), uy = p->vy[j] * (1.0 + e.ap);
        double w2 = ux * ux + uy * uy;
        double q = 0.5 * p->rho[j] * w2 * p->chord[j];
        double sa = sin(alpha_rad), ca = cos(alpha_rad);
        double row[14] = {alpha_deg, cl, cd, e.residual, e.a, e.ap, e.cn, e.ct, e.F, sqrt(w2), e.cn * q, e.ct * q,
                          cl * ca + cd * sa, cl * sa - cd * ca};
        for (int m = 0; m < 14; m++) out[m * n + j] = row[m];
    }
}
