/*
 * rotor_core.c -- instance life cycle, variable access, and the time stepping that ties
 * aerodynamics (aero.c), inflow (inflow.c) and structure (structure.c) together.
 *
 * One evaluation at the current state computes, for every blade and element:
 * free-stream velocity -> structural velocities -> quasi-steady BEM induction ->
 * dynamic induction (Oye filter, advanced over dt) -> loads; then the spanwise
 * integrals (trapezoid over [hub, stations..., tip], zero load at hub and tip):
 *   thrust = B int N' cos(cone) ds, torque = B int T' z ds, power = Omega Q,
 *   root flap / edge moment = int N' (z - z_root) ds / int T' (z - z_root) ds,
 * with the weights of calib.bem.solver.integration_weights written into the resources
 * (plus inertial and gravity terms with flexible blades), the same definitions as the
 * native BEM of calib.bem so that steady averages agree.
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "core_internal.h"

void core_vlog(CoreLogger log, void *env, int level, const char *fmt, va_list ap)
{
    char buf[1024];
    if (!log) return;
    vsnprintf(buf, sizeof buf, fmt, ap);
    log(env, level, buf);
}

void core_logf(const RotorCore *core, int level, const char *fmt, ...)
{
    va_list ap;
    if (!core) return;
    va_start(ap, fmt);
    core_vlog(core->log, core->log_env, level, fmt, ap);
    va_end(ap);
}

RotorCore *core_create(const char *resource_dir, CoreLogger log, void *log_env)
{
    char path[4096];
    size_t n;
    RotorCore *core = (RotorCore *)calloc(1, sizeof(RotorCore));
    if (!core) {
        if (log) log(log_env, 2, "out of memory allocating the rotor model");
        return NULL;
    }
    core->log = log;
    core->log_env = log_env;
    if (!resource_dir || !resource_dir[0]) {
        core_logf(core, 2, "no resource location given; the FMU needs resources/rotor.dat");
        free(core);
        return NULL;
    }
    n = strlen(resource_dir);
    snprintf(path, sizeof path, "%s%srotor.dat", resource_dir,
             resource_dir[n - 1] == '/' ? "" : "/");
    if (rotor_data_read(&core->data, path, core) != 0) {
        free(core);
        return NULL;
    }
    core_reset_state(core);
    return core;
}

void core_free(RotorCore *core)
{
    if (!core) return;
    rotor_data_free(&core->data);
    free(core);
}

void core_reset_state(RotorCore *core)
{
    CoreParams par = core->dyn.par;
    CoreInputs in = core->dyn.in;
    memset(&core->dyn, 0, sizeof core->dyn);
    core->dyn.par = par;
    core->dyn.in = in;
}

int core_var_size(const RotorCore *core, CoreVar var)
{
    switch (var) {
    case CV_DCL:
    case CV_DCD:
        return core->data.n_alpha_nodes * core->data.n_eta_nodes;
    case CV_PITCH_OFFSET_DEG:
    case CV_ROOT_FLAP_MOMENT:
    case CV_ROOT_EDGE_MOMENT:
    case CV_TIP_FLAP_DEFLECTION:
    case CV_TIP_EDGE_DEFLECTION:
        return CORE_MAX_BLADES;
    case CV_NORMAL_FORCE:
    case CV_ANGLE_OF_ATTACK:
    case CV_OUT_STATION_RADIUS:
        return core->data.n_out;
    default:
        return (var >= 0 && var < CV_COUNT) ? 1 : 0;
    }
}

/* Pointer to the storage of a parameter or input, NULL for outputs. */
static double *var_ref(RotorCore *core, CoreVar var, int i)
{
    CoreParams *p = &core->dyn.par;
    CoreInputs *in = &core->dyn.in;
    switch (var) {
    case CV_WIND_SPEED: return &in->wind_speed;
    case CV_ROTOR_SPEED_RPM: return &in->rotor_speed_rpm;
    case CV_PITCH_DEG: return &in->pitch_deg;
    case CV_AIR_DENSITY: return &in->air_density;
    case CV_YAW_DEG: return &in->yaw_deg;
    case CV_DCL: return &p->dcl[i];
    case CV_DCD: return &p->dcd[i];
    case CV_PITCH_OFFSET_DEG: return &p->pitch_offset_deg[i];
    case CV_STALL_DELAY_STRENGTH: return &p->stall_strength;
    case CV_TIP_LOSS: return &p->tip_loss;
    case CV_HUB_LOSS: return &p->hub_loss;
    case CV_TOWER_SHADOW: return &p->tower_shadow;
    case CV_SHEAR: return &p->shear;
    case CV_SHEAR_EXPONENT: return &p->shear_exponent;
    case CV_YAW_EFFECTS: return &p->yaw_effects;
    case CV_SKEWED_WAKE: return &p->skewed_wake;
    case CV_DYNAMIC_INFLOW: return &p->dynamic_inflow;
    case CV_STALL_DELAY_MODEL: return &p->stall_model;
    case CV_FLEXIBLE: return &p->flexible;
    case CV_GRAVITY: return &p->gravity;
    case CV_FLAP_FREQUENCY_HZ: return &p->flap_freq_hz;
    case CV_EDGE_FREQUENCY_HZ: return &p->edge_freq_hz;
    case CV_FLAP_DAMPING_RATIO: return &p->flap_damping;
    case CV_EDGE_DAMPING_RATIO: return &p->edge_damping;
    case CV_BLADE_MASS: return &p->blade_mass;
    case CV_TOWER_HEIGHT: return &p->tower_height;
    case CV_TOWER_BASE_DIAMETER: return &p->tower_base_d;
    case CV_TOWER_TOP_DIAMETER: return &p->tower_top_d;
    case CV_TOWER_CLEARANCE: return &p->tower_clearance;
    case CV_SHAFT_TILT_DEG: return &p->shaft_tilt_deg;
    case CV_N_BLADES: return &p->n_blades;
    case CV_MAX_STEP: return &p->max_step;
    case CV_MAX_AZIMUTH_STEP_DEG: return &p->max_azimuth_step_deg;
    case CV_INITIAL_AZIMUTH_DEG: return &p->initial_azimuth_deg;
    case CV_DEBUG_FAULT: return &p->debug_fault;
    case CV_DEBUG_FAULT_WIND_SPEED: return &p->debug_fault_wind_speed;
    default: return NULL;
    }
}

static int check_index(const RotorCore *core, CoreVar var, int index)
{
    int n = core_var_size(core, var);
    if (n <= 0 || index < 0 || index >= n) {
        core_logf(core, 2, "variable id %d has %d element(s); index %d is out of range",
                  (int)var, n, index);
        return -1;
    }
    return 0;
}

int core_set(RotorCore *core, CoreVar var, int index, double value)
{
    double *ref;
    if (check_index(core, var, index)) return -1;
    ref = var_ref(core, var, index);
    if (!ref) {
        core_logf(core, 2, "variable id %d is an output and cannot be set", (int)var);
        return -1;
    }
    if (!isfinite(value)) {
        core_logf(core, 2, "variable id %d[%d]: value must be finite, got %g", (int)var, index, value);
        return -1;
    }
    *ref = value;
    return 0;
}

int core_get(const RotorCore *core, CoreVar var, int i, double *value)
{
    const CoreDynamic *dyn = &core->dyn;
    double *ref;
    if (check_index(core, var, i)) return -1;
    ref = var_ref((RotorCore *)core, var, i);
    if (ref) {
        *value = *ref;
        return 0;
    }
    switch (var) {
    case CV_POWER: *value = dyn->power; break;
    case CV_TORQUE: *value = dyn->torque; break;
    case CV_THRUST: *value = dyn->thrust; break;
    case CV_AZIMUTH_DEG: {
        double a = fmod(dyn->azimuth * RAD2DEG, 360.0);
        *value = a < 0.0 ? a + 360.0 : a;
        break;
    }
    case CV_ROOT_FLAP_MOMENT: *value = dyn->flap_moment[i]; break;
    case CV_ROOT_EDGE_MOMENT: *value = dyn->edge_moment[i]; break;
    case CV_TIP_FLAP_DEFLECTION: *value = dyn->q[i][0]; break;
    case CV_TIP_EDGE_DEFLECTION: *value = dyn->q[i][1]; break;
    case CV_NORMAL_FORCE: *value = dyn->fn[0][core->data.out_station[i]]; break;
    case CV_ANGLE_OF_ATTACK: *value = dyn->aoa[0][core->data.out_station[i]] * RAD2DEG; break;
    case CV_OUT_STATION_RADIUS: *value = core->data.r[core->data.out_station[i]]; break;
    case CV_TIP_RADIUS: *value = core->data.tip_radius; break;
    case CV_AERO_FAILURES: *value = dyn->aero_failures; break;
    default:
        core_logf(core, 2, "unknown variable id %d", (int)var);
        return -1;
    }
    return 0;
}

/* sum_i f_i w_i (g_i): spanwise integral with precomputed trapezoid weights. */
static double weighted_sum(int n, const double *f, const double *w, const double *g)
{
    double sum = 0.0;
    int i;
    for (i = 0; i < n; i++) sum += f[i] * w[i] * (g ? g[i] : 1.0);
    return sum;
}

/* Evaluate loads at the current state. dt > 0 advances the Oye filters over dt;
 * dt == 0 sets the induction to its quasi-steady value (equilibrium). */
static void evaluate(RotorCore *core, double dt)
{
    const RotorData *d = &core->data;
    CoreDynamic *dyn = &core->dyn;
    const CoreParams *p = &dyn->par;
    const CoreInputs *in = &dyn->in;
    int nb = (int)p->n_blades, ns = d->n_stations, b, i;
    double omega = in->rotor_speed_rpm * M_PI / 30.0;
    double rho = in->air_density, g = structure_gravity();
    double omega_r = omega * d->tip_radius, mean_a = 0.0, count = 0.0;
    double lambda_rotor = omega_r / sqrt(in->wind_speed * in->wind_speed + omega_r * omega_r + 1e-12);
    int dynamic = p->dynamic_inflow > 0.5 && dt > 0.0;

    /* rotor-mean axial induction of the current state (wake skew angle) */
    for (b = 0; b < nb; b++)
        for (i = 0; i < ns; i++)
            if (in->wind_speed > 0.1) { mean_a += dyn->w[b][i] / in->wind_speed; count += 1.0; }
    mean_a = count > 0.0 ? mean_a / count : 0.0;

    dyn->power = dyn->torque = dyn->thrust = 0.0;
    for (b = 0; b < CORE_MAX_BLADES; b++) dyn->flap_moment[b] = dyn->edge_moment[b] = 0.0;

    for (b = 0; b < nb; b++) {
        double psi = dyn->azimuth + 2.0 * M_PI * b / nb;
        double pitch = (in->pitch_deg + p->pitch_offset_deg[b]) * DEG2RAD;
        double qf, qe, force_flap, force_edge, gravity_t;
        for (i = 0; i < ns; i++) {
            Element e;
            double vx, vyw, phi, a, ap, w_eff, ux, uy, cl, cd, cn, ct, w2, sphi, cphi;
            double r = d->r[i];
            if (r <= d->hub_radius * (1.0 + 1e-9) || r >= d->tip_radius * (1.0 - 1e-9)) {
                dyn->fn[b][i] = dyn->ft[b][i] = dyn->aoa[b][i] = 0.0;   /* no load at hub/tip */
                dyn->w[b][i] = dyn->w_int[b][i] = dyn->w_qs[b][i] = dyn->w_qs_prev[b][i] = 0.0;
                continue;
            }
            inflow_wind(core, psi, i, &vx, &vyw);
            e.core = core;
            e.station = i;
            e.r = r;
            e.chord = d->chord[i];
            e.theta = d->twist_deg[i] * DEG2RAD + pitch;
            e.sigma_p = p->n_blades * d->chord[i] / (2.0 * M_PI * r);
            e.vx = vx - omega * d->y_az[i] * sin(d->cone[i])
                   - dyn->qd[b][0] * core->st.phi[i];                  /* flap velocity */
            e.vy = vyw + omega * d->z_az[i] + dyn->qd[b][1] * core->st.phi[i];  /* edge */
            e.lambda_rotor = lambda_rotor;
            if (aero_solve_element(&e, &phi, &a, &ap) != 0) dyn->aero_failures += 1.0;
            dyn->w_qs[b][i] = a * e.vx;
            if (dynamic) {
                inflow_oye_update(&dyn->w[b][i], &dyn->w_int[b][i], dyn->w_qs[b][i],
                                  dyn->w_qs_prev[b][i], dt, r / d->tip_radius, d->tip_radius,
                                  in->wind_speed, e.vx);
            } else {
                dyn->w[b][i] = dyn->w_int[b][i] = dyn->w_qs[b][i];
            }
            dyn->w_qs_prev[b][i] = dyn->w_qs[b][i];
            w_eff = dyn->w[b][i] * inflow_skew_factor(core, psi, r, mean_a);
            ux = e.vx - w_eff;
            uy = e.vy * (1.0 + ap);
            phi = atan2(ux, uy);
            sphi = sin(phi);
            cphi = cos(phi);
            aero_coefficients(&e, phi - e.theta, &cl, &cd);
            cn = cl * cphi + cd * sphi;
            ct = cl * sphi - cd * cphi;
            w2 = ux * ux + uy * uy;
            dyn->fn[b][i] = 0.5 * rho * w2 * e.chord * cn;
            dyn->ft[b][i] = 0.5 * rho * w2 * e.chord * ct;
            dyn->aoa[b][i] = phi - e.theta;
        }
        dyn->thrust += weighted_sum(ns, dyn->fn[b], d->w_thrust, NULL);
        dyn->torque += weighted_sum(ns, dyn->ft[b], d->w_torque, NULL);
        force_flap = weighted_sum(ns, dyn->fn[b], d->ds, core->st.phi);
        gravity_t = p->gravity > 0.5 ? g * sin(psi) : 0.0;
        force_edge = weighted_sum(ns, dyn->ft[b], d->ds, core->st.phi) + core->st.mass_phi * gravity_t;
        structure_accelerations(core, b, force_flap, force_edge, &qf, &qe);
        dyn->qdd[b][0] = qf;
        dyn->qdd[b][1] = qe;
        dyn->flap_moment[b] = weighted_sum(ns, dyn->fn[b], d->w_root, NULL) - qf * core->st.mass_phi_arm;
        dyn->edge_moment[b] = weighted_sum(ns, dyn->ft[b], d->w_root, NULL) - qe * core->st.mass_phi_arm
                              + core->st.mass_arm * gravity_t;
    }
    dyn->power = omega * dyn->torque;
}

static int check_inputs(const RotorCore *core, const CoreDynamic *dyn)
{
    const CoreInputs *in = &dyn->in;
    if (!(in->wind_speed >= 0.0 && in->wind_speed < 100.0)) {
        core_logf(core, 2, "wind speed must lie in [0, 100) m/s, got %g", in->wind_speed);
        return -1;
    }
    if (!(in->rotor_speed_rpm >= 0.0 && in->rotor_speed_rpm < 1000.0)) {
        core_logf(core, 2, "rotor speed must lie in [0, 1000) rpm, got %g", in->rotor_speed_rpm);
        return -1;
    }
    if (!(in->air_density > 0.0 && in->air_density < 10.0)) {
        core_logf(core, 2, "air density must lie in (0, 10) kg/m^3, got %g", in->air_density);
        return -1;
    }
    if (!(fabs(in->yaw_deg) < 89.0)) {
        core_logf(core, 2, "yaw misalignment must lie in (-89, 89) deg, got %g", in->yaw_deg);
        return -1;
    }
    if (!(fabs(in->pitch_deg) <= 180.0)) {
        core_logf(core, 2, "pitch must lie in [-180, 180] deg, got %g", in->pitch_deg);
        return -1;
    }
    return 0;
}

static int check_params(const RotorCore *core, const CoreDynamic *dyn)
{
    const CoreParams *p = &dyn->par;
    const RotorData *d = &core->data;
    if (p->n_blades != 2.0 && p->n_blades != 3.0) {
        core_logf(core, 2, "n_blades must be 2 or 3, got %g", p->n_blades);
        return -1;
    }
    if (!(p->max_step > 0.0) || !(p->max_azimuth_step_deg > 0.0)) {
        core_logf(core, 2, "max_step and max_azimuth_step must be > 0 (got %g s, %g deg)",
                  p->max_step, p->max_azimuth_step_deg);
        return -1;
    }
    if (p->flexible > 0.5 && !(p->flap_freq_hz > 0.0 && p->edge_freq_hz > 0.0 &&
                               p->flap_damping >= 0.0 && p->edge_damping >= 0.0 &&
                               p->blade_mass > 0.0)) {
        core_logf(core, 2, "flexible blades need frequencies > 0 Hz, damping ratios >= 0 "
                  "and blade mass > 0 kg");
        return -1;
    }
    /* semi-implicit Euler is stable for omega dt < 2; keep it accurate (omega dt <= 0.5) */
    if (p->flexible > 0.5 && 2.0 * M_PI * fmax(p->flap_freq_hz, p->edge_freq_hz) * p->max_step > 0.5) {
        core_logf(core, 2, "flexible blades: 2 pi f max_step = %g exceeds 0.5 (f = %g Hz, max_step = "
                  "%g s); lower the internal step", 2.0 * M_PI * fmax(p->flap_freq_hz, p->edge_freq_hz)
                  * p->max_step, fmax(p->flap_freq_hz, p->edge_freq_hz), p->max_step);
        return -1;
    }
    if ((p->flexible > 0.5 || p->gravity > 0.5) && !(p->blade_mass > 0.0)) {
        core_logf(core, 2, "blade mass must be > 0 kg, got %g", p->blade_mass);
        return -1;
    }
    if (p->tower_shadow > 0.5 && !(p->tower_height > 0.0 && p->tower_base_d > 0.0 &&
                                   p->tower_top_d > 0.0 && p->tower_clearance > 0.0)) {
        core_logf(core, 2, "tower shadow needs tower height, diameters and clearance > 0 m");
        return -1;
    }
    if (p->shear > 0.5 && !(d->hub_height > d->tip_radius)) {
        core_logf(core, 2, "shear needs a hub height above the tip radius (rotor data has %g m)",
                  d->hub_height);
        return -1;
    }
    if (p->stall_model != 0.0 && p->stall_model != 1.0 && p->stall_model != 2.0) {
        core_logf(core, 2, "stall delay model must be 0 (off), 1 (Snel) or 2 (Du & Selig), got %g",
                  p->stall_model);
        return -1;
    }
    return 0;
}

int core_initialize(RotorCore *core, double start_time)
{
    CoreDynamic *dyn = &core->dyn;
    int b, nb;
    if (check_params(core, dyn) || check_inputs(core, dyn)) return -1;
    structure_setup(core);
    dyn->time = start_time;
    dyn->azimuth = dyn->par.initial_azimuth_deg * DEG2RAD;
    memset(dyn->q, 0, sizeof dyn->q);
    memset(dyn->qd, 0, sizeof dyn->qd);
    evaluate(core, 0.0);
    nb = (int)dyn->par.n_blades;
    if (dyn->par.flexible > 0.5) {
        /* start from the static deflection under the initial loads */
        for (b = 0; b < nb; b++) {
            double wf = 2.0 * M_PI * dyn->par.flap_freq_hz, we = 2.0 * M_PI * dyn->par.edge_freq_hz;
            dyn->q[b][0] = dyn->qdd[b][0] / (wf * wf);
            dyn->q[b][1] = dyn->qdd[b][1] / (we * we);
        }
        evaluate(core, 0.0);
    }
    dyn->initialized = 1;
    return 0;
}

/* TEST ONLY (adapter fault tests): what parameter debug_fault asks doStep to do instead of
 * stepping: 1 refuse with an error, 2 abort the process (a crash), 3 never return (a hang). */
static int debug_fault(RotorCore *core)
{
    volatile unsigned long spin = 0;
    int kind = (int)core->dyn.par.debug_fault;
    if (kind == 2) {
        core_logf(core, 2, "debug_fault = 2: aborting the process (test of crash handling)");
        abort();
    }
    if (kind == 3) {
        core_logf(core, 1, "debug_fault = 3: doStep hangs (test of timeout handling)");
        for (;;) spin++;
    }
    core_logf(core, 2, "debug_fault = %d: doStep refused (test of error handling)", kind);
    return CORE_STEP_REFUSED;
}

int core_do_step(RotorCore *core, double h)
{
    CoreDynamic *dyn = &core->dyn;
    double omega, dt_max, dt, n_needed;
    int n, k;
    if (!dyn->initialized) {
        core_logf(core, 2, "do_step called before initialization");
        return CORE_STEP_REFUSED;
    }
    if (!(h > 0.0) || !isfinite(h)) {
        core_logf(core, 2, "communication step size must be finite and > 0, got %g", h);
        return CORE_STEP_REFUSED;
    }
    if (check_inputs(core, dyn)) return CORE_STEP_REFUSED;
    if (dyn->par.debug_fault != 0.0 && dyn->in.wind_speed > dyn->par.debug_fault_wind_speed)
        return debug_fault(core);
    omega = dyn->in.rotor_speed_rpm * M_PI / 30.0;
    dt_max = dyn->par.max_step;
    if (fabs(omega) > 0.0) {
        double dt_az = dyn->par.max_azimuth_step_deg * DEG2RAD / fabs(omega);
        if (dt_az < dt_max) dt_max = dt_az;
    }
    n_needed = ceil(h / dt_max - 1e-9);       /* compared as a double: no int overflow */
    if (!(n_needed <= CORE_MAX_SUBSTEPS)) {
        core_logf(core, 2, "a communication step of %g s needs %.0f internal steps of at most %g s, "
                  "more than the %d allowed per doStep; use a shorter communication step",
                  h, n_needed, dt_max, CORE_MAX_SUBSTEPS);
        return CORE_STEP_REFUSED;
    }
    n = n_needed < 1.0 ? 1 : (int)n_needed;
    dt = h / n;
    for (k = 0; k < n; k++) {
        dyn->azimuth = fmod(dyn->azimuth + omega * dt, 2.0 * M_PI);
        structure_advance(core, dt);
        evaluate(core, dt);
        if (!isfinite(dyn->power) || !isfinite(dyn->thrust)) {
            core_logf(core, 2, "non-finite loads at t = %g s (unstable structure or inflow?)",
                      dyn->time + (k + 1) * dt);
            return CORE_STEP_FAILED;
        }
    }
    dyn->time += h;
    return 0;
}

/* ---- FMU state ------------------------------------------------------------------------ */
/* Are the n doubles stored from address p (a struct made of doubles only, or an array)
 * finite? Read with memcpy: no aliasing or bounds assumptions. */
static int finite_doubles(const void *p, size_t n_bytes)
{
    size_t i;
    for (i = 0; i + sizeof(double) <= n_bytes; i += sizeof(double)) {
        double x;
        memcpy(&x, (const char *)p + i, sizeof x);
        if (!isfinite(x)) return 0;
    }
    return 1;
}

int core_check_dynamic(const RotorCore *core, const CoreDynamic *dyn)
{
    const CoreParams *p = &dyn->par;
    struct { const char *what; const void *where; size_t bytes; } blocks[] = {
        {"parameters", &dyn->par, sizeof dyn->par},
        {"inputs", &dyn->in, sizeof dyn->in},
        {"induced velocities", dyn->w, sizeof dyn->w},
        {"induced velocities", dyn->w_int, sizeof dyn->w_int},
        {"induced velocities", dyn->w_qs_prev, sizeof dyn->w_qs_prev},
        {"induced velocities", dyn->w_qs, sizeof dyn->w_qs},
        {"modal coordinates", dyn->q, sizeof dyn->q},
        {"modal rates", dyn->qd, sizeof dyn->qd},
        {"modal accelerations", dyn->qdd, sizeof dyn->qdd},
        {"element loads", dyn->fn, sizeof dyn->fn},
        {"element loads", dyn->ft, sizeof dyn->ft},
        {"angles of attack", dyn->aoa, sizeof dyn->aoa},
        {"root moments", dyn->flap_moment, sizeof dyn->flap_moment},
        {"root moments", dyn->edge_moment, sizeof dyn->edge_moment},
    };
    size_t k;
    for (k = 0; k < sizeof blocks / sizeof blocks[0]; k++) {
        if (!finite_doubles(blocks[k].where, blocks[k].bytes)) {
            core_logf(core, 2, "FMU state: non-finite %s", blocks[k].what);
            return -1;
        }
    }
    if (!isfinite(dyn->time) || !isfinite(dyn->azimuth) || !isfinite(dyn->power) ||
        !isfinite(dyn->torque) || !isfinite(dyn->thrust)) {
        core_logf(core, 2, "FMU state: non-finite time, azimuth or rotor loads");
        return -1;
    }
    if (dyn->initialized != 0 && dyn->initialized != 1) {
        core_logf(core, 2, "FMU state: initialization flag %d is neither 0 nor 1", dyn->initialized);
        return -1;
    }
    /* what indexes arrays or bounds loops must hold even before initialization */
    if (p->n_blades != 2.0 && p->n_blades != 3.0) {
        core_logf(core, 2, "FMU state: number of blades %g is not 2 or 3", p->n_blades);
        return -1;
    }
    if (!(dyn->aero_failures >= 0.0)) {
        core_logf(core, 2, "FMU state: negative failure count %g", dyn->aero_failures);
        return -1;
    }
    if (!(fabs(dyn->azimuth) <= 2.0 * M_PI)) {
        core_logf(core, 2, "FMU state: azimuth %g rad outside [-2 pi, 2 pi]", dyn->azimuth);
        return -1;
    }
    if (dyn->initialized && (check_params(core, dyn) || check_inputs(core, dyn))) {
        core_logf(core, 2, "FMU state: parameters or inputs invalid (see above)");
        return -1;
    }
    return 0;
}

void core_restore_dynamic(RotorCore *core, const CoreDynamic *dyn)
{
    memcpy(&core->dyn, dyn, sizeof core->dyn);
    if (core->dyn.initialized) structure_setup(core);   /* derived from the restored parameters */
}
