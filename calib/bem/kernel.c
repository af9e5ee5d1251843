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
    /* per node of each distinct table: C_L, C_L' h, C_D, C_D' h (SectionPolars.lookup's y and m) */
    const double *table;
    const int64_t *table_row;   /* (n_stations,) the table of each station */
    int64_t n_grid, n_stations;
    double step_deg, inv_step;  /* inv_step: 1 / step when that is exact (a power of two), else 0 */
    /* per section */
    const int64_t *station;
    const double *theta, *vx, *vy, *r, *sigma, *chord, *rho;
    const double *tip_f, *hub_f, *lam;  /* B (R - r) / (2 r), B (r - R_h) / (2 R_h), V_y / V_x */
    double n_blades;
    int tip_loss, hub_loss, drag_axial, drag_tangential, wake_rotation;
    /* an additive correction field on hat functions of (alpha, eta) after the look-up, or
     * field_alpha NULL (calib.bem.stages.CompiledPolar; calib.corrections.CorrectionGrid.evaluate
     * and calib.effects.correction_field.floor_drag): alpha nodes [deg], eta nodes [-], nodal
     * values of the lift and drag blocks (n_alpha x n_eta, row-major), the drag floor, and per
     * section the eta cell and its two hats' values at eta = r / R_tip (bem_eta_hats) */
    const double *field_alpha, *field_eta, *field_lift, *field_drag;
    int64_t field_n_alpha, field_n_eta;
    double field_floor;
    const int64_t *eta_cell;
    const double *eta_w0, *eta_w1;
} Problem;

/* numpy's float mod (np.mod): the sign of the divisor */
static double py_mod(double a, double b) {
    if (a > 0.0 && a < b) return a;      /* fmod's own result there, without the call */
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
    double x = p->inv_step != 0.0 ? a * p->inv_step : a / h;   /* equal when inv_step is exact */
    if (!isfinite(x)) {             /* numpy would fail to index; a NaN residual stops the section */
        *cl = *cd = NAN;
        return;
    }
    int64_t i = (int64_t)x;
    if (i > p->n_grid - 2) i = p->n_grid - 2;
    double t = x - (double)i;
    double t2 = t * t, t3 = t * t * t;
    double h00 = 2 * t3 - 3 * t2 + 1, h10 = t3 - 2 * t2 + t, h01 = -2 * t3 + 3 * t2, h11 = t3 - t2;
    const double *n0 = p->table + 4 * (p->table_row[p->station[j]] * p->n_grid + i), *n1 = n0 + 4;
    *cl = h00 * n0[0] + h10 * n0[1] + h01 * n1[0] + h11 * n1[1];
    *cd = h00 * n0[2] + h10 * n0[3] + h01 * n1[2] + h11 * n1[3];
}

/* the two hats at x on n nodes nd (corrections._hat_columns): cell k, values w0, w1 */
static void hats(const double *nd, int64_t n, double x, int64_t *k, double *w0, double *w1) {
    int64_t kk = 0;
    if (isnan(x)) kk = n - 2;
    else for (int64_t i = 1; i < n - 1; i++) kk += x >= nd[i];
    double t = (x - nd[kk]) / (nd[kk + 1] - nd[kk]);
    double a0 = 1.0 - t, a1 = t;
    if (x < nd[0]) {              /* the first hat ramps to zero over one spacing */
        double tb = (nd[0] - x) / (nd[1] - nd[0]);
        a0 = tb < 1.0 ? 1.0 - tb : 0.0;
        a1 = 0.0;
    } else if (x > nd[n - 1]) {   /* the last hat likewise */
        double ta = (x - nd[n - 1]) / (nd[n - 1] - nd[n - 2]);
        a1 = ta < 1.0 ? 1.0 - ta : 0.0;
        a0 = 0.0;
    }
    *k = kk; *w0 = a0; *w1 = a1;
}

/* the eta hats of n sections (once per batch): cell, values */
void bem_eta_hats(int64_t n, const double *nodes, int64_t n_nodes, const double *eta, int64_t *cell, double *w0,
                  double *w1) {
    for (int64_t j = 0; j < n; j++) hats(nodes, n_nodes, eta[j], cell + j, w0 + j, w1 + j);
}

/* sum over the four corners of a section's cell, in CorrectionGrid._corners' order */
static double corners(const double *nodal, int64_t row, int64_t ne, const double v[4]) {
    double total = v[0] * nodal[row];
    total = total + v[1] * nodal[row + 1];
    total = total + v[2] * nodal[row + ne];
    return total + v[3] * nodal[row + ne + 1];
}

/* C_L, C_D of section j at alpha [deg]: the table, then the correction field when there is one */
static void polar(const Problem *p, int64_t j, double alpha_deg, double *cl, double *cd) {
    lookup(p, j, alpha_deg, cl, cd);
    if (!p->field_alpha) return;
    int64_t k, ke;
    double a0, a1, e0, e1;
    hats(p->field_alpha, p->field_n_alpha, alpha_deg, &k, &a0, &a1);
    ke = p->eta_cell[j]; e0 = p->eta_w0[j]; e1 = p->eta_w1[j];
    int64_t ne = p->field_n_eta, row = k * ne + ke;
    double v[4] = {a0 * e0, a0 * e1, a1 * e0, a1 * e1};
    double cd0 = *cd, floor = cd0 < p->field_floor ? cd0 : p->field_floor;
    double c = cd0 + corners(p->field_drag, row, ne, v);
    *cl = *cl + corners(p->field_lift, row, ne, v);
    *cd = c >= floor ? c : floor;
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
    double F = 1.0, tip = 1.0, hub = 1.0;
    double as = fabs(s);
    if (p->tip_loss) tip = prandtl(p->tip_f[j] / as);
    if (p->hub_loss) hub = prandtl(p->hub_f[j] / as);
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
    double lam = p->lam[j];
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
    polar(p, j, (phi - p->theta[j]) * (180.0 / PI), &cl, &cd);
    return residual_at(p, j, phi, cl, cd);
}

/* R at (index[m], phi[m]) for m < n */
void bem_residual(const Problem *p, int64_t n, const int64_t *index, const double *phi, double *out) {
    for (int64_t m = 0; m < n; m++) out[m] = residual(p, index[m], phi[m]);
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
        polar(p, index[m], (phi[m] - p->theta[index[m]]) * (180.0 / PI), cl + m, cd + m);
}

/* The quantities of section_pass at the last residual evaluation of a section (rows of ROOT_ROWS) */
#define ROOT_ROWS 9
static void store_root(double *root, int64_t n, int64_t j, double alpha_deg, double cl, double cd, Equations e) {
    double row[ROOT_ROWS] = {alpha_deg, cl, cd, e.residual, e.a, e.ap, e.cn, e.ct, e.F};
    for (int m = 0; m < ROOT_ROWS; m++) root[m * n + j] = row[m];
}

/* Every section at its root phi[j] (sections.section_pass without effects, k = 0): angle of
 * attack [deg], C_L, C_D, residual, a, a', c_n, c_t (rotor axes), F, W [m/s], N', T' [N/m],
 * c_n, c_t (chord axes); out is (14, n), row-major. Where phi[j] is the phi bem_solve ended on
 * (solved_phi[j]), its stored quantities (root, ROOT_ROWS x n) are the same numbers and are reused;
 * solved_phi may be NULL. */
void bem_values(const Problem *p, int64_t n, const double *phi, const double *solved_phi, const double *root,
                double *out) {
    for (int64_t j = 0; j < n; j++) {
        double alpha_rad = phi[j] - p->theta[j];
        double alpha_deg, cl, cd;
        Equations e;
        if (solved_phi && phi[j] == solved_phi[j]) {
            alpha_deg = root[j]; cl = root[n + j]; cd = root[2 * n + j];
            e.residual = root[3 * n + j]; e.a = root[4 * n + j]; e.ap = root[5 * n + j];
            e.cn = root[6 * n + j]; e.ct = root[7 * n + j]; e.F = root[8 * n + j];
        } else {
            alpha_deg = alpha_rad * (180.0 / PI);
            polar(p, j, alpha_deg, &cl, &cd);
            e = equations(p, j, phi[j], cl, cd);
        }
        double ux = p->vx[j] * (1.0 - e.a), uy = p->vy[j] * (1.0 + e.ap);
        double w2 = ux * ux + uy * uy;
        double q = 0.5 * p->rho[j] * w2 * p->chord[j];
        double sa = sin(alpha_rad), ca = cos(alpha_rad);
        double row[14] = {alpha_deg, cl, cd, e.residual, e.a, e.ap, e.cn, e.ct, e.F, sqrt(w2), e.cn * q, e.ct * q,
                          cl * ca + cd * sa, cl * sa - cd * ca};
        for (int m = 0; m < 14; m++) out[m * n + j] = row[m];
    }
}

/* Ning's bracket and the Anderson-Bjorck iteration per section, the sequence of rootfind.bracket
 * and rootfind.solve_brackets for each section, with LANES sections in flight at once: their
 * residual evaluations are independent, so the processor overlaps them. */
#define LANES 4

typedef struct {
    int64_t j, it;
    int stage;             /* 0: at lo, 1: at hi, 2: at -pi/4, 3: at -eps, 4: at pi - eps, 5: iterating */
    double lo, hi, flo, fhi, fa_neg, a, b, fa, fb, x;
    double alpha_deg, cl, cd;   /* of the last evaluation */
    Equations e;
} Lane;

typedef struct {
    const Problem *p;
    double xtol, ftol;
    int64_t max_iter;
    double *lo, *hi, *flo, *fhi, *phi, *fphi, *root;
    uint8_t *found;
    int64_t *iters;
    int64_t n;
} Out;

static void finish(const Out *o, Lane *l, int found, double phi, double fphi) {
    int64_t j = l->j;
    o->lo[j] = l->lo; o->hi[j] = l->hi; o->flo[j] = l->flo; o->fhi[j] = l->fhi; o->found[j] = (uint8_t)found;
    o->phi[j] = phi; o->fphi[j] = fphi; o->iters[j] = l->it;
    /* what section_pass needs at the root: the last evaluation's, where the section ended on it */
    if (l->stage == 5 && phi == l->x) {
        store_root(o->root, o->n, j, l->alpha_deg, l->cl, l->cd, l->e);
    } else if (isfinite(phi)) {             /* an endpoint of the bracket that is a root */
        double alpha_deg = (phi - o->p->theta[j]) * (180.0 / PI), cl, cd;
        polar(o->p, j, alpha_deg, &cl, &cd);
        store_root(o->root, o->n, j, alpha_deg, cl, cd, equations(o->p, j, phi, cl, cd));
    }
    l->j = -1;
}

/* next Anderson-Bjorck point of an iterating lane (it already incremented) */
static void ab_point(Lane *l) {
    double a = l->a, b = l->b, fa = l->fa, fb = l->fb;
    double c = b - fb * (b - a) / (fb - fa);
    double lo_w = a < b ? a : b, hi_w = a > b ? a : b;
    if (!isfinite(c) || c <= lo_w || c >= hi_w || l->it % 8 == 0) c = 0.5 * (a + b);
    l->x = c;
}

/* the bracket is found: start the iteration (or finish at an endpoint that is a root) */
static void start_iteration(const Out *o, Lane *l) {
    l->a = l->lo; l->b = l->hi; l->fa = l->flo; l->fb = l->fhi;
    if (fabs(l->fa) <= o->ftol || fabs(l->fb) <= o->ftol) {
        int pick_a = fabs(l->fa) <= fabs(l->fb);
        finish(o, l, 1, pick_a ? l->a : l->b, pick_a ? l->fa : l->fb);
        return;
    }
    if (o->max_iter < 1) { finish(o, l, 1, l->b, l->fb); return; }
    l->stage = 5;
    l->it = 1;
    ab_point(l);
}

/* take the residual f at l->x and set the next point (or finish) */
static void consume(const Out *o, Lane *l, double f) {
    switch (l->stage) {
    case 0:
        l->flo = f; l->stage = 1; l->x = HALF_PI;
        return;
    case 1:
        l->fhi = f;
        if (isfinite(l->flo) && isfinite(l->fhi) && (l->flo * l->fhi <= 0)) { start_iteration(o, l); return; }
        l->stage = 2; l->x = -0.25 * PI;
        return;
    case 2:
        l->fa_neg = f; l->stage = 3; l->x = -EPS_PHI;
        return;
    case 3:
        if (l->fa_neg < 0 && f > 0) {
            l->lo = -0.25 * PI; l->hi = -EPS_PHI; l->flo = l->fa_neg; l->fhi = f;
            start_iteration(o, l);
            return;
        }
        l->stage = 4; l->x = PI - EPS_PHI;
        return;
    case 4:
        l->lo = HALF_PI; l->hi = PI - EPS_PHI; l->flo = l->fhi; l->fhi = f;
        if (isfinite(l->flo) && isfinite(f) && (l->flo * f <= 0)) start_iteration(o, l);
        else finish(o, l, 0, NAN, NAN);
        return;
    default: {
        double c = l->x, fc = f, fb = l->fb;
        int flip = fc * fb < 0;
        double m = 1.0 - fc / fb;
        if (!(m > 0 && isfinite(m))) m = 0.5;
        double new_a = flip ? l->b : l->a;
        double new_fa = flip ? fb : l->fa * m;
        l->a = new_a; l->fa = new_fa; l->b = c; l->fb = fc;
        double ac = fabs(c);
        int conv = (fabs(fc) <= o->ftol || fabs(c - new_a) <= o->xtol * (ac > 1.0 ? ac : 1.0)) && isfinite(fc);
        if (conv) { finish(o, l, 1, c, fc); return; }
        if (l->it == o->max_iter) { finish(o, l, 1, l->b, l->fb); return; }
        l->it++;
        ab_point(l);
    }
    }
}

void bem_solve(const Problem *p, int64_t n, double xtol, double ftol, int64_t max_iter,
               double *lo_out, double *hi_out, double *flo_out, double *fhi_out, uint8_t *found_out,
               double *phi_out, double *fphi_out, int64_t *iters_out, double *root_out, int64_t *order,
               int64_t *start) {
    /* root_out: ROOT_ROWS x n (see bem_values); order: n and start: n_stations + 1 zeros, scratch */
    Out o = {p, xtol, ftol, max_iter, lo_out, hi_out, flo_out, fhi_out, phi_out, fphi_out, root_out, found_out,
             iters_out, n};
    Lane lanes[LANES];
    int64_t next = 0;
    /* sections station by station (a counting sort): each station's table stays in cache */
    for (int64_t j = 0; j < n; j++) start[p->station[j] + 1]++;
    for (int64_t q = 0; q < p->n_stations; q++) start[q + 1] += start[q];
    for (int64_t j = 0; j < n; j++) order[start[p->station[j]]++] = j;
    for (int q = 0; q < LANES; q++) lanes[q].j = -1;
    for (;;) {
        int busy = 0;
        for (int q = 0; q < LANES; q++) {
            Lane *l = &lanes[q];
            if (l->j < 0 && next < n) {
                l->j = order[next++]; l->it = 0; l->stage = 0; l->x = EPS_PHI; l->lo = EPS_PHI; l->hi = HALF_PI;
            }
        }
        double f[LANES];
        for (int q = 0; q < LANES; q++) {
            Lane *l = &lanes[q];
            if (l->j >= 0) {
                l->alpha_deg = (l->x - p->theta[l->j]) * (180.0 / PI);
                polar(p, l->j, l->alpha_deg, &l->cl, &l->cd);
                l->e = equations(p, l->j, l->x, l->cl, l->cd);
                f[q] = l->e.residual;
                busy = 1;
            }
        }
        if (!busy) break;
        for (int q = 0; q < LANES; q++)
            if (lanes[q].j >= 0) consume(&o, &lanes[q], f[q]);
    }
}

/* NaN when either is (np.minimum) */
static double nan_min(double a, double b) {
    if (isnan(a) || isnan(b)) return NAN;
    return a < b ? a : b;
}

/* The screen for several roots at sections index[m] (the converged ones) at their roots phi[j]:
 * a negative lift slope within the window (SlopeEnvelope.at on env, 4 x (n_stations x env_grid):
 * cl_min, cl_max, cd_min, cd_max [1/deg]), then the slope budget of multiple_roots.needs_search
 * with the one-sided partials of bem_residual_partials at C_L, C_D after the field (if any).
 * search[j] set to 1 where to search. */
void bem_screen(const Problem *p, int64_t n_c, const int64_t *index, const double *phi, const double *env,
                int64_t env_grid, int64_t first_node, double env_step, double margin, double rel_step,
                uint8_t *search) {
    int64_t plane = p->n_stations * env_grid;
    const double per_rad = 180.0 / PI;
    for (int64_t m = 0; m < n_c; m++) {
        int64_t j = index[m];
        double alpha_deg = (phi[j] - p->theta[j]) * (180.0 / PI);
        double node_f = rint(py_mod(alpha_deg + 180.0, 360.0) / env_step);
        if (!isfinite(node_f)) { search[j] = 1; continue; }
        int64_t node = (int64_t)node_f - first_node;
        if (node < 0) node = 0;
        if (node > env_grid - 1) node = env_grid - 1;
        int64_t at = p->station[j] * env_grid + node;
        double cl_min = env[at], cl_max = env[plane + at], cd_min = env[2 * plane + at], cd_max = env[3 * plane + at];
        if (!(cl_min < 0.0)) continue;
        double cl, cd, d0, d_cl, d_cd;
        polar(p, j, alpha_deg, &cl, &cd);
        bem_residual_partials(p, 1, &j, phi + j, &cl, &cd, rel_step, &d0, &d_cl, &d_cd);
        double worst = d0 + nan_min(d_cl * (cl_min * per_rad), d_cl * (cl_max * per_rad))
                       + nan_min(d_cd * (cd_min * per_rad), d_cd * (cd_max * per_rad));
        search[j] = !(worst >= margin * fabs(d0)) || !(d0 > 0);
    }
}

/* ---- exact derivatives at the root: forward mode on KMAX columns (sections.section_pass on
 * calib.bem.dual numbers, for chains the kernel runs: the field or no polar effect, no induction
 * or loads effect). Columns: 0 phi, 1 pitch [rad], 2 inflow speed [m/s], then the field's two
 * probes (additive C_L, C_D) at probe_col, probe_col + 1 (probe_col < 0: no field). */
#define KMAX 6
typedef struct { double v, d[KMAX]; } Dn;

static Dn dn_const(double v) { Dn r; r.v = v; for (int c = 0; c < KMAX; c++) r.d[c] = 0.0; return r; }
static Dn dn_add(Dn a, Dn b) { Dn r; r.v = a.v + b.v; for (int c = 0; c < KMAX; c++) r.d[c] = a.d[c] + b.d[c]; return r; }
static Dn dn_sub(Dn a, Dn b) { Dn r; r.v = a.v - b.v; for (int c = 0; c < KMAX; c++) r.d[c] = a.d[c] - b.d[c]; return r; }
static Dn dn_mul(Dn a, Dn b) {
    Dn r; r.v = a.v * b.v;
    for (int c = 0; c < KMAX; c++) r.d[c] = a.d[c] * b.v + b.d[c] * a.v;
    return r;
}
static Dn dn_div(Dn a, Dn b) {
    Dn r; r.v = a.v / b.v;
    for (int c = 0; c < KMAX; c++) r.d[c] = (a.d[c] - b.d[c] * r.v) / b.v;
    return r;
}
static Dn dn_scale(Dn a, double s) { Dn r; r.v = a.v * s; for (int c = 0; c < KMAX; c++) r.d[c] = a.d[c] * s; return r; }
static Dn dn_shift(Dn a, double s) { a.v = a.v + s; return a; }
/* f(a) with f'(a.v) = slope */
static Dn dn_chain(Dn a, double value, double slope) {
    Dn r; r.v = value;
    for (int c = 0; c < KMAX; c++) r.d[c] = a.d[c] * slope;
    return r;
}
static Dn dn_rsub(double s, Dn a) { return dn_shift(dn_scale(a, -1.0), s); }
static Dn dn_sqrt(Dn a) { double q = sqrt(a.v); return dn_chain(a, q, 0.5 / q); }

/* (2/pi) acos(exp(-f)) on duals (prandtl) */
static Dn dn_prandtl(Dn f) {
    double e = exp(-f.v);
    Dn x = dn_chain(dn_scale(f, -1.0), e, e);
    return dn_scale(dn_chain(x, acos(e), -1.0 / sqrt(1.0 - e * e)), 2.0 / PI);
}

/* sections at their roots phi: the derivatives of the residual, N', T', c_n, c_t (chord axes) and
 * the angle of attack [deg] on the first k columns (dout: 6 x n x k, row-major); the values are
 * bem_values' */
void bem_derivatives(const Problem *p, int64_t n, int64_t k, int64_t probe_col, const double *phi,
                     const double *vx_per_wind, const double *vy_per_wind, double *dout) {
    for (int64_t j = 0; j < n; j++) {
        Dn ph = dn_const(phi[j]), th = dn_const(p->theta[j]);
        ph.d[0] = 1.0; th.d[1] = 1.0;
        Dn vx = dn_const(p->vx[j]), vy = dn_const(p->vy[j]);
        vx.d[2] = vx_per_wind[j]; vy.d[2] = vy_per_wind[j];
        Dn alpha_rad = dn_sub(ph, th);
        double alpha_deg = alpha_rad.v * (180.0 / PI);
        Dn alpha_x = dn_scale(alpha_rad, 180.0 / PI);
        alpha_x.v = alpha_deg;
        /* the table and its slopes [1/deg] (SectionPolars.lookup) */
        double h = p->step_deg, cl0, cd0, dcl0, dcd0;
        {
            double a = py_mod(alpha_deg + 180.0, 360.0);
            double x = p->inv_step != 0.0 ? a * p->inv_step : a / h;
            int64_t i = isfinite(x) ? (int64_t)x : 0;
            if (i > p->n_grid - 2) i = p->n_grid - 2;
            double t = x - (double)i, t2 = t * t, t3 = t * t * t;
            double h00 = 2 * t3 - 3 * t2 + 1, h10 = t3 - 2 * t2 + t, h01 = -2 * t3 + 3 * t2, h11 = t3 - t2;
            double d00 = 6 * t2 - 6 * t, d10 = 3 * t2 - 4 * t + 1, d01 = -6 * t2 + 6 * t, d11 = 3 * t2 - 2 * t;
            const double *n0 = p->table + 4 * (p->table_row[p->station[j]] * p->n_grid + i), *n1 = n0 + 4;
            cl0 = h00 * n0[0] + h10 * n0[1] + h01 * n1[0] + h11 * n1[1];
            cd0 = h00 * n0[2] + h10 * n0[3] + h01 * n1[2] + h11 * n1[3];
            dcl0 = (d00 * n0[0] + d10 * n0[1] + d01 * n1[0] + d11 * n1[1]) / h;
            dcd0 = (d00 * n0[2] + d10 * n0[3] + d01 * n1[2] + d11 * n1[3]) / h;
            if (!isfinite(x)) cl0 = cd0 = dcl0 = dcd0 = NAN;
        }
        Dn cl = dn_chain(alpha_x, cl0, dcl0), cd = dn_chain(alpha_x, cd0, dcd0);
        if (p->field_alpha) {
            int64_t ka, ke;
            double a0, a1, e0, e1;
            const double *nd = p->field_alpha;
            int64_t na = p->field_n_alpha, ne = p->field_n_eta;
            hats(nd, na, alpha_deg, &ka, &a0, &a1);
            ke = p->eta_cell[j]; e0 = p->eta_w0[j]; e1 = p->eta_w1[j];
            /* the alpha hats' slopes [1/deg] (corrections._hat_columns) */
            double s0 = -1.0 / (nd[ka + 1] - nd[ka]), s1 = 1.0 / (nd[ka + 1] - nd[ka]);
            if (alpha_deg < nd[0]) {
                double h0 = nd[1] - nd[0];
                s0 = (nd[0] - alpha_deg) / h0 < 1.0 ? 1.0 / h0 : 0.0; s1 = 0.0;
            } else if (alpha_deg > nd[na - 1]) {
                double hn = nd[na - 1] - nd[na - 2];
                s1 = (alpha_deg - nd[na - 1]) / hn < 1.0 ? -1.0 / hn : 0.0; s0 = 0.0;
            }
            int64_t row = ka * ne + ke;
            double v[4] = {a0 * e0, a0 * e1, a1 * e0, a1 * e1}, dv[4] = {s0 * e0, s0 * e1, s1 * e0, s1 * e1};
            Dn dcl = dn_chain(alpha_x, corners(p->field_lift, row, ne, v), corners(p->field_lift, row, ne, dv));
            Dn dcd = dn_chain(alpha_x, corners(p->field_drag, row, ne, v), corners(p->field_drag, row, ne, dv));
            Dn cd_base = cd;
            cl = dn_add(cl, dcl);
            cd = dn_add(cd, dcd);
            cl.d[probe_col] += 1.0;
            cd.d[probe_col + 1] += 1.0;
            Dn floor = cd_base.v < p->field_floor ? cd_base : dn_const(p->field_floor);
            if (!(cd.v >= floor.v)) cd = floor;
        }
        /* section_equations */
        Dn s = dn_chain(ph, sin(ph.v), cos(ph.v)), c = dn_chain(ph, cos(ph.v), -sin(ph.v));
        Dn as = dn_chain(s, fabs(s.v), s.v > 0 ? 1.0 : (s.v < 0 ? -1.0 : 0.0));
        Dn F = dn_const(1.0), tip = dn_const(1.0), hub = dn_const(1.0);
        if (p->tip_loss) tip = dn_prandtl(dn_div(dn_const(p->tip_f[j]), as));
        if (p->hub_loss) hub = dn_prandtl(dn_div(dn_const(p->hub_f[j]), as));
        if (!p->tip_loss) F = hub;
        else F = p->hub_loss ? dn_mul(tip, hub) : tip;
        Dn cn = dn_add(dn_mul(cl, c), dn_mul(cd, s));
        Dn ct = dn_sub(dn_mul(cl, s), dn_mul(cd, c));
        Dn cn_i = p->drag_axial ? cn : dn_mul(cl, c);
        Dn ct_i = p->drag_tangential ? ct : dn_mul(cl, s);
        Dn kk = dn_div(dn_scale(cn_i, p->sigma[j]), dn_mul(dn_mul(dn_scale(F, 4.0), s), s));
        Dn kp = dn_div(dn_scale(ct_i, p->sigma[j]), dn_mul(dn_mul(dn_scale(F, 4.0), s), c));
        Dn a;
        if (ph.v > 0) {
            if (kk.v <= 2.0 / 3.0) {
                a = dn_div(kk, dn_shift(kk, 1.0));
            } else {
                Dn fk2 = dn_mul(dn_scale(F, 2.0), kk);
                Dn g1 = dn_sub(fk2, dn_rsub(10.0 / 9.0, F));
                Dn g2 = dn_sub(fk2, dn_mul(F, dn_rsub(4.0 / 3.0, F)));
                Dn g3 = dn_sub(fk2, dn_rsub(25.0 / 9.0, dn_scale(F, 2.0)));
                a = fabs(g3.v) < 1e-6 ? dn_rsub(1.0, dn_div(dn_const(0.5), dn_sqrt(g2)))
                                      : dn_div(dn_sub(g1, dn_sqrt(g2)), g3);
            }
        } else {
            a = kk.v > 1.0 ? dn_div(kk, dn_shift(kk, -1.0)) : dn_scale(kk, 0.0);
        }
        if (!p->wake_rotation) kp = dn_scale(kp, 0.0);
        Dn ap = dn_div(kp, dn_rsub(1.0, kp));
        Dn lam = dn_div(vy, vx);
        Dn tail = dn_mul(dn_div(c, lam), dn_rsub(1.0, kp));
        Dn res = ph.v > 0 ? dn_sub(dn_div(s, dn_rsub(1.0, a)), tail) : dn_sub(dn_mul(s, dn_rsub(1.0, kk)), tail);
        /* section_loads */
        Dn ux = dn_mul(vx, dn_rsub(1.0, a)), uy = dn_mul(vy, dn_shift(ap, 1.0));
        Dn w2 = dn_add(dn_mul(ux, ux), dn_mul(uy, uy));
        Dn q = dn_scale(w2, 0.5 * p->rho[j] * p->chord[j]);
        Dn Np = dn_mul(cn, q), Tp = dn_mul(ct, q);
        Dn sa = dn_chain(alpha_rad, sin(alpha_rad.v), cos(alpha_rad.v));
        Dn ca = dn_chain(alpha_rad, cos(alpha_rad.v), -sin(alpha_rad.v));
        Dn cn_c = dn_add(dn_mul(cl, ca), dn_mul(cd, sa)), ct_c = dn_sub(dn_mul(cl, sa), dn_mul(cd, ca));
        const Dn *qs[6] = {&res, &Np, &Tp, &cn_c, &ct_c, &alpha_x};
        for (int m = 0; m < 6; m++)
            for (int64_t col = 0; col < k; col++) dout[(m * n + j) * k + col] = qs[m]->d[col];
    }
}

/* The implicit-function step at the roots (sections.eliminate_phi) on bem_derivatives' output d
 * (6 x n x k): for each quantity q of rows 1..5, dq/dc + dq/dphi dphi/dc with dphi/dc = -dR/dc / dR/dphi
 * for the columns c >= 1 (the pitch column per degree), written at sel[j] of full (5 x size x (k - 1),
 * zeros on entry) for the converged sections; the same operations in the same order as numpy's. */
void bem_eliminate(int64_t n, int64_t k, const double *d, const uint8_t *converged, const int64_t *sel,
                   int64_t size, double *full) {
    double dphi[KMAX];
    for (int64_t j = 0; j < n; j++) {
        if (!converged[j]) continue;
        const double *R = d + j * k;
        for (int64_t c = 1; c < k; c++) dphi[c] = -R[c] / R[0];
        for (int64_t m = 1; m < 6; m++) {
            const double *q = d + (m * n + j) * k;
            double *out = full + ((m - 1) * size + sel[j]) * (k - 1);
            for (int64_t c = 1; c < k; c++) out[c - 1] = q[c] + q[0] * dphi[c];
            out[0] *= PI / 180.0;
        }
    }
}
