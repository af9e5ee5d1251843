/*
 * inflow.c -- azimuth-resolved free stream and dynamic inflow.
 *
 * Wind at a blade element (CCBlade windComponents, S.A. Ning, NREL; the same as
 * calib.bem.kinematics): with yaw y, tilt t, local cone c, azimuth a (0 = blade up,
 * increasing with rotation) and the blade axis (x_az, y_az, z_az) in the azimuthal frame,
 *   V(h)   = V_hub (1 + h / H)^alpha_shear,  h = (y_az sin a + z_az cos a) cos t - x_az sin t
 *   Vx     = V [(cos y sin t cos a + sin y sin a) sin c + cos y cos t cos c]
 *   Vy,wind= V (cos y sin t sin a - sin y cos a)
 * and the rotation adds -Omega y_az sin c to Vx and Omega z_az to Vy (caller).
 *
 * Tower shadow: potential flow around a cylinder upstream of the tower (Bak, Aagaard
 * Madsen & Johansen, Risoe-R-1143, 2001; the AeroDyn "TwrPotent" model):
 *   u / V = 1 - R_t^2 (x^2 - y^2) / (x^2 + y^2)^2
 * with x the upwind distance of the element from the tower axis, y the lateral offset
 * and R_t(z) the local tower radius (linear taper); applied below the tower top.
 *
 * Dynamic inflow: the Oye model (Snel & Schepers, ECN-C--94-107, 1995; M.O.L. Hansen,
 * Aerodynamics of Wind Turbines, 3rd ed., 2015, section 10.1), two first-order filters
 * on the induced velocity W per element,
 *   W_int + tau1 dW_int/dt = W_qs + k tau1 dW_qs/dt,  W + tau2 dW/dt = W_int,
 *   tau1 = 1.1 / (1 - 1.3 a) R / V0,  tau2 = (0.39 - 0.26 (r/R)^2) tau1,  k = 0.6,
 * integrated exactly over a step for a piecewise-constant right-hand side. In steady
 * conditions W = W_qs, the quasi-steady BEM induction of the element.
 *
 * Skewed wake in yaw (Glauert; Pitt & Peters 1981; Burton et al., Wind Energy Handbook
 * 2nd ed., eq. 4.55): a_skew = a [1 + 15 pi/32 (r/R) tan(chi/2) sin(psi)],
 * chi = (0.6 a + 1) gamma the wake skew angle.
 */
#include <math.h>

#include "core_internal.h"

static double tower_factor(const RotorCore *core, double psi, int st)
{
    const CoreParams *p = &core->dyn.par;
    const RotorData *d = &core->data;
    double t = p->shaft_tilt_deg * DEG2RAD, sa = sin(psi), ca = cos(psi);
    double x_az = d->x_az[st], y_az = d->y_az[st], z_az = d->z_az[st];
    double height = d->hub_height + (y_az * sa + z_az * ca) * cos(t) - x_az * sin(t);
    double lateral = z_az * sa - y_az * ca;
    /* upwind distance from the tower axis: x_az points downwind (CCBlade), and shaft
     * tilt moves the lower half of the disc away from the tower */
    double x = p->tower_clearance - x_az * cos(t) - z_az * ca * sin(t);
    double frac, radius, den;
    if (height >= p->tower_height || height < 0.0) return 1.0;
    frac = height / p->tower_height;
    radius = 0.5 * (p->tower_base_d + frac * (p->tower_top_d - p->tower_base_d));
    den = (x * x + lateral * lateral);
    if (den < radius * radius) den = radius * radius;   /* never inside the tower */
    return 1.0 - radius * radius * (x * x - lateral * lateral) / (den * den);
}

void inflow_wind(const RotorCore *core, double psi, int st, double *vx, double *vy_wind)
{
    const CoreParams *p = &core->dyn.par;
    const RotorData *d = &core->data;
    const CoreInputs *in = &core->dyn.in;
    double yaw = p->yaw_effects > 0.5 ? in->yaw_deg * DEG2RAD : 0.0;
    double t = p->shaft_tilt_deg * DEG2RAD;
    double sy = sin(yaw), cy = cos(yaw), s_t = sin(t), c_t = cos(t), sa = sin(psi), ca = cos(psi);
    double sc = sin(d->cone[st]), cc = cos(d->cone[st]);
    double v = in->wind_speed;
    if (p->shear > 0.5 && p->shear_exponent != 0.0) {
        double h = (d->y_az[st] * sa + d->z_az[st] * ca) * c_t - d->x_az[st] * s_t;
        double ratio = 1.0 + h / d->hub_height;
        v *= ratio > 0.0 ? pow(ratio, p->shear_exponent) : 0.0;
    }
    if (p->tower_shadow > 0.5) v *= tower_factor(core, psi, st);
    *vx = v * ((cy * s_t * ca + sy * sa) * sc + cy * c_t * cc);
    *vy_wind = v * (cy * s_t * sa - sy * ca);
}

void inflow_oye_update(double *w, double *w_int, double w_qs, double w_qs_prev,
                       double dt, double radius_ratio, double rotor_radius, double wind_speed,
                       double axial_velocity)
{
    const double k = 0.6;
    double a = axial_velocity > 1e-6 ? *w / axial_velocity : 0.0;
    double v0 = wind_speed > 0.1 ? wind_speed : 0.1;
    double tau1, tau2, h;
    if (a > 0.5) a = 0.5;
    if (a < 0.0) a = 0.0;
    tau1 = 1.1 / (1.0 - 1.3 * a) * rotor_radius / v0;
    tau2 = (0.39 - 0.26 * radius_ratio * radius_ratio) * tau1;
    h = w_qs + k * tau1 * (w_qs - w_qs_prev) / dt;
    *w_int = h + (*w_int - h) * exp(-dt / tau1);
    *w = *w_int + (*w - *w_int) * exp(-dt / tau2);
}

double inflow_skew_factor(const RotorCore *core, double psi, double r, double mean_induction)
{
    const CoreParams *p = &core->dyn.par;
    double gamma, chi, f;
    if (p->yaw_effects < 0.5 || p->skewed_wake < 0.5) return 1.0;
    gamma = core->dyn.in.yaw_deg * DEG2RAD;
    chi = (0.6 * mean_induction + 1.0) * gamma;
    f = 1.0 + 15.0 * M_PI / 32.0 * (r / core->data.tip_radius) * tan(0.5 * chi) * sin(psi);
    return f > 0.0 ? f : 0.0;
}
